"""Start-up cost of the CLI, as wall time and as a ratio to ``python -c pass`` measured in the same run.

Run: .venv/bin/python bench/bench_startup.py [--rounds 20]

Each round runs, one after the other (interleaved, so machine load hits every command alike):
``python -c pass``; ``roarmctl --help``; ``roarmctl plan plans/pick_place.yaml`` (whole process,
planning included; its own ``planning_time`` in this fresh process is reported too, with its stage split); a bare
``import toppra``; and ``import_toppra()`` (toppra with pyplot and the matplotlib package deferred).
Targets (issue 10): plan <= 1.0 s, --help <= 0.3 s on an idle 2-core machine; planning_time <= 100 ms.
Bytecode: a user's install has every module's .pyc (pip writes them; Python writes the missing ones on the
first run). So roarmctl is compiled first (python -m compileall), every command runs once untimed before the
rounds, and all runs go without PYTHONDONTWRITEBYTECODE (removed from their environment if set): with it, a
module whose .pyc is missing or stale is compiled from source in every run, which once counted ~40 ms of
"planning_time" for the modules the plan imports lazily.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
CLI = [PY, "-m", "roarmctl"]


def _run(cmd: list[str], env: dict[str, str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    dt = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()}")
    return dt, proc.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run([PY, "-m", "compileall", "-q", str(ROOT / "roarmctl")], check=True, env=env, capture_output=True)
    out = Path(tempfile.mkdtemp()) / "pick_place.traj.json"
    cases = {
        "python -c pass": [PY, "-c", "pass"],
        "roarmctl --help": CLI + ["--help"],
        "roarmctl plan pick_place": CLI + ["plan", "plans/pick_place.yaml", "-o", str(out), "--json"],
        "import toppra (plain)": [PY, "-c", "import toppra, toppra.algorithm, toppra.constraint"],
        "import_toppra() (deferred pyplot)": [PY, "-c", "from roarmctl.motion.timing import import_toppra; import_toppra()"],
    }
    for cmd in cases.values():  # warm-up: writes any .pyc still missing, as a user's first run does
        _run(cmd, env)
    walls: dict[str, list[float]] = {k: [] for k in cases}
    planning: list[float] = []
    stages: dict[str, list[float]] = {}
    for _ in range(args.rounds):
        for name, cmd in cases.items():
            dt, stdout = _run(cmd, env)
            walls[name].append(dt)
            if name.startswith("roarmctl plan"):
                result = json.loads(stdout)
                planning.append(result["planning_time"])
                for stage, t in result["timings"].items():
                    stages.setdefault(stage, []).append(t)
    base = statistics.median(walls["python -c pass"])
    print(f"{args.rounds} interleaved rounds after one warm-up round, bytecode compiled, PYTHONDONTWRITEBYTECODE unset; "
          "medians (ratio to `python -c pass` in the same run)")
    for name, v in walls.items():
        m = statistics.median(v)
        print(f"  {name:<36} {m * 1000:7.0f} ms   {m / base:6.1f}x")
    print(f"  {'planning_time of pick_place (fresh)':<36} {statistics.median(planning) * 1000:7.0f} ms")
    split = ", ".join(f"{k} {statistics.median(v) * 1000:.0f}" for k, v in stages.items() if any(v))
    print(f"  {'  its stages (medians, ms)':<36} {split}")


if __name__ == "__main__":
    main()
