"""A pick and place in a 100,000-point cloud of a cluttered desk: the figure the README quotes (issue 25).

Run: .venv/bin/python bench/bench_desk.py [--rounds 10] [--points 100000]

The plan is ``plans/pick_place.yaml`` (the cube 30 cm to the left, then home) with its table replaced by the
cloud of ``bench/scenes.py`` (the desk top, a monitor stand, books, a mug, a bottle, a box of parts and a phone),
read from a ``.npy`` file as the plan's ``table`` at 5 mm cells. Each round plans it with the next seed through
``roarmctl.api.plan`` (the CLI's pipeline) in this process, after one plan of ``plans/pick_place.yaml`` on its own
table (the imports the planner makes on first use); the first call in the cloud, which reads the file and builds
the cloud's cells and octrees (kept for the process afterwards), is reported apart. Printed: medians over the rounds
of the wall and CPU time of ``api.plan``, its planning stages (``PlanResult.timings``), and the trajectory's
duration; the cloud's points and occupied cells.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import desk_cloud  # noqa: E402

import roarmctl.api as rc  # noqa: E402
from roarmctl.motion.octree import cells_of  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RESOLUTION = 0.005  # m: the cloud's cells


def desk_plan(folder: Path, n_points: int) -> Path:
    """plans/pick_place.yaml with the desk cloud (``n_points``) as its table, written into ``folder``."""
    points = desk_cloud(n_points)
    np.save(folder / "desk.npy", points)
    doc = yaml.safe_load((ROOT / "plans" / "pick_place.yaml").read_text())
    doc["scene"] = {"table": {"shape": "cloud", "file": "desk.npy", "resolution": RESOLUTION, "xyz": [0, 0, 0]}}
    path = folder / "desk_pick_place.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def timed_plan(path: Path, seed: int) -> tuple[float, float, float, float]:
    """(wall s, CPU s, planning stages s, trajectory duration s) of one ``api.plan`` call."""
    w0, c0 = time.perf_counter(), time.process_time()
    res = rc.plan(path, seed=seed)
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    return wall, cpu, float(sum(res.timings.values())), float(res.trajectory.duration)


def main() -> None:
    """Plan the desk pick and place ``--rounds`` times (seeds 1..N) and print the medians."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--points", type=int, default=100_000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = desk_plan(Path(tmp), args.points)
        cells = len(cells_of(np.load(Path(tmp) / "desk.npy"), RESOLUTION))
        imports = timed_plan(ROOT / "plans" / "pick_place.yaml", 1)  # the planner's lazy imports (toppra, ...)
        first = timed_plan(path, 1)
        rows = [timed_plan(path, seed) for seed in range(1, args.rounds + 1)]
    med = [statistics.median(r[i] for r in rows) for i in range(4)]
    print(f"desk cloud: {args.points:,} points, {cells:,} occupied {RESOLUTION * 1e3:.0f} mm cells; "
          "plans/pick_place.yaml's pick, place and home on it")
    print(f"plans/pick_place.yaml first, on its table (the imports on first use): {imports[0] * 1e3:.0f} ms wall")
    print(f"first call in the cloud (reads it, builds its cells and octrees): {first[0] * 1e3:.0f} ms wall, "
          f"{first[1] * 1e3:.0f} ms CPU")
    print(f"api.plan, median of {args.rounds} seeds: {med[0] * 1e3:.1f} ms wall, {med[1] * 1e3:.1f} ms CPU; "
          f"planning stages {med[2] * 1e3:.1f} ms; trajectory {med[3]:.2f} s")


if __name__ == "__main__":
    main()
