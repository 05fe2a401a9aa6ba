"""Load time and state-validity checks per second: the mesh RoArm-M2-S next to the boxed robots.

Run: .venv/bin/python bench/bench_robots.py [--repeats 5]
Robots: the bundled boxed ``roarm_m3_pro`` and ``roarm_m2_s``, and Waveshare's M2-S MoveIt package
(URDF with STL meshes checked as convex hulls, SRDF, joint_limits.yaml; read from ../shared when it
is there) with a small sidecar. Load time: a fresh process-level load (the mesh reader's cache
cleared), median over repeats. Checks/s: 2000 uniform random arm configurations in
example_scene (table, wall, cube, can), batch API, median over repeats; "valid" is the share of
them that pass (an invalid state usually costs less: its check stops at the first hit). Pinned to
one core.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from roarmctl.motion.collision import CollisionChecker  # noqa: E402
from roarmctl.motion.scene import example_scene  # noqa: E402
from roarmctl.robot import loader, meshes  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
VENDOR = next((d / "shared/reference/roarm_m3/m2s_roarm_ws_em0" for d in (ROOT.parent, ROOT.parent.parent)
               if (d / "shared/reference/roarm_m3/m2s_roarm_ws_em0").is_dir()), None)


def vendor_sidecar(folder: Path) -> str:
    side = {"format": "roarmctl.robot/1", "name": "m2s_moveit_meshes",
            "urdf": str(VENDOR / "urdf/roarm_description.urdf"), "srdf": str(VENDOR / "config/roarm_description.srdf"),
            "joint_limits": str(VENDOR / "config/joint_limits.yaml"), "packages": {"roarm_description": str(VENDOR)},
            "ik": "roarm3", "base_links": ["base_link", "link1"]}
    p = folder / "m2s.yaml"
    p.write_text(yaml.safe_dump(side))
    return str(p)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    tmp = Path(tempfile.mkdtemp())
    specs = [("roarm_m3_pro (boxes)", "roarm_m3_pro"), ("roarm_m2_s (boxes)", "roarm_m2_s")]
    if VENDOR is not None:
        specs.append(("M2-S MoveIt package (STL hulls)", vendor_sidecar(tmp)))
    else:
        print("(Waveshare's M2-S package not found beside the clone: mesh robot skipped)")
    print(f"{'robot':34s} {'load ms':>9s} {'checks/s':>10s} {'valid':>6s} {'shapes':>7s}")
    for label, spec in specs:
        loads = []
        for _ in range(args.repeats):
            loader._CACHE.clear()
            meshes._LOADED.clear()
            t = time.perf_counter()
            robot = loader.load_robot(spec)
            loads.append((time.perf_counter() - t) * 1000)
        checker = CollisionChecker(robot, example_scene(), padding=0.005)
        rng = np.random.default_rng(0)
        arm = robot.arm_indices
        q = rng.uniform(robot.lower[arm], robot.upper[arm], (2000, len(arm)))
        valid = checker.validity_batch(q).mean()  # also the warm-up
        rates = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            checker.validity_batch(q)
            rates.append(len(q) / (time.perf_counter() - t))
        print(f"{label:34s} {statistics.median(loads):9.1f} {statistics.median(rates):10.0f} {valid:6.0%} {len(robot.collision):7d}")


if __name__ == "__main__":
    main()
