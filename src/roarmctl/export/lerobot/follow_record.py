"""A followed episode (``roarmctl follow --record DIR``) as a LeRobot v3.0 episode, in the schema ``datagen``
writes (``roarmctl.export.lerobot.dataset``: the same writer), so that teleoperated and planned data train together.

At each frame time ``k / fps`` from the first accepted target to the follower's last measured pose:

* ``action``: the source's newest accepted target by then (the leader's state, a policy's output), in the robot's
  joint order, rad; refused targets never appear (they were not followed);
* ``observation.state``: the follower's measured joints, from its validated feedback (the follow log's
  ``measured``), linearly between two frames.

No cameras: a dataset with cameras gets no episode without video (the writer says so).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.errors import InputError
from roarmctl.export.lerobot.dataset import DatasetSpec, Episode, append_episodes

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot


def follow_episode(log: dict[str, Any], robot: Robot, fps: int, task: str) -> Episode:
    """The ``Episode`` of a follow log (``Follower.log``) at ``fps`` frames per second. Raises InputError when
    nothing was followed (no accepted target, or no measured pose after it)."""
    n = robot.dof
    acc = [(float(e["t"]), np.asarray(e["q"], dtype=float)) for e in log.get("targets", [])
           if "refused" not in e and e.get("q") is not None and len(e["q"]) == n]
    meas = np.asarray(log.get("measured", []), dtype=float).reshape(-1, n + 1)
    if not acc or len(meas) == 0 or meas[-1, 0] < acc[0][0]:
        raise InputError("nothing to record: no target was followed", "the episode is not written")
    t_acc = np.array([t for t, _ in acc])
    q_acc = np.array([q for _, q in acc])
    start, end = t_acc[0], float(meas[-1, 0])
    frames = int(math.floor((end - start) * fps + 1e-9)) + 1
    ts = start + np.arange(frames) / fps
    action = q_acc[np.searchsorted(t_acc, ts, side="right") - 1]
    state = np.column_stack([np.interp(ts, meas[:, 0], meas[:, 1 + j]) for j in range(n)])
    return Episode(task, state.astype(np.float32), action.astype(np.float32))


def record_follow(root: str | Path, robot: Robot, log: dict[str, Any], fps: int = 30, task: str = "follow") -> Path:
    """Append the followed episode to the dataset at ``root`` (a new one if there is none); the dataset's path."""
    if isinstance(fps, bool) or not isinstance(fps, int) or not 1 <= fps <= 1000:
        raise InputError(f"the recording's fps must be a whole number in [1, 1000], got {fps!r}")
    spec = DatasetSpec(fps, robot.name, list(robot.joint_names))
    return append_episodes(root, spec, [follow_episode(log, robot, fps, task)])
