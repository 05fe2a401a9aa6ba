"""xacro input: expand a ``.xacro`` robot description to URDF text with the ``xacro`` package.

``args`` (the sidecar's ``xacro_args: {name: value}``) are xacro's ``name:=value`` arguments.
``$(find PKG)`` resolves through the sidecar's ``packages`` map and ``--package-path``. What an
expression may do, which files may be read and how much work an expansion may take is
``roarmctl.robot.xacro_safe``'s business: no expression runs code unless the user trusts the file.
"""

from __future__ import annotations

import io
from contextlib import redirect_stderr
from pathlib import Path
from typing import Any

from roarmctl.errors import DescriptionError
from roarmctl.fileio import Roots
from roarmctl.robot.xacro_safe import Refused, find_refusal, hooks

#: Set by the CLI's ``--trust-xacro``: the user vouches for every xacro file of this command.
TRUST_ALL = False


def expand(path: Path, args: dict[str, Any] | None, where: str, packages: dict[str, Path] | None = None, *,
           roots: Roots | None = None, trusted: bool = False) -> str:
    """The URDF text of xacro file ``path``; any xacro error is a ``DescriptionError`` naming the file.

    ``packages``: NAME -> folder for ``$(find NAME)`` (then ``--package-path``). ``roots``: the folders
    the expansion may read (default: the file's folder and the packages). ``trusted``: xacro
    evaluates expressions itself (only for a file the user vouched for, see ``xacro_safe``).
    """
    import xacro

    from roarmctl.robot.meshes import PACKAGE_PATHS

    known = {**PACKAGE_PATHS, **(packages or {})}
    if roots is None:
        roots = Roots([Path(path).parent], known)
    else:
        roots = Roots(roots.folders, {**known, **roots.packages})
    if args is not None and (not isinstance(args, dict) or not all(isinstance(k, str) for k in args)):
        raise DescriptionError(f"{where}: xacro_args: expected a mapping name -> value")
    mappings = {k: str(v) for k, v in (args or {}).items()}
    err = io.StringIO()
    try:
        with redirect_stderr(err), hooks(roots, str(path), trusted or TRUST_ALL):
            doc = xacro.process_file(str(path), mappings=mappings)
            text = doc.toxml()
    except DescriptionError:
        raise
    except Exception as exc:  # xacro raises XacroException, NameError, XML errors, ... around ours
        inner = find_refusal(exc)
        if isinstance(inner, DescriptionError):
            raise inner from None
        if isinstance(inner, Refused):
            expr = _expression_of(exc)
            raise DescriptionError(f"{path}: xacro: {inner}" + (f" (in {expr})" if expr else ""),
                                   "a description is data: see 'What a description may do' in docs/reference.md") from None
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        detail = err.getvalue().strip().splitlines()
        extra = f" ({detail[-1]})" if detail and detail[-1] not in msg else ""
        raise DescriptionError(f"{path}: xacro: {msg[:200]}{extra[:200]}",
                               "fix the xacro file or pass its arguments with xacro_args") from None
    return text


def _expression_of(exc: BaseException | None) -> str | None:
    """The '${...}' text xacro names in the suffix of its wrapped exception, cut to one short piece."""
    seen = 0
    while exc is not None and seen < 50:
        suffix = getattr(exc, "suffix", None)
        if isinstance(suffix, str) and "when evaluating expression" in suffix:
            text = suffix.strip().split("when evaluating expression", 1)[1].strip()
            text = text.strip("'")
            return "${" + (text if len(text) <= 60 else text[:57] + "...") + "}"
        exc = getattr(exc, "exc", None) or exc.__cause__ or exc.__context__
        seen += 1
    return None
