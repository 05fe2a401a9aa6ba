"""The timing stage alone, this tree against another revision's, call by call: an A/B that a busy machine cannot tilt.

Run: .venv/bin/python bench/bench_timing.py [--base REV] [--rounds 15] [--split] [--seeds 1-3]

Every ``time_parameterise`` call that planning makes (the free motions a-e of bench/bench_vs_mplib.py, each planned
through ``roarmctl.api.plan`` as a one-motion plan, and the bundled plans; seeds 1-3 unless ``--seeds``) is recorded with its arguments,
then replayed ``--rounds`` times with REV's timing modules (``motion/timing.py``, ``jerk_filter.py`` and
``toppra_constraints.py`` read with ``git show REV:...``; default HEAD, i.e. the change not yet committed) and with
this tree's, one after the other for each call, in alternating order (so load that comes and goes hits both sides
alike). Printed per item: the medians over the rounds of each side's CPU time (``time.process_time``) for one plan,
their ratio, and whether the two sides return the same samples, bit for bit (times, q, qd, qdd, s, filter width).

``--split``: instead, where this tree's timing spends its CPU time, per plan (medians over the rounds, each part
inclusive of what it calls; no profiler, which inflates numpy's many small calls): TOPP-RA (its set-up and its two
passes), the spline through the waypoints, the jerk filter (and how many jerk checks it made), the sampling and
slowing down.

Whole plans (bench_plan.py) vary by 10-15 % from one run to the next on the shared machine; paired this way, a
change that does nothing (REV = this tree) reads 0.95-1.05 per item and within 0.03 of 1 over all of them.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/bench_vs_mplib.py, bench/scenes.py

ROOT = Path(__file__).resolve().parents[1]
PLANS = ("pick_place", "multi_object", "obstacle", "payload", "m2s_pick_place", "scan_desk")
QUERIES = {"a": "free", "b": "wall", "c": "post", "d": "tray", "e": "posts"}  # as bench_vs_mplib.API_FROM
MODULES = ("toppra_constraints", "jerk_filter", "timing")  # in import order


def revision_timing(rev: str, folder: Path) -> ModuleType:
    """REV's ``roarmctl.motion.timing`` loaded beside this tree's (under other module names), wired to REV's
    ``jerk_filter`` and ``toppra_constraints``."""
    mods: dict[str, ModuleType] = {}
    for name in MODULES:
        text = subprocess.run(["git", "show", f"{rev}:src/roarmctl/motion/{name}.py"], cwd=ROOT, check=True,
                              capture_output=True, text=True).stdout
        for other in MODULES:  # REV's modules import one another, not this tree's
            text = text.replace(f"from roarmctl.motion.{other} import", f"from rev_{other} import")
        path = folder / f"rev_{name}.py"
        path.write_text(text)
        spec = importlib.util.spec_from_file_location(f"rev_{name}", path)
        assert spec is not None and spec.loader is not None
        mods[name] = sys.modules[f"rev_{name}"] = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mods[name])
    return mods["timing"]


def query_docs() -> dict[str, dict]:
    """The one-motion plans of queries a-e, as bench_vs_mplib.py builds them (its captured start and goal)."""
    import bench_vs_mplib as vs

    docs = {}
    for name, source in QUERIES.items():
        ctx, step, q = vs.capture(*vs.QUERIES[source])
        goal = step.q_to.copy()
        goal[ctx.gi] = q[ctx.gi]
        plan = vs.plan_source(vs.QUERIES[source][0])
        docs[name] = vs.api_query(q, goal, dict(plan.get("scene") or {}), plan.get("objects") or [], plan)
    return docs


def record_calls(docs: dict[str, dict], seeds: range) -> dict[str, list]:
    """Item -> the (args, kwargs) of every time_parameterise call its planning makes over ``seeds``."""
    import roarmctl.api as rc
    from roarmctl.motion.planning import grasp, motions

    plain = motions.time_parameterise
    calls: dict[str, list] = {}
    current: list = []

    def recording(*args, **kwargs):
        current.append((args, kwargs))
        return plain(*args, **kwargs)

    motions.time_parameterise = grasp.time_parameterise = recording
    try:
        for item in [*docs, *PLANS]:
            current = calls[item] = []
            for seed in seeds:
                rc.plan(docs[item], seed=seed, base_dir=ROOT / "plans") if item in docs \
                    else rc.plan(ROOT / "plans" / f"{item}.yaml", seed=seed)
    finally:
        motions.time_parameterise = grasp.time_parameterise = plain
    return calls


def same(a, b) -> bool:
    """Whether two TimedPaths are the same, bit for bit."""
    return a.jerk_filter == b.jerk_filter and all(
        np.array_equal(getattr(a, f), getattr(b, f)) for f in ("times", "q", "qd", "qdd", "s"))


def split(calls: dict[str, list], rounds: int, seeds: int) -> None:
    """Print where this tree's time_parameterise spends its CPU time, per item (medians over ``rounds``)."""
    import toppra
    import toppra.algorithm

    from roarmctl.motion import jerk_filter, timing

    spent: dict[str, float] = {}
    counted: dict[str, int] = {}

    def timed(owner: object, attr: str, part: str) -> None:
        plain = getattr(owner, attr)

        def wrapper(*a, **k):
            c = time.process_time()
            try:
                return plain(*a, **k)
            finally:
                spent[part] = spent.get(part, 0.0) + time.process_time() - c
                counted[part] = counted.get(part, 0) + 1
        setattr(owner, attr, wrapper)

    parts = {"TOPP-RA set-up": (toppra.algorithm.TOPPRA, "__init__"),
             "TOPP-RA passes": (toppra.algorithm.TOPPRA, "compute_parameterization"),
             "spline": (toppra.SplineInterpolator, "__init__"), "jerk filter": (timing, "jerk_filtered"),
             "jerk checks": (jerk_filter, "_jerk_ok"), "sampling": (timing, "sampled_within_limits")}
    for part, (owner, attr) in parts.items():
        timed(owner, attr, part)
    print(f"{rounds} rounds, load {os.getloadavg()[0]:.1f}; this tree's timing, CPU ms per plan (medians), inclusive")
    print(f"{'item':<16}{'all':>7}" + "".join(f"{p:>16}" for p in parts))
    for item, recorded in calls.items():
        runs = []
        for _ in range(rounds):
            spent.clear()
            counted.clear()
            c = time.process_time()
            for a, k in recorded:
                timing.time_parameterise(*a, **k)
            runs.append((time.process_time() - c, dict(spent), dict(counted)))
        row = f"{item:<16}{statistics.median(r[0] for r in runs) * 1e3 / seeds:>7.2f}"
        for part in parts:
            ms = statistics.median(r[1].get(part, 0.0) for r in runs) * 1e3 / seeds
            row += f"{ms:>9.2f} ({runs[0][2].get(part, 0) / seeds:>4.1f})"
        print(row)
    print("(in brackets: calls per plan)")


def main() -> None:
    """Record the calls, replay them paired, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="HEAD", help="the revision to compare this tree with (default HEAD)")
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--split", action="store_true", help="where this tree's timing spends its time, no A/B")
    parser.add_argument("--seeds", default="1-3", help="planning seeds FIRST-LAST (bench_vs_mplib.py's rounds: 100-119)")
    args = parser.parse_args()

    from roarmctl.motion import timing
    from roarmctl.motion.pipeline import load_planning_libraries

    load_planning_libraries()
    with tempfile.TemporaryDirectory() as folder:
        sides = {"base": revision_timing(args.base, Path(folder)).time_parameterise, "tree": timing.time_parameterise}
    first, last = (int(v) for v in args.seeds.split("-"))
    seeds = range(first, last + 1)
    calls = record_calls(query_docs(), seeds)
    if args.split:
        split(calls, args.rounds, len(seeds))
        return
    cpu = {item: {side: [] for side in sides} for item in calls}
    equal = dict.fromkeys(calls, True)
    load = os.getloadavg()[0]
    for r in range(args.rounds):
        for item, recorded in calls.items():
            total = dict.fromkeys(sides, 0.0)
            for i, (a, k) in enumerate(recorded):
                out = {}
                for side in (("base", "tree") if (i + r) % 2 == 0 else ("tree", "base")):
                    c = time.process_time()
                    out[side] = sides[side](*a, **k)
                    total[side] += time.process_time() - c
                if r == 0:
                    equal[item] &= same(out["base"], out["tree"])
            for side, v in total.items():
                cpu[item][side].append(v / len(seeds))
    print(f"{args.rounds} rounds, load {load:.1f} -> {os.getloadavg()[0]:.1f}; base {args.base}; "
          f"timing calls per plan: " + ", ".join(f"{k} {len(v) / len(seeds):.1f}" for k, v in calls.items()))
    print(f"{'item':<16}{'base ms':>9}{'tree ms':>9}{'ratio':>7}  same samples")
    sums = dict.fromkeys(sides, 0.0)
    for item in calls:
        m = {side: statistics.median(v) * 1e3 for side, v in cpu[item].items()}
        for side in sums:
            sums[side] += m[side]
        print(f"{item:<16}{m['base']:>9.2f}{m['tree']:>9.2f}{m['tree'] / m['base']:>7.2f}  {equal[item]}")
    print(f"{'all':<16}{sums['base']:>9.2f}{sums['tree']:>9.2f}{sums['tree'] / sums['base']:>7.2f}  {all(equal.values())}")


if __name__ == "__main__":
    main()
