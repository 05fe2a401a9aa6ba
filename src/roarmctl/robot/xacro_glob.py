"""Where a xacro include's file pattern (``$(dirname)/parts/*.xacro``) may look: inside a description's roots only."""

from __future__ import annotations

import fnmatch
import os
import re

from roarmctl.errors import DescriptionError
from roarmctl.fileio import Roots
from roarmctl.robot.xacro_eval import MAX_INCLUDES, Refused

MAX_GLOB_ENTRIES = 10_000  # files and folders one include pattern may look at (``/proc/*/root/*/...`` never ends)
_MAGIC = re.compile(r"[*?[]")  # what makes xacro treat an include's file name as a pattern (``get_include_files``)


def include_glob(pattern: str, roots: Roots, what: str) -> list[str]:
    """The files an include pattern (``$(dirname)/parts/*.xacro``) names, as ``glob.glob`` would find them, walked
    inside ``roots`` only: the part before the first wildcard must lie inside; ``..`` after a wildcard is
    refused (it could climb out of whatever the wildcard matched); a folder is listed only once it resolves
    inside (a symlink to ``/`` or ``/proc/*/root`` is refused, naming the link, never what lies beyond it); each
    file found must resolve inside; at most ``MAX_GLOB_ENTRIES`` entries are looked at and ``MAX_INCLUDES``
    files returned. Hidden names match only a part that starts with '.', as in ``glob``."""
    parts = pattern.split(os.sep)
    first = next((k for k, part in enumerate(parts) if _MAGIC.search(part)), len(parts))
    if ".." in parts[first:]:
        raise Refused(f"the include pattern '{pattern}' has '..' after a wildcard (it could lead out of the folders "
                      "this description may read): name the folder before the wildcard")
    head = os.sep.join(parts[:first]) or (os.sep if pattern.startswith(os.sep) else os.curdir)
    roots.check(head, what, DescriptionError)
    found, looked_at = [head], 0
    for k, part in enumerate(parts[first:], first):
        last = k == len(parts) - 1
        matches = []
        for folder in found:
            if not _MAGIC.search(part):
                path = os.path.join(folder, part)
                if os.path.lexists(path) and (last or os.path.isdir(path)):
                    matches.append(path)
                continue
            roots.check(folder, what, DescriptionError)  # never list a folder outside, whatever led to it
            try:
                with os.scandir(folder) as entries:
                    for entry in entries:
                        looked_at += 1
                        if looked_at > MAX_GLOB_ENTRIES:
                            raise Refused(f"the include pattern '{pattern}' looks at more than {MAX_GLOB_ENTRIES:,} "
                                          "files and folders")
                        if entry.name.startswith(".") and not part.startswith("."):
                            continue
                        if fnmatch.fnmatchcase(entry.name, part) and (last or entry.is_dir()):
                            matches.append(os.path.join(folder, entry.name))
            except (NotADirectoryError, FileNotFoundError, PermissionError):
                continue
        found = matches
    if len(found) > MAX_INCLUDES:
        raise Refused(f"the include pattern '{pattern}' matches more than {MAX_INCLUDES} files")
    for path in found:
        roots.check(path, what, DescriptionError)
    return sorted(found)
