"""How far the description's collision boxes of the jaws are from the jaw table (issue 35): at each row of a gripper's
jaw table (the fingertips' gap, from Waveshare's CAD meshes), the distance between the description's fixed-jaw box
and each box of the moving jaw, measured with FCL (python-fcl) at that gripper value, beside the table's width. The
physics' jaws were these boxes; they are now the jaw meshes' convex pieces (tests/test_jaw_pieces.py holds those to
the table within 1 mm), and the boxes meet the table, obstacles and the arm only.

Run: .venv/bin/python bench/bench_jaws.py [--robot roarm_m3_pro]
Prints, per gripper value (rad): the table's width, each moving shape's least distance to the fixed jaw's shape (mm,
FCL's; "overlaps" where they intersect), and how much less than the table the last shape's (the finger's) is.
Geometry only: no clock, the same figures on any machine.
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robot", default="roarm_m3_pro")
    args = ap.parse_args()
    import fcl

    from roarmctl.robot.loader import load_robot

    robot = load_robot(args.robot)
    gr = robot.gripper
    assert gr is not None and gr.has_widths and gr.fixed_jaw is not None, "a gripper with a jaw table and a fixed jaw"
    joint = next(j for j in robot.joints if j.name == gr.joint)
    face = np.asarray(gr.fixed_jaw.point, dtype=float)
    fixed = [s for s in robot.collision if s.link == gr.fixed_jaw.link and s.kind == "box"]
    # the fixed jaw's shape: the box of its link nearest the face's point
    fixed_box = min(fixed, key=lambda s: float(np.linalg.norm(s.origin[:3, 3] - face)))
    moving = [s for s in robot.collision if s.link == joint.child and s.kind == "box"]

    def box(s, pose: np.ndarray) -> fcl.CollisionObject:
        m = pose @ s.origin
        return fcl.CollisionObject(fcl.Box(*s.size), fcl.Transform(m[:3, :3], m[:3, 3]))

    def rot(axis: np.ndarray, a: float) -> np.ndarray:
        k = axis / np.linalg.norm(axis)
        c = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        out = np.eye(4)
        out[:3, :3] = np.eye(3) + np.sin(a) * c + (1 - np.cos(a)) * c @ c
        return out

    f = box(fixed_box, np.eye(4))
    names = [s.name or f"shape {k}" for k, s in enumerate(moving)]
    print(f"{robot.name}: fixed jaw '{fixed_box.name}' on {gr.fixed_jaw.link}; moving jaw {joint.child} ({', '.join(names)})")
    print(f"{'q rad':>6}{'table mm':>10}" + "".join(f"{n[:14]:>16}" for n in names) + f"{'finger nearer by':>18}")
    for q, w in zip(gr.jaw_q, gr.jaw_width):
        pose = joint.origin @ rot(np.asarray(joint.axis, dtype=float), joint.multiplier * q + joint.offset) @ joint.post
        d = [fcl.distance(f, box(s, pose), fcl.DistanceRequest(), fcl.DistanceResult()) for s in moving]
        shown = "".join(f"{x * 1e3:>16.1f}" if x > -1 else f"{'overlaps':>16}" for x in d)
        nearer = f"{(w - d[-1]) * 1e3:>18.1f}" if d[-1] > -1 else f"{'(overlap)':>18}"
        print(f"{q:>6.2f}{w * 1e3:>10.1f}{shown}{nearer}")


if __name__ == "__main__":
    main()
