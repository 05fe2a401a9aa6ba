"""Plan a pick-and-place from a Python dict (no YAML file) and save the trajectory.

    python examples/01_plan_from_dict.py [OUT_DIR]
"""

import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")

plan = {
    "robot": "roarm_m3_pro",
    "start": "home",
    "scene": {"table": {"shape": "box", "size": [0.8, 0.6, 0.02], "xyz": [0.15, 0.0, -0.01]}},
    "objects": [{"name": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "xyz": [0.25, -0.15, 0.02]}],
    "tasks": [
        {"pick": {"object": "cube"}},
        {"place": {"xyz": [0.25, 0.15, 0.02]}},
        {"move": {"pose": "home"}},
    ],
    "planner": {"seed": 1},
}

result = rc.plan(plan)
traj = result.trajectory
path = rc.save_trajectory(traj, out_dir / "from_dict.traj.json")
print(f"planned {len(traj.times)} points, {traj.duration:.2f} s, events: {[e.kind for e in traj.events]}")
print(f"wrote {path}")
