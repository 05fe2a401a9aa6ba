"""Where the TCP goes so that a picked object sits in the jaws the way it physically can (``tasks.expand_pick``).

A claw gripper such as the RoArm's has one fixed jaw and one jaw that swings toward it; the
description gives the fixed jaw's face (``Gripper.fixed_jaw``). The moving jaw pushes the object
against that face, so the object's centre ends up half its width (plus ``MARGIN``) from it, whatever
point the TCP names. On the RoArm-M3 Waveshare's TCP is 10 mm from the fixed face (the
description's ``gripper.fixed_jaw``, from Waveshare's CAD): a 40 mm cube centred on it would overlap
the fixed jaw by 10 mm, which a plan may not ask of a real arm (the physics run shows it at once).

* ``object_offset``: the vector from the TCP to the centre of an object of a given width resting
  against the fixed jaw, in the world frame, at a configuration.
* ``aligned_roll``: the wrist roll that turns the jaws' closing direction onto the nearest face
  normal of a box (a claw closing across a cube's edge would not hold it), for a RoArm whose roll
  turns the tool about its approach axis.

Units: m, rad.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from roarmctl.robot.model import Robot

#: How far from the fixed jaw's face an object's side is at the grasp (m): the jaw comes down beside the
#: object without scraping it, and the moving jaw pushes the object this far onto the face.
MARGIN = 0.001
#: Rounds of "solve the IK, move the target by the jaw offset at that pose" (the offset turns with the base yaw,
#: which moves with the target, and with the wrist roll aligned to the box): at most ITERATIONS, until the target
#: moves less than SETTLE (m, and rad for the roll). A pick's target moves ~0.15 times as far each round (10 um
#: left after 4 rounds, from 1 cm), a place's ~0.02 times. The settled target is then rounded to STEP (m, rad) and
#: solved once more: the same pick or place from another pose of the arm (the wrist roll the IK starts from) gives
#: bit for bit the same target, so the cycles of a plan repeat exactly after the first (and reuse what they computed).
ITERATIONS, SETTLE, STEP = 24, 1e-9, 1e-6


def rounded(v: npt.ArrayLike, step: float = STEP) -> npt.NDArray[np.float64]:
    """``v`` (a float or an array) rounded to a multiple of ``step``, without negative zeros."""
    return np.round(np.asarray(v, dtype=float) / step) * step + 0.0


def closing_axis(robot: Robot, q: npt.ArrayLike) -> np.ndarray:
    """The fixed jaw's face normal (toward the moving jaw) in the world frame at ``q`` (3,)."""
    jaw = robot.gripper.fixed_jaw if robot.gripper is not None else None
    assert jaw is not None  # called for a gripper with a fixed jaw only
    t = robot.kin.fk(robot.full_q(q), jaw.link)
    return t[:3, :3] @ np.asarray(jaw.normal, dtype=float)


def object_offset(robot: Robot, q: npt.ArrayLike, width: float, margin: float = MARGIN) -> np.ndarray:
    """World vector (3,) from the TCP to the centre of a ``width``-wide object resting ``margin`` from the
    fixed jaw's face, at configuration ``q``."""
    jaw = robot.gripper.fixed_jaw if robot.gripper is not None else None
    assert jaw is not None  # called for a gripper with a fixed jaw only
    q = robot.full_q(q)
    t_jaw = robot.kin.fk(q, jaw.link)
    n = t_jaw[:3, :3] @ np.asarray(jaw.normal, dtype=float)
    face = t_jaw[:3, :3] @ np.asarray(jaw.point, dtype=float) + t_jaw[:3, 3]
    tcp = robot.kin.fk(q)[:3, 3]
    return n * (0.5 * width + margin - float(n @ (tcp - face)))


def aligned_roll(robot: Robot, q: npt.ArrayLike, roll_index: int, box_rotation: np.ndarray,
                 box_size: Sequence[float] | np.ndarray, across: float) -> float | None:
    """The roll joint value (rad) that puts the closing axis on the nearest box face normal whose box side
    is ``across`` long (the width the jaws close on), turning about the roll joint's axis; None when no
    such face normal is square to that axis (the approach is not along a box axis)."""
    q = robot.full_q(q)
    n = closing_axis(robot, q)
    joint = next(j for j in robot.joints if j.name == robot.joint_names[roll_index])
    t_child = robot.kin.fk(q, joint.child)
    u = t_child[:3, :3] @ np.asarray(joint.axis, dtype=float)  # the roll axis, world frame
    best = None
    for k in range(3):
        if abs(float(box_size[k]) - across) > 1e-6:
            continue
        t = box_rotation[:, k] - u * float(u @ box_rotation[:, k])
        if np.linalg.norm(t) < 0.99:  # the face normal is not square to the roll axis
            continue
        t = t / np.linalg.norm(t)
        for s in (1.0, -1.0):
            delta = math.atan2(float(u @ np.cross(n, s * t)), float(n @ (s * t)))
            if best is None or abs(delta) < abs(best):
                best = delta
    if best is None:
        return None
    return float(q[roll_index] + best)
