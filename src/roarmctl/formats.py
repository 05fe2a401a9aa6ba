"""What the file formats share: the names of shapes and roles, and the bounds on a trajectory's length.

A plan file, a trajectory file, an execution log, the scene and the pictures all speak of scene items;
these are the one list of the words they use (``roarmctl.plan`` reads them, ``roarmctl.motion.scene`` and
``roarmctl.motion.validate`` check them, ``roarmctl.viz`` draws them). The bounds keep memory and time small
for every reader of a trajectory or a log (docs/reference.md, "The trajectory file"); ``read_document`` is their
one bounded read of such a file.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from roarmctl.errors import TrajectoryFileError
from roarmctl.validation import load_json

Role = Literal["table", "obstacle", "object"]
Shape = Literal["box", "cylinder", "sphere", "mesh", "cloud"]
ROLES: tuple[Role, ...] = ("table", "obstacle", "object")
PRIMITIVES: tuple[Shape, ...] = ("box", "cylinder", "sphere")  # an object (grasped) is one of these
SHAPES: tuple[Shape, ...] = PRIMITIVES + ("mesh", "cloud")  # the table and obstacles: also meshes and point clouds

MAX_DURATION = 3600.0  # s a trajectory may last (streaming builds one command per tick: the duration bounds memory)
MAX_POINTS = 1_000_000  # samples of a trajectory
MIN_SPEED_SCALE = 1e-3  # the slowest run (fraction of planned speed): slowed further, an hour would last 40 days
MAX_FILE_BYTES = 256 * 1024 * 1024  # a trajectory file or execution log (a one-hour trajectory at 100 Hz is about 80 MB)


def read_document(path: str | Path) -> Any:
    """The JSON of a trajectory file or execution log, read within ``MAX_FILE_BYTES`` (``roarmctl.validation``)."""
    return load_json(path, TrajectoryFileError, limit=MAX_FILE_BYTES,
                     hint="the file is damaged or cut short; make it again (plan a trajectory; execute or simulate for a log)")
