"""What a robot with high-resolution visual meshes costs a picture: the triangles before and after the decimation to
the budget (``roarmctl.robot.visuals.MAX_TRIANGLES``), the time to read and decimate them, and the page's size.

    .venv/bin/python bench/bench_visual_budget.py [--subdivisions 7] [--links 2]

The robot is the bundled RoArm-M3 Pro with a sphere of ``20 x 4**subdivisions`` triangles (trimesh's icosphere, an
STL) as the visual of each of ``--links`` links; the page is ``view_document`` + ``write_page`` of three samples
at home. Times are one run each (the decimation's result is the same every run: no randomness in it).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
import yaml

from roarmctl.motion.trajectory import Trajectory
from roarmctl.robot import visuals
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.viz.web.document import view_document
from roarmctl.viz.web.page import write_page

LINKS = ("link1", "link2", "link3", "link4", "link5")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subdivisions", type=int, default=7)
    ap.add_argument("--links", type=int, default=2, choices=range(1, len(LINKS) + 1))
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        trimesh.creation.icosphere(subdivisions=args.subdivisions, radius=0.02).export(d / "ball.stl")
        urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
        for link in LINKS[:args.links]:
            urdf = urdf.replace(f'<link name="{link}">',
                                f'<link name="{link}"><visual><geometry><mesh filename="ball.stl"/></geometry></visual>', 1)
        (d / "arm.urdf").write_text(urdf)
        side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
        side["urdf"] = "arm.urdf"
        (d / "arm.yaml").write_text(yaml.safe_dump(side))
        robot = load_robot(str(d / "arm.yaml"))
        before = args.links * 20 * 4 ** args.subdivisions
        t0 = time.perf_counter()
        shapes, notes = visuals.visual_shapes(robot)
        took = time.perf_counter() - t0
        after = sum(len(v.shape.mesh.faces) for v in shapes if v.shape.kind == "mesh")
        q = np.tile(robot.full_q(robot.named_poses["home"]), (3, 1))
        traj = Trajectory(str(d / "arm.yaml"), list(robot.joint_names), np.array([0.0, 0.1, 0.2]), q,
                          np.zeros_like(q), np.zeros_like(q))
        page = write_page(view_document(traj, robot), d / "page.html")
        print(f"visual triangles: {before:,} -> {after:,} (budget {visuals.MAX_TRIANGLES:,}); read and decimated in "
              f"{took:.2f} s; page {page.stat().st_size / 1e6:.1f} MB "
              f"(undecimated the triangles alone would be {before * 36 * 4 / 3 / 1e6:.1f} MB of base64)")
        for n in notes:
            print("note:", n)


if __name__ == "__main__":
    main()
