"""datagen benchmark: episodes per hour per core, CPU time per stage, success rate and size per episode.

    .venv/bin/python bench/bench_datagen.py [--episodes 4] [--sizes 320x240,640x480] [--workers 1,2] [--ray]
    .venv/bin/python bench/bench_datagen.py --stages 8 [--sizes 320x240]      # the steady state, per try
    .venv/bin/python bench/bench_datagen.py --stages 6 --sizes 320x240 --base REV --rounds 3   # that, REV against this tree

Runs ``roarmctl datagen --json`` (a fresh process per run: no library or plan cached from a previous run) on
the bundled template (plans/datagen/pick_place.yaml, seed 0) for each image size and worker count (h264), once
more at the first size on one worker with AV1 (lerobot's default codec), and with
``--ray`` the largest worker count again as Ray tasks on a local Ray started by the run (its start-up
included: the overhead a user sees); ``--success N``: N episodes without cameras on 2 workers, for the success
rate and the causes of the rejections. Per run: kept/tried (success rate); wall time and episodes per hour per
core by the wall clock (kept x 3600 / (wall x workers), the load average beside it: on a shared machine the
wall includes waiting for a core); episodes per hour per core by CPU time (kept x 3600 / the CPU seconds of
all stages of all workers: what a free core gives); the CPU seconds of each stage (sample, plan, physics,
render, encode, stage, write) and their share; render+encode CPU against planning CPU (issue 34's goal: at
most 3x at 320x240); and the dataset's size per episode.

``--stages N`` runs N tries in this process after one try that pays the imports (OMPL, FCL, TOPP-RA, MuJoCo,
PyAV: about 1 s of CPU, once per worker), as a worker of a long run does, and prints each stage's CPU per kept
try (median and total) and render+encode against planning over those tries: the steady-state figure, which
a short run's totals hide under the imports. With ``--base REV`` (a git revision) it runs that in fresh processes,
REV's package (its source unpacked and its kernel built by ``bench_api_ab.revision_tree``) and this tree's in turn,
``--rounds`` times, and prints each side's medians over the rounds and the ratio of each stage: a before/after at
one load.
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/bench_api_ab.py
STEADY = ("plan", "physics", "render", "encode")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--ray", action="store_true", help="also the largest worker count as Ray tasks (local Ray)")
    ap.add_argument("--success", type=int, default=0, help="also N episodes without cameras: the success rate and its causes")
    ap.add_argument("--stages", type=int, default=0, help="only: N tries in this process after a warm-up try, CPU per stage")
    ap.add_argument("--codec", default="h264")
    ap.add_argument("--base", help="with --stages: this git revision's package against this tree's, in turn")
    ap.add_argument("--rounds", type=int, default=3, help="with --base: runs of each side")
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)  # --stages: one JSON line (for --base)
    args = ap.parse_args()
    if args.stages and args.base:
        for size in args.sizes.split(","):
            against(args.base, args.rounds, args.stages, size, args.codec)
        return 0
    if args.stages:
        for size in args.sizes.split(","):
            steady_state(args.stages, size, args.codec, args.json)
        return 0
    template = ROOT / "plans" / "datagen" / "pick_place.yaml"
    first = args.sizes.split(",")[0]
    runs: list[tuple[str, int, bool, str]] = [(s, int(w), False, "h264") for s in args.sizes.split(",") for w in args.workers.split(",")]
    runs.append((first, 1, False, "av1"))  # lerobot's default codec, for its cost
    if args.ray:
        runs.append((first, max(int(w) for w in args.workers.split(",")), True, "h264"))
    print(f"{os.cpu_count()} CPUs; {args.episodes} episodes per run; template {template.name}, seed 0; CPU s per stage")
    print(f"{'size':>8} {'codec':>5} {'engine':>6} {'workers':>7} {'kept/tried':>10} {'wall s':>7} {'load':>5} {'ep/h/core wall':>14} "
          f"{'ep/h/core CPU':>13} {'(render+encode)/plan':>20} {'MB/ep':>6}  stages")
    for size, workers, ray, codec in runs:
        tmp = Path(tempfile.mkdtemp(prefix="bench_datagen_"))
        cmd = [sys.executable, "-m", "roarmctl", "datagen", str(template), "-n", str(args.episodes), "-o", str(tmp / "ds"),
               "--size", size, "--workers", str(workers), "--seed", "0", "--codec", codec, "--json"] + (["--ray", "local"] if ray else [])
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=3600)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        if proc.returncode != 0:
            print(f"{size} {workers}: exit {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]}")
            continue
        s = json.loads(proc.stdout)
        st = s["stages_s"]
        cpu = sum(st.values())
        ratio = (st.get("render", 0) + st.get("encode", 0)) / max(st.get("plan", 0), 1e-9)
        kept = f"{s['episodes']}/{s['tried']}"
        stages = ", ".join(f"{k} {v:.1f} ({100 * v / cpu:.0f} %)" for k, v in st.items() if v >= 0.05)
        print(f"{size:>8} {codec:>5} {'ray' if ray else 'pool':>6} {workers:>7} {kept:>10} {s['wall_s']:7.1f} "
              f"{os.getloadavg()[0]:5.1f} {s['episodes'] * 3600 / (s['wall_s'] * workers):14.0f} {s['episodes'] * 3600 / cpu:13.0f} "
              f"{ratio:20.2f} {s['bytes'] / 1e6 / s['episodes']:6.2f}  {stages}")
    if args.success:
        tmp = Path(tempfile.mkdtemp(prefix="bench_datagen_"))
        try:
            proc = subprocess.run([sys.executable, "-m", "roarmctl", "datagen", str(template), "-n", str(args.success), "-o",
                                   str(tmp / "ds"), "--cameras", "none", "--workers", "2", "--seed", "0", "--json"],
                                  capture_output=True, text=True, timeout=7200)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        s = json.loads(proc.stdout)
        causes = ", ".join(f"{k} {v}" for k, v in s["rejected"].items() if v) or "none"
        print(f"success rate: {s['episodes']} kept of {s['tried']} tries ({100 * s['episodes'] / s['tried']:.0f} %); "
              f"rejected: {causes}")
    return 0


def steady_state(n: int, size: str, codec: str, as_json: bool = False) -> None:
    """``--stages``: CPU seconds per stage of each kept try among tries 1..n (try 0 pays the imports)."""
    from roarmctl.export.lerobot.datagen import run_shard

    w, h = (int(v) for v in size.split("x"))
    template = str(ROOT / "plans" / "datagen" / "pick_place.yaml")
    tmp = tempfile.mkdtemp(prefix="bench_datagen_")
    load0 = os.getloadavg()[0]
    try:
        run_shard(template, tmp, [0], 0, w, h, codec=codec)
        outs = [o for o in run_shard(template, tmp, list(range(1, n + 1)), 0, w, h, codec=codec) if o["kept"]]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    per = {k: [o["timings"].get(k, 0.0) for o in outs] for k in STEADY}
    total = {k: sum(v) for k, v in per.items()}
    if as_json:
        print(json.dumps({"kept": len(outs), "median": {k: statistics.median(v) for k, v in per.items()}, "total": total,
                          "load": [load0, os.getloadavg()[0]]}))
        return
    print(f"{size} {codec}: {len(outs)} kept of {n} tries, one process, load {load0:.1f} -> {os.getloadavg()[0]:.1f}; "
          "CPU s per kept try, median (total):")
    print("  " + ", ".join(f"{k} {statistics.median(v):.3f} ({total[k]:.2f})" for k, v in per.items()))
    print(f"  (render+encode)/plan over those tries: {(total['render'] + total['encode']) / total['plan']:.2f}")


def against(base: str, rounds: int, n: int, size: str, codec: str) -> None:
    """``--base``: ``--stages n`` of REV's package and of this tree's in fresh processes, in turn, ``rounds`` times."""
    from bench_api_ab import revision_tree

    scratch = Path(tempfile.mkdtemp(prefix="bench_datagen_base_"))
    try:
        tree = revision_tree(base, scratch / "tree")
        runs: dict[str, list[dict]] = {"base": [], "tree": []}
        for r in range(rounds):
            for side in ("base", "tree") if r % 2 == 0 else ("tree", "base"):
                env = dict(os.environ, PYTHONPATH=str(tree / "src")) if side == "base" else dict(os.environ)
                proc = subprocess.run([sys.executable, __file__, "--stages", str(n), "--sizes", size, "--codec", codec, "--json"],
                                      capture_output=True, text=True, timeout=3600, env=env, cwd=ROOT)
                if proc.returncode != 0:
                    raise SystemExit(f"{side}: exit {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]}")
                runs[side].append(json.loads(proc.stdout.strip().splitlines()[-1]))
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    loads = [x for side in runs.values() for run in side for x in run["load"]]
    print(f"{size} {codec}: {base} (base) against this tree, {rounds} rounds of {n} tries each, fresh processes in turn, "
          f"load {min(loads):.1f}-{max(loads):.1f}; CPU s per kept try, median over the rounds of each run's median:")
    for side, label in (("base", base), ("tree", "this tree")):
        med = {k: statistics.median(run["median"][k] for run in runs[side]) for k in STEADY}
        ratios = [(run["total"]["render"] + run["total"]["encode"]) / run["total"]["plan"] for run in runs[side]]
        print(f"  {label:>10}: " + ", ".join(f"{k} {v:.3f}" for k, v in med.items())
              + "; (render+encode)/plan per round " + ", ".join(f"{x:.2f}" for x in ratios))
    for k in STEADY:
        pairs = [t["median"][k] / b["median"][k] for b, t in zip(runs["base"], runs["tree"]) if b["median"][k] > 0]
        print(f"  {k}: this tree / base per round " + ", ".join(f"{x:.2f}" for x in pairs))


if __name__ == "__main__":
    sys.exit(main())
