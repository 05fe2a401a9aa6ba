"""A LeRobotDataset v3.0 on disk, written with pyarrow and PyAV, and read back with pyarrow.

The layout is lerobot's (huggingface/lerobot ``src/lerobot/datasets/utils.py``, ``dataset_metadata.py``,
``dataset_writer.py``)::

    meta/info.json                                   codebase_version "v3.0", fps, features, totals, paths, robot_type
    meta/stats.json                                  per feature: min max mean std count q01 q10 q50 q90 q99
    meta/tasks.parquet                               task_index, indexed by the task string (pandas' index)
    meta/episodes/chunk-000/file-000.parquet         one row per episode: tasks, length, where its rows and
                                                     videos are, and its stats (stats/<feature>/<stat>)
    data/chunk-000/file-000.parquet                  one row per frame
    videos/observation.images.<cam>/chunk-000/file-000.mp4

Frame columns: ``observation.state`` and ``action`` (fixed-size lists of float32, the joint names in
``info.json``), ``timestamp`` (float32, ``frame_index / fps``), ``frame_index``, ``episode_index``, ``index``
(the frame's row in the dataset), ``task_index`` (int64). Every file goes in chunk 0, file 0: lerobot starts
a new file past 100 MB of frames or 200 MB of video, a writer's policy that readers do not rely on (the
episodes' metadata says where each episode is).

The API (``roarmctl datagen``, ``roarmctl export --lerobot`` and the recorder use it):

    spec = DatasetSpec(fps=30, robot_type="roarm_m3_pro", joint_names=names, cameras={"front": (96, 96)})
    write_dataset(root, spec, [Episode(task, state, action, videos={"front": mp4_bytes})])   # a new dataset
    append_episodes(root, spec, [Episode(...)])                                             # to an existing one
    t, action = read_actions(root, episode_index)                                           # (F,) s, (F, dof)
"""

from __future__ import annotations

import functools
import io
import json
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import InputError
from roarmctl.export.lerobot import stats as st
from roarmctl.export.lerobot import video
from roarmctl.fileio import atomic_write_json, atomic_write_with, new_folder_beside, replace_folder

CODEBASE_VERSION = "v3.0"
CHUNKS_SIZE = 1000
DATA_FILES_SIZE_IN_MB = 100
VIDEO_FILES_SIZE_IN_MB = 200
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-000/file-000.parquet"
TASKS_PATH = "meta/tasks.parquet"
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
STATE, ACTION = "observation.state", "action"
MAX_INFO_BYTES = 4 << 20  # a dataset's info.json is a few kB


def image_key(camera: str) -> str:
    """The feature of a camera: ``observation.images.<camera>``."""
    return f"observation.images.{camera}"


@dataclass
class DatasetSpec:
    """What every episode of a dataset shares: ``fps``, ``robot_type``, the ``joint_names`` of state and action,
    and ``cameras``: name -> (height, width) pixels (none: no video features)."""

    fps: int
    robot_type: str
    joint_names: Sequence[str]
    cameras: dict[str, tuple[int, int]] = field(default_factory=dict)

    def features(self, video_info: dict[str, dict[str, Any]] | None = None) -> dict[str, dict[str, Any]]:
        """``info.json``'s ``features`` (lerobot's order: the data, the cameras, then its default features)."""
        n = len(self.joint_names)
        out: dict[str, dict[str, Any]] = {
            STATE: {"dtype": "float32", "shape": [n], "names": list(self.joint_names)},
            ACTION: {"dtype": "float32", "shape": [n], "names": list(self.joint_names)},
        }
        for cam, (h, w) in self.cameras.items():
            out[image_key(cam)] = {"dtype": "video", "shape": [h, w, 3], "names": ["height", "width", "channels"],
                                   "info": (video_info or {}).get(cam)}
        for name, dtype in (("timestamp", "float32"), ("frame_index", "int64"), ("episode_index", "int64"),
                            ("index", "int64"), ("task_index", "int64")):
            out[name] = {"dtype": dtype, "shape": [1], "names": None}
        return out


@dataclass
class Episode:
    """One episode to write: its ``task`` (the instruction), ``state`` and ``action`` (F, dof), and per camera
    its video (``videos``: MP4 bytes from ``roarmctl.export.lerobot.video.encode``, F frames) with the stats of
    its frames (``image_stats``: ``stats.image_stats``; computed from the video when missing)."""

    task: str
    state: np.ndarray
    action: np.ndarray
    videos: dict[str, bytes] = field(default_factory=dict)
    image_stats: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    @property
    def length(self) -> int:
        """Frames."""
        return len(self.state)


def _check(spec: DatasetSpec, episodes: Sequence[Episode]) -> None:
    n = len(spec.joint_names)
    for i, e in enumerate(episodes):
        if e.state.shape != (e.length, n) or e.action.shape != (e.length, n) or e.length < 1:
            raise InputError(f"episode {i}: state and action must be (frames, {n}) with frames >= 1; got "
                             f"{e.state.shape} and {e.action.shape}")
        if not (np.all(np.isfinite(e.state)) and np.all(np.isfinite(e.action))):
            raise InputError(f"episode {i}: state or action holds a non-finite value")
        if set(e.videos) != set(spec.cameras):
            raise InputError(f"episode {i}: videos of {sorted(e.videos) or 'no camera'}, the dataset has {sorted(spec.cameras) or 'none'}",
                             "every episode needs a video of each camera of the dataset")


def _episode_stats(spec: DatasetSpec, e: Episode, ts: np.ndarray, index: np.ndarray, ep: int,
                   task: int) -> dict[str, dict[str, np.ndarray]]:
    out = {STATE: st.vector_stats(e.state), ACTION: st.vector_stats(e.action)}
    for cam in spec.cameras:
        s = e.image_stats.get(cam)
        if s is None:
            s = st.image_stats(video.decode(io.BytesIO(e.videos[cam]))[0])
        out[image_key(cam)] = s
    f = np.arange(e.length)
    out |= {"timestamp": st.vector_stats(ts), "frame_index": st.vector_stats(f), "episode_index": st.vector_stats(np.full(e.length, ep)),
            "index": st.vector_stats(index), "task_index": st.vector_stats(np.full(e.length, task))}
    return out


def write_dataset(root: str | Path, spec: DatasetSpec, episodes: Sequence[Episode]) -> Path:
    """Write ``episodes`` as a new dataset into the folder ``root`` (every file written atomically, the same
    bytes for the same episodes); returns ``root``."""
    import pyarrow as pa

    episodes = list(episodes)
    if not episodes:
        raise InputError("no episode to write")
    _check(spec, episodes)
    root = Path(root)
    n = len(spec.joint_names)
    tasks: dict[str, int] = {}
    cols: dict[str, list[np.ndarray]] = {k: [] for k in (STATE, ACTION, "timestamp", "frame_index", "episode_index", "index", "task_index")}
    rows: list[dict[str, Any]] = []
    ep_stats = []
    start = 0
    frames_before = 0
    for ep, e in enumerate(episodes):
        task = tasks.setdefault(e.task, len(tasks))
        f = np.arange(e.length, dtype=np.int64)
        ts = (f / spec.fps).astype(np.float32)
        index = start + f
        for k, v in ((STATE, e.state.astype(np.float32)), (ACTION, e.action.astype(np.float32)), ("timestamp", ts),
                     ("frame_index", f), ("episode_index", np.full(e.length, ep, dtype=np.int64)), ("index", index),
                     ("task_index", np.full(e.length, task, dtype=np.int64))):
            cols[k].append(v)
        s = _episode_stats(spec, e, ts, index, ep, task)
        ep_stats.append(s)
        row: dict[str, Any] = {"episode_index": ep, "tasks": [e.task], "length": e.length, "data/chunk_index": 0, "data/file_index": 0,
                               "dataset_from_index": start, "dataset_to_index": start + e.length}
        for cam in spec.cameras:
            key = image_key(cam)
            row |= {f"videos/{key}/chunk_index": 0, f"videos/{key}/file_index": 0,
                    f"videos/{key}/from_timestamp": frames_before / spec.fps, f"videos/{key}/to_timestamp": (frames_before + e.length) / spec.fps}
        for feat, fs in s.items():
            for k in st.KEYS:
                row[f"stats/{feat}/{k}"] = np.asarray(fs[k]).tolist()
        row |= {"meta/episodes/chunk_index": 0, "meta/episodes/file_index": 0}
        rows.append(row)
        start += e.length
        frames_before += e.length
    vec = pa.list_(pa.float32(), n)
    data = pa.table({
        STATE: pa.FixedSizeListArray.from_arrays(pa.array(np.concatenate(cols[STATE]).ravel()), n).cast(vec),
        ACTION: pa.FixedSizeListArray.from_arrays(pa.array(np.concatenate(cols[ACTION]).ravel()), n).cast(vec),
        **{k: pa.array(np.concatenate(cols[k])) for k in ("timestamp", "frame_index", "episode_index", "index", "task_index")}})
    _write_parquet(root / DATA_PATH.format(chunk_index=0, file_index=0), data)
    video_info: dict[str, dict[str, Any]] = {}
    for cam in spec.cameras:
        path = root / VIDEO_PATH.format(video_key=image_key(cam), chunk_index=0, file_index=0)
        atomic_write_with(path, functools.partial(_join, [e.videos[cam] for e in episodes], [e.length for e in episodes], spec.fps))
        video_info[cam] = video.probe(path)
    _write_parquet(root / EPISODES_PATH, pa.Table.from_pylist(rows))
    _write_tasks(root, tasks)
    total = {f: st.aggregate([s[f] for s in ep_stats]) for f in ep_stats[0]}
    atomic_write_json(root / STATS_PATH, st.to_json(total), indent=4)
    info = {"codebase_version": CODEBASE_VERSION, "robot_type": spec.robot_type, "total_episodes": len(episodes),
            "total_frames": start, "total_tasks": len(tasks), "chunks_size": CHUNKS_SIZE,
            "data_files_size_in_mb": DATA_FILES_SIZE_IN_MB, "video_files_size_in_mb": VIDEO_FILES_SIZE_IN_MB,
            "fps": spec.fps, "splits": {"train": f"0:{len(episodes)}"}, "data_path": DATA_PATH,
            "video_path": VIDEO_PATH if spec.cameras else None, "features": spec.features(video_info)}
    atomic_write_json(root / INFO_PATH, info, indent=4)
    return root


def _join(parts: list[bytes], lengths: list[int], fps: int, out: Any) -> None:
    video.join(parts, lengths, fps, out)


def _write_parquet(path: Path, table: Any) -> None:
    import pyarrow.parquet as pq

    atomic_write_with(path, lambda f: pq.write_table(table, f, compression="snappy"))


def _write_tasks(root: Path, tasks: dict[str, int]) -> None:
    """``meta/tasks.parquet`` as pandas writes lerobot's frame: a ``task_index`` column indexed by the task string."""
    import pyarrow as pa

    names = list(tasks)
    pandas_meta = {"index_columns": ["task"], "column_indexes": [], "columns": [
        {"name": "task_index", "field_name": "task_index", "pandas_type": "int64", "numpy_type": "int64", "metadata": None},
        {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": None}],
        "creator": {"library": "pyarrow", "version": pa.__version__}, "pandas_version": "2.2.0"}
    table = pa.table({"task_index": pa.array([tasks[t] for t in names], pa.int64()), "task": pa.array(names, pa.string())})
    table = table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})
    _write_parquet(root / TASKS_PATH, table)


# ------------------------------------------------------------------------------------------------ reading
def read_info(root: str | Path) -> dict[str, Any]:
    """``meta/info.json`` of a v3.0 dataset (``InputError`` for anything else)."""
    from roarmctl.validation import load_json

    path = Path(root) / INFO_PATH
    info = load_json(path, InputError, limit=MAX_INFO_BYTES)
    if not isinstance(info, dict) or info.get("codebase_version") != CODEBASE_VERSION:
        raise InputError(f"{path}: not a LeRobot v3.0 dataset (codebase_version {info.get('codebase_version') if isinstance(info, dict) else '?'})")
    return info


def spec_of(root: str | Path) -> DatasetSpec:
    """The ``DatasetSpec`` a dataset was written with."""
    info = read_info(root)
    f = info["features"]
    cams = {k.removeprefix("observation.images."): (int(v["shape"][0]), int(v["shape"][1])) for k, v in f.items() if v.get("dtype") == "video"}
    return DatasetSpec(int(info["fps"]), str(info.get("robot_type")), list(f[STATE]["names"]), cams)


def read_frames(root: str | Path, episode_index: int | None = None) -> Any:
    """The frame rows (a pyarrow Table), of one episode or all."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    table = pq.read_table(Path(root) / DATA_PATH.format(chunk_index=0, file_index=0))
    if episode_index is not None:
        table = table.filter(pc.equal(table["episode_index"], episode_index))
    return table


def read_actions(root: str | Path, episode_index: int) -> tuple[np.ndarray, np.ndarray]:
    """(timestamps (F,) s, actions (F, dof)) of one episode, in frame order; ``InputError`` if it has no frames."""
    t = read_frames(root, episode_index)
    if t.num_rows == 0:
        raise InputError(f"{root}: no episode {episode_index}", f"the dataset has {read_info(root)['total_episodes']} episodes")
    order = np.argsort(t["frame_index"].to_numpy())
    action = np.asarray(t[ACTION].combine_chunks().flatten().to_numpy()).reshape(t.num_rows, -1)
    return t["timestamp"].to_numpy()[order].astype(np.float64), action[order].astype(np.float64)


def read_episodes(root: str | Path) -> list[Episode]:
    """Every episode of a dataset as ``Episode``s (state, action, task, each video cut out of its file, the image
    stats from the metadata): what ``append_episodes`` rewrites with the new ones."""
    import pyarrow.parquet as pq

    root = Path(root)
    spec = spec_of(root)
    meta = pq.read_table(root / EPISODES_PATH).to_pylist()
    data = read_frames(root)
    n = len(spec.joint_names)
    state = np.asarray(data[STATE].combine_chunks().flatten().to_numpy()).reshape(-1, n)
    action = np.asarray(data[ACTION].combine_chunks().flatten().to_numpy()).reshape(-1, n)
    out = []
    for row in meta:
        a, b = int(row["dataset_from_index"]), int(row["dataset_to_index"])
        e = Episode(str(row["tasks"][0]), state[a:b].copy(), action[a:b].copy())
        for cam in spec.cameras:
            key = image_key(cam)
            first = int(round(float(row[f"videos/{key}/from_timestamp"]) * spec.fps))
            e.videos[cam] = video.cut(root / VIDEO_PATH.format(video_key=key, chunk_index=0, file_index=0), first, b - a, spec.fps)
            e.image_stats[cam] = {k: np.asarray(row[f"stats/{key}/{k}"]) for k in st.KEYS}
        out.append(e)
    return out


def append_episodes(root: str | Path, spec: DatasetSpec, episodes: Iterable[Episode]) -> Path:
    """Add ``episodes`` after those of the dataset at ``root`` (a new dataset when there is none). The dataset
    is written whole into a new folder beside ``root`` and swapped in by one rename
    (``roarmctl.fileio.replace_folder``): a kill leaves the old dataset or the new one, never half of each."""
    root = Path(root)
    old: list[Episode] = []
    if (root / INFO_PATH).exists():
        have = spec_of(root)
        if (have.fps, list(have.joint_names), have.cameras) != (spec.fps, list(spec.joint_names), spec.cameras):
            raise InputError(f"{root}: the dataset has fps {have.fps}, joints {', '.join(have.joint_names)} and cameras "
                             f"{', '.join(have.cameras) or 'none'}; the new episodes have fps {spec.fps}, joints "
                             f"{', '.join(spec.joint_names)} and cameras {', '.join(spec.cameras) or 'none'}",
                             "append to a dataset of the same robot, rate and cameras, or give a new folder")
        if have.robot_type != spec.robot_type:
            raise InputError(f"{root}: the dataset is of {have.robot_type}, the new episodes of {spec.robot_type}")
        old = read_episodes(root)
    tmp = new_folder_beside(root)
    try:
        write_dataset(tmp, spec, old + list(episodes))
        return replace_folder(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise

