"""Picture formats: chosen by the output file's extension (no matplotlib import here)."""

from __future__ import annotations

from pathlib import Path

from roarmctl.errors import InputError

PICTURE_FORMATS = ("png", "svg", "pdf")


def picture_format(path: str | Path) -> str:
    """'png', 'svg' or 'pdf' from ``path``'s extension; anything else is an input error (exit 2)."""
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in PICTURE_FORMATS:
        raise InputError(f"{path}: cannot tell the picture format from '{Path(path).suffix or 'no extension'}'",
                         "end the file name in .png, .svg or .pdf")
    return suffix
