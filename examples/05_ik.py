"""Inverse kinematics with the planner: every valid joint solution for a TCP pose, nearest first.

    python examples/05_ik.py [OUT_DIR]

As mplib's ``planner.IK(pose, qpos)``: here ``Planner.ik(Pose, q_ref)`` returns an ``IKResult`` whose
``solutions`` are within the joint limits, collision-free in the scene and clear of the singularity margin.
"""

import json
import math
import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
planner = rc.Planner(robot, seed=1)

pose = rc.Pose((0.25, -0.15, 0.06), pitch=math.pi / 2)  # 6 cm above the desk, gripper pointing down
found = planner.ik(pose, q_ref=robot.named_poses["home"])
for q in found.solutions:
    tcp = robot.kin.fk(q)[:3, 3]
    print("q =", [round(float(v), 4) for v in q], "-> TCP at", [round(float(v), 4) for v in tcp], "m")
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "ik.json").write_text(json.dumps({"xyz": pose.xyz, "solutions": [q.tolist() for q in found.solutions]}))
