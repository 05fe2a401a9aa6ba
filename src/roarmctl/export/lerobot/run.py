"""An executed run (``execute``'s log, or ``simulate``'s run file) as one LeRobot episode, in datagen's schema.

At each frame time ``k / fps`` from the start of motion to the last command or reading: ``observation.state`` is
the last joint reading by then (the firmware's T:1051 feedback, at the time it read the servos; before the first
reading, the first), ``action`` the last joint goals sent by then (T:102 and the gripper's T:101, decoded with
the robot's wire map; before the first, the first), both as ``roarmctl.export.streams.log_streams`` reads the
log for the other exports. No camera: the episode has no video, so it joins datasets made without cameras
(``roarmctl datagen --cameras none``) or starts a new one.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import InputError
from roarmctl.export import load_source, streams_for
from roarmctl.export.lerobot.dataset import (
    INFO_PATH,
    TASKS_PATH,
    DatasetSpec,
    Episode,
    append_episodes,
    read_info,
    spec_of,
)
from roarmctl.export.streams import JointStates

DEFAULT_FPS = 30
DEFAULT_TASK = "pick and place"


def held(states: JointStates, times: np.ndarray) -> np.ndarray:
    """The last state at or before each time (the first before it): (len(times), dof)."""
    k = np.searchsorted(states.times, times + 1e-12, side="right") - 1
    return states.positions[np.clip(k, 0, len(states.times) - 1)]


def episode_of(log_streams: Any, fps: int, task: str) -> Episode:
    """The run's episode at ``fps`` (see the module doc)."""
    measured: JointStates = log_streams.joint_states["measured"]
    commanded: JointStates = log_streams.joint_states["commanded"]
    if len(measured.times) == 0 or len(commanded.times) == 0:
        raise InputError("the execution log has no joint readings or no joint commands",
                         "export a log of a run that moved the arm with feedback on")
    end = max(float(measured.times[-1]), float(commanded.times[-1]))
    times = np.arange(int(np.floor(max(end, 0.0) * fps + 1e-9)) + 1) / fps
    return Episode(task, held(measured, times).astype(np.float32), held(commanded, times).astype(np.float32))


def export_run(source: str | os.PathLike, dataset: str | os.PathLike, *, task: str | None = None,
               fps: int | None = None) -> dict[str, Any]:
    """Append the run ``source`` to the dataset at ``dataset`` (made if missing); returns a summary."""
    if fps is not None and not 1 <= fps <= 120:  # before the run is read; 0 is a value, not "left out"
        raise InputError(f"{fps} is out of range", "1 to 120 frames per second", option="fps")
    kind, _ = load_source(source)
    if kind != "log":
        raise InputError(f"{source}: a LeRobot episode is made of an execution log (.exec.json or a simulate run file), "
                         "not of a trajectory",
                         "execute or simulate it first; datagen makes datasets of plans")
    streams = streams_for(source)
    root = Path(dataset)
    if (root / INFO_PATH).exists():
        have = spec_of(root)
        if have.cameras:
            raise InputError(f"{root}: the dataset has cameras ({', '.join(have.cameras)}) and the run has no video",
                             "append to a dataset datagen made without cameras, or give a new folder", option="lerobot")
        if fps is not None and fps != have.fps:
            raise InputError(f"{fps}: the dataset has {have.fps} frames per second", f"leave it out or give {have.fps}",
                             option="fps")
        spec = have
        if task is None:
            import pyarrow.parquet as pq

            tasks = pq.read_table(root / TASKS_PATH)["task"].to_pylist()
            task = str(tasks[0]) if tasks else DEFAULT_TASK
    else:
        spec = DatasetSpec(DEFAULT_FPS if fps is None else fps, streams.robot.name, list(streams.joint_names))
    task = DEFAULT_TASK if task is None else task
    if not task.strip() or "\n" in task or len(task) > 500:
        raise InputError("expected one line of text (1 to 500 characters)", option="task")
    if not 1 <= spec.fps <= 120:
        raise InputError(f"{spec.fps} is out of range", "1 to 120 frames per second", option="fps")
    episode = episode_of(streams, spec.fps, task.strip())
    append_episodes(root, spec, [episode])
    info = spec_of(root)
    return {"output": str(root), "format": "lerobot", "frames": episode.length, "fps": info.fps,
            "episode_index": _total(root) - 1}


def _total(root: Path) -> int:
    return int(read_info(root)["total_episodes"])
