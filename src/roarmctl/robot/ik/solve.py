"""The IK entry points: ``solve_ik`` (which family runs, the solutions sorted), ``solve_ik_near`` (the solution
that continues a configuration), the pitch search (``solve_ik_auto_pitch``), targets in another frame
(``solve_ik_frame``) and the FK check of a solution."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError, UnreachableError, rejection
from roarmctl.robot.frames import Frame, device_point, from_frame
from roarmctl.robot.ik.common import POS_TOL, default_ref, rot_angle, vec3
from roarmctl.robot.ik.dls import dls_solve, pitch_aim
from roarmctl.robot.ik.pitch import pitch_candidates, tool_pitch
from roarmctl.robot.ik.roarm3 import Roarm3IK
from roarmctl.robot.ik.roarm5 import roarm5_solver
from roarmctl.robot.ik.ur6 import ur6_solve
from roarmctl.robot.model import Robot, transform

#: Analytic IK families a description may name with ``ik:`` (or through ``singularity_model``).
IK_FAMILIES = ("roarm5", "roarm3", "ur6")


def solve_ik(
    robot: Robot,
    position: npt.ArrayLike,
    *,
    pitch: float | None = None,
    roll: float | None = None,
    rpy: npt.ArrayLike | None = None,
    q_ref: npt.ArrayLike | None = None,
    all_solutions: bool = False,
) -> list[np.ndarray]:
    """Joint configurations that put the TCP at ``position`` (m, root frame).

    Args:
        position: target TCP position (3,), metres, in the robot's root (world) frame.
        pitch: angle (rad) of the TCP approach axis (TCP +x; ``hand_tcp`` on the RoArm) below the
            horizontal, measured in the vertical plane through the base axis and the target, positive
            downward: ``0`` points straight away from the base axis (the ``home`` pose),
            ``+pi/2`` points straight down (top-down grasp), ``-pi/2`` straight up, ``pi`` back
            toward the base axis. When the target is on the base axis, "away" is the direction of
            the reference base angle (``q_ref`` or 0). Left out: searched (see below). Arms without
            a closed form hold it with the numerical IK (``pitch_aim``; the base axis is the vertical
            through the first joint); ``roarm3`` (position only) refuses it.
        roll: RoArm: the wrist-roll joint value (rad), i.e. the turn of the tool about its
            approach axis relative to the arm's plane. Default: ``q_ref``'s roll, else 0. Note that
            the base-flipped branch (base + pi, arm leaning back) has the same approach axis but
            its tool turned by pi about it for the same roll value. Other arms: the turn about the
            approach axis from the pose whose TCP +y is horizontal (``pitch_aim``); needs ``pitch``;
            left out, the turn is free (the numerical IK keeps near ``q_ref``).
        rpy: full target orientation of the TCP as URDF roll-pitch-yaw (rad), R = Rz Ry Rx. Excludes
            ``pitch`` and ``roll``. A 5-joint RoArm can only reach orientations whose approach axis
            lies in the vertical plane through the base axis and the target.
        q_ref: reference configuration (arm-only or full, rad). Solutions are sorted by distance to
            it, its gripper value is kept, and it seeds the numerical solver.
        all_solutions: return every solution found (every branch within limits: up to 4 for the
            RoArm, up to 8 for the UR10, the distinct ones the restarts find otherwise, the search
            stopping once ``DLS_ENOUGH`` are found or a batch of starts adds none) instead
            of only the best (closest to ``q_ref``, else to the ``home`` pose, else to zero).

    Returns:
        A non-empty list of full configuration vectors (``robot.dof``,), rad, within the limits,
        each verified by FK (position error <= ``POS_TOL``; orientation <= ``ORI_TOL`` when given).

    Pitch left free (RoArm): each branch uses the preferred pitch (that of ``q_ref`` at the target,
    else pi/2, top-down) when it can hold it; otherwise the pitch is searched on a 0.5 deg grid and
    the feasible sample nearest to the preferred one is taken, moved 3 deg inside the feasible
    interval so that the result does not sit on a joint limit or the reach boundary. So with
    ``q_ref`` = FK's own configuration, position-only IK gives ``q_ref`` back.

    Raises:
        UnreachableError: with ``reason`` ``"out_of_reach"``, ``"joint_limit"`` or ``"orientation"``.
        InputError: malformed arguments (wrong lengths, pitch and rpy together, ...).
    """
    p = vec3(position, "position")
    for name, angle in (("pitch", pitch), ("roll", roll)):
        if angle is not None and not math.isfinite(float(angle)):  # inf reached the closed form's cos: a bug report
            raise InputError(f"{name}: expected a finite angle (rad), got {float(angle):g}")
    if rpy is not None and (pitch is not None or roll is not None):
        raise InputError("give either rpy or pitch/roll, not both")
    rot = None if rpy is None else transform(rpy=vec3(rpy, "rpy"))[:3, :3]
    qr = None if q_ref is None else robot.full_q(np.asarray(q_ref, dtype=float))
    model = robot.ik or ""
    if model == "roarm5":
        sols = roarm5_solver(robot).solve(p, pitch, roll, rot, qr)
    elif model == "roarm3":
        if pitch is not None or roll is not None or rot is not None:
            raise InputError(f"{robot.name}: the roarm3 IK is position only (the tool pitch follows from the "
                             f"geometry); leave out pitch, roll and rpy")
        solver = robot.derived.get("roarm3_ik")
        if solver is None:  # geometry read once per loaded robot
            solver = robot.derived["roarm3_ik"] = Roarm3IK(robot)
        sols = solver.solve(p, qr)
    else:
        aim = None
        if pitch is not None or roll is not None:
            if pitch is None:
                raise InputError(f"{robot.name}: a roll needs a pitch (it turns the tool about the approach axis "
                                 f"the pitch sets); give both")
            aim = pitch_aim(robot, p, float(pitch), None if roll is None else float(roll), qr)
            rot = aim.rot
        if model == "ur6" and rot is not None:
            sols = ur6_solve(robot, p, rot, qr)
        else:
            sols = dls_solve(robot, p, rot, qr, all_solutions, aim=aim)
    ref = qr if qr is not None else default_ref(robot)
    arm = robot.arm_indices
    sols.sort(key=lambda q: float(np.linalg.norm(q[arm] - ref[arm])))
    return sols if all_solutions else sols[:1]


def solve_ik_near(robot: Robot, position: npt.ArrayLike, q_ref: npt.ArrayLike, *, pitch: float | None = None,
                  roll: float | None = None) -> np.ndarray:
    """The IK solution (full q, rad) that continues ``q_ref``: the one with the smallest largest joint change.

    Closed forms give every branch and the nearest is taken; the numerical IK starts from ``q_ref`` alone
    (converging to the solution it leads to) and runs its restarts only when that start fails.
    Raises ``UnreachableError`` as ``solve_ik``.
    """
    qr = robot.full_q(np.asarray(q_ref, dtype=float))
    arm = robot.arm_indices
    numeric = (robot.ik or "") not in IK_FAMILIES or ((robot.ik == "ur6") and (pitch is None or roll is None))
    sols = solve_ik(robot, position, pitch=pitch, roll=roll, q_ref=qr, all_solutions=not numeric)
    return min(sols, key=lambda s: float(np.max(np.abs(s[arm] - qr[arm]))))


def solve_ik_auto_pitch(robot: Robot, position: npt.ArrayLike, *, preferred: float,
                        accept: Callable[[np.ndarray], bool | str], roll: float | None = None,
                        q_ref: npt.ArrayLike | None = None, all_solutions: bool = False,
                        solve: Callable | None = None) -> tuple[list[np.ndarray], float]:
    """RoArm IK with the pitch chosen: the pitch nearest to ``preferred`` (rad, 1 deg steps) at which
    some solution is within the limits and ``accept``-ed (e.g. collision-free and clear of the
    singularity margin). ``accept`` returns True for a solution it takes, else the cause that rejects it
    ("collision", "singularity" or "joint_limit", as ``Validity.kind``; False: "collision"). Returns (the
    accepted solutions, best first; the pitch). ``solve`` replaces ``solve_ik`` (same keywords), e.g. for
    targets in another frame.

    Raises UnreachableError when no pitch works: when some pitch had in-limit solutions, its reason is what
    rejected them (the one cause, or "mixed") and the message counts each cause; else the reason the
    preferred pitch failed.
    """
    solve = solve or (lambda p, **kw: solve_ik(robot, p, **kw))
    first: UnreachableError | None = None  # why the first pitch that had no solution failed
    causes: list[str] = []  # the cause of each rejected in-limit solution
    for pitch in pitch_candidates(preferred):
        try:
            sols = solve(position, pitch=pitch, roll=roll, q_ref=q_ref, all_solutions=True)
        except UnreachableError as exc:
            first = first or exc
            continue
        ok = []
        for q in sols:
            verdict = accept(q)
            if verdict is True:
                ok.append(q)
            else:
                causes.append(verdict or "collision")
        if ok:
            return (ok if all_solutions else ok[:1]), pitch
    at = f"{math.degrees(preferred):.1f} deg"
    if not causes:
        assert first is not None  # every pitch either failed or gave solutions
        raise UnreachableError(f"no tool pitch reaches the target; at the preferred pitch {at}: {first.message}",
                               first.reason, "move the target")
    reason, said = rejection(causes)
    raise UnreachableError(f"no tool pitch reaches the target validly: the {len(causes)} in-limit solutions of the pitches "
                           f"that reach it are rejected ({said})", reason, "move the target")


def solve_ik_frame(robot: Robot, frame: Frame, position: npt.ArrayLike, **kw: Any) -> list[np.ndarray]:
    """``solve_ik`` for a target given in a robot frame (``roarmctl.robot.frames.Frame``, its unit)
    for the frame's device end point (e.g. the RoArm firmware's own TCP, 2-3 mm from ``hand_tcp``).

    The end point's offset from the TCP depends on the base angle and the pitch only (it lies in the
    arm's plane), so a few fixed-point steps with the pitch held settle it to below ``POS_TOL``.
    """
    target = from_frame(frame, position)
    if frame.point_link is None:
        return solve_ik(robot, target, **kw)
    pitch = kw.pop("pitch", None)
    all_solutions = kw.pop("all_solutions", False)
    p_tcp = target.copy()
    for _ in range(8):
        sols = solve_ik(robot, p_tcp, pitch=pitch, all_solutions=False, **kw)
        q = sols[0]
        if pitch is None:
            pitch = tool_pitch(robot, q, p_tcp)
        err = target - device_point(robot, frame, q)
        if float(np.linalg.norm(err)) <= POS_TOL * 0.5:
            break
        p_tcp = p_tcp + err
    sols = solve_ik(robot, p_tcp, pitch=pitch, all_solutions=all_solutions, **kw)
    # other branches (base turned by pi) carry the end point on the other side: keep those that hit it
    hit = [q for q in sols if float(np.linalg.norm(device_point(robot, frame, q) - target)) <= 1e-5]
    if not hit:
        raise UnreachableError(f"no solution puts the {frame.name} end point at the target", "out_of_reach")
    return hit


@dataclass
class IKCheck:
    """FK check of one solution: position error (m), orientation error (rad, or None)."""

    position_error: float
    orientation_error: float | None


def check_solution(robot: Robot, q: np.ndarray, position: npt.ArrayLike, rpy: Iterable[float] | None = None) -> IKCheck:
    """Position and orientation error of configuration ``q`` against a target, by FK."""
    t = robot.kin.fk(robot.full_q(q))
    perr = float(np.linalg.norm(t[:3, 3] - np.asarray(position, dtype=float)))
    oerr = None
    if rpy is not None:
        oerr = rot_angle(transform(rpy=rpy)[:3, :3].T @ t[:3, :3])
    return IKCheck(perr, oerr)
