"""Planning time of the bundled example plans, split by stage (medians over repeats), against the figures last
recorded in bench/plans_baseline.json (with the commit and load they were measured at), so a regression shows in
the next run.

Run: .venv/bin/python bench/bench_plan.py [--repeats N] [--record]

Interpreter start-up and library imports are excluded (they are loaded once before timing); each plan is planned
once untimed first (its robot, meshes and first calls). Printed per plan: the median CPU time and wall time of
``plan_file`` over the repeats (seeds 1..N), the stage medians (``PlanResult.timings``, wall), the trajectory's
duration, and the ratio of the CPU median to the recorded one, flagged above ``REGRESSION`` (CPU time, since the
wall time of a busy machine says little; the load average is printed beside both). ``--record`` writes this run's
figures as the new baseline, with ``git describe`` of the tree.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import time
from pathlib import Path

from roarmctl.motion.pipeline import load_planning_libraries, plan_file

ROOT = Path(__file__).resolve().parents[1]
BASELINE = Path(__file__).resolve().parent / "plans_baseline.json"
PLANS = ("pick_place", "multi_object", "obstacle", "payload", "m2s_pick_place", "scan_desk")
REGRESSION = 1.25  # CPU median over the recorded one above which a plan is flagged


def commit() -> str:
    """``git describe --always --dirty`` of the tree, or "unknown" outside a checkout."""
    r = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=ROOT, capture_output=True, text=True)
    return r.stdout.strip() or "unknown"


def measure(plan: Path, repeats: int) -> dict:
    """Medians of one plan over ``repeats`` seeds: CPU and wall ms, stage ms, duration s."""
    plan_file(plan, seed=1)
    cpu, wall, stages, duration = [], [], {}, 0.0
    for seed in range(1, repeats + 1):
        c0, w0 = time.process_time(), time.perf_counter()
        result = plan_file(plan, seed=seed)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
        for k, v in result.timings.items():
            stages.setdefault(k, []).append(v)
        duration = float(result.trajectory.duration)
    return {"cpu_ms": round(statistics.median(cpu) * 1e3, 1), "wall_ms": round(statistics.median(wall) * 1e3, 1),
            "stages_ms": {k: round(statistics.median(v) * 1e3, 1) for k, v in stages.items()},
            "duration_s": round(duration, 4)}


def main() -> None:
    """Plan each bundled plan ``--repeats`` times and print the medians beside the recorded ones."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--record", action="store_true", help="write this run's figures as the new baseline")
    args = parser.parse_args()
    load_planning_libraries()
    base = json.loads(BASELINE.read_text()) if BASELINE.exists() else {"plans": {}}
    load = os.getloadavg()[0]
    print(f"this run: {commit()}, load {load:.1f}; baseline: {base.get('commit', 'none')}, load {base.get('load', 0):.1f}")
    print(f"{'plan':<16}{'CPU ms':>8}{'wall ms':>9}{'base CPU':>10}{'ratio':>7}  duration s  stage medians (wall ms)")
    figures = {}
    for name in PLANS:
        got = figures[name] = measure(ROOT / "plans" / f"{name}.yaml", args.repeats)
        old = base["plans"].get(name)
        ratio = got["cpu_ms"] / old["cpu_ms"] if old else float("nan")
        flag = "  REGRESSION" if ratio > REGRESSION else ""
        split = ", ".join(f"{k} {v:.0f}" for k, v in got["stages_ms"].items())
        print(f"{name:<16}{got['cpu_ms']:>8.1f}{got['wall_ms']:>9.1f}{(old or {}).get('cpu_ms', float('nan')):>10.1f}"
              f"{ratio:>7.2f}  {got['duration_s']:>10.3f}  {split}{flag}")
    if args.record:
        BASELINE.write_text(json.dumps({"commit": commit(), "load": round(load, 1), "repeats": args.repeats,
                                        "plans": figures}, indent=1) + "\n")
        print(f"recorded in {BASELINE.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
