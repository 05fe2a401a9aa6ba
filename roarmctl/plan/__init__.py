"""Plan files: the schema, bounded YAML reading with line numbers."""
