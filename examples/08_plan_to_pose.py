"""A collision-free joint path to a TCP pose: the IK's valid solutions tried nearest first.

    python examples/08_plan_to_pose.py [OUT_DIR]

As mplib's ``planner.plan_pose(pose, start)``: ``Planner.plan_to_pose(q_from, Pose)``.
"""

import json
import math
import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
scene.add_box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
scene.add_box("wall", (0.04, 0.10, 0.15), (0.28, 0.0, 0.075))
planner = rc.Planner(robot, scene, seed=1)

pose = rc.Pose((0.25, 0.15, 0.06), pitch=math.pi / 2)
path = planner.plan_to_pose(robot.named_poses["home"], pose)
end = robot.kin.fk(path.waypoints[-1])[:3, 3]
print(f"{len(path.waypoints)} waypoints; the last puts the TCP at {[round(float(v), 4) for v in end]} m")
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "pose_path.json").write_text(json.dumps({"xyz": pose.xyz, "waypoints": path.waypoints.tolist()}))
