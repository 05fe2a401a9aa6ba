"""Build a scene call by call: boxes, cylinders, spheres; take an item out again.

    python examples/10_scene.py [OUT_DIR]

As mplib's planning-world objects: ``Scene.add_box``, ``add_cylinder``, ``add_sphere`` (and ``add_mesh`` for
STL/OBJ files), ``remove``. The planner uses the scene as it is at each query.
"""

import json
import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
planner = rc.Planner(robot, scene)
q = [0.0, 0.6, 1.8, 0.0, 0.0]  # leaning forward, the hand low
print("free space:", bool(planner.is_valid(q)))
scene.add_box("crate", (0.10, 0.10, 0.10), (0.30, 0.0, 0.0))
scene.add_cylinder("post", radius=0.02, length=0.3, xyz=(0.0, 0.3, 0.15))
scene.add_sphere("ball", radius=0.03, xyz=(-0.2, -0.2, 0.03), role="object")
blocked = planner.is_valid(q)
print("with the crate:", bool(blocked), blocked.reason)
scene.remove("crate")
print("crate removed:", bool(planner.is_valid(q)), "items:", scene.names())
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "scene.json").write_text(json.dumps({"blocked": blocked.reason, "items": scene.names(),
                                                 "scene": scene.to_dict()}))
