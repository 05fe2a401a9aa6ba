"""xacro input: expand a ``.xacro`` robot description to URDF text with the ``xacro`` package.

``args`` (the sidecar's ``xacro_args: {name: value}``) are xacro's ``name:=value`` arguments.
``$(find PKG)`` resolves through the sidecar's ``packages`` map and ``--package-path`` as well as
ROS's own package index when one is installed.
"""

from __future__ import annotations

import io
from contextlib import redirect_stderr
from pathlib import Path

from roarmctl.errors import DescriptionError


def expand(path: Path, args, where: str, packages: dict[str, Path] | None = None) -> str:
    """The URDF text of xacro file ``path``; any xacro error is a ``DescriptionError`` naming the file.

    ``packages``: NAME -> folder for ``$(find NAME)`` (then ``--package-path``, then ROS's index).
    """
    import xacro
    from xacro import substitution_args

    from roarmctl.robot.meshes import PACKAGE_PATHS

    ros_find = substitution_args._eval_find
    known = {**PACKAGE_PATHS, **(packages or {})}

    def find(pkg: str) -> str:
        if pkg in known:
            return str(known[pkg])
        try:
            return ros_find(pkg)
        except ImportError:
            raise DescriptionError(f"{path}: xacro: $(find {pkg}): package '{pkg}' is unknown",
                                   f"map it in the sidecar (packages: {{{pkg}: DIR}}) or give --package-path {pkg}=DIR") from None

    if args is not None and (not isinstance(args, dict) or not all(isinstance(k, str) for k in args)):
        raise DescriptionError(f"{where}: xacro_args: expected a mapping name -> value")
    mappings = {k: str(v) for k, v in (args or {}).items()}
    err = io.StringIO()
    substitution_args._eval_find = find  # xacro has no hook for package lookup; restored below
    try:
        with redirect_stderr(err):
            doc = xacro.process_file(str(path), mappings=mappings)
    except DescriptionError:
        raise
    except Exception as exc:  # xacro raises XacroException, NameError, XML errors, ...
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        detail = err.getvalue().strip().splitlines()
        extra = f" ({detail[-1]})" if detail and detail[-1] not in msg else ""
        raise DescriptionError(f"{path}: xacro: {msg}{extra}", "fix the xacro file or pass its arguments with xacro_args") from None
    finally:
        substitution_args._eval_find = ros_find
    return doc.toxml()
