"""``datagen``: many episodes of a template as one LeRobot dataset, in shards on a process pool or on Ray.

Tries are numbered 0, 1, 2, ...; try ``t`` is ``roarmctl.physics.episode.run_episode(template, robot, t, seed)``,
a pure function of its arguments. Shards of ``SHARD`` consecutive tries run on the workers (in this process
for one worker, a process pool, or Ray tasks), no more at once than the episodes still missing need at the keep
rate seen so far (``_wanted``: -n 2 on two workers runs two tries when both are kept), each writing its tries into the staging folder
``DATASET/.datagen/`` (a kept try: its state, action, videos (encoded by the worker) and image stats, in a
folder renamed into place when whole; then, for every try, a small outcome file, the try's commit). The
dataset is the first ``n`` kept tries in try order: the same whatever the number of workers or the engine,
and shards still running past the ``n``-th kept try are waited for and left unused. When the kept tries
are known, ``roarmctl.export.lerobot.dataset.write_dataset`` writes the dataset into ``DATASET/.datagen/dataset``
(reading the staged tries one at a time), its folders move into ``DATASET/`` and the staging folder is removed.

A killed run leaves only whole staged tries (a half-written try is a ``.tmp-`` folder, removed on resume);
``resume=True`` takes them and runs only the missing tries. Nothing is written outside ``DATASET/`` (a local
Ray's session: ``_Ray``).
"""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import signal
import sys
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures import TimeoutError as FuturesTimeout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.checks import MAX_WHOLE, Bound, check_options
from roarmctl.errors import DeviceError, InfeasibleError, InputError, RoarmError
from roarmctl.export.lerobot import stats, video
from roarmctl.export.lerobot.dataset import DatasetSpec, Episode, read_info, write_dataset
from roarmctl.fileio import atomic_write_json, note_kept_on_stop
from roarmctl.physics.episode import CAUSES, IMAGE_SIDE, EpisodeOptions, run_episode
from roarmctl.physics.render import CAMERAS, FrameBuffers
from roarmctl.plan.template import check_reach, load_template
from roarmctl.robot.loader import load_robot
from roarmctl.validation import load_json

STAGING = ".datagen"
STATE_FILE = "run.json"
SHARD = 1  # tries per shard: one, so that a run starts no try it will not need (two ran -n 2 on 2 workers as 4 tries)
FORMAT = "roarmctl.datagen/1"
STAGES = ("sample", "plan", "physics", "render", "encode", "stage")
RAY_STARTS = 3  # tries to start a local Ray (each given 30 s by Ray)
POLL_S = 1.0  # s between looks at the running shards (progress, Ctrl-C)
CLOSE_S = 60.0  # s a worker gets to finish its shard when the run ends early
SHARD_CEILING_S = 3600.0  # s without any shard finishing: a worker hangs (a shard takes seconds to minutes)


#: DatagenOptions' bounds (``roarmctl.checks.check_options``).
DATAGEN_BOUNDS = {
    "episodes": Bound(1, 1_000_000, whole=True),
    "seed": Bound(0, MAX_WHOLE, whole=True),
    "workers": Bound(1, 1024, whole=True),
    "width": IMAGE_SIDE,
    "height": IMAGE_SIDE,
    "max_tries": Bound(0, 100_000_000, whole=True),  # 0: 20 per episode, at least 50
    "ray": Bound(text=True, optional=True),  # "": a local Ray; else a cluster's address
    "resume": Bound(flag=True),
    "cameras": Bound(choices=CAMERAS, many=True),
    "codec": Bound(choices=tuple(video.CODECS)),
}


@dataclass
class DatagenOptions:
    """``episodes`` to keep, the ``seed``, ``workers`` (processes or Ray tasks at once), image ``width`` x
    ``height``, ``max_tries`` (0: 20 per episode, at least 50) before giving up (exit 3), ``ray``: None
    (process pool), "" (a local Ray started here) or a cluster address, ``resume`` a killed run; checked on creation
    (``DATAGEN_BOUNDS``)."""

    episodes: int
    seed: int = 0
    workers: int = 1
    width: int = 640
    height: int = 480
    max_tries: int = 0
    ray: str | None = None
    resume: bool = False
    cameras: tuple[str, ...] = CAMERAS  # none: state and action only (real runs can join: export --lerobot)
    codec: str = "h264"  # roarmctl.export.lerobot.video.CODECS

    def __post_init__(self) -> None:
        check_options(self, DATAGEN_BOUNDS)
        if self.width % 2 or self.height % 2:  # between two fields: the size as the CLI takes it
            raise InputError(f"{self.width}x{self.height} has an odd side", "the videos (yuv420p) need even widths and heights",
                             option="size")

    @property
    def limit(self) -> int:
        """Tries before giving up."""
        return self.max_tries or max(50, 20 * self.episodes)


@dataclass
class Summary:
    """What a run did: ``kept`` episodes of ``tried`` tries (those up to the last episode kept), rejections by
    cause among them, CPU seconds per stage summed over every try run (``stages``: spare tries past the last
    episode included; the workers' CPU, so a busy machine does not inflate them), the dataset's ``frames``, its size on disk (bytes) and the wall time (s)."""

    kept: int = 0
    tried: int = 0
    causes: dict[str, int] = field(default_factory=dict)
    stages: dict[str, float] = field(default_factory=dict)
    frames: int = 0
    bytes: int = 0
    wall: float = 0.0
    resumed: int = 0  # tries taken from a killed run
    complete: bool = False  # --resume found the dataset already finished: nothing was run


class Complete(Exception):  # noqa: N818  (not an error: the run has nothing left to do)
    """``--resume`` on a finished dataset: nothing to do."""


# ------------------------------------------------------------------------------------------- the workers
_CACHE: dict[str, Any] = {}
_FRAMES = FrameBuffers()  # this worker's frame arrays, lent to one try after the other


def _loaded(template_path: str) -> tuple[Any, Any]:
    """The template and robot of this process (loaded once per worker)."""
    if template_path not in _CACHE:
        template = load_template(template_path)
        _CACHE[template_path] = (template, load_robot(template.plan.robot))
    return _CACHE[template_path]


def run_shard(template_path: str, staging: str, tries: list[int], seed: int, width: int, height: int,
              cameras: tuple[str, ...] = CAMERAS, codec: str = "h264") -> list[dict[str, Any]]:
    """Run ``tries`` and stage each (see the module doc); returns their outcomes."""
    template, robot = _loaded(template_path)
    options = EpisodeOptions(width=width, height=height, fps=template.fps, cameras=tuple(cameras))
    out = []
    for t in tries:
        r = run_episode(template, robot, t, seed, options, _FRAMES)  # encoded before the next try renders
        outcome: dict[str, Any] = {"try": t, "kept": r.kept, "cause": r.cause, "detail": r.detail, "timings": dict(r.timings)}
        if r.kept:
            assert r.state is not None and r.action is not None  # kept
            t0 = time.process_time()
            videos = {cam: video.encode(frames, template.fps, codec) for cam, frames in r.images.items()}
            image_stats = {cam: stats.to_json({"s": stats.image_stats(frames)})["s"] for cam, frames in r.images.items()}
            outcome["timings"]["encode"] = time.process_time() - t0
            t0 = time.process_time()
            _stage(Path(staging), t, r.state, r.action, videos, image_stats)
            outcome["timings"]["stage"] = time.process_time() - t0
            outcome["frames"] = len(r.state)
        _write_json(Path(staging) / f"{t:08d}.json", outcome)
        out.append(outcome)
    return out


def _write_json(path: Path, obj: Any) -> None:
    atomic_write_json(path, obj, indent=None)


def _stage(staging: Path, t: int, state: np.ndarray, action: np.ndarray, videos: dict[str, bytes],
           image_stats: dict[str, Any]) -> None:
    """A kept try's files, in a temporary folder renamed to ``NNNNNNNN/`` once whole."""
    final = staging / f"{t:08d}"
    tmp = staging / f".tmp-{t:08d}-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    np.save(tmp / "state.npy", state)
    np.save(tmp / "action.npy", action)
    for cam, data in videos.items():
        (tmp / f"{cam}.mp4").write_bytes(data)
    (tmp / "image_stats.json").write_text(json.dumps(image_stats))
    shutil.rmtree(final, ignore_errors=True)  # a try staged before its outcome file was written: done again
    os.replace(tmp, final)


# ------------------------------------------------------------------------------------------- the engines
def _wanted(episodes: int, kept: int, tried: int, running: int) -> bool:
    """Whether one more try is worth starting: ``kept`` of ``tried`` finished tries were kept and ``running`` run.

    Yes while the running tries, kept at the rate seen so far ((kept + 1) / (tried + 1): all of them before the
    first result), would not make up the ``episodes`` still missing, and always when none runs (the run must go
    on; a try before a kept one can still be missing after a resume). A try past the last one the dataset uses is
    spare work (waited for, not used): started only when rejections made it likely to be needed."""
    if running == 0:
        return True
    return running * (kept + 1) / (tried + 1) < episodes - kept


def _shards(start: int, done: set[int]) -> Iterator[list[int]]:
    t = start
    while True:
        shard = [k for k in range(t, t + SHARD) if k not in done]
        t += SHARD
        if shard:
            yield shard


class _Pool:
    """Shards on a process pool (spawned processes: no GL or OMPL state is forked), or in this process."""

    def __init__(self, workers: int) -> None:
        self.executor: Any = None
        if workers > 1:
            self.executor = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"))
        self.slots = workers

    def submit(self, *args: Any) -> Any:
        if self.executor is None:
            f: Future = Future()
            f.set_result(run_shard(*args))
            return f
        return self.executor.submit(run_shard, *args)

    def wait(self, pending: list[Any]) -> list[Any]:
        done, _ = wait(pending, timeout=POLL_S, return_when=FIRST_COMPLETED)
        return [f for f in pending if f in done]

    @staticmethod
    def result(f: Any) -> list[dict[str, Any]]:
        try:
            return f.result(timeout=SHARD_CEILING_S)
        except FuturesTimeout:  # a hung worker: said as the Ray engine says it, not a bare TimeoutError
            raise DeviceError(f"datagen: a worker gave no result in {SHARD_CEILING_S:.0f} s",
                              "check the machine (a worker hangs), then resume the run", option="workers") from None

    def close(self) -> None:
        """Stop the workers: queued shards cancelled, each worker given ``CLOSE_S`` to finish the shard it runs
        (its tries are staged whole or not at all), then killed; a hung worker does not hold the run."""
        if self.executor is None:
            return
        # the executor's own handles on its processes (Python 3.14 adds kill_workers() for this)
        procs = list((self.executor._processes or {}).values())
        self.executor.shutdown(wait=False, cancel_futures=True)
        deadline = time.monotonic() + CLOSE_S
        for proc in procs:
            proc.join(max(0.0, deadline - time.monotonic()))
            if proc.is_alive():
                proc.kill()
                proc.join(5.0)
        self.executor = None


def _children(pid: int) -> set[int]:
    """The processes descended from ``pid`` (Linux ``/proc``; elsewhere none)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").glob("[0-9]*"):
        try:
            stat = (d / "stat").read_text()
            parent[int(d.name)] = int(stat.rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
    out: set[int] = set()
    frontier = {pid}
    while frontier:
        frontier = {c for c, p in parent.items() if p in frontier} - out
        out |= frontier
    return out


class _Ray:
    """The same shards as Ray tasks: a local Ray started here (``address`` "") or an existing cluster.

    A local Ray keeps its session (sockets, logs, spilled objects) in a temporary folder of its own, removed
    by ``close``, and its token (Ray's token authentication) in this process's environment, not in
    ``~/.ray``; it collects no usage stats (``RAY_USAGE_STATS_ENABLED=0`` unless the caller set it). Ray gives a starting raylet a fixed 30 s to register (``ray/_private/node.py``), which a
    machine at a load of a few times its cores exceeds: a start is tried ``RAY_STARTS`` times, the processes
    a failed one left are ended, and then it is a ``DeviceError`` naming the load and the ways round it."""

    def __init__(self, address: str, workers: int) -> None:
        self.temp: Path | None = None
        self.env: dict[str, str | None] = {}
        self.slots = workers
        self.started = False
        if not address and "RAY_AUTH_MODE" not in os.environ and "RAY_AUTH_TOKEN" not in os.environ and "ray" not in sys.modules:
            # before Ray is imported: its token loader reads the environment once
            self._set_env({"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": os.urandom(32).hex()})
        if not address and "RAY_USAGE_STATS_ENABLED" not in os.environ:
            # a Ray started for one run reports nothing to Ray's usage-stats server (its default; Ray's docs,
            # "Usage Stats Collection": the variable is read when Ray starts)
            self._set_env({"RAY_USAGE_STATS_ENABLED": "0"})
        try:
            import ray
        except ImportError:
            self.close()
            raise InputError("Ray is not installed", "pip install 'ray[data]' (make install does)", option="ray") from None
        self.ray = ray
        self.started = not ray.is_initialized()
        if not self.started:
            self.task = ray.remote(num_cpus=1)(run_shard)
            return
        kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
        if address:
            kwargs["address"] = address
        else:
            import tempfile

            # a short path: Ray's Unix sockets live about 70 bytes below it, and a socket's path has 107 at most
            base = tempfile.gettempdir()
            self.temp = Path(tempfile.mkdtemp(prefix="roarmctl-ray-", dir=base if len(base) <= 24 else "/tmp"))
            kwargs |= {"num_cpus": workers, "_temp_dir": str(self.temp)}
        try:
            self._start(kwargs, address)
        except BaseException:
            self.close()
            raise
        self.task = ray.remote(num_cpus=1)(run_shard)

    def _set_env(self, values: dict[str, str]) -> None:
        for k, v in values.items():
            self.env.setdefault(k, os.environ.get(k))
            os.environ[k] = v

    def _start(self, kwargs: dict[str, Any], address: str) -> None:
        before = _children(os.getpid())
        for attempt in range(1, RAY_STARTS + 1):
            try:
                self.ray.init(**kwargs)
                return
            except Exception as exc:  # noqa: BLE001  (Ray raises a bare Exception when its raylet misses its 30 s)
                reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
                self.ray.shutdown()
                for pid in _children(os.getpid()) - before:  # what the failed start left running
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except OSError:
                        pass
                if address or attempt == RAY_STARTS or "timed out" not in reason:  # only the 30 s is worth another try
                    break
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        if address:
            raise DeviceError(f"{address}: no Ray cluster answered there: {reason}",
                              "check the address (ray status on the head node), or leave Ray out for the process pool",
                              option="ray")
        if "timed out" not in reason:
            raise DeviceError(f"local: Ray did not start: {reason}", "leave Ray out for the process pool, or start a Ray head "
                              "node yourself (Ray's own 'ray start') and give its address", option="ray")
        raise DeviceError(f"local: Ray did not start in {RAY_STARTS} tries ({reason}); Ray gives its raylet a fixed 30 s "
                          f"and this machine's load average is {load:.1f} on {os.cpu_count()} CPUs",
                          "try when the machine is less busy, start a Ray head node yourself (Ray's own 'ray start') and give its address, "
                          "or leave Ray out for the process pool", option="ray")

    def submit(self, *args: Any) -> Any:
        return self.task.remote(*args)

    def wait(self, pending: list[Any]) -> list[Any]:
        done, _ = self.ray.wait(pending, num_returns=1, timeout=POLL_S)
        return [f for f in pending if f in done]

    def result(self, f: Any) -> list[dict[str, Any]]:
        try:
            return self.ray.get(f, timeout=SHARD_CEILING_S)
        except self.ray.exceptions.RayTaskError as exc:  # the shard's own error, as the process pool gives it
            if isinstance(exc.cause, RoarmError):
                raise exc.cause from None
            raise
        except self.ray.exceptions.GetTimeoutError:
            raise DeviceError(f"datagen: a Ray task gave no result in {SHARD_CEILING_S:.0f} s",
                              "check the cluster (ray status), then resume the run", option="ray") from None

    def close(self) -> None:
        if self.started:
            self.ray.shutdown()
            self.started = False
        for k, v in self.env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        self.env = {}
        if self.temp is not None:
            shutil.rmtree(self.temp, ignore_errors=True)
            self.temp = None


# ------------------------------------------------------------------------------------------- the run
def _check_out(out: Path, options: DatagenOptions, state: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """The staged outcomes to resume from (none for a new run); refuses a folder that is not this run's."""
    staging = out / STAGING
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} exists and is not a folder", "give the name of a new folder", option="output")
    if not options.resume:
        if out.exists() and any(out.iterdir()):
            raise InputError(f"the folder {out} is not empty", "give a new folder, or resume a killed run into it",
                             option="output")
        return {}
    if not (staging / STATE_FILE).is_file():
        if (out / "meta" / "info.json").is_file():
            raise Complete(out)
        if out.exists() and any(out.iterdir()):
            raise InputError(f"{out}: no run of roarmctl datagen to resume there (no {STAGING}/{STATE_FILE})", option="output")
        return {}
    had = load_json(staging / STATE_FILE, InputError, limit=1 << 16)
    if had != state:
        diff = [k for k in state if not isinstance(had, dict) or had.get(k) != state[k]]
        raise InputError(f"{out}: the run there had other settings ({', '.join(diff)})",
                         "resume with the same template, seed and image size, or give a new folder", option="output")
    outcomes = {}
    for p in sorted(staging.iterdir()):
        if p.name.startswith(".tmp-"):
            shutil.rmtree(p, ignore_errors=True)  # a try killed while it was staged
        elif p.suffix == ".json" and p.name != STATE_FILE and p.stem.isdigit():
            try:
                o = json.loads(p.read_text())
            except (OSError, ValueError):
                continue  # written atomically: a broken one is not ours; the try runs again
            if o.get("kept") and not (staging / p.stem).is_dir():
                continue
            outcomes[int(p.stem)] = o
    return outcomes


def _first_kept(outcomes: dict[int, dict[str, Any]], n: int) -> list[int] | None:
    """The first ``n`` kept tries, if the tries before the ``n``-th kept one are all known."""
    kept = []
    t = 0
    while t in outcomes:
        if outcomes[t]["kept"]:
            kept.append(t)
            if len(kept) == n:
                return kept
        t += 1
    return None


def generate(template_path: str | Path, out: str | Path, options: DatagenOptions,
             progress: Callable[[Summary], None] | None = None) -> Summary:
    """Run the tries and write the dataset (see the module doc); ``progress(summary)`` after every shard.
    ``InfeasibleError`` (exit 3) when ``options.limit`` tries keep fewer than ``options.episodes``."""
    t_start = time.perf_counter()
    template_path = Path(template_path)
    out = Path(out)
    template, robot = _loaded(str(template_path))
    check_reach(template, robot)
    state = {"format": FORMAT, "template_sha256": template.sha256, "seed": options.seed, "width": options.width,
             "height": options.height, "fps": template.fps, "robot": robot.name, "cameras": list(options.cameras),
             "codec": options.codec}
    try:
        outcomes = _check_out(out, options, state)
    except Complete:
        info = read_info(out)
        return Summary(kept=int(info["total_episodes"]), frames=int(info["total_frames"]), complete=True,
                       bytes=sum(p.stat().st_size for p in out.rglob("*") if p.is_file()), wall=time.perf_counter() - t_start)
    staging = out / STAGING
    try:
        staging.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # under a file, in /proc, no permission: the user's path, not a bug
        raise InputError(f"cannot make {out}: {exc.strerror or exc}", "give a folder you can write to",
                         option="output") from None
    _write_json(staging / STATE_FILE, state)
    note_kept_on_stop(f"{out}: finished tries are kept in {staging}; the same command with --resume goes on")
    summary = Summary(resumed=len(outcomes), causes=dict.fromkeys(CAUSES, 0), stages=dict.fromkeys(STAGES, 0.0))

    def count(o: dict[str, Any]) -> None:
        summary.tried += 1
        if o["kept"]:
            summary.kept += 1
        else:
            summary.causes[o["cause"]] = summary.causes.get(o["cause"], 0) + 1
        for k, v in o.get("timings", {}).items():
            summary.stages[k] = summary.stages.get(k, 0.0) + float(v)

    for o in outcomes.values():
        count(o)
    chosen = _first_kept(outcomes, options.episodes)
    if chosen is None:
        engine: _Pool | _Ray = _Ray(options.ray, options.workers) if options.ray is not None else _Pool(options.workers)
        try:
            shards = _shards(0, set(outcomes))
            pending: list[Any] = []
            last = time.monotonic()  # when a shard last finished
            while chosen is None:
                while (len(pending) < engine.slots and summary.tried + SHARD * len(pending) < options.limit
                       and _wanted(options.episodes, summary.kept, summary.tried, SHARD * len(pending))):
                    pending.append(engine.submit(str(template_path), str(staging), next(shards), options.seed,
                                                 options.width, options.height, options.cameras, options.codec))
                if not pending:
                    break
                done = engine.wait(pending)
                if not done:
                    if time.monotonic() - last > SHARD_CEILING_S:
                        raise DeviceError(f"datagen: no shard finished in {SHARD_CEILING_S:.0f} s: a worker hangs",
                                          f"resume the run (the {summary.tried} tries done are kept)")
                    continue
                last = time.monotonic()
                for f in done:
                    pending.remove(f)
                    for o in engine.result(f):
                        outcomes[int(o["try"])] = o
                        count(o)
                if progress is not None:
                    progress(summary)
                chosen = _first_kept(outcomes, options.episodes)
            for f in pending:  # past the last episode needed: finished, not used
                for o in engine.result(f):
                    outcomes[int(o["try"])] = o
        finally:
            engine.close()
    if chosen is None:
        worst = max(summary.causes, key=lambda c: summary.causes[c])
        raise InfeasibleError(f"datagen: {summary.kept} of {options.episodes} episodes kept in {summary.tried} tries "
                              f"(most rejected: {worst}, {summary.causes[worst]})",
                              f"widen or move the template's regions, or raise max_tries; {out} keeps the tries to resume")
    used = [outcomes[t] for t in range(chosen[-1] + 1)]  # the tries the dataset depends on (later ones: spare work)
    summary.tried = len(used)
    summary.causes = dict.fromkeys(CAUSES, 0) | {c: sum(1 for o in used if o["cause"] == c) for c in CAUSES}
    cams = {c: (options.height, options.width) for c in options.cameras}
    spec = DatasetSpec(template.fps, robot.name, list(robot.joint_names), cams)
    frames = [0]

    def episodes() -> Iterator[Episode]:  # read from the staging folder one at a time: videos stay on disk
        for t in chosen:
            d = staging / f"{t:08d}"
            img = json.loads((d / "image_stats.json").read_text())
            e = Episode(template.task, np.load(d / "state.npy"), np.load(d / "action.npy"),
                        videos={c: d / f"{c}.mp4" for c in cams},
                        image_stats={c: {k: np.asarray(v) for k, v in img[c].items()} for c in cams})
            frames[0] += e.length
            yield e

    t0 = time.process_time()
    written = staging / "dataset"  # whole before any of it moves into DATASET/ (metadata last: readers start there)
    shutil.rmtree(written, ignore_errors=True)
    write_dataset(written, spec, episodes())
    for part in ("data", "videos", "meta"):
        if (written / part).exists():
            shutil.rmtree(out / part, ignore_errors=True)  # moved in by a run killed here, resumed now
            os.replace(written / part, out / part)
    summary.stages["write"] = time.process_time() - t0
    shutil.rmtree(staging)
    note_kept_on_stop(None)
    summary.kept = len(chosen)
    summary.frames = frames[0]
    summary.bytes = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
    summary.wall = time.perf_counter() - t_start
    if progress is not None:
        progress(summary)
    return summary
