"""``roarmctl.api.plan`` of this tree against another revision's, call by call: an A/B of the whole planning call.

Run: .venv/bin/python bench/bench_api_ab.py [--base REV] [--rounds 20] [--queries a,b,c,d,e] [--seeds 100]

REV's source (``git archive``; default HEAD, i.e. the change not yet committed) is unpacked into a scratch folder and its compiled kernel built there (setup.py
build_ext on REV's setup.py and kernel sources, about 20 s); then two worker processes, one importing REV's package and one this tree's, plan the
one-motion plans of queries a-e of bench/bench_vs_mplib.py (its captured starts and goals, as bench_timing.py builds
them) through ``roarmctl.api.plan``, one after the other for each call, in alternating order, round r with seed
``--seeds`` + r on both sides. Printed per query: the medians of each side's CPU time of the call (the worker
process's ``time.process_time``, every thread), the median of the per-call ratios (tree / base, paired), the
motion durations, and in how many rounds the two trajectories differ (times and positions, bit for bit).

bench_timing.py pairs the timing stage alone; this pairs everything ``api.plan`` does (reading the plan dict,
geometry, timing, the re-check, the trajectory and its report), which a change outside the timing moves.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/bench_timing.py

ROOT = Path(__file__).resolve().parents[1]

WORKER = r'''
import hashlib, json, sys, time
import numpy as np
import roarmctl.api as rc
from roarmctl.motion.pipeline import load_planning_libraries

load_planning_libraries()
docs = json.loads(open(sys.argv[1]).read())
for name in docs:  # once untimed: what a process does first (caches, lazy imports) is not the call's
    rc.plan(docs[name], seed=0, base_dir=sys.argv[2])
print("ready", flush=True)
for line in sys.stdin:
    name, seed = line.split()
    c = time.process_time()
    traj = rc.plan(docs[name], seed=int(seed), base_dir=sys.argv[2]).trajectory
    c = time.process_time() - c
    digest = hashlib.sha256(np.ascontiguousarray(traj.times).tobytes() + np.ascontiguousarray(traj.positions).tobytes())
    print(json.dumps({"cpu": c, "duration": float(traj.times[-1]), "digest": digest.hexdigest()}), flush=True)
'''


def revision_tree(rev: str, folder: Path) -> Path:
    """REV's source unpacked into ``folder`` with its kernel built into its ``src/roarmctl``; returns ``folder``."""
    archive = subprocess.run(["git", "archive", rev], cwd=ROOT, check=True, capture_output=True).stdout
    folder.mkdir(parents=True, exist_ok=True)
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    # the build sees setup.py and the kernel's C sources alone (as tests/test_build.py builds): REV's pyproject.toml
    # is for pip, and this setuptools may read it otherwise
    build = folder / "build"
    (build / "src" / "roarmctl").mkdir(parents=True)
    shutil.copy(folder / "setup.py", build / "setup.py")
    for source in (folder / "src" / "roarmctl").glob("_kernel*.c"):
        shutil.copy(source, build / "src" / "roarmctl" / source.name)
    subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--build-lib", "lib", "--build-temp", "tmp"],
                   cwd=build, check=True, capture_output=True, timeout=600)
    for built in (build / "lib" / "roarmctl").glob("_kernel*.so"):
        shutil.copy(built, folder / "src" / "roarmctl" / built.name)
    return folder


def start(src: Path, docs: Path) -> subprocess.Popen:
    """A worker planning with the package under ``src``."""
    env = dict(os.environ, PYTHONPATH=str(src))
    worker = subprocess.Popen([sys.executable, "-c", WORKER, str(docs), str(ROOT / "plans")], stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True, env=env)
    assert worker.stdout is not None
    if worker.stdout.readline().strip() != "ready":
        raise SystemExit(f"the worker for {src} did not start")
    return worker


def main() -> None:
    """Build REV, start the two workers, alternate the calls, print the table."""
    from bench_timing import query_docs

    from roarmctl.motion.pipeline import load_planning_libraries

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", default="HEAD", help="the revision to compare this tree with (default HEAD)")
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--queries", default="a,b,c,d,e")
    parser.add_argument("--seeds", type=int, default=100, help="the first round's seed (bench_vs_mplib.py's: 100)")
    args = parser.parse_args()
    names = args.queries.split(",")
    load_planning_libraries()
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        docs = folder / "docs.json"
        docs.write_text(json.dumps({k: v for k, v in query_docs().items() if k in names}))
        base = revision_tree(args.base, folder / "base")
        workers = {"base": start(base / "src", docs), "tree": start(ROOT / "src", docs)}
        try:
            rows: dict[str, list[dict]] = {n: [] for n in names}
            load = os.getloadavg()[0]
            for r in range(args.rounds):
                for i, name in enumerate(names):
                    got = {}
                    for side in (("base", "tree") if (r + i) % 2 == 0 else ("tree", "base")):
                        w = workers[side]
                        assert w.stdin is not None and w.stdout is not None
                        w.stdin.write(f"{name} {args.seeds + r}\n")
                        w.stdin.flush()
                        got[side] = json.loads(w.stdout.readline())
                    rows[name].append(got)
        finally:
            for w in workers.values():
                if w.stdin is not None:
                    w.stdin.close()
                try:
                    w.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    w.kill()
    print(f"{args.rounds} rounds, load {load:.1f} -> {os.getloadavg()[0]:.1f}; base {args.base}; api.plan CPU ms "
          "(medians), tree / base paired per call")
    print(f"{'query':<7}{'base ms':>9}{'tree ms':>9}{'ratio':>7}   duration base / tree (s)   trajectories differ")
    for name in names:
        base_cpu = [g["base"]["cpu"] * 1000 for g in rows[name]]
        tree_cpu = [g["tree"]["cpu"] * 1000 for g in rows[name]]
        ratio = statistics.median(t / b for t, b in zip(tree_cpu, base_cpu))
        differ = sum(g["base"]["digest"] != g["tree"]["digest"] for g in rows[name])
        db = statistics.median(g["base"]["duration"] for g in rows[name])
        dt = statistics.median(g["tree"]["duration"] for g in rows[name])
        print(f"{name:<7}{statistics.median(base_cpu):>9.2f}{statistics.median(tree_cpu):>9.2f}{ratio:>7.2f}"
              f"   {db:.4f} / {dt:.4f}{'':>13}{differ} of {len(rows[name])}")


if __name__ == "__main__":
    main()
