"""Load time, state-validity checks per second and planning time for every arm of the corpus of published
descriptions (tests/data/arms/NAME: the published URDF/xacro/SRDF files as they are, a short sidecar and a
pick-and-place-over-a-wall plan).

Run: .venv/bin/python bench/bench_arms.py [--repeats 3] [NAME ...]

Load: a fresh load (the loader's and the mesh reader's caches cleared: xacro expansion, SRDF, meshes read
and their hulls), median over repeats. Checks/s: 2000 uniform random arm configurations in the arm's own
plan scene (table, wall, block), batch API, median over repeats; "valid" is the share that passes (an
invalid state usually costs less: its check stops at the first hit). Plan: the plan's planning time
(IK, OMPL, TOPP-RA, re-check, blending) as ``roarmctl plan`` reports it, median over repeats, and the
motion's duration. Pinned to one core.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from roarmctl.motion.collision import CollisionChecker  # noqa: E402
from roarmctl.motion.pipeline import plan_file  # noqa: E402
from roarmctl.motion.planning.context import scene_item  # noqa: E402
from roarmctl.motion.scene import Scene  # noqa: E402
from roarmctl.plan.schema import load_plan  # noqa: E402
from roarmctl.robot import loader, meshes  # noqa: E402

CORPUS = Path(__file__).resolve().parents[1] / "tests" / "data" / "arms"


def fresh_load(spec: str):
    """Load ``spec`` with every cache cleared; (robot, seconds)."""
    loader._CACHE.clear()
    meshes._LOADED.clear()
    t0 = time.perf_counter()
    robot = loader.load_robot(spec)
    return robot, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("names", nargs="*", default=sorted(p.name for p in CORPUS.iterdir() if (p / "robot.yaml").is_file()))
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    print(f"{'arm':20s} {'dof':>3s} {'shapes':>6s} {'load ms':>8s} {'checks/s':>9s} {'valid':>6s} {'plan ms':>8s} {'motion s':>8s}")
    for name in args.names:
        spec = str(CORPUS / name / "robot.yaml")
        loads = []
        for _ in range(args.repeats):
            robot, dt = fresh_load(spec)
            loads.append(dt)
        plan = load_plan(CORPUS / name / "plan.yaml")
        scene = Scene([scene_item(s) for s in plan.scene + plan.objects])
        checker = CollisionChecker(robot, scene, padding=plan.planner.padding,
                                   singularity_margin=plan.planner.singularity_margin or None)
        q = np.random.default_rng(0).uniform(checker._lower, checker._upper, (2000, robot.arm_dof))
        checker.validity_batch(q[:50])  # warm-up
        rates = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            valid = checker.validity_batch(q)
            rates.append(len(q) / (time.perf_counter() - t0))
        plans, duration = [], 0.0
        for _ in range(args.repeats):
            res = plan_file(CORPUS / name / "plan.yaml")
            plans.append(sum(res.timings.values()))
            duration = res.trajectory.duration
        print(f"{name:20s} {robot.dof:3d} {len(robot.collision):6d} {statistics.median(loads) * 1000:8.0f} "
              f"{statistics.median(rates):9.0f} {valid.mean():6.0%} {statistics.median(plans) * 1000:8.0f} {duration:8.2f}")


if __name__ == "__main__":
    main()
