"""Success rate over many seeds: every bundled example plan planned with seeds 0..N-1.

Run: .venv/bin/python bench/bench_seeds.py [--seeds 100] [--plans obstacle multi_object pick_place]

A feasible plan must plan with every seed (no spurious "infeasible"). Each result is also checked
here, independently of the planner's own re-check: joint limits, scaled velocity and acceleration
limits on every sample, at rest at both ends, and the grasp/release events present.
Prints per plan: successes, median planning time, and each distinct failure message with its seeds.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from roarmctl.errors import RoarmError
from roarmctl.motion.pipeline import load_planning_libraries, plan_file
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]


def _check(result, robot) -> str | None:
    """Independent sanity check of a planned trajectory; returns a problem or None."""
    tr = result.trajectory
    lim = tr.limits
    v = np.asarray(lim["velocity"]) * lim["velocity_scale"]
    a = np.asarray(lim["acceleration"]) * lim["acceleration_scale"]
    if np.any(tr.positions < robot.lower - 1e-6) or np.any(tr.positions > robot.upper + 1e-6):
        return "outside the joint limits"
    if np.any(np.abs(tr.velocities) > v * (1 + 1e-6) + 1e-6):
        return "velocity over the limit"
    if np.any(np.abs(tr.accelerations) > a * (1 + 1e-6) + 1e-6):
        return "acceleration over the limit"
    if np.any(np.abs(tr.velocities[[0, -1]]) > 1e-9):
        return "not at rest at an end"
    if np.any(np.diff(tr.times) <= 0):
        return "times not increasing"
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--plans", nargs="*", default=["obstacle", "multi_object", "pick_place"])
    args = parser.parse_args()
    load_planning_libraries()
    total_ok = total = 0
    for name in args.plans:
        plan = ROOT / "plans" / f"{name}.yaml"
        robot = None
        ok, times, failures = 0, [], defaultdict(list)
        for seed in range(args.seeds):
            t0 = time.perf_counter()
            try:
                result = plan_file(plan, seed=seed)
            except RoarmError as exc:
                failures[exc.message.split(": ", 1)[-1][:120]].append(seed)
                continue
            times.append(time.perf_counter() - t0)
            robot = robot or load_robot(result.trajectory.robot)
            problem = _check(result, robot)
            if problem:
                failures["output: " + problem].append(seed)
            else:
                ok += 1
        total_ok, total = total_ok + ok, total + args.seeds
        med = statistics.median(times) * 1000 if times else float("nan")
        print(f"{name:<14} {ok:>4}/{args.seeds} ok   median planning {med:.0f} ms")
        for msg, seeds in failures.items():
            print(f"    {len(seeds):>3} x {msg}  (seeds {seeds[:10]}{' ...' if len(seeds) > 10 else ''})")
    print(f"all            {total_ok:>4}/{total} ok ({100.0 * total_ok / max(total, 1):.1f} %)")


if __name__ == "__main__":
    main()
