"""Plan files: the schema (every field checked, errors naming the file, line and field) and the ``Plan`` a file
becomes. The YAML itself is read by ``roarmctl.validation``; tasks become motions in
``roarmctl.motion.planning.tasks``."""
