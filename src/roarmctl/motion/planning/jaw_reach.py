"""How far a claw gripper closes on an object where the object is, from the jaws' own geometry.

A gripper's jaw table (``Gripper.jaw_width``) is the gap at the fingertips. A picked object sits deeper in the
jaws (the RoArm-M3's TCP is 4.5 mm short of the tips, and a 30 mm cube reaches 15 mm further toward the hinge),
where the swinging jaw is nearer the fixed one: closed to "35 mm" by the table, the M3's moving jaw already presses
1 mm into a 30 mm cube. When the description gives its jaw meshes (``Gripper.jaw_meshes``), a pick closes by them
instead, with the convex pieces the physics squeezes with (``roarmctl.robot.jaw_pieces``), so "3 mm squeeze" or
"5 mm short" means the same to the planner and the physics.

The object is where the pick puts it: its side ``fixed_jaw.MARGIN`` off the fixed jaw's face. The moving jaw pushes
it onto the face (``pressed``: the object moved by the margin along the face normal), then squeezes: closing to a
squeeze ``s`` is the gripper value at which the moving jaw's pieces just touch the pressed object moved a further
``s`` into the fixed jaw. FCL tells whether two convex shapes touch; the gripper value is found by bisection (the
jaw sweeps toward the fixed one as the value falls).

Units: m, rad.
"""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.kept import Kept
from roarmctl.robot.jaw_pieces import jaw_pieces
from roarmctl.robot.meshes import convex_hull

if TYPE_CHECKING:
    from roarmctl.plan.types import ItemSpec
    from roarmctl.robot.model import Robot

#: Bisection steps on the gripper value: 1.5 rad / 2^30, about 1.4 nrad.
STEPS = 30


_CONVEXES: Kept[list] = Kept(16)  # the pieces' vertices (bytes) -> their FCL convex hulls: every pick asks again


def _convexes(pieces: list[np.ndarray], link: str) -> list:
    """FCL convex polytopes of ``pieces`` (each (V, 3) m, their convex hulls), made once per process for the same
    pieces: their hulls took ~0.15 s a jaw of 32 pieces, at every pick of every cycle."""
    import fcl  # FCL loads when a pick first needs it, as the planner's checker does

    key = (link, hashlib.sha256(b"".join(np.ascontiguousarray(v, dtype="<f8").tobytes() for v in pieces)).hexdigest())
    if key in _CONVEXES:
        return _CONVEXES[key]
    out = []
    for v in pieces:
        hv, hf = convex_hull(np.asarray(v, dtype=float), f"gripper.jaw_meshes ({link})")
        out.append(fcl.Convex(hv, len(hf), np.hstack([np.full((len(hf), 1), 3), hf]).ravel()))
    return _CONVEXES.keep(key, out)


class JawReach:
    """The moving jaw's pieces against one object held at one arm configuration.

    ``q`` (dof,) rad: the grasp configuration (its gripper value is ignored); ``spec``: the object, at its pose
    ``pose`` (4, 4, world) where the pick puts it; ``margin`` (m): how far its side is from the fixed jaw's face.
    """

    def __init__(self, robot: Robot, q: np.ndarray, spec: ItemSpec, pose: np.ndarray, margin: float) -> None:

        from roarmctl.motion.geometry import fcl_geometry

        gr = robot.gripper
        assert gr is not None and gr.fixed_jaw is not None  # checked by ``available``
        self.robot, self.q = robot, np.asarray(q, dtype=float).copy()
        self.gi = robot.joint_index(gr.joint)
        self.link = next(j.child for j in robot.joints if j.name == gr.joint)
        t_fixed = robot.kin.fk(self.q, gr.fixed_jaw.link)
        n = t_fixed[:3, :3] @ np.asarray(gr.fixed_jaw.normal, dtype=float)
        self.normal = n / np.linalg.norm(n)  # world: from the fixed face toward the moving jaw
        self.pose, self.margin = np.asarray(pose, dtype=float), float(margin)
        self.shape = fcl_geometry(spec.shape, spec.size, spec.radius, spec.length)
        self.pieces = _convexes(jaw_pieces(robot).get(self.link, []), self.link)

    def touches(self, g: float, into: float) -> bool:
        """Whether, at gripper value ``g`` (rad), the moving jaw's pieces touch the object pressed onto the fixed jaw
        and moved ``into`` (m) further toward it (negative: away from it, toward the moving jaw)."""
        import fcl

        q = self.q.copy()
        q[self.gi] = g
        t = self.robot.kin.fk(q, self.link)
        at = self.pose[:3, 3] - (self.margin + into) * self.normal
        obj = fcl.CollisionObject(self.shape, fcl.Transform(self.pose[:3, :3], at))
        for piece in self.pieces:
            jaw = fcl.CollisionObject(piece, fcl.Transform(t[:3, :3], t[:3, 3]))
            if fcl.collide(jaw, obj, fcl.CollisionRequest(), fcl.CollisionResult()):
                return True
        return False

    def closing(self, into: float, lo: float, hi: float) -> float | None:
        """The largest gripper value in [``lo``, ``hi``] (rad, ``lo`` closed) at which the moving jaw touches the
        object pressed and moved ``into`` (m; ``touches``): the jaw closed that far squeezes the object by ``into``
        (or stops ``-into`` short of it). None when the jaw does not touch it even at ``lo``; ``hi`` when it
        touches it even there."""
        if not self.touches(lo, into):
            return None
        if self.touches(hi, into):
            return hi
        for _ in range(STEPS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if self.touches(mid, into) else (lo, mid)
        return lo


def available(robot: Robot, spec: ItemSpec) -> bool:
    """Whether a pick of ``spec`` closes by the jaws' own geometry: a fixed jaw, jaw meshes for the link the
    gripper joint moves, and an object of a primitive shape whose width across the jaws is its own (no
    ``grasp_width``)."""
    gr = robot.gripper
    if gr is None or gr.fixed_jaw is None or not gr.jaw_meshes or spec.grasp_width is not None:
        return False
    if spec.shape not in ("box", "cylinder", "sphere"):
        return False
    link = next((j.child for j in robot.joints if j.name == gr.joint), None)
    return any(m.link == link for m in gr.jaw_meshes)
