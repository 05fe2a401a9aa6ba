"""A collision-free joint path between two configurations, around a wall.

    python examples/07_plan_to_joints.py [OUT_DIR]

As mplib's ``planner.plan_qpos([goal], start)``: ``Planner.plan_to_joints(q_from, q_to)`` returns a
``JointPath`` (its ``waypoints``, untimed: ``Planner.time`` times it, see 09_time_path.py).
"""

import json
import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
scene.add_box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
scene.add_box("wall", (0.04, 0.10, 0.15), (0.28, 0.0, 0.075))
planner = rc.Planner(robot, scene, seed=1)

left, right = [-0.54, 0.53, 1.93, 0.67, 0.0], [0.54, 0.53, 1.93, 0.67, 0.0]  # low, either side of the wall
path = planner.plan_to_joints(left, right)
print(f"{len(path.waypoints)} waypoints, {path.length:.3f} rad of joint travel, {path.checks} state checks")
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "path.json").write_text(json.dumps({"waypoints": path.waypoints.tolist()}))
