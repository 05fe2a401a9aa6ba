"""The jaws' convex pieces (``roarmctl.robot.jaw_pieces``): CoACD's CPU time per jaw mesh, the pieces' size, and
how far the pieces stand outside the mesh they come from; ``--write`` puts the pieces of the bundled descriptions'
jaws, made from Waveshare's published meshes (tests/data/meshes, see its README.md), into the package
(``jaw_pieces.BUNDLED``, the files the sidecars' ``jaw_meshes`` name), where the planner and the physics read them.

Run: .venv/bin/python bench/bench_jaw_pieces.py [--robot roarm_m3_pro --robot roarm_m2_s] [--write]
Prints, per jaw mesh: triangles, CPU s of one decomposition (process time: the same on a busy machine), pieces,
vertices, and the largest distance (mm) by which a point of a piece's hull lies outside the mesh (trimesh's signed
distance over 300 surface samples per piece, seed 0). Writing twice gives the same bytes (the decomposition is
seeded; tests/test_jaw_pieces.py checks it).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

MESHES = Path(__file__).resolve().parents[1] / "tests" / "data" / "meshes"
#: bundled robot -> link -> (Waveshare's published mesh of that jaw, its scale to m)
PUBLISHED = {"roarm_m3_pro": {link: (MESHES / "waveshare_roarm_m3" / f"{link}.stl", 0.001) for link in ("link5", "gripper_link")},
             "roarm_m2_s": {link: (MESHES / "waveshare_roarm_m2_s" / f"{link}.stl", 1.0) for link in ("link3", "gripper_link")}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", action="append", default=None)
    ap.add_argument("--write", action="store_true", help="write the pieces into the package (jaw_pieces.BUNDLED)")
    args = ap.parse_args()
    import trimesh

    from roarmctl.fileio import atomic_write_text
    from roarmctl.robot.jaw_meshes import jaw_triangles
    from roarmctl.robot.jaw_pieces import cache_key, cache_text, decompose
    from roarmctl.robot.loader import load_robot
    from roarmctl.robot.model import JawMesh

    for name in args.robot or sorted(PUBLISHED):
        robot = load_robot(name)
        for bundled in robot.gripper.jaw_meshes if robot.gripper is not None else ():
            path, scale = PUBLISHED[name][bundled.link]
            mesh = JawMesh(bundled.link, str(path), scale)
            v, f = jaw_triangles(mesh)
            t = time.process_time()
            pieces = decompose(v, f)
            cpu = time.process_time() - t
            query = trimesh.proximity.ProximityQuery(trimesh.Trimesh(v, f, process=False))
            outside = 0.0
            for p in pieces:
                hull = trimesh.Trimesh(p, process=False).convex_hull
                pts = trimesh.sample.sample_surface_even(hull, 300, seed=0)[0]
                outside = max(outside, float(-query.signed_distance(pts).min()))
            text = cache_text(cache_key(v, f), pieces)
            print(f"{name} {mesh.link}: {len(f)} triangles, {cpu:.1f} s CPU, {len(pieces)} pieces, "
                  f"{sum(len(p) for p in pieces)} vertices, {len(text) / 1e3:.0f} kB, outside the mesh by at most "
                  f"{outside * 1e3:.2f} mm", flush=True)
            if args.write and bundled.pieces is not None:
                atomic_write_text(bundled.pieces, text)


if __name__ == "__main__":
    main()
