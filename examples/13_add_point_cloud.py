"""A point cloud in the scene: points (from a depth camera, a scan) as occupied 1 cm cells.

    python examples/13_add_point_cloud.py [OUT_DIR]

As mplib's ``planner.update_point_cloud(points, resolution)``: ``Scene.add_point_cloud(name, points, resolution)``
with an (N, 3) array in metres, or a PLY, PCD or .npy file.
"""

import json
import sys
from pathlib import Path

import numpy as np

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
planner = rc.Planner(robot, scene)
q = [0.0, 0.6, 1.8, 0.0, 0.0]  # leaning forward, the hand low
# a 10 cm cube of surface points around (0.30, 0, 0), as a scan of a box would give
g = np.linspace(-0.05, 0.05, 11)
face = np.array([(a, b) for a in g for b in g])
points = np.vstack([np.insert(face, k, s, axis=1) for k in range(3) for s in (-0.05, 0.05)])
scene.add_point_cloud("scan", points, resolution=0.01, xyz=(0.30, 0.0, 0.0))
blocked = planner.is_valid(q)
print(f"{len(points)} points; with the scan:", bool(blocked), blocked.reason)
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "cloud.json").write_text(json.dumps({"blocked": blocked.reason, "valid": bool(blocked)}))
