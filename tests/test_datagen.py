"""roarmctl datagen: templates, episodes, the LeRobot v3.0 writer, shards, determinism and resume.

The datasets are read back with plain pyarrow and numpy (and pandas for the tasks, as lerobot reads them), not
with the writer's own reader; lerobot itself and Ray Data's ``read_lerobot`` (which needs lerobot) only where
they are installed."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from tests.clirun import roarmctl

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "plans" / "datagen" / "pick_place.yaml"
SIZE = 96


def _template(tmp_path: Path, datagen: str) -> Path:
    """The bundled template with its datagen block replaced."""
    text = TEMPLATE.read_text()
    plan = text[: text.index("datagen:")]
    p = tmp_path / "t.yaml"
    p.write_text(plan + datagen)
    return p


# ------------------------------------------------------------------------------------------- bad templates
@pytest.mark.parametrize(("block", "words"), [
    ("datagen:\n  task: t\n  objects:\n    cube: {x: [0.30, 0.20]}\n", "is empty"),
    ("datagen:\n  task: t\n  objects:\n    cube: {x: [0.20, .nan]}\n", "finite"),
    ("datagen:\n  task: t\n  objects:\n    cube: {mass: [0.02, .inf]}\n", "finite"),
    ("datagen:\n  task: t\n  places:\n    - {x: [0.45, 0.55], y: [0.10, 0.15]}\n", "cannot reach"),
    ("datagen:\n  task: t\n  objects:\n    mug: {x: [0.2, 0.25]}\n", "unknown key"),
    ("datagen:\n  task: t\n  places: [{x: [0.2, 0.25], y: [0.1, 0.12]}, {x: [0.2, 0.25], y: [0.1, 0.12]}]\n", "one region per place"),
    ("datagen:\n  task: t\n  distractors: {count: [0, 99], x: [0.1, 0.2], y: [0, 0.1], size: 0.02}\n", "out of range"),
    ("datagen:\n  task: ''\n", "task"),
    ("", "not a datagen template"),
])
def test_a_bad_template_exits_2_with_one_line_and_writes_nothing(tmp_path, block, words):
    p = _template(tmp_path, block)
    out = tmp_path / "ds"
    r = roarmctl("datagen", str(p), "-n", "1", "-o", str(out), "--size", "32x32")
    assert r.returncode == 2, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.strip()]
    assert len(lines) == 1 and words in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()


def test_bad_options_exit_2(tmp_path):
    for args in (["-n", "0"], ["-n", "1", "--size", "9x"], ["-n", "1", "--workers", "0"], ["-n", "1", "--size", "95x96"],
                 ["-n", "1", "--codec", "vp9"], ["-n", "1", "--cameras", "top"]):
        r = roarmctl("datagen", str(TEMPLATE), *args, "-o", str(tmp_path / "ds"))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    for size in ("0x96", "96x8000"):  # named as typed: it said --width / --height, options datagen does not have
        r = roarmctl("datagen", str(TEMPLATE), "-n", "1", "--size", size, "-o", str(tmp_path / "ds"))
        assert r.returncode == 2 and r.stderr.startswith("error: --size: "), r.stderr


def test_an_output_folder_that_cannot_be_made_exits_2_with_one_line(tmp_path):
    """-o under a file (any user, root too, cannot make a folder there): was an internal error (exit 1)."""
    (tmp_path / "a_file").write_text("x")
    r = roarmctl("datagen", str(TEMPLATE), "-n", "1", "--size", "32x32", "-o", str(tmp_path / "a_file" / "ds"))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "a_file" in lines[0] and "Traceback" not in r.stderr, r.stderr
    assert (tmp_path / "a_file").read_text() == "x"


def test_a_stopped_run_says_what_it_kept_and_how_to_go_on(tmp_path, monkeypatch):
    """Ctrl-C once the run's folder is made: it said "nothing was written" and left DATASET/.datagen behind."""
    from roarmctl.export.lerobot import datagen

    def stop(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(datagen, "_first_kept", stop)
    out = tmp_path / "ds"
    r = roarmctl("datagen", str(TEMPLATE), "-n", "1", "--size", "32x32", "-o", str(out))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 130 and len(lines) == 1, r.stderr
    assert "nothing was written" not in lines[0] and "--resume" in lines[0] and str(out) in lines[0], r.stderr
    assert (out / datagen.STAGING / datagen.STATE_FILE).is_file()  # what --resume goes on from
    from roarmctl.fileio import interrupted_write_state

    assert interrupted_write_state() is None  # said once: a later command's stop is not this run's


@pytest.mark.parametrize("fps", ["0", "-1", "121"])
def test_export_lerobot_fps_out_of_range_exits_2_before_reading_the_run(tmp_path, fps):
    """--fps 0 was taken as 'not given' and a 30 fps dataset was written with exit 0."""
    r = roarmctl("export", str(tmp_path / "run.exec.json"), "--lerobot", str(tmp_path / "ds"), "--fps", fps)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "--fps" in lines[0] and "1 to 120" in lines[0], r.stderr
    assert not (tmp_path / "ds").exists()


def test_a_sampled_scene_stays_within_the_regions_and_is_the_same_for_the_same_try():
    from roarmctl.physics.episode import sample_plan
    from roarmctl.plan.template import load_template
    from roarmctl.robot.loader import load_robot

    t = load_template(TEMPLATE)
    robot = load_robot(t.plan.robot)
    cube = t.objects["cube"]
    for k in range(30):
        a = sample_plan(t, robot, np.random.default_rng([5, k]))
        b = sample_plan(t, robot, np.random.default_rng([5, k]))
        assert a == b and a is not None
        doc, colors = a
        obj = next(o for o in doc["objects"] if o["name"] == "cube")
        assert cube.x.lo <= obj["xyz"][0] <= cube.x.hi and cube.y.lo <= obj["xyz"][1] <= cube.y.hi
        # the bottom stays on the table whatever the scale
        assert obj["xyz"][2] - obj["size"][2] / 2 == pytest.approx(0.0, abs=1e-12)
        assert 0.02 <= obj["mass"] <= 0.04 and tuple(colors["cube"]) in cube.colors
        place = next(task["place"] for task in doc["tasks"] if "place" in task)
        assert t.places[0].x.lo <= place["xyz"][0] <= t.places[0].x.hi
        assert place["xyz"][2] == pytest.approx(obj["xyz"][2])  # the place height follows the object's size
        start = np.array(doc["start"])
        assert np.all(np.abs(start - robot.named_poses["home"]) <= t.start_jitter + 1e-12)


# ------------------------------------------------------------------------------------------- stats
@settings(max_examples=40, deadline=None)
@given(hs.lists(hs.integers(1, 40), min_size=1, max_size=6), hs.integers(0, 2**31))
def test_aggregated_stats_equal_the_stats_of_all_frames(lengths, seed):
    from roarmctl.export.lerobot import stats

    rng = np.random.default_rng(seed)
    parts = [rng.normal(rng.normal(), rng.uniform(0.1, 3), size=(n, 3)) for n in lengths]
    agg = stats.aggregate([stats.vector_stats(p) for p in parts])
    every = np.concatenate(parts)
    np.testing.assert_allclose(agg["mean"], every.mean(axis=0), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(agg["std"], every.std(axis=0), rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(agg["min"], every.min(axis=0))
    np.testing.assert_array_equal(agg["max"], every.max(axis=0))
    assert agg["count"].tolist() == [len(every)]
    # lerobot's rule for the quantiles (aggregate_feature_stats, lerobot 0.4.4): the episodes' weighted by their frames
    for key, q in (("q01", 0.01), ("q50", 0.5), ("q99", 0.99)):
        by_frames = sum(len(p) * np.quantile(p, q, axis=0) for p in parts) / len(every)
        np.testing.assert_allclose(agg[key], by_frames, rtol=1e-12, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(hs.sampled_from([1, 2, 5, 99, 100, 101, 150, 217, 600]), hs.integers(1, 9), hs.integers(0, 2**31),
       hs.sampled_from([2, 40, 256]))
def test_image_stats_from_histograms_equal_numpy_over_lerobots_sample_of_the_pixels(frames, side, seed, levels):
    """Against numpy over the frames lerobot's compute_stats samples, written out here: for 1-500 frames 100 of
    them (all when fewer), else int(n ** 0.75), evenly spaced from the first to the last (rounded)."""
    from roarmctl.export.lerobot import stats

    rng = np.random.default_rng(seed)
    img = rng.integers(0, levels, size=(frames, side, side + 1, 3)).astype(np.uint8)
    got = stats.image_stats(img)
    k = min(frames, 100) if frames <= 500 else int(frames**0.75)
    picked = [int(np.round(i * (frames - 1) / (k - 1))) if k > 1 else 0 for i in range(k)]
    assert picked[0] == 0 and picked[-1] == frames - 1
    px = img[picked].reshape(-1, 3).astype(np.float64) / 255.0
    want = stats.vector_stats(px)
    for key in ("min", "max", "mean", "std") + stats.Q_KEYS:
        np.testing.assert_allclose(got[key].ravel(), want[key], rtol=1e-9, atol=1e-12, err_msg=key)
    assert got["count"].tolist() == [k] and got["mean"].shape == (3, 1, 1)


# ------------------------------------------------------------------------------------------- the writer
def _synthetic(n_frames: list[int], seed: int = 0, size: int = 64, codec: str = "h264") -> list:
    from roarmctl.export.lerobot import video
    from roarmctl.export.lerobot.dataset import Episode

    rng = np.random.default_rng(seed)
    out = []
    for k, n in enumerate(n_frames):
        frames = np.zeros((n, size, size, 3), dtype=np.uint8)
        for f in range(n):  # a square that moves: each frame differs
            frames[f, (f * 3) % (size - 8):(f * 3) % (size - 8) + 8, 10:18] = (200, 40 + 10 * k, 30)
        out.append(Episode(f"task {k % 2}", rng.normal(size=(n, 6)).astype(np.float32), rng.normal(size=(n, 6)).astype(np.float32),
                           videos={"front": video.encode(frames, 10, codec)}))
    return out


def _spec(size: int = 64):
    from roarmctl.export.lerobot.dataset import DatasetSpec

    return DatasetSpec(10, "roarm_m3_pro", ["base", "shoulder", "elbow", "wrist", "roll", "hand"], {"front": (size, size)})


def _check_dataset(root: Path, lengths: list[int], fps: int, cams: list[str]) -> None:
    """The layout and contents, read with pyarrow (each folder as one dataset: every file in it), numpy,
    pandas and PyAV (not the writer's reader)."""
    import av
    import pandas as pd
    import pyarrow.parquet as pq

    info = json.loads((root / "meta/info.json").read_text())
    assert info["codebase_version"] == "v3.0" and info["fps"] == fps
    assert info["total_episodes"] == len(lengths) and info["total_frames"] == sum(lengths)
    assert info["data_path"] == "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
    assert info["video_path"] == "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    feats = info["features"]
    assert feats["observation.state"]["names"] == feats["action"]["names"] and feats["action"]["shape"] == [6]
    data = pq.read_table(root / "data").sort_by("index")
    assert data.num_rows == sum(lengths)
    ep = data["episode_index"].to_numpy()
    fi = data["frame_index"].to_numpy()
    assert data["index"].to_numpy().tolist() == list(range(sum(lengths)))
    assert np.array_equal(data["timestamp"].to_numpy(), (fi / fps).astype(np.float32))
    episodes = pq.read_table(root / "meta/episodes").sort_by("episode_index").to_pylist()
    assert len(episodes) == len(lengths)
    tasks = pd.read_parquet(root / "meta/tasks.parquet")
    state = np.stack(data["observation.state"].to_numpy(zero_copy_only=False))
    before = 0
    in_file: dict = {}  # (camera, chunk, file) -> frames of the episodes before, in that file
    for k, (row, n) in enumerate(zip(episodes, lengths)):
        assert row["episode_index"] == k and row["length"] == n
        a, b = row["dataset_from_index"], row["dataset_to_index"]
        assert (a, b) == (before, before + n)
        assert np.all(ep[a:b] == k) and fi[a:b].tolist() == list(range(n))
        rows_there = pq.read_table(root / f"data/chunk-{row['data/chunk_index']:03d}/file-{row['data/file_index']:03d}.parquet")
        assert (rows_there["episode_index"].to_numpy() == k).sum() == n  # the episode is whole in the file it names
        assert tasks.loc[row["tasks"][0], "task_index"] == data["task_index"].to_numpy()[a]
        s = state[a:b]
        np.testing.assert_allclose(row["stats/observation.state/mean"], s.mean(axis=0), rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(row["stats/observation.state/q50"], np.quantile(s.astype(np.float64), 0.5, axis=0), rtol=1e-6, atol=1e-7)
        for cam in cams:
            key = f"observation.images.{cam}"
            where = (cam, row[f"videos/{key}/chunk_index"], row[f"videos/{key}/file_index"])
            first = in_file.get(where, 0)
            assert row[f"videos/{key}/from_timestamp"] == pytest.approx(first / fps)
            assert row[f"videos/{key}/to_timestamp"] == pytest.approx((first + n) / fps)
            in_file[where] = first + n
        before += n
    total = json.loads((root / "meta/stats.json").read_text())
    np.testing.assert_allclose(total["observation.state"]["mean"], state.mean(axis=0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(total["observation.state"]["std"], state.std(axis=0), rtol=1e-4, atol=1e-6)
    assert set(total["action"]) == {"min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"}
    for cam in cams:
        key = f"observation.images.{cam}"
        assert np.asarray(total[key]["mean"]).shape == (3, 1, 1)
        files = sorted((root / f"videos/{key}").glob("chunk-*/file-*.mp4"))
        assert len(files) == len([w for w in in_file if w[0] == cam])
        for (c, chunk, file), frames in in_file.items():
            if c != cam:
                continue
            with av.open(str(root / f"videos/{key}/chunk-{chunk:03d}/file-{file:03d}.mp4")) as f:
                times = [fr.time for fr in f.decode(video=0)]
            assert len(times) == frames
            np.testing.assert_allclose(times, np.arange(frames) / fps, atol=1e-6)
        assert feats[key]["info"]["video.codec"] in ("h264", "av1") and feats[key]["info"]["video.fps"] == fps
        assert feats[key]["info"]["video.pix_fmt"] == "yuv420p" and feats[key]["info"]["video.g"] == 2
        assert feats[key]["info"]["video.is_depth_map"] is False  # lerobot 0.4.4's get_video_info writes it
    # lerobot keeps an integer feature's min and max integers (as lerobot 0.4.4 writes them, read from its output)
    schema = pq.read_schema(next((root / "meta/episodes").glob("chunk-*/file-*.parquet")))
    for name in ("frame_index", "episode_index", "index", "task_index"):
        for stat in ("min", "max"):
            assert str(schema.field(f"stats/{name}/{stat}").type) == "list<element: int64>", (name, stat)
        assert str(schema.field(f"stats/{name}/mean").type) == "list<element: double>"


@pytest.mark.slow
@pytest.mark.parametrize("codec", ["h264", "av1"])
def test_a_written_dataset_reads_back_with_pyarrow(tmp_path, codec):
    from roarmctl.export.lerobot.dataset import read_actions, write_dataset

    eps = _synthetic([7, 12, 5], codec=codec)
    write_dataset(tmp_path / "ds", _spec(), eps)
    _check_dataset(tmp_path / "ds", [7, 12, 5], 10, ["front"])
    t, a = read_actions(tmp_path / "ds", 1)
    np.testing.assert_array_equal(a, eps[1].action)
    np.testing.assert_allclose(t, np.arange(12) / 10, atol=1e-6)


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="SVT-AV1 raises its threads only as root")
def test_an_av1_encode_as_root_runs_and_leaves_no_real_time_policy():
    """SVT-AV1 run as root starts its encoder threads SCHED_FIFO 99 and leaves the calling thread so (measured), and a
    process started from it then inherits that: a busy child would own its core. With roarmctl's encode no thread
    of the process is real-time while it runs (a watcher reads every thread's policy from /proc every millisecond),
    the right to be is back afterwards, and a child runs under the normal policy."""
    import threading

    import pyprctl

    from roarmctl.export.lerobot import video

    def policies() -> set[int]:
        out = set()
        for tid in os.listdir("/proc/self/task"):
            with contextlib.suppress(OSError):
                stat = Path(f"/proc/self/task/{tid}/stat").read_text()
                out.add(int(stat.rsplit(")", 1)[1].split()[38]))  # field 41, policy (proc(5))
        return out

    seen: set[int] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.update(policies())
            done.wait(0.001)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        frames = np.random.default_rng(0).integers(0, 255, (60, 96, 96, 3), dtype=np.uint8)
        video.encode(frames, 30, "av1")
    finally:
        done.set()
        watcher.join(timeout=10)
    # real-time policies only: a worker that rendered before keeps Mesa's shader-cache thread ("disk$0"), which Mesa
    # runs SCHED_BATCH (a normal, lower-interactivity policy; seen in a CI rehearsal)
    assert not seen & {os.SCHED_FIFO, os.SCHED_RR}, seen
    assert pyprctl.Cap.SYS_NICE in pyprctl.CapState.get_current().effective
    child = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)"],
                           capture_output=True, text=True, timeout=60)
    assert child.stdout.split() == [str(os.SCHED_OTHER), "0"], child.stdout


@pytest.mark.slow
def test_appending_gives_the_same_bytes_as_writing_all_at_once(tmp_path):
    from roarmctl.export.lerobot.dataset import append_episodes, write_dataset

    eps = _synthetic([6, 9, 4, 7, 5], seed=3)
    spec = _small_files_spec(eps)  # the files roll over too
    write_dataset(tmp_path / "all", spec, eps)
    append_episodes(tmp_path / "grown", spec, eps[:2])
    append_episodes(tmp_path / "grown", spec, eps[2:])
    files = sorted(p.relative_to(tmp_path / "all") for p in (tmp_path / "all").rglob("*") if p.is_file())
    assert len([p for p in files if p.suffix == ".mp4"]) >= 2
    assert files == sorted(p.relative_to(tmp_path / "grown") for p in (tmp_path / "grown").rglob("*")
                           if p.is_file() and not p.name.startswith("."))
    for rel in files:
        assert (tmp_path / "all" / rel).read_bytes() == (tmp_path / "grown" / rel).read_bytes(), rel


def _small_files_spec(eps: list, per_file: float = 2.5):
    """A spec whose files roll over every few episodes: video files at ``per_file`` episodes' MP4s, data files
    at about a kilobyte, two files a chunk."""
    from dataclasses import replace

    mean = np.mean([len(e.videos["front"]) for e in eps])
    return replace(_spec(), chunks_size=2, data_files_size_in_mb=1000 / 1024**2,
                   video_files_size_in_mb=per_file * mean / 1024**2)


@pytest.mark.slow
def test_files_roll_over_as_lerobot_rolls_them_and_a_reader_sees_every_episode(tmp_path):
    """Small limits (lerobot's rule, huggingface/lerobot datasets/dataset_writer.py: a video file is full when its
    episodes' MP4 bytes plus the next episode's reach video_files_size_in_mb MiB; a new chunk every chunks_size
    files): several data and video files in several chunks, each episode whole in the files its metadata names,
    and pyarrow reading each folder as one dataset sees every frame and episode."""
    import pyarrow.parquet as pq

    from roarmctl.export.lerobot.dataset import read_actions, read_episodes, write_dataset

    lengths = [7, 12, 5, 9, 6, 8, 4, 11, 3]
    eps = _synthetic(lengths, seed=5)
    spec = _small_files_spec(eps)
    write_dataset(tmp_path / "ds", spec, eps)
    _check_dataset(tmp_path / "ds", lengths, 10, ["front"])
    limit = spec.video_files_size_in_mb * 1024**2
    want, size, file = [], 0, 0  # lerobot's rule by hand: the file of each episode's video
    for k, e in enumerate(eps):
        if k and size + len(e.videos["front"]) >= limit:
            file, size = file + 1, 0
        size += len(e.videos["front"])
        want.append((file // 2, file % 2))
    rows = pq.read_table(tmp_path / "ds" / "meta/episodes").sort_by("episode_index").to_pylist()
    got = [(r["videos/observation.images.front/chunk_index"], r["videos/observation.images.front/file_index"]) for r in rows]
    assert got == want and len(set(want)) >= 3
    data_files = sorted((tmp_path / "ds" / "data").glob("chunk-*/file-*.parquet"))
    assert len(data_files) >= 3 and (tmp_path / "ds" / "data" / "chunk-001").is_dir()
    assert {(r["data/chunk_index"], r["data/file_index"]) for r in rows} == {
        (int(p.parent.name[6:]), int(p.stem[5:])) for p in data_files}
    info = json.loads((tmp_path / "ds" / "meta/info.json").read_text())
    assert info["chunks_size"] == 2 and info["video_files_size_in_mb"] == spec.video_files_size_in_mb
    back = read_episodes(tmp_path / "ds")  # the writer's own reader, across the files
    assert [e.length for e in back] == lengths
    for k in (0, 4, 8):
        np.testing.assert_array_equal(back[k].state, eps[k].state)
        np.testing.assert_array_equal(read_actions(tmp_path / "ds", k)[1], eps[k].action)


def test_appending_other_joints_or_cameras_is_refused(tmp_path):
    from roarmctl.errors import InputError
    from roarmctl.export.lerobot.dataset import DatasetSpec, append_episodes, write_dataset

    write_dataset(tmp_path / "ds", _spec(), _synthetic([4]))
    other = DatasetSpec(10, "roarm_m3_pro", ["base", "shoulder", "elbow", "wrist", "roll", "hand"], {})
    with pytest.raises(InputError, match="cameras"):
        append_episodes(tmp_path / "ds", other, [])


@pytest.mark.slow
@pytest.mark.parametrize(("field", "value"), [("chunks_size", 0), ("data_files_size_in_mb", "big"), ("video_files_size_in_mb", None),
                                             ("video_files_size_in_mb", -1.0), ("fps", [30]), ("features", 7)])
def test_appending_to_a_dataset_whose_info_is_broken_is_an_input_error(tmp_path, field, value):
    """A dataset's info.json is data: a missing or wrong field is an InputError naming the file (exit 2), not a
    traceback, and the dataset is left as it was."""
    from roarmctl.errors import InputError
    from roarmctl.export.lerobot.dataset import append_episodes, write_dataset

    eps = _synthetic([4, 3])
    write_dataset(tmp_path / "ds", _spec(), eps[:1])
    path = tmp_path / "ds" / "meta" / "info.json"
    info = json.loads(path.read_text())
    info[field] = value
    path.write_text(json.dumps(info))
    before = sorted((p.relative_to(tmp_path), p.read_bytes()) for p in tmp_path.rglob("*") if p.is_file())
    with pytest.raises(InputError, match=r"info\.json"):
        append_episodes(tmp_path / "ds", _spec(), eps[1:])
    assert sorted((p.relative_to(tmp_path), p.read_bytes()) for p in tmp_path.rglob("*") if p.is_file()) == before


# ------------------------------------------------------------------------------------------- whole runs
def docs_command(ray: bool) -> list[str]:
    """The docs' ``datagen`` command at 96x96 pixels with ``--ray local`` (docs/guide.md) or without it
    (docs/benchmarks.md's lerobot dataset), as written: its arguments after ``roarmctl``."""
    from test_readme_examples import COMMANDS

    (cmd,) = [c for c in COMMANDS if c.startswith("roarmctl datagen") and f"--size {SIZE}x{SIZE}" in c
              and ("--ray local" in c) == ray]
    return cmd.split()[1:]


def _option(args: list[str], name: str) -> str:
    return args[args.index(name) + 1]


EPISODES = int(_option(docs_command(ray=False), "-n"))


def _generate(out: Path, workers: int = 1, **kw):
    from roarmctl.export.lerobot.datagen import DatagenOptions, generate

    return generate(TEMPLATE, out, DatagenOptions(episodes=EPISODES, seed=0, workers=workers, width=SIZE, height=SIZE, **kw))


@pytest.fixture(scope="module")
def dataset96(tmp_path_factory):
    """docs/benchmarks.md's dataset, its command run as written (test_readme_examples leaves it to this fixture, so it
    is written once): one worker, in this process. The killed run's test resumes on two workers and the Ray test
    runs the tries as Ray tasks, both to the same bytes: the dataset is the same whatever the workers or the engine.
    Returns the dataset's folder and the command's output."""
    args = docs_command(ray=False)
    assert _option(args, "--size") == f"{SIZE}x{SIZE}" and "--workers" not in args and "--seed" not in args, args
    work = tmp_path_factory.mktemp("datagen")
    (work / "plans").symlink_to(ROOT / "plans")  # the command's paths are the docs' (from the clone's top)
    r = roarmctl(*args, cwd=work)
    assert r.returncode == 0, r.stderr
    return work / _option(args, "-o"), r.stdout


FILES = ("data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet", "meta/tasks.parquet",
         "meta/stats.json", "meta/info.json")
VIDEOS = ("videos/observation.images.front/chunk-000/file-000.mp4", "videos/observation.images.wrist/chunk-000/file-000.mp4")


@pytest.mark.slow  # three episodes planned, run in physics and rendered (about 10 s on an idle core)
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_the_docs_dataset_at_96_pixels(dataset96):
    import pyarrow.parquet as pq

    out, said = dataset96
    assert not (out / ".datagen").exists()
    lengths = [r["length"] for r in pq.read_table(out / "meta/episodes/chunk-000/file-000.parquet").to_pylist()]
    assert len(lengths) == EPISODES and f"{EPISODES} episodes, {sum(lengths)} frames" in " ".join(said.split())
    _check_dataset(out, lengths, 30, ["front", "wrist"])
    assert sorted(p.name for p in out.iterdir()) == ["data", "meta", "videos"]


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_actions_are_what_execute_sends_and_states_follow_the_plan(dataset96):
    """Each episode's trajectory is planned again from its try (the same draw), and the commands of the
    streamer's schedule (``build_schedule``, as execute sends them) decoded at each frame time must be its
    action column; the state is measured, so it follows the plan closely but is not the command."""
    import pyarrow.parquet as pq

    from roarmctl.device.protocol import M3_FIELDS, WireMap
    from roarmctl.device.schedule import build_schedule, sample
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.episode import sample_plan
    from roarmctl.plan.template import load_template
    from roarmctl.robot.loader import load_robot

    out, _ = dataset96
    t = load_template(TEMPLATE)
    robot = load_robot(t.plan.robot)
    data = pq.read_table(out / "data/chunk-000/file-000.parquet")
    action = np.stack(data["action"].to_numpy(zero_copy_only=False)).astype(np.float64)
    state = np.stack(data["observation.state"].to_numpy(zero_copy_only=False)).astype(np.float64)
    ep = data["episode_index"].to_numpy()
    ts = data["frame_index"].to_numpy() / 30.0  # the instants exactly (the timestamp column is float32)
    wm = WireMap(robot)
    matched = 0
    for k in range(12):  # the kept tries are among the first ones (the fixture kept EPISODES)
        rng = np.random.default_rng([0, k])
        drawn = sample_plan(t, robot, rng)
        if drawn is None:
            continue
        try:
            traj = plan_file(drawn[0], seed=int(rng.integers(2**31 - 1)), base_dir=TEMPLATE.parent).trajectory
        except Exception:  # noqa: BLE001  (a rejected try)
            continue
        ticks = build_schedule(traj, robot, sag=True)  # as execute sends it by default
        wire = dict(zip(wm.field_names, wm.to_wire_array(traj.positions[:1])[0]))
        rows = np.flatnonzero(ep == matched)
        want = []
        i = 0
        for time_s in ts[rows]:
            while i < len(ticks) and ticks[i].t <= time_s + 1e-9:
                for cmd in ticks[i].commands:
                    if cmd.get("T") == 102:
                        wire.update({f: float(cmd[f]) for f in wm.field_names if f in cmd})
                    elif cmd.get("T") == 101:
                        wire[M3_FIELDS[int(cmd["joint"]) - 1]] = float(cmd["rad"])
                i += 1
            want.append(wm.from_wire(wire))
        if len(rows) and np.allclose(np.array(want), action[rows], atol=2e-6):
            arm = robot.arm_indices
            plan = sample(traj, np.clip(ts[rows], 0, traj.duration))
            assert np.max(np.abs(state[rows][:, arm] - plan[:, arm])) < 0.25  # the servos track the plan
            assert not np.allclose(state[rows], action[rows], atol=1e-4)  # measured, not commanded
            matched += 1
            if matched == EPISODES:
                break
    assert matched == EPISODES


@pytest.mark.slow  # a run killed with SIGKILL after its first staged try, then resumed
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_a_killed_run_resumed_on_two_workers_is_the_dataset_one_worker_wrote(dataset96, tmp_path):
    """One worker until killed, the resume on the process pool (two workers, spawned processes; the tries left
    are run there), against the fixture's one worker in its own process: the same bytes in every file and the same
    frames in every video, so neither a resume nor the engine that runs the tries changes the dataset."""
    from roarmctl.export.lerobot import video

    out, _ = dataset96
    target = tmp_path / "ds"
    env = {**os.environ, "COLUMNS": "80"}
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "datagen", str(TEMPLATE), "-n", str(EPISODES), "-o", str(target),
                             "--size", f"{SIZE}x{SIZE}", "--json"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        deadline = time.monotonic() + 300  # a ceiling only: the test waits for a staged try, not for a time
        while time.monotonic() < deadline and proc.poll() is None:
            if (target / ".datagen" / "00000001.json").exists():
                break
            time.sleep(0.05)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
    staged = target / ".datagen"
    assert staged.is_dir() and not (target / "meta").exists()  # killed before the dataset was written
    r = roarmctl("datagen", str(TEMPLATE), "-n", str(EPISODES), "-o", str(target), "--size", f"{SIZE}x{SIZE}")
    assert r.returncode == 2 and "--resume" in r.stderr  # a non-empty folder needs --resume
    summary = _generate(target, workers=2, resume=True)
    assert summary.resumed >= 2
    for rel in FILES + VIDEOS:
        assert (out / rel).read_bytes() == (target / rel).read_bytes(), rel
    for rel in VIDEOS:
        a, _ = video.decode(out / rel)
        b, _ = video.decode(target / rel)
        assert np.array_equal(a, b), rel
    assert sorted(p.name for p in target.iterdir()) == ["data", "meta", "videos"]


def _lerobot_python() -> str | None:
    """The Python that has lerobot: ``ROARMCTL_LEROBOT_PYTHON`` (lerobot in a venv of its own, as docs/guide.md
    shows: it pins torch, which roarmctl does not need), else this one if lerobot imports here, else None."""
    import importlib.util

    given = os.environ.get("ROARMCTL_LEROBOT_PYTHON")
    if given:
        return given
    return sys.executable if importlib.util.find_spec("lerobot") is not None else None


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_lerobot_itself_reads_the_frames_written(dataset96):
    """Optional (skipped where lerobot is not installed; CI does not have it): ``LeRobotDataset`` of lerobot itself,
    run by ``tests/lerobot_read.py`` in lerobot's Python, reads the dataset as pyarrow and PyAV read it: the same
    episodes and frames, indices, timestamps k / fps, tasks, ``observation.state`` and ``action`` to the bit, at
    three frames of each episode each camera's image as PyAV decodes the episode's frame from the file, and the
    stats of state and action as lerobot computes them from those frames (its quantiles from a histogram)."""
    import pyarrow.parquet as pq

    from roarmctl.export.lerobot import video

    python = _lerobot_python()
    if python is None:
        pytest.skip("lerobot is not installed here: set ROARMCTL_LEROBOT_PYTHON to the python of a venv that has it")
    out, _ = dataset96
    r = subprocess.run([python, str(ROOT / "tests" / "lerobot_read.py"), str(out), "3"], capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout)
    data = pq.read_table(out / "data/chunk-000/file-000.parquet").to_pydict()
    episodes = pq.read_table(out / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    tasks = pq.read_table(out / "meta/tasks.parquet").to_pandas()
    assert got["num_episodes"] == EPISODES == len(episodes) and got["num_frames"] == len(data["index"])
    assert got["fps"] == 30 and got["camera_keys"] == ["observation.images.front", "observation.images.wrist"]
    rows = got["rows"]
    for key in ("index", "episode_index", "frame_index", "task_index"):
        assert [row[key] for row in rows] == data[key], key
    timestamps = np.array([row["timestamp"] for row in rows], dtype=np.float32)
    np.testing.assert_array_equal(timestamps, (np.array(data["frame_index"]) / 30).astype(np.float32))
    np.testing.assert_array_equal(timestamps, np.array(data["timestamp"], dtype=np.float32))
    for key in ("observation.state", "action"):
        np.testing.assert_array_equal(np.array([row[key] for row in rows], dtype=np.float32), np.array(data[key], dtype=np.float32))
    written = json.loads((out / "meta/stats.json").read_text())
    for key in ("observation.state", "action"):
        assert got["stats_loaded"][key] == written[key]
        theirs, ours = got["stats_computed"][key], written[key]
        assert theirs["count"] == ours["count"]
        span = np.array(ours["max"]) - np.array(ours["min"])
        np.testing.assert_array_equal(theirs["min"], ours["min"])
        np.testing.assert_array_equal(theirs["max"], ours["max"])
        for stat in ("mean", "std"):  # lerobot sums float32 values, roarmctl float64
            assert np.all(np.abs(np.array(theirs[stat]) - ours[stat]) <= 1e-4 * span + 1e-7), (key, stat)
        for q in ("q01", "q10", "q50", "q90", "q99"):  # lerobot's from a histogram (~0.2 % of the span here), ours exact
            assert np.all(np.abs(np.array(theirs[q]) - ours[q]) <= 0.01 * span + 1e-7), (key, q)
    decoded = {cam: video.decode(out / f"videos/{cam}/chunk-000/file-000.mp4")[0] for cam in got["camera_keys"]}
    assert len(got["images"]) == 3 * EPISODES
    for img in got["images"]:
        ep = episodes[img["episode_index"]]
        assert img["task"] == tasks.index[data["task_index"][img["index"]]]
        for cam in got["camera_keys"]:
            k = round(ep[f"videos/{cam}/from_timestamp"] * 30) + img["frame_index"]  # the frame's place in the file
            theirs = np.array(img[cam]).transpose(1, 2, 0)  # C x H x W -> H x W x C
            assert theirs.shape == decoded[cam][k].shape == (SIZE, SIZE, 3)
            # the same frame: both decode it with FFmpeg; colour conversions may round apart by a level or two
            assert np.abs(theirs - decoded[cam][k].astype(int)).max() <= 3, (cam, img["index"])


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_lerobot_itself_writes_the_same_layout(dataset96, tmp_path):
    """Optional, as the test above: the dataset's frames written again by lerobot's own writer
    (``tests/lerobot_write.py``: ``LeRobotDataset.create``, ``add_frame``, ``save_episode``) give the same files,
    the episodes' and frames' parquet with the same columns of the same types, the same values in the frames'
    columns and in the episodes' but their stats (lengths, indices, chunks and files, video timestamps), and
    info.json with the same keys and values, but for the videos' codec, with more of roarmctl's own."""
    import pyarrow.parquet as pq

    python = _lerobot_python()
    if python is None:
        pytest.skip("lerobot is not installed here: set ROARMCTL_LEROBOT_PYTHON to the python of a venv that has it")
    out, _ = dataset96
    theirs = tmp_path / "lerobot_written"
    r = subprocess.run([python, str(ROOT / "tests" / "lerobot_write.py"), str(out), str(theirs)], capture_output=True,
                       text=True, timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    files = sorted(str(p.relative_to(theirs)) for p in theirs.rglob("*") if p.is_file())
    assert files == sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    for rel in ("data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet"):
        a, b = pq.read_table(out / rel), pq.read_table(theirs / rel)
        assert [(f.name, str(f.type)) for f in a.schema] == [(f.name, str(f.type)) for f in b.schema], rel
        for name in a.column_names:
            if not name.startswith("stats/"):
                assert a[name].to_pylist() == b[name].to_pylist(), (rel, name)
    ours_info, their_info = (json.loads((root / "meta/info.json").read_text()) for root in (out, theirs))
    for k in set(ours_info) | set(their_info):
        if k != "features":
            assert ours_info.get(k) == their_info.get(k), k
    for k, f in their_info["features"].items():
        assert {kk: v for kk, v in ours_info["features"][k].items() if kk != "info"} == \
            {kk: v for kk, v in f.items() if kk != "info"}, k
        for kk, v in f.get("info", {}).items():  # every key lerobot writes, with its value, but its codec's name
            if kk != "video.codec":
                assert ours_info["features"][k]["info"].get(kk) == v, (k, kk)


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_ray_data_reads_the_dataset(dataset96):
    """Optional: Ray Data's read_lerobot (which decodes through lerobot) where both are installed here."""
    pytest.importorskip("lerobot")
    ray = pytest.importorskip("ray")
    out, _ = dataset96
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("local/roarmctl", root=out)
    assert ds.num_episodes == EPISODES
    ray.init(num_cpus=1, include_dashboard=False)
    try:
        rows = ray.data.read_lerobot(str(out)).count()
        assert rows == ds.num_frames
    finally:
        ray.shutdown()


def test_video_join_and_cut_keep_every_frame():
    from roarmctl.export.lerobot import video

    eps = _synthetic([5, 8], seed=1)
    buf = io.BytesIO()
    video.join([e.videos["front"] for e in eps], [5, 8], 10, buf)
    frames, times = video.decode(io.BytesIO(buf.getvalue()))
    assert len(frames) == 13
    np.testing.assert_allclose(times, np.arange(13) / 10, atol=1e-6)
    second, _ = video.decode(io.BytesIO(eps[1].videos["front"]))
    assert np.array_equal(frames[5:], second)
    cut, _ = video.decode(io.BytesIO(video.cut(io.BytesIO(buf.getvalue()), 5, 8, 10)))
    assert np.array_equal(cut, second)


# ------------------------------------------------------------------------------------------- real runs
@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A run of the bundled pick-and-place as simulate writes it (an execution log, roarmctl.execlog/1)."""
    d = tmp_path_factory.mktemp("run")
    assert roarmctl("plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(d / "pp.traj.json"), "--json").returncode == 0
    r = roarmctl("simulate", str(d / "pp.traj.json"), "-o", str(d / "pp.run.json"), "--json")
    assert r.returncode == 0, r.stderr
    return d / "pp.run.json"


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-run-file")  # the run planned and simulated once (module fixture)
def test_an_executed_run_appends_as_an_episode_of_measured_state_and_sent_goals(run_file, tmp_path):
    """The episode against the log itself: at each frame the last T:1051 reading (firmware radians, by the time the
    servos were read: the log's one measured-frame time, ``frame_read_time``) and the last T:102 goals sent, both mapped to joints by the robot's wire map."""
    import pyarrow.parquet as pq

    from roarmctl.device.protocol import M3_FEEDBACK_KEYS, M3_FIELDS, WireMap, frame_read_time
    from roarmctl.robot.loader import load_robot

    ds = tmp_path / "real"
    for task in ("move the cube left", None):
        r = roarmctl("export", str(run_file), "--lerobot", str(ds), *(["--task", task] if task else []))
        assert r.returncode == 0, r.stderr
    data = pq.read_table(ds / "data/chunk-000/file-000.parquet")
    ep = data["episode_index"].to_numpy()
    assert set(ep.tolist()) == {0, 1}
    info = json.loads((ds / "meta/info.json").read_text())
    assert info["video_path"] is None and info["robot_type"] == "roarm_m3_pro" and info["total_tasks"] == 1
    log = json.loads(run_file.read_text())
    wm = WireMap(load_robot("roarm_m3_pro"))
    keys = dict(zip(M3_FEEDBACK_KEYS, M3_FIELDS))
    reads = [(frame_read_time(e), wm.from_wire({keys[k]: v for k, v in e["feedback"].items() if k in keys}))
             for e in log["received"]]
    sent = [(e["t"], wm.from_wire({f: e["cmd"][f] for f in M3_FIELDS})) for e in log["sent"] if e["cmd"].get("T") == 102]
    rows = np.flatnonzero(ep == 1)
    state = np.stack(data["observation.state"].to_numpy(zero_copy_only=False))[rows]
    action = np.stack(data["action"].to_numpy(zero_copy_only=False))[rows]
    for k in range(0, len(rows), 7):
        t = k / 30
        want_state = [q for when, q in reads if when <= t + 1e-9][-1:] or [reads[0][1]]
        want_action = [q for when, q in sent if when <= t + 1e-9][-1:] or [sent[0][1]]
        np.testing.assert_allclose(state[k], want_state[0], atol=1e-6)
        np.testing.assert_allclose(action[k][:5], want_action[0][:5], atol=1e-6)  # the gripper's own T:101 may follow


@pytest.mark.slow
@pytest.mark.xdist_group("datagen-run-file")  # the run planned and simulated once (module fixture)
def test_a_run_does_not_join_a_dataset_with_cameras_or_a_trajectory(run_file, tmp_path):
    from roarmctl.export.lerobot.dataset import write_dataset

    write_dataset(tmp_path / "cams", _spec(), _synthetic([3]))
    r = roarmctl("export", str(run_file), "--lerobot", str(tmp_path / "cams"))
    assert r.returncode == 2 and "cameras" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    traj = run_file.with_name("pp.traj.json")
    r = roarmctl("export", str(traj), "--lerobot", str(tmp_path / "new"))
    assert r.returncode == 2 and "execution log" in r.stderr and not (tmp_path / "new").exists()
    r = roarmctl("export", str(run_file))
    assert r.returncode == 2 and "--lerobot" in r.stderr


RAY_ENV = """
import json, os, sys
import ray
from roarmctl.export.lerobot.datagen import _Ray
seen = []
def init(**kwargs):  # records what a started Ray would read, then fails as a start that timed out would not
    seen.append(os.environ.get("RAY_USAGE_STATS_ENABLED"))
    raise Exception("no start here")
ray.init = init
try:
    _Ray(sys.argv[1], 1)
except Exception as exc:
    pass
print(json.dumps({"at_init": seen, "after": os.environ.get("RAY_USAGE_STATS_ENABLED")}))
"""


@pytest.mark.slow  # imports Ray (seconds of CPU)
@pytest.mark.parametrize(("address", "given", "at_init"), [("", None, "0"), ("", "1", "1"), ("ray://head:10001", None, None)])
def test_a_local_ray_collects_no_usage_stats_unless_the_user_asked(address, given, at_init):
    """Ray collects usage stats by default (docs.ray.io, "Usage Stats Collection"); a Ray that datagen starts for one
    run does not (``RAY_USAGE_STATS_ENABLED=0`` while it starts, the caller's environment as it was afterwards); a
    value the user set is kept, and a cluster of the user's (an address) is left to its own settings."""
    pytest.importorskip("ray")
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")} | ({} if given is None else
                                                                              {"RAY_USAGE_STATS_ENABLED": given})
    r = subprocess.run([sys.executable, "-c", RAY_ENV, address], env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"at_init": [at_init], "after": given}, out


@pytest.mark.slow  # Ray started on this machine (tens of seconds on a busy one)
@pytest.mark.xdist_group("datagen-dataset96")  # the dataset written once (module fixture)
def test_ray_tasks_write_the_same_dataset_as_the_process_pool_and_nothing_outside_it(dataset96, tmp_path):
    """The guide's ``--ray local`` command as written (test_readme_examples leaves it to this test, so Ray starts
    once), in a process of its own whose home and temporary folders are empty folders here: the same bytes as the
    fixture's run of the same command without ``--ray`` (docs/benchmarks.md's, on one worker; the killed run's test
    shows two pool workers write those bytes too), and afterwards both folders are empty again (Ray's session files
    and token were kept in roarmctl's own temporary folder and environment) and no process of that Ray is left."""
    pytest.importorskip("ray")
    import tempfile

    args = docs_command(ray=True)
    pool, _ = dataset96
    at = args.index("--ray")
    without = args[:at] + args[at + 2:]  # --ray, and --workers (the bytes do not depend on them), left out
    if "--workers" in without:
        w = without.index("--workers")
        without = without[:w] + without[w + 2:]
    without[without.index("-o") + 1] = pool.name
    assert without == docs_command(ray=False), "the docs' Ray command must be their 96x96 dataset's with --ray"
    out = _option(args, "-o")
    work = tmp_path / "work"
    shutil.copytree(ROOT / "plans", work / "plans")  # the command's paths are the docs' (from the clone's top)
    home = tmp_path / "home"
    home.mkdir()
    tmp = Path(tempfile.mkdtemp(prefix="dg-", dir="/tmp"))  # short: Ray's sockets go below it (107 bytes a path)
    request_cleanup = tmp
    env = {k: v for k, v in os.environ.items() if not k.startswith("RAY_")}
    # MPLCONFIGDIR: matplotlib (which TOPP-RA imports) keeps a font cache in the home folder, planning's and not Ray's
    env |= {"HOME": str(home), "TMPDIR": str(tmp), "COLUMNS": "80", "MPLCONFIGDIR": str(tmp_path / "mpl")}
    try:
        r = subprocess.run([sys.executable, "-m", "roarmctl", *args, "--json"], cwd=work, env=env, capture_output=True,
                           text=True, timeout=550)
        left = [p for p in Path("/proc").glob("[0-9]*") if str(tmp).encode() in _cmdline(p)]
        assert not left, "a process of the test's Ray is still running"
        assert sorted(home.rglob("*")) == [] and sorted(tmp.rglob("*")) == [], (sorted(home.rglob("*")), sorted(tmp.rglob("*"))[:5])
    finally:
        shutil.rmtree(request_cleanup, ignore_errors=True)
    if r.returncode == 4 and "Ray did not start" in r.stderr:  # Ray's fixed 30 s for its raylet, on a loaded machine
        assert len(r.stderr.strip().splitlines()) == 1 and "load average" in r.stderr and "--ray" in r.stderr
        pytest.skip(r.stderr.strip())
    assert r.returncode == 0, r.stderr
    for rel in FILES + VIDEOS:
        assert (pool / rel).read_bytes() == (work / out / rel).read_bytes(), rel


def _cmdline(proc: Path) -> bytes:
    try:
        return (proc / "cmdline").read_bytes()
    except OSError:
        return b""


@pytest.mark.slow
def test_cameras_after_mujoco_was_imported_without_a_gl_back_end_are_refused_not_an_abort():
    """MuJoCo imported first with no MUJOCO_GL renders through GLFW, which aborts a process without a display (a
    pytest worker died of it): ``offscreen`` refuses with a RenderError (exit 4) naming MUJOCO_GL instead; imported
    first with MUJOCO_GL=egl it goes on."""
    code = ("import mujoco\nfrom roarmctl.physics.render import offscreen, RenderError\n"
            "try:\n    offscreen()\n    print('went on')\nexcept RenderError as e:\n    print('refused', e.exit_code, e.hint)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.startswith("refused 4") and "MUJOCO_GL=egl" in out.stdout, out
    out = subprocess.run([sys.executable, "-c", code], env={**env, "MUJOCO_GL": "egl"}, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "went on", out


def test_a_shard_that_never_ends_is_a_device_error_naming_the_workers(monkeypatch):
    """The process pool's wait for a shard's result is bounded and ends as the Ray engine's does: a DeviceError (exit 4)
    naming the workers, not a bare TimeoutError (a traceback)."""
    from concurrent.futures import Future

    from roarmctl.errors import DeviceError
    from roarmctl.export.lerobot import datagen

    monkeypatch.setattr(datagen, "SHARD_CEILING_S", 0.01)
    with pytest.raises(DeviceError) as err:
        datagen._Pool.result(Future())
    assert err.value.exit_code == 4 and "workers" in str(err.value) and "\n" not in str(err.value)


class _ScriptedEngine:
    """Stands in for the process pool: each try's verdict is scripted (``kept[t]``; kept past the script), a kept
    try staged as two frames whose state is its number, and the running tries end in the order ``rng`` draws."""

    def __init__(self, kept: list[bool], workers: int, rng, dof: int) -> None:
        self.kept, self.slots, self.rng, self.dof = kept, workers, rng, dof
        self.started: list[int] = []
        self.results: dict[int, list] = {}

    def submit(self, template, staging, tries, *_):
        from roarmctl.export.lerobot import datagen

        out = []
        for t in tries:
            self.started.append(t)
            kept = self.kept[t] if t < len(self.kept) else True
            o = {"try": t, "kept": kept, "cause": None if kept else "no path", "detail": "", "timings": {}}
            if kept:
                state = np.full((2, self.dof), float(t))
                datagen._stage(Path(staging), t, state, state, {}, {})
                o["frames"] = 2
            datagen._write_json(Path(staging) / f"{t:08d}.json", o)
            out.append(o)
        handle = len(self.results)
        self.results[handle] = out
        return handle

    def wait(self, pending):
        return [self.rng.choice(pending)]

    def result(self, handle):
        return self.results[handle]

    def close(self):
        pass


@settings(max_examples=25, deadline=None)
@given(kept=hs.lists(hs.booleans(), max_size=12), episodes=hs.integers(1, 5), workers=hs.integers(1, 4),
       order=hs.randoms(use_true_random=False))
def test_the_tries_started_are_the_ones_the_episodes_need_and_the_dataset_is_the_first_kept(kept, episodes, workers, order):
    """The scheduler of ``generate`` over scripted verdicts and any order of results: the dataset is the first
    ``episodes`` kept tries in try order, the tries started in order and none twice; when those are the first
    tries, exactly they ran (no spare try: with two tries a shard and no look at the episodes missing, ``-n 2`` on
    two workers ran four tries, two of them waited for and thrown away)."""
    import tempfile

    from roarmctl.export.lerobot import datagen
    from roarmctl.export.lerobot.dataset import read_episodes
    from roarmctl.plan.template import load_template
    from roarmctl.robot.loader import load_robot

    dof = len(load_robot(load_template(TEMPLATE).plan.robot).joint_names)
    engine = _ScriptedEngine(kept, workers, order, dof)
    pool = datagen._Pool
    datagen._Pool = lambda _workers: engine  # type: ignore[assignment,misc]
    try:
        with tempfile.TemporaryDirectory() as d:
            options = datagen.DatagenOptions(episodes=episodes, workers=workers, cameras=())
            summary = datagen.generate(TEMPLATE, Path(d) / "ds", options)
            got = [int(e.state[0, 0]) for e in read_episodes(Path(d) / "ds")]
    finally:
        datagen._Pool = pool  # type: ignore[misc]
    verdicts = kept + [True] * 100
    want = [t for t, k in enumerate(verdicts) if k][:episodes]
    assert got == want and summary.kept == episodes and summary.tried == want[-1] + 1 == episodes + sum(summary.causes.values())
    assert sorted(engine.started) == list(range(len(engine.started)))  # in order, none twice
    if want == list(range(episodes)):
        assert engine.started == want


@pytest.mark.slow  # three worlds built (the jaws' 64 meshes each) and drawn: ~2 s
def test_a_kept_gl_context_draws_the_next_scene_as_a_fresh_one_would():
    """Datagen's episodes differ in their objects, not in the meshes MuJoCo keeps on the GL side, so the renderer
    keeps its GL context for the next scene with the same assets (``render._Context``). A second scene (the cube
    elsewhere in another colour, a distractor more) drawn with the kept context is pixel for pixel what a context
    made for it draws, and both show the cube's colour where the scenes differ."""
    from roarmctl.motion.scene import Scene
    from roarmctl.physics import render
    from roarmctl.physics.world import World
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    table = {"name": "table", "role": "table", "shape": "box", "size": [0.8, 0.6, 0.02], "xyz": [0.15, 0.0, -0.01]}
    cube = {"name": "cube", "role": "object", "shape": "box", "size": [0.04, 0.04, 0.04], "mass": 0.03}
    first = World(robot, Scene.from_dict({"items": [table, {**cube, "xyz": [0.25, -0.15, 0.02]}]}))
    second = World(robot, Scene.from_dict({"items": [table, {**cube, "xyz": [0.22, 0.12, 0.02]},
                                                     {**cube, "name": "other", "size": [0.02, 0.02, 0.02], "xyz": [0.17, 0.0, 0.01]}]}))
    qpos = np.repeat(second.model.qpos0[None], 3, axis=0)
    qpos[:, second.qpos_adr[:3]] += np.array([[0.0, 0.0, 0.0], [0.3, 0.2, -0.2], [-0.4, 0.4, 0.3]])
    render.Cameras(first, 64, 48, {"cube": (0.1, 0.9, 0.1)}).render(np.repeat(first.model.qpos0[None], 2, axis=0))
    kept = render._Context.key
    seen = render.Cameras(second, 64, 48, {"cube": (0.9, 0.1, 0.1)}).render(qpos)
    assert render._Context.key == kept  # the same meshes: the context was kept
    render._Context.free()
    fresh = render.Cameras(second, 64, 48, {"cube": (0.9, 0.1, 0.1)}).render(qpos)
    for cam in render.CAMERAS:
        assert np.array_equal(seen[cam], fresh[cam]), cam
    red = (fresh["front"][..., 0] > 150) & (fresh["front"][..., 1] < 80)
    assert red.sum() > 5  # the red cube is in the picture
    render.Cameras(second, 64, 64).render(qpos[:1])
    assert render._Context.key != kept  # another size: a context of its own
