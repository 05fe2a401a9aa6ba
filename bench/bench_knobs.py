"""What the planner's work constants buy: ``roarmctl.api.plan`` of queries a-e with one constant changed at a time.

Run: .venv/bin/python bench/bench_knobs.py [--seeds 40] [--queries a,b,c,d,e] [--variants default,tries2,...]

The variants (each one constant of the library, set in this process for its calls only):
  default        as shipped: 3 OMPL tries a free motion (FREE_MOTION_TRIES), 40 shortcut attempts with a patience of
                 12 (SHORTCUT_ATTEMPTS, SHORTCUT_PATIENCE), TOPP-RA grids of at least 60 intervals (GRID_MIN)
  tries1, tries2 the shortest of 1 or 2 OMPL tries, not 3
  short30, short20   30 shortcut attempts with a patience of 10, or 20 with 8
  grid80, grid50     TOPP-RA grids of at least 80 (the minimum until 60 was measured here) or 50 intervals
Every variant plans the one-motion plans of queries a-e of bench/bench_vs_mplib.py (their captured starts and goals,
as bench_timing.py builds them) at seeds 100, 101, ... in one process, the variants in alternating order at each seed.
Printed per query and variant: the median, mean and 90th percentile of the motion's duration (s; a function of the
plan and the seed, the same on any machine), the median over the seeds of each call's CPU time over the default's at
the same seed (``time.process_time``, paired: load that comes and goes hits both), and the calls that raised.

A variant whose trajectories differ is judged by its durations over the seeds (its paths are other paths); limits,
clearance and targets are the pipeline's own checks on every call, which a call that raised did not pass.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/bench_timing.py

ROOT = Path(__file__).resolve().parents[1]


@contextmanager
def _set(module: object, name: str, value: object) -> Iterator[None]:
    old = getattr(module, name)
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, old)


def variants() -> dict[str, Callable[[], object]]:
    """Variant name -> a context manager that sets its constant."""
    from roarmctl.motion import ompl_planner, toppra_constraints
    from roarmctl.motion.planning import motions

    def shortcuts(attempts: int, patience: int) -> Callable[[], object]:
        simplify = ompl_planner.simplify_path  # free_path imports it at each call: the wrapper is what it gets

        @contextmanager
        def cm() -> Iterator[None]:
            with _set(ompl_planner, "SHORTCUT_PATIENCE", patience), \
                    _set(ompl_planner, "simplify_path", lambda *a, **k: simplify(*a, **{**k, "attempts": attempts})):
                yield
        return cm

    return {
        "default": lambda: _set(motions, "FREE_MOTION_TRIES", motions.FREE_MOTION_TRIES),
        "tries1": lambda: _set(motions, "FREE_MOTION_TRIES", 1),
        "tries2": lambda: _set(motions, "FREE_MOTION_TRIES", 2),
        "short30": shortcuts(30, 10),
        "short20": shortcuts(20, 8),
        "grid80": lambda: _set(toppra_constraints, "GRID_MIN", 80),
        "grid50": lambda: _set(toppra_constraints, "GRID_MIN", 50),
    }


def main() -> None:
    """Plan every query with every variant, seed by seed, and print the table."""
    import os

    from bench_timing import query_docs

    import roarmctl.api as rc
    from roarmctl.errors import RoarmError
    from roarmctl.motion.pipeline import load_planning_libraries

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40, help="seeds 100 .. 100 + N - 1")
    parser.add_argument("--queries", default="a,b,c,d,e")
    parser.add_argument("--variants", default="default,tries1,tries2,short30,short20,grid80,grid50")
    args = parser.parse_args()
    every = variants()
    names = args.variants.split(",")
    if names[0] != "default":
        names.insert(0, "default")
    load_planning_libraries()
    docs = query_docs()
    plans = str(ROOT / "plans")
    for doc in docs.values():  # once untimed: what a process does first (caches, lazy imports) is not the call's
        rc.plan(doc, seed=0, base_dir=plans)
    load = os.getloadavg()[0]
    print(f"{'query':<6}{'variant':<9}{'duration median':>16}{'mean':>8}{'p90':>8}{'CPU / default':>15}{'raised':>8}")
    for q in args.queries.split(","):
        rows: dict[str, dict[str, list]] = {v: {"d": [], "cpu": [], "raised": []} for v in names}
        for seed in range(100, 100 + args.seeds):
            for v in names if seed % 2 == 0 else names[::-1]:
                with every[v]():
                    c = time.process_time()
                    try:
                        d = float(rc.plan(docs[q], seed=seed, base_dir=plans).trajectory.times[-1])
                    except RoarmError:
                        d = float("nan")
                    c = time.process_time() - c
                rows[v]["d"].append(d)
                rows[v]["cpu"].append(c)
        base = np.array(rows["default"]["cpu"])
        for v in names:
            d = np.array(rows[v]["d"])
            ok = d[np.isfinite(d)]
            ratio = statistics.median(np.array(rows[v]["cpu"]) / base)
            print(f"{q:<6}{v:<9}{np.median(ok):>16.4f}{ok.mean():>8.4f}{np.percentile(ok, 90):>8.4f}{ratio:>15.3f}"
                  f"{int(np.sum(~np.isfinite(d))):>8}")
    print(f"seeds 100-{99 + args.seeds}; load {load:.1f} -> {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
