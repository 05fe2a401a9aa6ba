"""The targets a plan names and how close its trajectory comes to each: a move's target (a position, a named
pose or joint values), a pick's grasp and a place's release.

A target is *reached* when the TCP passes within ``ZONE_REACHED`` of it at some sample (and, for a joint target,
every arm joint within ``JOINTS_REACHED``); a move target with a zone (m, ``move: {zone: ...}`` or
``limits.zone``) may instead be passed within that distance, the path flowing on (blending rounds the corner
inside the zone only: ``blending.zone_limits``). ``target_table`` measures every target on the finished
trajectory; a target outside its zone fails the plan (exit 3), never silently.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

ZONE_REACHED = 5e-4  # m: the TCP this close to a target (zone 0) has reached it (a servo step moves it ~0.4 mm)
JOINTS_REACHED = 1e-3  # rad (m for a prismatic joint): every arm joint this close to a joint target has reached it


@dataclass
class Target:
    """A target the plan names: ``kind`` move | grasp | release; ``name`` says which task (``task 2 (move,
    line 7)``); ``step`` is the label of the motion that ends at it; ``position`` (3,) m the TCP's target;
    ``zone`` m; ``joints`` (arm dof,) rad for a joint or named-pose target; ``rotation`` (3, 3) the TCP's
    orientation there (a joint target's) or ``pitch`` rad the tool pitch the IK held (None: position only)."""

    kind: str
    name: str
    step: str
    position: np.ndarray
    zone: float = 0.0
    joints: np.ndarray | None = None
    rotation: np.ndarray | None = None
    pitch: float | None = None
    zone_field: str = "zone"  # where the zone was given: the move's own "zone" or the default "limits.zone"


def allowed(zone: float) -> float:
    """The distance (m) the TCP may pass a target at: its zone, and at least ``ZONE_REACHED``."""
    return max(float(zone), ZONE_REACHED)


def approach_direction(robot: Robot, q: np.ndarray, position: np.ndarray, pitch: float) -> np.ndarray:
    """The approach axis (3,) that ``pitch`` (rad, pi/2 straight down) asks for at ``position`` (m): tilted down by
    ``pitch`` from the horizontal direction out from the base axis (``robot.ik.pitch.tool_pitch``'s convention)."""
    base = robot.kin.fk(robot.full_q(q), robot.joints[robot.kin.tcp_chain_joints[0]].child)[:3, 3]
    rel = np.asarray(position[:2], dtype=float) - base[:2]
    if math.hypot(*rel) < 1e-9:  # on the base axis: the arm's azimuth
        az = float(robot.full_q(q)[robot.arm_indices[0]])
        u_h = np.array([math.cos(az), math.sin(az), 0.0])
    else:
        u_h = np.array([rel[0], rel[1], 0.0]) / math.hypot(*rel)
    return math.cos(pitch) * u_h + np.array([0.0, 0.0, -math.sin(pitch)])


def target_table(robot: Robot, traj: Trajectory, targets: list[Target]) -> list[dict[str, Any]]:
    """Per target, measured on ``traj``'s samples between the start of the motion that ends at it and the end of
    the segment after that (a target visited twice is measured on its own visit): ``distance`` (m, the closest
    TCP distance), ``time`` (s, when), ``zone`` (m, what it was allowed), ``orientation_error`` (rad: the angle
    between the approach axis and the asked pitch's, or between the TCP's and a joint target's orientation;
    absent for a position-only target), ``joint_error`` (rad, a joint target's largest joint difference at its
    nearest sample in joint space) and ``reached`` (within its zone)."""
    rows = []
    names = [s.label for s in traj.segments]
    for tgt in targets:
        lo, hi = 0.0, traj.duration
        if tgt.step in names:
            k = names.index(tgt.step)
            lo = traj.segments[k].start
            hi = traj.segments[k + 1].end if k + 1 < len(traj.segments) else traj.duration
        sel = np.flatnonzero((traj.times >= lo - 1e-9) & (traj.times <= hi + 1e-9))
        if not len(sel):
            sel = np.arange(len(traj.times))
        q = traj.positions[sel]
        frames = robot.kin.fk(q)
        d = np.linalg.norm(frames[:, :3, 3] - tgt.position, axis=1)
        i = int(np.argmin(d))
        row: dict[str, Any] = {"name": tgt.name, "kind": tgt.kind, "position": [float(v) for v in tgt.position],
                               "distance": float(d[i]), "time": float(traj.times[sel[i]]), "zone": float(tgt.zone)}
        reached = bool(d[i] <= allowed(tgt.zone))
        if tgt.joints is not None:
            arm = robot.arm_indices
            err = np.max(np.abs(q[:, arm] - tgt.joints), axis=1)
            j = int(np.argmin(err))
            row["joint_error"] = float(err[j])
            if tgt.zone <= 0.0:
                reached = reached and bool(err[j] <= JOINTS_REACHED)
        if tgt.rotation is not None:
            rel = tgt.rotation.T @ frames[i, :3, :3]
            row["orientation_error"] = float(math.acos(max(-1.0, min(1.0, (np.trace(rel) - 1.0) / 2.0))))
        elif tgt.pitch is not None:
            want = approach_direction(robot, q[i], tgt.position, tgt.pitch)
            row["orientation_error"] = float(math.acos(max(-1.0, min(1.0, float(frames[i, :3, 0] @ want)))))
        row["reached"] = reached
        rows.append(row)
    return rows


def summary(rows: list[dict[str, Any]]) -> str:
    """One line for ``plan``: ``6 targets reached (max 0.3 mm)``, those passed within a zone, those outside."""
    if not rows:
        return "no targets named"
    exact = [r for r in rows if r["reached"] and r["zone"] <= 0.0]
    zoned = [r for r in rows if r["reached"] and r["zone"] > 0.0]
    missed = [r for r in rows if not r["reached"]]
    parts = []
    if exact:
        parts.append(f"{len(exact)} target{'s' if len(exact) != 1 else ''} reached "
                     f"(max {max(r['distance'] for r in exact) * 1e3:.1f} mm)")
    if zoned:
        parts.append(f"{len(zoned)} passed within {'their zones' if len(zoned) != 1 else 'its zone'} "
                     f"(max {max(r['distance'] for r in zoned) * 1e3:.1f} mm, "
                     f"zone{'s up to' if len(zoned) != 1 else ''} {max(r['zone'] for r in zoned) * 1e3:.1f} mm)")
    if missed:
        parts.append(f"{len(missed)} outside {'their zones' if len(missed) != 1 else 'its zone'}")
    return ", ".join(parts)


def missed_text(rows: list[dict[str, Any]]) -> str:
    """The targets outside their zones, each with its distance and zone (for the error)."""
    return "; ".join(f"{r['name']} {r['kind']} target passed at {r['distance'] * 1e3:.1f} mm "
                     f"(allowed {allowed(r['zone']) * 1e3:.1f} mm)" for r in rows if not r["reached"])
