"""Files in and out, safely: atomic writes, and the one bounded reader every input goes through.

Writes: a temporary file in the target's directory, then a rename, so an interrupted run never
leaves a half-written trajectory, log or picture. Reads (``read_bytes``, ``read_text``): regular
files only, under a size cap, optionally only inside a description's ``Roots``. Parsing and field
checks of what was read live in ``roarmctl.validation`` and ``roarmctl.checks``.
"""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import stat
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

from roarmctl.errors import InputError


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    return atomic_write_with(path, lambda f: f.write(data))


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` as UTF-8 to ``path`` atomically; return the path."""
    return atomic_write_bytes(path, text.encode())


def atomic_write_json(path: str | os.PathLike, obj: Any, indent: int | None = 1) -> Path:
    """Write ``obj`` as JSON (and a newline) to ``path`` atomically; return the path."""
    return atomic_write_text(path, json.dumps(obj, indent=indent) + "\n")


def atomic_write_with(path: str | os.PathLike, writer: Callable[[Any], Any]) -> Path:
    """Call ``writer(binary_file)`` on a temporary file next to ``path``, then rename it into place."""
    import tempfile  # here, not at the top: it loads random, ~2.5 ms of every start-up

    target = check_output_file(path)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(target.parent)
        fd, tmp = tempfile.mkstemp(prefix=temporary_prefix(target), suffix=".tmp", dir=target.parent)
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


#: The temporaries roarmctl writes beside an output, named ``.NAME.roarmctl-PID-XXXXXXXX.tmp`` (a file) or
#: ``.NAME.roarmctl-PID-XXXXXXXX`` (a folder being filled: a bag), PID the writing process and XXXXXXXX
#: ``tempfile``'s random part: a name only roarmctl makes, so that a later run can remove what a killed one
#: (SIGKILL, a power cut) left, and nothing else.
_TEMPORARY = re.compile(r"\.(?:.+)\.roarmctl-([0-9]{1,10})-[a-z0-9_]{8}(\.tmp)?")
_SWEPT: set[str] = set()  # folders this process has swept (once each: a folder of many outputs is listed once)


def temporary_prefix(target: Path) -> str:
    """The start of the name of a temporary written beside ``target`` by this process (see ``_TEMPORARY``)."""
    return f".{target.name}.roarmctl-{os.getpid()}-"


def remove_stale_temporaries(folder: str | os.PathLike[str]) -> list[str]:
    """Remove from ``folder`` the temporaries of roarmctl processes that no longer run (a write killed before
    its rename): only names that match ``_TEMPORARY`` whose process is gone, a file for a ``.tmp`` name and a
    folder otherwise, symlinks never followed. Once per folder and process; returns the names removed."""
    try:
        key = os.path.realpath(folder)
    except (OSError, ValueError):
        return []
    if key in _SWEPT:
        return []
    _SWEPT.add(key)
    removed = []
    try:
        with os.scandir(os.fspath(folder)) as entries:
            stale = [(e, m) for e in entries if (m := _TEMPORARY.fullmatch(e.name)) and not _running(int(m[1]))]
        for entry, m in stale:
            if m[2] and entry.is_file(follow_symlinks=False):
                os.unlink(entry.path)
            elif not m[2] and entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                continue
            removed.append(entry.name)
    except OSError:
        pass  # a folder we cannot list or clean: the write itself says so if it fails
    return removed


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's counts)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True
    return True


def check_output_file(path: str | os.PathLike) -> Path:
    """``path`` as a file roarmctl may (re)write, else ``InputError`` (exit 2): a name of at most
    ``MAX_NAME_BYTES`` bytes that is not ``.``/``..``, and nothing there but a regular file (a rename
    would replace a device such as /dev/null or a serial port, or fail on a folder)."""
    target = Path(path)
    if target.name in ("", ".", "..") or str(path).endswith(os.sep):
        raise InputError(f"cannot write {_short(path)}: it names a folder", "give the path of a file to write")
    if len(os.fsencode(target.name)) > MAX_NAME_BYTES:
        raise InputError(f"cannot write {_short(path)}: the name is longer than {MAX_NAME_BYTES} bytes", "give a shorter name")
    try:
        st = os.stat(target)
    except FileNotFoundError:
        return target
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot write {_short(path)}: {_reason(exc)}") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"cannot write {_short(path)}: it is {_file_kind(st.st_mode)}, not a regular file",
                         "give the path of a file to write")
    return target


def check_writable(path: str | os.PathLike) -> Path:
    """``check_output_file``, and a probe that a file can be made where ``path`` will be written: in its folder, or
    in the nearest folder above it that exists (the missing ones are made at the write). Nothing is left behind.
    For an output written only after minutes of work or after the arm has moved (an execution log), so that a
    path that cannot be written is ``InputError`` (exit 2) before the work, not a lost result after it."""
    import tempfile

    target = check_output_file(path)
    folder = target.parent if str(target.parent) else Path(".")
    while not os.path.lexists(folder) and folder != folder.parent:
        folder = folder.parent
    try:
        fd, probe = tempfile.mkstemp(prefix=temporary_prefix(target), suffix=".tmp", dir=folder)
    except OSError as exc:
        raise InputError(f"cannot write {_short(path)}: {_reason(exc)}", "choose a folder you can write to") from None
    os.close(fd)
    os.unlink(probe)
    return target


def _mode_for(target: Path) -> int:
    """The existing file's mode, or 0666 less the process umask for a new file."""
    try:
        return target.stat().st_mode & 0o7777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


# --------------------------------------------------------------------------- bounded reading
#: The largest file any reader takes unless it gives its own cap (bytes).
DEFAULT_LIMIT = 16 * 1024 * 1024
_CHUNK = 1024 * 1024


#: The folder ``$(find NAME)`` stands for when package NAME is not declared: expanding a xacro that only
#: names such a folder in a string works; reading anything under it is refused naming the package.
UNKNOWN_PACKAGE = "/nonexistent/roarmctl-unknown-package"


class Roots:
    """The folders a description may read: its own folder and the package folders it declares.

    Every path is resolved (symlinks followed, ``..`` removed) before it is compared, so neither a
    symlink nor ``package://pkg/../..`` leads out. ``packages`` maps a ROS package name to its folder
    (``package://NAME/...``, ``$(find NAME)``); each package folder is a root too.
    """

    def __init__(self, folders: list[Path] | tuple[Path, ...] = (), packages: dict[str, Path] | None = None) -> None:
        self.packages = {str(k): Path(v).resolve() for k, v in (packages or {}).items()}
        self.folders = tuple(dict.fromkeys([Path(f).resolve() for f in folders] + list(self.packages.values())))

    def with_folder(self, folder: Path) -> Roots:
        """These roots plus ``folder``."""
        return Roots(self.folders + (Path(folder),), self.packages)

    def contains(self, path: Path) -> bool:
        """Whether the resolved ``path`` lies inside a root (a root itself counts)."""
        return any(path == f or f in path.parents for f in self.folders)

    def check(self, path: str | os.PathLike, what: str, error: type[InputError] = InputError,
              hint: str | None = None) -> Path:
        """``path`` resolved; raises ``error`` if it resolves outside every root (or in a symlink loop)."""
        p = Path(path)
        real = resolved(p, what, error)
        if str(p).startswith(UNKNOWN_PACKAGE + "/"):
            name = str(p)[len(UNKNOWN_PACKAGE) + 1:].split("/")[0]
            raise error(f"{what}: $(find {name}): package '{name}' is unknown",
                        f"map it in the sidecar (packages: {{{name}: DIR}}) or give package_path {name}=DIR")
        if not self.contains(real):
            where = ", ".join(str(f) for f in self.folders) or "none"
            raise error(f"{what}: '{_short(p)}' lies outside the folders this description may read ({where})",
                        hint or "keep the files in the description's folder, or give their package with package_path NAME=DIR")
        return real

    def __repr__(self) -> str:
        return f"Roots({[str(f) for f in self.folders]}, packages={sorted(self.packages)})"


def resolved(path: str | os.PathLike, what: str, error: type[InputError] = InputError) -> Path:
    """``path`` with symlinks followed and ``..`` removed; ``error`` naming ``what`` for a symlink loop or a
    name the OS refuses (``Path.resolve`` raises RuntimeError for a loop before Python 3.13, OSError after)."""
    p = Path(path)
    try:
        return p.resolve(strict=False)
    except (RuntimeError, OSError, ValueError) as exc:
        raise error(f"{what}: '{_short(p)}' cannot be resolved ({_reason(exc)})", "remove the symlink loop") from None


def _short(p: str | os.PathLike, n: int = 120) -> str:
    s = str(p)
    return s if len(s) <= n else s[: n - 3] + "..."


def _reason(exc: BaseException) -> str:
    return getattr(exc, "strerror", None) or str(exc) or type(exc).__name__


class FilesRead:
    """The files ``read_bytes`` read while this is open (a ``with`` block; blocks may nest, each sees every read):
    ``stamps`` maps each file's absolute path, as named (symlinks not followed, so a retargeted link counts
    as a change), to its stamp when it was read. ``unchanged()`` says whether every one is still the same
    file with the same content stamp: what a result built from those files may be kept under."""

    def __init__(self) -> None:
        self.stamps: dict[str, tuple[int, ...]] = {}

    def __enter__(self) -> FilesRead:
        _RECORDING.append(self)
        return self

    def __exit__(self, *exc: object) -> None:
        _RECORDING.remove(self)

    def unchanged(self) -> bool:
        """True when every file read still has the stamp it had (one ``os.stat`` each); False when one was
        edited, replaced, touched or removed."""
        for name, stamp in self.stamps.items():
            try:
                if _stamp(os.stat(name)) != stamp:
                    return False
            except (OSError, ValueError):
                return False
        return True


_RECORDING: list[FilesRead] = []  # the open FilesRead blocks (other threads' reads are recorded too: only extra stats)


def _stamp(st: os.stat_result) -> tuple[int, ...]:
    # ctime too: a copy that keeps the old mtime and size (cp -p, rsync -t, tar) still changes it
    return (st.st_mtime_ns, st.st_ctime_ns, st.st_size, st.st_ino, st.st_dev)


def note_read(path: str | os.PathLike, st: os.stat_result) -> None:
    """Record that the file ``path`` (as named) was read with status ``st`` in every open ``FilesRead``: for a
    reader that serves a file from its own store without ``read_bytes`` (it must still stat the file)."""
    if _RECORDING:
        name = os.path.abspath(path)
        for files in _RECORDING:
            files.stamps.setdefault(name, _stamp(st))


def read_bytes(path: str | os.PathLike, what: str | None = None, limit: int = DEFAULT_LIMIT, *,
               roots: Roots | None = None, error: type[InputError] = InputError, hint: str | None = None) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them: the ONE way roarmctl reads an input.

    ``what`` names the field that refers to the file (``"arm.yaml: srdf"``), None for a file named on
    the command line. Refused with ``error`` (exit 2), naming the file: a missing file, a folder,
    anything not a regular file (a FIFO or a device is refused before it is opened, so nothing blocks
    and no serial port is touched), a file over ``limit`` bytes (checked before and while reading: a
    sparse or growing file stops at the cap), a path outside ``roots`` (after resolving symlinks), a
    symlink loop, a name the OS refuses.
    """
    p = Path(path)

    def fail(text: str, fix: str | None = None) -> NoReturn:
        raise error(f"{what}: file '{_short(p)}' {text}" if what else f"{_short(p)}: {text}", hint or fix)

    if roots is not None:
        p = roots.check(p, what or str(p), error, hint)
    try:
        st = os.stat(p)
        if not stat.S_ISREG(st.st_mode):
            fail(f"is {_file_kind(st.st_mode)}, not a regular file", "give the path of a file")
        if st.st_size > limit:
            fail(f"has {_size(st.st_size)}, more than the {_size(limit)} allowed", "is this the right file?")
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        fail("not found" if what else "no such file", "check the path")
    except (OSError, ValueError) as exc:  # ELOOP, ENAMETOOLONG, EACCES, a NUL byte in the name
        fail(f"cannot be read ({_reason(exc)})")
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):  # swapped between stat and open
            fail(f"is {_file_kind(st.st_mode)}, not a regular file", "give the path of a file")
        note_read(path, st)
        chunks, total = [], 0
        while True:
            chunk = os.read(fd, min(_CHUNK, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > limit:
                fail(f"has more than the {_size(limit)} allowed", "is this the right file?")
        return b"".join(chunks)
    except OSError as exc:
        fail(f"cannot be read ({_reason(exc)})")
        raise  # unreachable: fail raises
    finally:
        os.close(fd)


def read_text(path: str | os.PathLike, what: str | None = None, limit: int = DEFAULT_LIMIT, *,
              roots: Roots | None = None, error: type[InputError] = InputError, hint: str | None = None) -> str:
    """``read_bytes`` decoded as UTF-8 (a byte-order mark is dropped); a bad byte is refused with its line."""
    data = read_bytes(path, what, limit, roots=roots, error=error, hint=hint)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        where = f"{what}: file '{_short(path)}' line {line}" if what else f"{_short(path)}:{line}"
        raise error(f"{where}: not UTF-8 text (byte {exc.start})", "save the file as UTF-8") from None


def _file_kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _size(n: int) -> str:
    for unit, scale in (("GiB", 2 ** 30), ("MiB", 2 ** 20), ("KiB", 2 ** 10)):
        if n >= scale:
            return f"{n / scale:.0f} {unit}" if n % scale == 0 or n >= 10 * scale else f"{n / scale:.1f} {unit}"
    return f"{n} bytes"


# --------------------------------------------------------------------------- output folders
#: The file roarmctl writes into every folder it makes (a ROS 2 bag): proof that replacing the folder
#: deletes nothing of the user's. Its content names the program; readers of the bag ignore it.
MARKER = ".roarmctl-output"
MAX_NAME_BYTES = 200  # of a file or folder name roarmctl writes (the OS allows 255; temporaries add a suffix)

_PENDING: list[list] = []  # [target, token in the new MARKER, an old folder was there, where the old one waits]
_KEPT: list[str] = []  # what a stopped run keeps on purpose (note_kept_on_stop), said instead of "nothing was written"


def note_kept_on_stop(text: str | None) -> None:
    """Say what a stop from now on leaves on disk on purpose (a resumable run's finished work), or None when
    it has gone (the run ended); ``interrupted_write_state`` returns it while no folder replacement is under way."""
    _KEPT[:] = [] if text is None else [text]


def interrupted_write_state(clear: bool = True) -> str | None:
    """What is on disk after a signal stopped a folder replacement (``replace_folder``), read from the
    disk itself (the new folder's ``MARKER`` carries a token): None when no replacement was under way."""
    if not _PENDING:
        kept = _KEPT[-1] if _KEPT else None
        if clear:
            _KEPT.clear()
        return kept
    target, token, existed, old_at = _PENDING[-1]
    if clear:
        _PENDING.clear()
    try:
        ours = token in (target / MARKER).read_text()
    except OSError:
        ours = False
    if ours:
        return f"{target} is complete (the new one{' replaced the old' if existed else ''})"
    if existed and os.path.lexists(target):
        return f"{target} is unchanged (the old one)"
    if existed and old_at is not None:
        return f"{target} is missing: the old folder is at {old_at}"
    return "nothing was written"


def check_output_folder(path: str | os.PathLike, force: bool = False,
                        made_by_us: Callable[[Path], bool] | None=None) -> Path:
    """``path`` as a folder roarmctl may (re)write, else ``InputError`` (exit 2); returns the path.

    Refused: a name longer than ``MAX_NAME_BYTES`` bytes, ``.``/``..``/``/`` or any folder holding the
    current one, and - unless ``force`` - an existing path that roarmctl did not make: a file, or a
    folder without ``MARKER`` for which ``made_by_us(folder)`` (an exact match of what roarmctl writes
    there, for folders written before the marker existed) is not true.
    """
    target = Path(path)
    name = target.name
    if not name or name in (".", ".."):
        raise InputError(f"give the name of a new folder, not '{path}'", "e.g. out/run1_bag", option="output")
    if len(os.fsencode(name)) > MAX_NAME_BYTES:
        raise InputError(f"{_short(path)}: the name is longer than {MAX_NAME_BYTES} bytes", "give a shorter name",
                         option="output")
    try:
        real = target.resolve()
        cwd = Path.cwd().resolve()
        exists = os.path.lexists(target)
    except (OSError, RuntimeError, ValueError) as exc:
        raise InputError(f"{_short(path)}: cannot use this path ({_reason(exc)})", option="output") from None
    if real == cwd or real in cwd.parents or real == Path(real.anchor):
        raise InputError(f"{path}: that folder holds the current folder; roarmctl would replace it",
                         "give the name of a new folder", option="output")
    if not exists or force:
        return target
    if target.is_symlink() or not target.is_dir():
        raise InputError(f"{path} exists and is not a folder roarmctl wrote",
                         "choose another name, or add force to replace it", option="output")
    if (target / MARKER).is_file() or (made_by_us is not None and made_by_us(target)):
        return target
    raise InputError(f"the folder {path} exists and roarmctl did not write it (no {MARKER} in it); "
                     "replacing it would delete its files", "choose another name, or add force to replace it", option="output")


def new_folder_beside(target: str | os.PathLike) -> Path:
    """An empty hidden temporary folder next to ``target`` (same file system, for the final rename),
    holding ``MARKER``."""
    import tempfile

    target = Path(target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(target.parent)
        tmp = Path(tempfile.mkdtemp(prefix=temporary_prefix(target), dir=target.parent))
    except OSError as exc:
        raise InputError(f"cannot write {_short(target)}: {_reason(exc)}", "choose a folder you can write to") from None
    return tmp


def note_output_folder(target: str | os.PathLike) -> None:
    """Say that a folder is being written to ``target`` (before the work starts), so that a signal
    until ``replace_folder`` finishes is reported with what is at ``target`` (``interrupted_write_state``)."""
    target = Path(target)
    _PENDING[:] = [[target, os.urandom(8).hex(), os.path.lexists(target), None]]


def replace_folder(new: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Move the complete folder ``new`` to ``target``; an existing ``target`` is swapped out in ONE
    rename (Linux ``renameat2(RENAME_EXCHANGE)``) and deleted only afterwards, so a signal at any
    moment leaves at ``target`` either the old folder or the new one, whole. ``MARKER`` is written into
    ``new`` first; after a signal ``interrupted_write_state()`` says which folder is at ``target``."""
    import tempfile

    new, target = Path(new), Path(target)
    token = os.urandom(8).hex()  # as secrets.token_hex(8), without loading hmac and OpenSSL's hashlib at start-up
    (new / MARKER).write_text(f"written by roarmctl ({token}); replacing this folder deletes nothing else\n")
    existed = os.path.lexists(target)
    _PENDING[:] = [[target, token, existed, None]]
    try:
        if not existed:
            os.replace(new, target)
        elif _exchange(new, target):  # new now holds the old folder
            shutil.rmtree(new, ignore_errors=True)
        else:  # no atomic exchange on this system: two renames, the old folder kept until the new is in place
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
            _PENDING[-1][3] = old / target.name
            os.replace(target, old / target.name)
            os.replace(new, target)
            shutil.rmtree(old, ignore_errors=True)
    except OSError as exc:
        _PENDING.clear()
        raise InputError(f"cannot write {_short(target)}: {_reason(exc)}", "check the disk space and permissions") from None
    return target


def _exchange(a: Path, b: Path) -> bool:
    """Swap the paths ``a`` and ``b`` atomically; False where the system cannot (then nothing changed)."""
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err))
