"""Read a dataset with lerobot itself and print what it saw as JSON (not a test module: tests/test_datagen.py runs it).

    PYTHON tests/lerobot_read.py DATASET [FRAMES_PER_EPISODE]

Run by the Python of an environment where lerobot is installed (its own venv: lerobot pins torch, which roarmctl
does not need), so it imports nothing of roarmctl. ``LeRobotDataset("local/roarmctl", root=DATASET)`` with the
video backend lerobot picks, torchcodec, where it loads (it needs the system's FFmpeg libraries), else PyAV
(lerobot's own fallback); for every frame: episode and frame index,
timestamp, task, ``observation.state`` and ``action``; for the first, middle and last frames of each episode
(or ``FRAMES_PER_EPISODE`` spread over it) each camera's image as lerobot returns it (float C x H x W in 0-1),
scaled back to 0-255 and rounded, as nested lists; the stats of ``observation.state`` and ``action`` as lerobot
loads them from ``meta/stats.json`` and as lerobot computes them from the frames (``compute_episode_stats`` per
episode, ``aggregate_stats`` over them).
"""

from __future__ import annotations

import json
import sys
from importlib.metadata import version


def main() -> int:
    import numpy as np
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = sys.argv[1]
    per_episode = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    try:
        import torchcodec.decoders  # noqa: F401  (loads its FFmpeg libraries)

        backend = "torchcodec"
    except Exception:  # noqa: BLE001  (torchcodec raises OSError or RuntimeError when FFmpeg's libraries are missing)
        backend = "pyav"
    ds = LeRobotDataset("local/roarmctl", root=root, video_backend=backend)
    out: dict = {"lerobot": version("lerobot"), "torch": version("torch"), "backend": ds.video_backend,
                 "num_episodes": ds.num_episodes, "num_frames": ds.num_frames, "fps": ds.fps,
                 "camera_keys": list(ds.meta.camera_keys), "rows": [], "images": []}
    hf = ds.hf_dataset.with_format(None)
    for row in hf:
        out["rows"].append({k: row[k] for k in ("index", "episode_index", "frame_index", "timestamp", "task_index",
                                                 "observation.state", "action")})
    starts: dict[int, list[int]] = {}
    for i, row in enumerate(out["rows"]):
        starts.setdefault(row["episode_index"], []).append(i)
    for ep, rows in sorted(starts.items()):
        for k in np.unique(np.round(np.linspace(0, len(rows) - 1, per_episode)).astype(int)):
            item = ds[rows[k]]
            out["images"].append({"index": rows[k], "episode_index": ep, "frame_index": int(item["frame_index"]), "task": item["task"],
                                  **{cam: np.round(item[cam].numpy() * 255).astype(int).tolist() for cam in ds.meta.camera_keys}})
    from lerobot.datasets.compute_stats import aggregate_stats, compute_episode_stats

    vectors = ("observation.state", "action")
    per_episode_stats = []
    for rows in starts.values():
        data = {k: np.array([out["rows"][i][k] for i in rows], dtype=np.float32) for k in vectors}
        per_episode_stats.append(compute_episode_stats(data, {k: ds.meta.features[k] for k in vectors}))
    computed = aggregate_stats(per_episode_stats)
    out["stats_loaded"] = {k: {s: np.asarray(v).tolist() for s, v in ds.meta.stats[k].items()} for k in vectors}
    out["stats_computed"] = {k: {s: np.asarray(v).tolist() for s, v in computed[k].items()} for k in vectors}
    json.dump(out, sys.stdout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
