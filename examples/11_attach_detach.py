"""Carry an object: attach it to the TCP at the grasp, move, detach it where the TCP has taken it.

    python examples/11_attach_detach.py [OUT_DIR]

As mplib's ``planner.update_attached_box(...)`` / detaching: ``Scene.attach(name, q)`` and ``Scene.detach(name,
q)``. While carried, the object is checked like a part of the arm (it must clear the scene too).
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
scene.add_box("cube", (0.04, 0.04, 0.04), (0.25, -0.15, 0.02), role="object")
planner = rc.Planner(robot, scene, seed=1)

grasp = planner.ik(rc.Pose((0.25, -0.15, 0.02), pitch=math.pi / 2), q_ref=robot.named_poses["home"], touching="cube").best
scene.attach("cube", grasp)  # the cube now moves with the TCP
above = planner.ik(rc.Pose((0.25, 0.15, 0.12), pitch=math.pi / 2), q_ref=grasp).best
path = planner.plan_to_joints(grasp, above)
put = planner.ik(rc.Pose((0.25, 0.15, 0.02), pitch=math.pi / 2), q_ref=above).best
cube = scene.detach("cube", put)
print("cube put down at", [round(float(v), 4) for v in cube.pose[:3, 3]], "m after", len(path.waypoints), "waypoints")
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "carried.json").write_text(json.dumps({"put": put.tolist(), "cube": cube.pose.tolist()}))
