"""datagen benchmark: episodes per hour per core, time per stage, success rate and size per episode.

    .venv/bin/python bench/bench_datagen.py [--episodes 4] [--sizes 320x240,640x480] [--workers 1,2] [--ray]

Runs ``roarmctl.export.lerobot.datagen.generate`` (what ``roarmctl datagen`` runs) on the bundled template
(plans/datagen_pick_place.yaml, seed 0) for each image size and worker count, and with ``--ray`` the largest
worker count again as Ray tasks on a local Ray started by the run (its start-up included: that is the
overhead a user sees). Per run: kept/tried (success rate), wall time, episodes per hour per core (kept
episodes x 3600 / (wall x workers)), the CPU seconds of each stage summed over the tries (sample, plan,
physics, render, encode, stage, and the final write) and their share, the render+encode time against the
planning time (issue 34's goal: at most 3x at 320x240), and the dataset's size per episode. Wall figures on a
shared machine include waiting for a core: the load average is printed with them.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--sizes", default="320x240,640x480")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--ray", action="store_true", help="also the largest worker count as Ray tasks (local Ray)")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    from roarmctl.export.lerobot.datagen import DatagenOptions, generate

    template = ROOT / "plans" / "datagen_pick_place.yaml"
    runs = [(s, int(w), None) for s in args.sizes.split(",") for w in args.workers.split(",")]
    if args.ray:
        runs.append((args.sizes.split(",")[0], max(int(w) for w in args.workers.split(",")), ""))
    print(f"{os.cpu_count()} CPUs; {args.episodes} episodes per run; template {template.name}, seed 0")
    print(f"{'size':>8} {'engine':>8} {'workers':>7} {'kept/tried':>10} {'wall s':>7} {'ep/h/core':>9} {'render+encode / plan':>21} "
          f"{'MB/ep':>6} {'load':>5}  stages (CPU s)")
    for size, workers, ray in runs:
        w, h = (int(v) for v in size.split("x"))
        out = Path(tempfile.mkdtemp(prefix="bench_datagen_")) / "ds"
        try:
            s = generate(template, out, DatagenOptions(episodes=args.episodes, seed=0, workers=workers, width=w, height=h, ray=ray))
        finally:
            shutil.rmtree(out.parent, ignore_errors=True)
        rate = s.kept * 3600.0 / (s.wall * workers)
        ratio = (s.stages.get("render", 0) + s.stages.get("encode", 0)) / max(s.stages.get("plan", 0), 1e-9)
        total = sum(s.stages.values())
        stages = ", ".join(f"{k} {v:.1f} ({100 * v / total:.0f} %)" for k, v in s.stages.items() if v >= 0.05)
        print(f"{size:>8} {'ray' if ray is not None else 'pool':>8} {workers:>7} {f'{s.kept}/{s.tried}':>10} {s.wall:7.1f} {rate:9.0f} "
              f"{ratio:21.2f} {s.bytes / 1e6 / s.kept:6.2f} {os.getloadavg()[0]:5.1f}  {stages}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
