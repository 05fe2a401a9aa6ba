"""Run a planned trajectory on the built-in RoArm-M3 firmware simulator (a real pseudo-terminal)
and report how closely it followed the plan.

    python examples/03_run_on_simulator.py [TRAJ] [LOG]

Behind the simulated firmware are the physics servos (MuJoCo, the ST3235 model: lag, gravity, the
trajectory's payload; docs/physics.md), as with ``roarmctl execute --sim``. ``servos="ideal"`` gives
servos that run their trapezoids exactly (no lag, no gravity), for a check that needs an ideal arm.
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
print(f"TCP tracking error (feedback) RMS {summary['tracking_mm']['rms']:.1f} mm, max {summary['tracking_mm']['max']:.1f} mm")
true = summary["simulator"]
if true["rms_mm"] is not None:
        print(f"TCP tracking error (the simulated servos' true positions) RMS {true['rms_mm']:.1f} mm, max {true['max_mm']:.1f} mm")
if log:
    print(f"log: {log}")
