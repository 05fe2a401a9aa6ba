"""A mesh in the scene: an STL file (here a 10 cm box written with trimesh, in mm) where the arm leans.

    python examples/12_add_mesh.py [OUT_DIR]

As mplib's ``planning_world.add_object(FCLObject(... Convex/BVH ...))``: ``Scene.add_mesh(name, file, xyz, rpy,
scale=..)`` (or vertices and ``faces=``), checked as the convex hulls of its parts, or its triangles with ``exact``.
"""

import json
import sys
from pathlib import Path

import trimesh

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
out_dir.mkdir(parents=True, exist_ok=True)
trimesh.creation.box((100.0, 100.0, 100.0)).export(out_dir / "crate_mm.stl")  # a CAD export in millimetres

robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
planner = rc.Planner(robot, scene)
q = [0.0, 0.6, 1.8, 0.0, 0.0]  # leaning forward, the hand low
scene.add_mesh("crate", out_dir / "crate_mm.stl", xyz=(0.30, 0.0, 0.0), scale=0.001)
blocked = planner.is_valid(q)
print("with the mesh crate:", bool(blocked), blocked.reason)
(out_dir / "mesh.json").write_text(json.dumps({"blocked": blocked.reason, "valid": bool(blocked)}))
