"""Start-up cost of the CLI, as wall time and as a ratio to ``python -c pass`` measured in the same run.

Run: .venv/bin/python bench/bench_startup.py [--rounds 20]

Each round runs, one after the other (interleaved, so machine load hits every command alike):
``python -c pass``; ``roarmctl --help``; ``roarmctl plan plans/pick_place.yaml`` (whole process,
planning included, with ``--json``: its own ``planning_time`` in this fresh process is reported too, with its stage
split); the same without ``--json`` (the issue's command: the summary as rich tables); ``import numpy``; a bare
``import toppra`` (scipy.interpolate and matplotlib.pyplot inside, see ``timing.import_toppra``); what the plan
command imports beside toppra (the CLI, the planning pipeline, FCL, Ruckig, OMPL: the floor of a ``plan`` whose
timing loaded no toppra); and scipy.interpolate and matplotlib.pyplot alone.
Targets (issue 25): plan <= 0.5 s, --help <= 0.12 s on an idle 2-core machine. CPU time (user + sys) is printed
beside the wall time: on a machine shared with other work it moves far less than the wall time.
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
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable
CLI = [PY, "-m", "roarmctl"]


def _run(cmd: list[str], env: dict[str, str]) -> tuple[float, str, float]:
    """(wall s, stdout, CPU s of the child: user + sys)."""
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=env)
    dt = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()}")
    return dt, proc.stdout, (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    args = parser.parse_args()
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run([PY, "-m", "compileall", "-q", str(ROOT / "src" / "roarmctl")], check=True, env=env, capture_output=True)
    out = Path(tempfile.mkdtemp()) / "pick_place.traj.json"
    cases = {
        "python -c pass": [PY, "-c", "pass"],
        "roarmctl --help": CLI + ["--help"],
        "roarmctl plan pick_place": CLI + ["plan", "plans/pick_place.yaml", "-o", str(out), "--json"],
        # the command as a user types it: the summary as rich tables (rich is imported for them)
        "roarmctl plan pick_place (tables)": CLI + ["plan", "plans/pick_place.yaml", "-o", str(out)],
        "import numpy": [PY, "-c", "import numpy"],
        # what the plan command imports beside toppra: the floor of a plan whose timing needed no toppra
        "plan's imports but toppra": [PY, "-c", "import roarmctl.cli, roarmctl.motion.pipeline, fcl, ruckig, ompl.base, ompl.geometric"],
        "import toppra": [PY, "-c", "import toppra, toppra.algorithm, toppra.constraint"],
        "import scipy.interpolate": [PY, "-c", "import scipy.interpolate"],
        "import matplotlib.pyplot": [PY, "-c", "import matplotlib.pyplot"],
    }
    for cmd in cases.values():  # warm-up: writes any .pyc still missing, as a user's first run does
        _run(cmd, env)
    walls: dict[str, list[float]] = {k: [] for k in cases}
    cpus: dict[str, list[float]] = {k: [] for k in cases}
    planning: list[float] = []
    stages: dict[str, list[float]] = {}
    for _ in range(args.rounds):
        for name, cmd in cases.items():
            dt, stdout, cpu = _run(cmd, env)
            walls[name].append(dt)
            cpus[name].append(cpu)
            if name == "roarmctl plan pick_place":
                result = json.loads(stdout)
                planning.append(result["planning_time"])
                for stage, t in result["timings"].items():
                    stages.setdefault(stage, []).append(t)
    base = statistics.median(walls["python -c pass"])
    print(f"{args.rounds} interleaved rounds after one warm-up round, bytecode compiled, PYTHONDONTWRITEBYTECODE unset; "
          "medians (ratio to `python -c pass` in the same run)")
    print(f"  {'':<36} {'wall':>7}       {'':>6}   {'CPU':>7}")
    for name, v in walls.items():
        m = statistics.median(v)
        print(f"  {name:<36} {m * 1000:7.0f} ms   {m / base:6.1f}x   {statistics.median(cpus[name]) * 1000:7.0f} ms")
    print(f"  {'planning_time of pick_place (fresh)':<36} {statistics.median(planning) * 1000:7.0f} ms")
    split = ", ".join(f"{k} {statistics.median(v) * 1000:.0f}" for k, v in stages.items() if any(v))
    print(f"  {'  its stages (medians, ms)':<36} {split}")


if __name__ == "__main__":
    main()
