"""Run a planned trajectory on the built-in RoArm-M3 firmware simulator (a real pseudo-terminal)
and report how closely it followed the plan.

    python examples/03_run_on_simulator.py [TRAJ] [LOG]
"""

import sys
from pathlib import Path

import roarmctl.api as rc

if len(sys.argv) > 1:
    traj = rc.load_trajectory(sys.argv[1])
else:
    traj = rc.plan(Path(__file__).resolve().parents[1] / "plans" / "pick_place.yaml").trajectory
log = sys.argv[2] if len(sys.argv) > 2 else None

summary = rc.execute(traj, sim=True, log=log)  # on a real arm: rc.execute(traj, port="/dev/ttyUSB0", confirm=...)
print(f"{summary['outcome']}: {summary['commands']} commands on {summary['port']}")
print(f"TCP tracking error RMS {summary['tracking_mm']['rms']:.1f} mm, max {summary['tracking_mm']['max']:.1f} mm")
if log:
    print(f"log: {log}")
