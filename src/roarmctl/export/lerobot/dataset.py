"""A LeRobotDataset v3.0 on disk, written with pyarrow and PyAV, and read back with pyarrow.

The layout is lerobot's (huggingface/lerobot ``src/lerobot/datasets/utils.py``, ``dataset_metadata.py``,
``dataset_writer.py``)::

    meta/info.json                                   codebase_version "v3.0", fps, features, totals, paths, robot_type
    meta/stats.json                                  per feature: min max mean std count q01 q10 q50 q90 q99
    meta/tasks.parquet                               task_index, indexed by the task string (pandas' index)
    meta/episodes/chunk-CCC/file-FFF.parquet         one row per episode: tasks, length, where its rows and
                                                     videos are, and its stats (stats/<feature>/<stat>)
    data/chunk-CCC/file-FFF.parquet                  one row per frame
    videos/observation.images.<cam>/chunk-CCC/file-FFF.mp4

Frame columns: ``observation.state`` and ``action`` (fixed-size lists of float32, the joint names in
``info.json``), ``timestamp`` (float32, ``frame_index / fps``), ``frame_index``, ``episode_index``, ``index``
(the frame's row in the dataset), ``task_index`` (int64). Files roll over as lerobot's writer rolls them: a
data (or episodes' metadata) file past ``data_files_size_in_mb`` (100 MiB), a video file past
``video_files_size_in_mb`` (200 MiB), a new chunk folder every ``chunks_size`` (1000) files; an episode is never
split, and the episodes' metadata says which file holds each episode's rows and video, and from when.

The API (``roarmctl datagen``, ``roarmctl export --lerobot`` and the recorder use it):

    spec = DatasetSpec(fps=30, robot_type="roarm_m3_pro", joint_names=names, cameras={"front": (96, 96)})
    write_dataset(root, spec, [Episode(task, state, action, videos={"front": mp4_bytes})])   # a new dataset
    append_episodes(root, spec, [Episode(...)])                                             # to an existing one
    t, action = read_actions(root, episode_index)                                           # (F,) s, (F, dof)
"""

from __future__ import annotations

import io
import json
import re
import shutil
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.checks import Bound, check_options
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
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
METADATA_BUFFER = 10  # episodes' rows per row group of meta/episodes (lerobot's metadata_buffer_size)
MB = 1024**2  # lerobot's file sizes are MiB (io_utils.get_file_size_in_mb)
TASKS_PATH = "meta/tasks.parquet"
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
STATE, ACTION = "observation.state", "action"
MAX_INFO_BYTES = 4 << 20  # a dataset's info.json is a few kB


def image_key(camera: str) -> str:
    """The feature of a camera: ``observation.images.<camera>``."""
    return f"observation.images.{camera}"


#: Where a dataset's files roll over (``roarmctl.checks.check_options``); the other fields of a ``DatasetSpec`` come
#: from the run (the robot, its cameras) or from a dataset's info.json (``spec_of``, which names the file when a
#: value is refused).
LAYOUT_BOUNDS = {
    "chunks_size": Bound(1, 10**9, whole=True),  # files per chunk
    "data_files_size_in_mb": Bound(0.0, 1e6, strict_lo=True),  # MiB
    "video_files_size_in_mb": Bound(0.0, 1e6, strict_lo=True),  # MiB
}


@dataclass
class DatasetSpec:
    """What every episode of a dataset shares: ``fps``, ``robot_type``, the ``joint_names`` of state and action,
    ``cameras``: name -> (height, width) pixels (none: no video features), and where files roll over (MiB,
    files per chunk; lerobot's defaults; checked on creation against ``LAYOUT_BOUNDS``)."""

    fps: int
    robot_type: str
    joint_names: Sequence[str]
    cameras: dict[str, tuple[int, int]] = field(default_factory=dict)
    chunks_size: int = CHUNKS_SIZE
    data_files_size_in_mb: float = DATA_FILES_SIZE_IN_MB
    video_files_size_in_mb: float = VIDEO_FILES_SIZE_IN_MB

    def __post_init__(self) -> None:
        check_options(self, LAYOUT_BOUNDS)

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
    its video (``videos``: MP4 bytes from ``roarmctl.export.lerobot.video.encode``, or the file holding them, F frames) with the stats of
    its frames (``image_stats``: ``stats.image_stats``; computed from the video when missing)."""

    task: str
    state: np.ndarray
    action: np.ndarray
    videos: dict[str, bytes | Path] = field(default_factory=dict)
    image_stats: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    @property
    def length(self) -> int:
        """Frames."""
        return len(self.state)


def _check(spec: DatasetSpec, i: int, e: Episode) -> None:
    n = len(spec.joint_names)
    if e.state.shape != (e.length, n) or e.action.shape != (e.length, n) or e.length < 1:
        raise InputError(f"episode {i}: state and action must be (frames, {n}) with frames >= 1; got "
                         f"{e.state.shape} and {e.action.shape}")
    if not (np.all(np.isfinite(e.state)) and np.all(np.isfinite(e.action))):
        raise InputError(f"episode {i}: state or action holds a non-finite value")
    if set(e.videos) != set(spec.cameras):
        raise InputError(f"episode {i}: videos of {sorted(e.videos) or 'no camera'}, the dataset has {sorted(spec.cameras) or 'none'}",
                         "every episode needs a video of each camera of the dataset")


def _video_bytes(v: bytes | Path) -> bytes:
    return v if isinstance(v, bytes) else Path(v).read_bytes()


def _episode_stats(spec: DatasetSpec, e: Episode, ts: np.ndarray, index: np.ndarray, ep: int,
                   task: int) -> dict[str, dict[str, np.ndarray]]:
    out = {STATE: st.vector_stats(e.state), ACTION: st.vector_stats(e.action)}
    for cam in spec.cameras:
        s = e.image_stats.get(cam)
        if s is None:
            s = st.image_stats(video.decode(io.BytesIO(_video_bytes(e.videos[cam])))[0])
        out[image_key(cam)] = s
    f = np.arange(e.length)
    out["timestamp"] = st.vector_stats(ts)
    for name, values in (("frame_index", f), ("episode_index", np.full(e.length, ep)), ("index", index),
                         ("task_index", np.full(e.length, task))):
        s = st.vector_stats(values)
        # lerobot's min and max of an integer feature stay integers (int64 in the episodes' parquet)
        out[name] = s | {"min": s["min"].astype(np.int64), "max": s["max"].astype(np.int64)}
    return out


def next_file(chunk: int, file: int, chunks_size: int) -> tuple[int, int]:
    """The chunk and file index after ``chunk``/``file``: a new chunk after ``chunks_size`` files (lerobot's
    ``update_chunk_file_indices``)."""
    return (chunk + 1, 0) if file == chunks_size - 1 else (chunk, file + 1)


class _Parquets:
    """Parquet files of one kind (``pattern``: data, or the episodes' metadata), a row group per ``add``, rolled
    over as lerobot's writer rolls them (``dataset_writer._save_episode_data``): the next file when the bytes
    written to this one plus the new rows at its average bytes per row would reach ``limit_mb`` MiB."""

    def __init__(self, root: Path, pattern: str, limit_mb: float, chunks_size: int) -> None:
        self.root, self.pattern, self.limit, self.chunks_size = root, pattern, limit_mb * MB, chunks_size
        self.chunk = self.file = 0
        self.sink: Any = None
        self.writer: Any = None
        self.rows = 0  # in the file being written

    def where(self, rows: int) -> tuple[int, int]:
        """The chunk and file index the next ``rows`` rows go to."""
        if self.writer is not None:
            size = self.sink.tell()
            if size + size / self.rows * rows >= self.limit:
                self.close()
                self.chunk, self.file = next_file(self.chunk, self.file, self.chunks_size)
        return self.chunk, self.file

    def add(self, table: Any, rows: int) -> tuple[int, int]:
        """Write ``table`` (``rows`` rows) as a row group; returns where it went."""
        import pyarrow.parquet as pq

        where = self.where(rows)
        if self.writer is None:
            path = self.root / self.pattern.format(chunk_index=self.chunk, file_index=self.file)
            path.parent.mkdir(parents=True, exist_ok=True)
            self.sink = open(path, "wb")  # noqa: SIM115  (closed by close())
            self.writer = pq.ParquetWriter(self.sink, table.schema, compression="snappy", use_dictionary=True)
            self.rows = 0
        self.writer.write_table(table.cast(self.writer.schema))
        self.rows += rows
        return where

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self.sink.close()
            self.writer = self.sink = None


class _Videos:
    """One camera's video files: each episode's MP4 joined onto the file being written (packets copied), the
    next file when the file's episodes plus the new one would reach ``video_files_size_in_mb`` MiB (lerobot's
    rule, ``dataset_writer._save_episode_video``, with the episodes' MP4 sizes for the file's)."""

    def __init__(self, root: Path, key: str, spec: DatasetSpec) -> None:
        self.root, self.key, self.spec = root, key, spec
        self.chunk = self.file = 0
        self.joiner: video.Joiner | None = None
        self.bytes = self.frames = 0  # in the file being written

    def add(self, part: bytes, frames: int) -> dict[str, Any]:
        """Join one episode's MP4 (``frames`` frames); returns its ``videos/<key>/...`` columns."""
        if self.joiner is not None and self.bytes + len(part) >= self.spec.video_files_size_in_mb * MB:
            self.close()
            self.chunk, self.file = next_file(self.chunk, self.file, self.spec.chunks_size)
        if self.joiner is None:
            path = self.root / VIDEO_PATH.format(video_key=self.key, chunk_index=self.chunk, file_index=self.file)
            path.parent.mkdir(parents=True, exist_ok=True)
            self.joiner = video.Joiner(path, self.spec.fps)
            self.bytes = self.frames = 0
        first = self.frames
        self.joiner.add(part, frames)
        self.bytes += len(part)
        self.frames += frames
        return {f"videos/{self.key}/chunk_index": self.chunk, f"videos/{self.key}/file_index": self.file,
                f"videos/{self.key}/from_timestamp": first / self.spec.fps,
                f"videos/{self.key}/to_timestamp": self.frames / self.spec.fps}

    def close(self) -> None:
        if self.joiner is not None:
            self.joiner.close()
            self.joiner = None


def _frames_table(n: int, e: Episode, ts: np.ndarray, f: np.ndarray, ep: int, index: np.ndarray, task: int) -> Any:
    import pyarrow as pa

    vec = pa.list_(pa.float32(), n)
    return pa.table({
        STATE: pa.FixedSizeListArray.from_arrays(pa.array(e.state.astype(np.float32).ravel()), n).cast(vec),
        ACTION: pa.FixedSizeListArray.from_arrays(pa.array(e.action.astype(np.float32).ravel()), n).cast(vec),
        "timestamp": pa.array(ts), "frame_index": pa.array(f), "episode_index": pa.array(np.full(e.length, ep, dtype=np.int64)),
        "index": pa.array(index), "task_index": pa.array(np.full(e.length, task, dtype=np.int64))})


def write_dataset(root: str | Path, spec: DatasetSpec, episodes: Iterable[Episode]) -> Path:
    """Write ``episodes`` (any iterable; one episode's video is read at a time) as a new dataset into the
    folder ``root``; returns ``root``. The same episodes give the same bytes. Data, video and metadata files
    roll over at ``spec``'s sizes as lerobot's writer rolls them (``_Parquets``, ``_Videos``). ``root`` is a
    folder of its own that the caller moves into place when this returns (``append_episodes`` and datagen
    do): a file in it is whole only then."""
    import pyarrow as pa

    root = Path(root)
    n = len(spec.joint_names)
    tasks: dict[str, int] = {}
    data = _Parquets(root, DATA_PATH, spec.data_files_size_in_mb, spec.chunks_size)
    meta = _Parquets(root, EPISODES_PATH, spec.data_files_size_in_mb, spec.chunks_size)
    videos = {cam: _Videos(root, image_key(cam), spec) for cam in spec.cameras}
    rows: list[dict[str, Any]] = []
    ep_stats = []
    start = 0
    try:
        for ep, e in enumerate(episodes):
            _check(spec, ep, e)
            task = tasks.setdefault(e.task, len(tasks))
            f = np.arange(e.length, dtype=np.int64)
            ts = (f / spec.fps).astype(np.float32)
            index = start + f
            chunk, file = data.add(_frames_table(n, e, ts, f, ep, index, task), e.length)
            row: dict[str, Any] = {"episode_index": ep, "tasks": [e.task], "length": e.length, "data/chunk_index": chunk,
                                   "data/file_index": file, "dataset_from_index": start, "dataset_to_index": start + e.length}
            for cam, v in videos.items():
                row |= v.add(_video_bytes(e.videos[cam]), e.length)
            s = _episode_stats(spec, e, ts, index, ep, task)
            ep_stats.append(s)
            for feat, fs in s.items():
                for k in st.KEYS:
                    row[f"stats/{feat}/{k}"] = np.asarray(fs[k]).tolist()
            rows.append(row)
            start += e.length
        if not rows:
            raise InputError("no episode to write")
        for first in range(0, len(rows), METADATA_BUFFER):  # lerobot writes the episodes' rows 10 at a time
            group = rows[first:first + METADATA_BUFFER]
            chunk, file = meta.where(len(group))
            for row in group:
                row |= {"meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file}
            meta.add(pa.Table.from_pylist(group), len(group))
    finally:
        data.close()
        meta.close()
        for v in videos.values():
            v.close()
    video_info = {cam: video.probe(root / VIDEO_PATH.format(video_key=image_key(cam), chunk_index=0, file_index=0))
                  for cam in spec.cameras}
    _write_tasks(root, tasks)
    total = {f: st.aggregate([s[f] for s in ep_stats]) for f in ep_stats[0]}
    atomic_write_json(root / STATS_PATH, st.to_json(total), indent=4)
    info = {"codebase_version": CODEBASE_VERSION, "robot_type": spec.robot_type, "total_episodes": len(rows),
            "total_frames": start, "total_tasks": len(tasks), "chunks_size": spec.chunks_size,
            "data_files_size_in_mb": spec.data_files_size_in_mb, "video_files_size_in_mb": spec.video_files_size_in_mb,
            "fps": spec.fps, "splits": {"train": f"0:{len(rows)}"}, "data_path": DATA_PATH,
            "video_path": VIDEO_PATH if spec.cameras else None, "features": spec.features(video_info)}
    atomic_write_json(root / INFO_PATH, info, indent=4)
    return root


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
    """The ``DatasetSpec`` a dataset was written with; ``InputError`` naming ``info.json`` when a field it needs
    is missing or of the wrong kind."""
    info = read_info(root)
    try:
        f = info["features"]
        cams = {k.removeprefix("observation.images."): (int(v["shape"][0]), int(v["shape"][1])) for k, v in f.items()
                if v.get("dtype") == "video"}
        return DatasetSpec(int(info["fps"]), str(info.get("robot_type")), list(f[STATE]["names"]), cams,
                           chunks_size=int(info.get("chunks_size", CHUNKS_SIZE)),
                           data_files_size_in_mb=float(info.get("data_files_size_in_mb", DATA_FILES_SIZE_IN_MB)),
                           video_files_size_in_mb=float(info.get("video_files_size_in_mb", VIDEO_FILES_SIZE_IN_MB)))
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError, InputError) as exc:
        why = exc.message if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
        raise InputError(f"{Path(root) / INFO_PATH}: not a dataset of this layout ({why})",
                         "give a LeRobot v3.0 dataset written by roarmctl or lerobot, or a new folder") from None


def read_episode_rows(root: str | Path) -> list[dict[str, Any]]:
    """Every row of ``meta/episodes`` (all its files, in chunk and file order), one per episode."""
    import pyarrow.parquet as pq

    folder = Path(root) / "meta" / "episodes"
    files = []
    for p in folder.glob("chunk-*/file-*.parquet"):
        m = re.fullmatch(r"chunk-(\d+)", p.parent.name), re.fullmatch(r"file-(\d+)\.parquet", p.name)
        if m[0] and m[1]:
            files.append(((int(m[0][1]), int(m[1][1])), p))
    rows = [r for _, p in sorted(files) for r in pq.read_table(p).to_pylist()]
    if not rows:
        raise InputError(f"{root}: no episodes in {folder}")
    return sorted(rows, key=lambda r: int(r["episode_index"]))


def _data_files(rows: Sequence[dict[str, Any]]) -> list[tuple[int, int]]:
    """The (chunk, file) of each data file the episodes ``rows`` are in, in order."""
    return list(dict.fromkeys((int(r["data/chunk_index"]), int(r["data/file_index"])) for r in rows))


def read_frames(root: str | Path, episode_index: int | None = None) -> Any:
    """The frame rows (a pyarrow Table), of one episode or all (every data file, in the episodes' order)."""
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    rows = read_episode_rows(root)
    if episode_index is not None:
        rows = [r for r in rows if int(r["episode_index"]) == episode_index]
    tables = [pq.read_table(Path(root) / DATA_PATH.format(chunk_index=c, file_index=f)) for c, f in _data_files(rows)]
    if not tables:
        return pa.table({"episode_index": pa.array([], pa.int64()), "frame_index": pa.array([], pa.int64())})
    table = pa.concat_tables(tables)
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
    root = Path(root)
    spec = spec_of(root)
    rows = read_episode_rows(root)
    data = read_frames(root)
    n = len(spec.joint_names)
    state = np.asarray(data[STATE].combine_chunks().flatten().to_numpy()).reshape(-1, n)
    action = np.asarray(data[ACTION].combine_chunks().flatten().to_numpy()).reshape(-1, n)
    index = data["index"].to_numpy()
    by_index = np.argsort(index, kind="stable")  # the frames in index order: an episode is one run of it
    sorted_index = index[by_index]
    out = []
    for row in rows:
        a, b = int(row["dataset_from_index"]), int(row["dataset_to_index"])
        # its frames by bisection (a scan of every frame per episode was episodes x frames on each append)
        lo, hi = np.searchsorted(sorted_index, [a, b])
        at = by_index[lo:hi]
        e = Episode(str(row["tasks"][0]), state[at].copy(), action[at].copy())
        for cam in spec.cameras:
            key = image_key(cam)
            first = int(round(float(row[f"videos/{key}/from_timestamp"]) * spec.fps))
            path = root / VIDEO_PATH.format(video_key=key, chunk_index=int(row[f"videos/{key}/chunk_index"]),
                                            file_index=int(row[f"videos/{key}/file_index"]))
            e.videos[cam] = video.cut(path, first, b - a, spec.fps)
            e.image_stats[cam] = {k: np.asarray(row[f"stats/{key}/{k}"]) for k in st.KEYS}
        out.append(e)
    return out


def append_episodes(root: str | Path, spec: DatasetSpec, episodes: Iterable[Episode]) -> Path:
    """Add ``episodes`` after those of the dataset at ``root`` (a new dataset when there is none; an existing
    one keeps its file sizes). The dataset is written whole into a new folder beside ``root`` and swapped in
    by one rename (``roarmctl.fileio.replace_folder``): a kill leaves the old dataset or the new one, never
    half of each."""
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
        spec = have
    tmp = new_folder_beside(root)
    try:
        write_dataset(tmp, spec, old + list(episodes))
        return replace_folder(tmp, root)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
