"""Atomic file writes: a temporary file in the target's directory, then a rename.

An interrupted run therefore never leaves a half-written trajectory, log or picture.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from roarmctl.errors import InputError


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    return atomic_write_with(path, lambda f: f.write(data))


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    return atomic_write_bytes(path, text.encode())


def atomic_write_json(path: str | os.PathLike, obj: Any, indent: int | None = 1) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=indent) + "\n")


def atomic_write_with(path: str | os.PathLike, writer: Callable[[Any], Any]) -> Path:
    """Call ``writer(binary_file)`` on a temporary file next to ``path``, then rename it into place."""
    target = Path(path)
    if target.exists() and not target.is_file():
        # a rename would replace a device (/dev/null, a serial port) or fail on a directory
        what = "a directory" if target.is_dir() else "not a regular file"
        raise InputError(f"cannot write {target}: it is {what}", "give the path of a file to write")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    except OSError as exc:
        raise InputError(f"cannot write {target}: {exc.strerror or exc}", "choose a directory you can write to") from None
    try:
        with os.fdopen(fd, "wb") as f:
            writer(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, _mode_for(target))  # mkstemp makes 0600; give the file the usual mode
        os.replace(tmp, target)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):
            raise InputError(f"cannot write {target}: {exc.strerror or exc}", "check the disk space and permissions") from None
        raise
    return target


def _mode_for(target: Path) -> int:
    """The existing file's mode, or 0666 less the process umask for a new file."""
    try:
        return target.stat().st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask
