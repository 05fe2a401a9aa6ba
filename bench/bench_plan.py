"""Planning time of the bundled example plans, split by stage (medians over repeats).

Run: .venv/bin/python bench/bench_plan.py [--repeats N]
Interpreter start-up and library imports are excluded (they are loaded once before timing).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from roarmctl.motion.pipeline import load_planning_libraries, plan_file

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    load_planning_libraries()
    plan_file(ROOT / "plans" / "pick_place.yaml")  # warm caches (robot description, first calls)
    print(f"{'plan':<18}{'total ms':>10}  stage medians (ms)")
    for plan in sorted((ROOT / "plans").glob("*.yaml")):
        totals, stages = [], {}
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            result = plan_file(plan)
            totals.append(time.perf_counter() - t0)
            for k, v in result.timings.items():
                stages.setdefault(k, []).append(v)
        split = ", ".join(f"{k} {statistics.median(v) * 1000:.0f}" for k, v in stages.items())
        print(f"{plan.stem:<18}{statistics.median(totals) * 1000:>10.0f}  {split}")


if __name__ == "__main__":
    main()
