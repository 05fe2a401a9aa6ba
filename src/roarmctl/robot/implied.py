"""What a robot description implies without writing it, as the loader applies it (``roarmctl.robot.loader``):
the limits roarmctl takes where a description gives none (and the note that says so), the link pairs that
touch by construction (joined by a joint, seen through links without geometry; the gripper's own moving
parts), where a movable joint that nothing drives is held, and the range a mimic joint's own limits leave
its leader. Units: m, rad, s.
"""

from __future__ import annotations

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.model import Joint, Robot, axis_angle, transform

DEFAULT_VELOCITY = 1.0  # rad/s, used only where a description gives none
DEFAULT_ACCELERATION = 2.0  # rad/s^2
# Where a description gives no jerk limit: the acceleration may rise from zero to its limit in 0.1 s.
DEFAULT_JERK_PER_ACCELERATION = 10.0  # 1/s


def default_notes(robot: Robot) -> list[str]:
    """One line naming the limits that are roarmctl's defaults (``robot.defaults``), with the values and
    units by joint type, or none."""
    if not robot.defaults:
        return []
    kinds = {n: j.kind for j in robot.joints for n in [j.name]}

    def unit(name: str, power: int) -> str:
        return ("m" if kinds.get(name) == "prismatic" else "rad") + ("/s" if power == 1 else f"/s^{power}")

    parts = []
    for key, power in (("velocity", 1), ("acceleration", 2), ("jerk", 3)):
        js = robot.defaults.get(key)
        if not js:
            continue
        if key == "jerk":
            parts.append(f"jerk = acceleration limit x {DEFAULT_JERK_PER_ACCELERATION:g}/s (full acceleration in "
                         f"{1 / DEFAULT_JERK_PER_ACCELERATION:g} s) for "
                         + ("every joint" if len(js) == robot.dof else ", ".join(js)))
            continue
        value = DEFAULT_VELOCITY if key == "velocity" else DEFAULT_ACCELERATION
        groups: dict[str, list[str]] = {}
        for n in js:
            groups.setdefault(unit(n, power), []).append(n)
        parts.append(f"{key} " + "; ".join(f"{value:g} {u} for " + ("every joint" if len(g) == robot.dof else ", ".join(g))
                                         for u, g in groups.items()))
    return [f"{robot.name}: limits the description does not give, roarmctl's defaults used: " + "; ".join(parts)
            + " (set them in the sidecar's limits:)"]

def adjacent_pairs(robot: Robot) -> set[frozenset[str]]:
    """Pairs of links joined by a joint, counting a link without collision geometry as transparent (its
    neighbours are joined to each other, as MoveIt Setup Assistant's "Adjacent" pairs are computed,
    moveit_setup_srdf_plugins compute_default_collisions.cpp): links that touch at a joint and whose
    meshes usually overlap there are not checked against each other (Drake's and PyBullet's default too).
    Franka's link7 and hand, joined through the geometry-less link8, are such a pair.

    Computed by groups: links without geometry that are joined to each other form a group, and the group
    with every link joined to it are all adjacent to each other (what joining the neighbours of each such
    link, one after the other, comes to), in time linear in the links plus the pairs it returns (the
    one-link-at-a-time way took a cubic time: a chain of 1,000 fixed frames hung)."""
    near: dict[str, set[str]] = {name: set() for name in robot.link_names}
    for j in robot.joints:
        near[j.parent].add(j.child)
        near[j.child].add(j.parent)
    pairs = {frozenset((a, b)) for a, bs in near.items() for b in bs}
    solid = {s.link for s in robot.collision}
    seen: set[str] = set()
    for start in robot.link_names:
        if start in solid or start in seen:
            continue
        group, stack = set(), [start]  # the geometry-less links joined to ``start`` through each other
        while stack:
            link = stack.pop()
            if link in group:
                continue
            group.add(link)
            stack.extend(n for n in near[link] if n not in solid and n not in group)
        seen |= group
        members = sorted(group | {n for g in group for n in near[g]})
        pairs |= {frozenset((a, b)) for i, a in enumerate(members) for b in members[i + 1:]}
    return pairs


def gripper_part_pairs(robot: Robot) -> set[frozenset[str]]:
    """Pairs of the gripper's moving parts (everything the gripper joint and the joints mimicking it move): they
    touch each other by design (fingers that close on nothing, a four-bar's knuckles) and are not checked against
    each other (MoveIt Setup Assistant finds such pairs by sampling); against the rest of the robot they are."""
    if robot.gripper is None:
        return set()
    below: dict[str, list[str]] = {}
    for j in robot.joints:
        below.setdefault(j.parent, []).append(j.child)
    parts, todo = set(), [j.child for j in robot.joints_moved_by(robot.gripper.joint)]
    while todo:
        link = todo.pop()
        parts.add(link)
        todo.extend(below.get(link, []))
    return {frozenset((a, b)) for a in parts for b in parts if a < b}


def rest_value(joint: Joint) -> float:
    """Where a movable joint that nothing drives is held: 0 when its limits allow it, else the middle of
    its range (MoveIt's default joint position, moveit_core RevoluteJointModel/PrismaticJointModel
    ``computeVariablePositions``)."""
    return 0.0 if joint.lower <= 0.0 <= joint.upper else 0.5 * (joint.lower + joint.upper)

def held_fixed(ordered: list[Joint], held: list[str]) -> list[Joint]:
    """``ordered`` with every joint in ``held`` (and every joint mimicking one) made fixed at its rest value."""
    rest = {j.name: rest_value(j) for j in ordered if j.name in held}
    out = []
    for j in ordered:
        lead = j.name if j.name in rest else j.mimic if j.mimic in rest else None
        if lead is None:
            out.append(j)
            continue
        value = j.multiplier * rest[lead] + j.offset
        motion = axis_angle(j.axis, value) if j.kind == "revolute" else transform(value * np.asarray(j.axis))
        out.append(Joint(j.name, "fixed", j.parent, j.child, j.origin @ motion @ j.post))
    return out

def mimic_bounds(ordered: list[Joint], names: list[str], bounded: set[str], lower: np.ndarray, upper: np.ndarray,
                  notes: list[str]) -> None:
    """Narrow a driven joint's limits (in place) to the values at which every joint mimicking it stays within its
    own URDF limits (multiplier x q + offset inside [lower, upper] of the mimic joint); said in ``notes``."""
    for j in ordered:
        if j.mimic is None or j.name not in bounded or j.mimic not in names:
            continue
        k = names.index(j.mimic)
        a, b = sorted(((j.lower - j.offset) / j.multiplier, (j.upper - j.offset) / j.multiplier))
        lo, hi = max(lower[k], a), min(upper[k], b)
        if lo > hi:
            raise DescriptionError(f"joint '{j.name}' mimics '{j.mimic}' but no value of '{j.mimic}' within its limits "
                                   f"keeps '{j.name}' within [{j.lower:g}, {j.upper:g}]")
        if lo > lower[k] + 1e-9 or hi < upper[k] - 1e-9:
            notes.append(f"joint '{j.mimic}' limited to [{lo:.6g}, {hi:.6g}] so that '{j.name}', which mimics it, stays "
                         f"within its own limits [{j.lower:g}, {j.upper:g}]")
            lower[k], upper[k] = lo, hi
