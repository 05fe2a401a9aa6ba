"""CLI commands of this area (being written)."""


def register(app) -> None:
    """Add this module's commands to ``app``."""
