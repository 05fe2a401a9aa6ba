"""Inverse kinematics: closed form for the RoArm-M3 and the UR10, damped least squares for the rest.

Entry point: ``solve_ik(robot, position, pitch=..., roll=..., rpy=..., q_ref=..., all_solutions=...)``.
It returns full configuration vectors (``robot.dof``, gripper included), every one within the
joint limits and checked by forward kinematics before it is returned; or it raises
``UnreachableError`` whose ``reason`` is ``"out_of_reach"``, ``"joint_limit"`` or ``"orientation"``.

Which solver runs:

* ``singularity_model == "roarm5"`` (the RoArm-M3 Pro): planar closed form about the base axis,
  target = TCP position + tool pitch (+ roll), or position + full orientation (``rpy``).
* ``singularity_model == "ur6"`` with ``rpy`` (or pitch and roll): the 8-solution analytic IK of the
  UR10 (modified DH); position only (or pitch alone) falls back to damped least squares.
* anything else: damped least squares with seeded random restarts, run as batches of starts
  (position only, position + approach axis for a tool pitch, or full pose).

Closed forms are exact for the ideal geometry; a few Newton steps on the true FK then remove what the
description's rounding leaves (Waveshare's URDF writes pi/2 as 1.5708, which tilts axes by 3.7 urad
and moves the TCP by about 1 um), so every returned solution meets ``POS_TOL`` on the real model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from roarmctl.errors import InputError, UnreachableError
from roarmctl.robot.kinematics import cross_rows
from roarmctl.robot.model import Robot, transform

WRIST_SINGULAR = 1e-6  # |sin theta5| below this is the UR wrist singularity (theta4, theta6 coupled)
STRETCH_SLACK = 1e-4  # cos(elbow) this far beyond 1 still counts as reachable (model noise; FK decides)
LIMIT_SLACK = 1e-3  # rad: closed-form candidates this far outside a limit are polished, then re-checked
POS_TOL = 1e-6  # m: every returned solution reaches the target position this closely (FK-checked)
ORI_TOL = 1e-5  # rad: orientation check; covers the few-urad axis tilt of the rounded RoArm URDF
PITCH_GRID = 721  # pitch samples over [-pi, pi] when the RoArm pitch is left free (0.5 deg)


#: Analytic IK families a description may name with ``ik:`` (or through ``singularity_model``).
IK_FAMILIES = ("roarm5", "roarm3", "ur6")


# ----------------------------------------------------------------------------------- public
def solve_ik(
    robot: Robot,
    position: Sequence[float],
    *,
    pitch: float | None = None,
    roll: float | None = None,
    rpy: Sequence[float] | None = None,
    q_ref: Sequence[float] | None = None,
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
    p = _vec3(position, "position")
    if rpy is not None and (pitch is not None or roll is not None):
        raise InputError("give either rpy or pitch/roll, not both")
    rot = None if rpy is None else transform(rpy=_vec3(rpy, "rpy"))[:3, :3]
    qr = None if q_ref is None else robot.full_q(np.asarray(q_ref, dtype=float))
    model = robot.ik or ""
    if model == "roarm5":
        solver = getattr(robot, "_roarm_ik", None)
        if solver is None:  # geometry read once per loaded robot
            solver = robot._roarm_ik = _RoarmIK(robot)
        sols = solver.solve(p, pitch, roll, rot, qr)
    elif model == "roarm3":
        if pitch is not None or roll is not None or rot is not None:
            raise InputError(f"{robot.name}: the roarm3 IK is position only (the tool pitch follows from the "
                             f"geometry); leave out pitch, roll and rpy")
        solver = getattr(robot, "_roarm3_ik", None)
        if solver is None:
            solver = robot._roarm3_ik = _Roarm3IK(robot)
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
            sols = _ur6_solve(robot, p, rot, qr)
        else:
            sols = _dls_solve(robot, p, rot, qr, all_solutions, aim=aim)
    ref = qr if qr is not None else _default_ref(robot)
    arm = robot.arm_indices
    sols.sort(key=lambda q: float(np.linalg.norm(q[arm] - ref[arm])))
    return sols if all_solutions else sols[:1]


def tool_pitch(robot: Robot, q: np.ndarray, position=None) -> float:
    """RoArm tool pitch (rad) of configuration ``q``: the approach axis (TCP +x) below the horizontal,
    in the vertical plane through the base axis and ``position`` (default: the TCP), as ``solve_ik``'s
    ``pitch`` means it (pi/2 = straight down)."""
    t = robot.kin.fk(robot.full_q(q))
    p = t[:3, 3] if position is None else np.asarray(position, dtype=float)
    base = robot.kin.fk(robot.full_q(q), robot.joints[robot.kin.tcp_chain_joints[0]].child)[:3, 3]
    rel = p[:2] - base[:2]
    if math.hypot(*rel) < 1e-9:
        az = float(robot.full_q(q)[robot.arm_indices[0]])
        u_h = np.array([math.cos(az), math.sin(az), 0.0])
    else:
        u_h = np.array([rel[0], rel[1], 0.0]) / math.hypot(*rel)
    return _pitch_of(t, u_h)


PITCH_STEP = math.radians(1.0)  # pitch: auto tries the preferred pitch, then +-1 deg, +-2 deg, ...


def pitch_candidates(preferred: float, step: float = PITCH_STEP) -> list[float]:
    """Pitches (rad) in the order ``pitch: auto`` tries them: ``preferred``, then alternately above
    and below it in ``step``s, over the whole circle (wrapped to [-pi, pi])."""
    out = [float(_wrap(preferred))]
    n = int(math.ceil(math.pi / step))
    for k in range(1, n + 1):
        for sgn in (1.0, -1.0):
            v = float(_wrap(preferred + sgn * k * step))
            if all(abs(_wrap(v - o)) > 1e-9 for o in out):
                out.append(v)
    return out


def solve_ik_auto_pitch(robot: Robot, position, *, preferred: float, accept: Callable[[np.ndarray], bool],
                        roll: float | None = None, q_ref=None, all_solutions: bool = False,
                        solve: Callable | None = None) -> tuple[list[np.ndarray], float]:
    """RoArm IK with the pitch chosen: the pitch nearest to ``preferred`` (rad, 1 deg steps) at which
    some solution is within the limits and ``accept``-ed (e.g. collision-free and clear of the
    singularity margin). Returns (the accepted solutions, best first; the pitch). ``solve`` replaces
    ``solve_ik`` (same keywords), e.g. for targets in another frame.

    Raises UnreachableError when no pitch works, naming why the preferred one failed.
    """
    solve = solve or (lambda p, **kw: solve_ik(robot, p, **kw))
    first: UnreachableError | None = None
    rejected = 0
    for pitch in pitch_candidates(preferred):
        try:
            sols = solve(position, pitch=pitch, roll=roll, q_ref=q_ref, all_solutions=True)
        except UnreachableError as exc:
            first = first or exc
            continue
        ok = [q for q in sols if accept(q)]
        rejected += len(sols) - len(ok)
        if ok:
            return (ok if all_solutions else ok[:1]), pitch
    why = first.message if first is not None else "every solution collides or is too close to a singularity"
    reason = "collision" if rejected and first is None else (first.reason if first else "out_of_reach")
    raise UnreachableError(f"no tool pitch reaches the target validly ({rejected} in-limit solutions rejected); "
                           f"at the preferred pitch {math.degrees(preferred):.1f} deg: {why}", reason,
                           "move the target")


def solve_ik_frame(robot: Robot, frame, position, **kw) -> list[np.ndarray]:
    """``solve_ik`` for a target given in a robot frame (``roarmctl.robot.frames.Frame``, its unit)
    for the frame's device end point (e.g. the RoArm firmware's own TCP, 2-3 mm from ``hand_tcp``).

    The end point's offset from the TCP depends on the base angle and the pitch only (it lies in the
    arm's plane), so a few fixed-point steps with the pitch held settle it to below ``POS_TOL``.
    """
    from roarmctl.robot.frames import device_point, from_frame

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


def check_solution(robot: Robot, q: np.ndarray, position, rpy=None) -> IKCheck:
    """Position and orientation error of configuration ``q`` against a target, by FK."""
    t = robot.kin.fk(robot.full_q(q))
    perr = float(np.linalg.norm(t[:3, 3] - np.asarray(position, dtype=float)))
    oerr = None
    if rpy is not None:
        oerr = _rot_angle(transform(rpy=rpy)[:3, :3].T @ t[:3, :3])
    return IKCheck(perr, oerr)


# ---------------------------------------------------------------------------------- helpers
def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{what}: expected 3 finite numbers, got {v!r}")
    return a


def _rot_angle(m: np.ndarray) -> float:
    """Rotation angle (rad) of a 3x3 rotation matrix, accurate near 0."""
    s = 0.5 * np.linalg.norm([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    c = 0.5 * (np.trace(m) - 1.0)
    return float(math.atan2(s, c))


def _rot_vec(m: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle) of a 3x3 rotation matrix."""
    ang = _rot_angle(m)
    w = np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    if ang < 1e-9:
        return 0.5 * w
    if ang > math.pi - 1e-6:  # near pi: axis from the symmetric part
        b = (m + np.eye(3)) / 2.0
        k = int(np.argmax(np.diag(b)))
        axis = b[:, k] / math.sqrt(max(b[k, k], 1e-300))
        if np.dot(axis, w) < 0:
            axis = -axis
        return axis * ang
    return w * (ang / (2.0 * math.sin(ang)))


_TWO_PI_SHIFTS = np.array([2 * np.pi * k for k in (-1, 0, 1)])


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _default_ref(robot: Robot) -> np.ndarray:
    home = robot.named_poses.get("home")
    return robot.full_q(home) if home is not None else robot.full_q(np.zeros(robot.arm_dof))


def _gripper_value(robot: Robot, qr: np.ndarray | None) -> float | None:
    if robot.gripper is None:
        return None
    gi = robot.joint_index(robot.gripper.joint)
    return float(qr[gi]) if qr is not None else robot.gripper.closed


def _fit_limits(robot: Robot, q: np.ndarray, ref: np.ndarray | None, tol: float = 1e-7) -> np.ndarray | None:
    """Shift revolute joints by multiples of 2 pi into their limits (nearest to ``ref``); None if impossible."""
    out = q.copy()
    lo, hi = robot.lower, robot.upper
    for i in robot.arm_indices:
        best = None
        for k in range(-2, 3):
            v = q[i] + 2 * np.pi * k
            if lo[i] - tol <= v <= hi[i] + tol:
                d = abs(v - (ref[i] if ref is not None else 0.0))
                if best is None or d < best[0]:
                    best = (d, v)
        if best is None:
            return None
        out[i] = min(max(best[1], lo[i]), hi[i])
    return out


def _newton(residual: Callable[[np.ndarray], np.ndarray], q: np.ndarray, idx: list[int],
            iters: int = 12, tol: float = 1e-13, h: float = 1e-7) -> np.ndarray:
    """Gauss-Newton on the joints ``idx`` of one configuration ``q`` (dof,) with a forward-difference
    Jacobian: ``_newton_rows`` with one row. ``residual`` maps a batch of configurations (k, dof), q and
    its len(idx) perturbations, to residuals (k, m), so each iteration costs one batched FK call."""
    return _newton_rows(lambda batch, rows, k1: residual(batch), q[None], idx, iters, tol, h)[0]


def _newton_rows(residual: Callable[[np.ndarray, np.ndarray, int], np.ndarray], q: np.ndarray, idx: list[int],
                 iters: int = 12, tol: float = 1e-13, h: float = 1e-7) -> np.ndarray:
    """Gauss-Newton on the joints ``idx`` of every row of ``q`` (N, dof) at once, each row on its own: it stops
    when its residual norm is below ``tol`` or its step would exceed 0.2 rad (a polish, not a search: never
    wander to another branch). A whisker of damping keeps directions the target does not constrain (the
    base, when the TCP is on the base axis) put instead of absorbing urad-level model noise with huge steps.

    ``residual(batch, rows, k1)`` maps the configurations (len(rows) * k1, dof), k1 consecutive ones per
    active row (the row, then its perturbations), to residuals (len(rows) * k1, m). The per-row linear
    algebra is one stacked numpy/LAPACK call; the stops compare norms as ``math.sqrt(v.dot(v))`` does.
    """
    q = q.copy()
    n, dof = q.shape
    k = len(idx)
    idx_a = np.asarray(idx)
    pert = np.arange(1, k + 1)
    damp = 1e-10 * np.eye(k)
    active = np.arange(n)
    for _ in range(iters):
        if not len(active):
            break
        batch = np.repeat(q[active][:, None], k + 1, axis=1)
        batch[:, pert, idx_a] += h
        res = residual(batch.reshape(-1, dof), active, k + 1).reshape(len(active), k + 1, -1)
        r = res[:, 0]
        go = ~_below(r, tol)
        active, res, r = active[go], res[go], r[go]
        if not len(active):
            break
        jac = (res[:, 1:] - r[:, None]).transpose(0, 2, 1) / h
        jt = jac.transpose(0, 2, 1)
        step = np.linalg.solve(jt @ jac + damp, ((-jt) @ r[:, :, None]))[:, :, 0]
        move = ~_above(step, 0.2)
        active, step = active[move], step[move]
        q[active[:, None], idx_a] += step
    return q


def _below(v: np.ndarray, tol: float) -> np.ndarray:
    """Rows of ``v`` (N, m) whose norm is below ``tol``, decided as ``math.sqrt(r.dot(r)) < tol`` (the
    scalar form where the batched sum could differ in the last bit)."""
    nv = np.sqrt(np.sum(v * v, axis=1))
    out = nv < tol
    for i in np.flatnonzero(np.abs(nv - tol) <= 1e-6 * tol):
        out[i] = math.sqrt(v[i].dot(v[i])) < tol
    return out


def _above(v: np.ndarray, tol: float) -> np.ndarray:
    """Rows of ``v`` (N, m) whose norm exceeds ``tol`` (``math.sqrt(s.dot(s)) > tol``, as ``_below``)."""
    nv = np.sqrt(np.sum(v * v, axis=1))
    out = nv > tol
    for i in np.flatnonzero(np.abs(nv - tol) <= 1e-6 * tol):
        out[i] = math.sqrt(v[i].dot(v[i])) > tol
    return out


def _fit_limits_rows(robot: Robot, q: np.ndarray, tol: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """``_fit_limits`` of every row of ``q`` (N, dof) where it does not depend on the reference.

    Returns (fitted (N, dof), with NaN rows where no representative is within a limit; ambiguous (N,):
    rows where some joint has two representatives within its limits, so the reference picks one)."""
    arm = robot.arm_indices
    lo, hi = robot.lower[arm], robot.upper[arm]
    v = q[:, arm, None] + 2 * np.pi * np.arange(-2, 3)  # (N, A, 5): the candidates _fit_limits tries
    inside = (lo[None, :, None] - tol <= v) & (v <= hi[None, :, None] + tol)
    count = inside.sum(axis=2)
    out = q.copy()
    pick = np.take_along_axis(v, np.argmax(inside, axis=2)[:, :, None], 2)[:, :, 0]
    out[:, arm] = np.minimum(np.maximum(pick, lo), hi)
    out[np.any(count == 0, axis=1)] = np.nan
    return out, np.any(count > 1, axis=1)


def _dedupe(sols: list[np.ndarray], idx: list[int], tol: float = 1e-5) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    for q in sols:
        if all(np.max(np.abs(_wrap(q[idx] - o[idx]))) > tol for o in out):
            out.append(q)
    return out


# ----------------------------------------------------------------------------- RoArm-M3 (planar)
class _RoarmIK:
    """Closed-form IK of the RoArm-M3: base yaw, then a planar 3R arm (shoulder, elbow, wrist pitch).

    Geometry is read from the robot's own frames at q = 0 (Waveshare's URDF): in the arm's plane,
    with "up" the base axis and "forward" the base's +x, the shoulder axis sits at height z_s, the
    upper arm is (0.236815 along, 0.030002 across), the forearm 0.144586 along, the TCP
    (0.169081 along, 0.015147 across) from the wrist-pitch axis, and the approach axis points "along".
    A segment's direction is written as its angle from vertical, positive toward forward.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.arm = robot.arm_indices
        if len(self.arm) != 5:
            raise InputError(f"{robot.name}: the roarm5 IK needs 5 arm joints, found {len(self.arm)}")
        f0 = robot.kin.link_frames(robot.full_q(np.zeros(len(self.arm))))
        moving = [robot.joints[j] for j in robot.kin.tcp_chain_joints if robot.joints[j].kind != "fixed"]
        idx = robot.kin.link_index
        sh, el, wr = (f0[idx[m.child], :3, 3] for m in moving[1:4])
        tcp = f0[robot.kin.tcp_index]
        self.z_s = float(sh[2])
        self.base_xy = sh[:2].copy()

        def polar(v):  # (across=x, along=z) -> (length, angle from vertical)
            return math.hypot(v[0], v[2]), math.atan2(v[0], v[2])

        self.l2, self.t2 = polar(el - sh)
        self.l3, self.t3 = polar(wr - el)
        self.l4, self.t4 = polar(tcp[:3, 3] - wr)
        a0 = tcp[:3, 0]
        self.a0 = math.atan2(a0[0], a0[2])  # approach-axis angle from vertical at q = 0 (0 here)
        self.reach = self.l2 + self.l3 + self.l4

    # -- the planar sub-problem, vectorised over pitch (phi) -------------------------------------
    def _planar(self, r: float, z: float, phi: np.ndarray, elbow_sign: float):
        """Shoulder, elbow, wrist (arrays) for TCP at (r, z) in the plane and approach angle phi.

        ``r`` is signed (negative: behind the base axis), ``z`` is height above the shoulder axis.
        Returns (s, e, w, ok) where ok marks the reachable samples.
        """
        tdir = phi - self.a0 + self.t4  # direction of the wrist->TCP segment
        wr = r - self.l4 * np.sin(tdir)
        wz = z - self.l4 * np.cos(tdir)
        d2 = wr * wr + wz * wz
        c = (d2 - self.l2 ** 2 - self.l3 ** 2) / (2 * self.l2 * self.l3)
        # The ideal planar model is ~1 um off the real one, so a target the real arm reaches with the
        # elbow (almost) stretched can read as slightly out of reach here: accept it, and start the
        # polish a little bent toward the branch's side so Newton has a gradient to follow.
        ok = np.abs(c) <= 1.0 + STRETCH_SLACK
        delta = elbow_sign * np.maximum(np.arccos(np.clip(c, -1.0, 1.0)), np.where(c > 1.0 - 1e-6, 1e-3, 0.0))
        gamma = np.arctan2(wr, wz)
        alpha2 = gamma - np.arctan2(self.l3 * np.sin(delta), self.l2 + self.l3 * np.cos(delta))
        s = alpha2 - self.t2
        e = alpha2 + delta - self.t3 - s
        w = phi - self.a0 - s - e
        return s, e, w, ok

    def _branch_q(self, base: float, s, e, w, roll: float, grip: float | None) -> np.ndarray:
        n = np.size(s)
        q = np.zeros((n, self.robot.dof))
        q[:, self.arm[0]] = base
        q[:, self.arm[1]] = s
        q[:, self.arm[2]] = e
        q[:, self.arm[3]] = w
        q[:, self.arm[4]] = roll
        if grip is not None:
            q[:, self.robot.joint_index(self.robot.gripper.joint)] = grip
        return q

    def _in_limits(self, q: np.ndarray) -> np.ndarray:
        """(N,) whether each full configuration of ``q`` (N, dof) has a 2pi representative of every arm
        angle within the limits (all joints and representatives in one array operation)."""
        arm = self.arm
        qa = q[:, arm]
        qa[:, 1:4] = _wrap(qa[:, 1:4])  # pitch joints: bring angles to (-pi, pi] before the test
        # elbow range can exceed pi (0..2.95): allow the +2pi representative too
        tol = LIMIT_SLACK  # the ideal-geometry closed form is off by ~urad; the polish settles it
        v = qa[:, :, None] + _TWO_PI_SHIFTS  # (N, 5, 3)
        lo = (self.robot.lower[arm] - tol)[None, :, None]
        hi = (self.robot.upper[arm] + tol)[None, :, None]
        return np.all(np.any((v >= lo) & (v <= hi), axis=2), axis=1)

    def _violation(self, qs: np.ndarray) -> str:
        """Which joint limit the least-violating sample of ``qs`` (k, dof) breaks, in words."""
        lo, hi = self.robot.lower, self.robot.upper
        idx = self.arm[:4]
        shifts = np.array([-2 * np.pi, 0.0, 2 * np.pi])
        v = qs[:, idx][:, :, None] + shifts  # (k, 4, 3): each angle's 2pi representatives
        ex = np.maximum(np.maximum(lo[idx][None, :, None] - v, v - hi[idx][None, :, None]), 0.0)
        best = np.argmin(ex, axis=2)  # the representative nearest to the range
        ex_b = np.take_along_axis(ex, best[:, :, None], 2)[:, :, 0]
        v_b = np.take_along_axis(v, best[:, :, None], 2)[:, :, 0]
        if not len(qs) or not np.any(ex_b > 0):
            return "every branch violates a limit"
        k = int(np.argmin(np.where(np.any(ex_b > 0, axis=1), ex_b.sum(axis=1), np.inf)))
        j = int(np.argmax(ex_b[k] > 0))
        i = idx[j]
        return (f"{self.robot.joint_names[i]} would be at {math.degrees(v_b[k, j]):.1f} deg, outside "
                f"[{math.degrees(lo[i]):.1f}, {math.degrees(hi[i]):.1f}] deg")

    def solve(self, p: np.ndarray, pitch: float | None, roll: float | None,
              rot: np.ndarray | None, qr: np.ndarray | None) -> list[np.ndarray]:
        robot = self.robot
        rel = p.copy()
        rel[:2] -= self.base_xy
        rho = float(np.hypot(rel[0], rel[1]))
        z = float(p[2] - self.z_s)
        dist = math.hypot(rho, z)
        where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
        if dist > self.reach + 1e-6:  # model noise margin; the FK check decides
            raise UnreachableError(
                f"{where} is {dist:.3f} m from the shoulder axis; the arm reaches {self.reach:.3f} m",
                "out_of_reach", "move the target closer to the arm")
        ref_base = float(qr[self.arm[0]]) if qr is not None else 0.0
        on_axis = rho < 1e-9
        az = ref_base if on_axis else math.atan2(rel[1], rel[0])
        u_h = np.array([math.cos(az), math.sin(az), 0.0])  # outward horizontal direction
        grip = _gripper_value(robot, qr)

        want_roll = None
        if rot is not None:
            a = rot[:, 0]
            lateral = float(np.dot(a, np.cross([0.0, 0.0, 1.0], u_h)))
            if on_axis and math.hypot(a[0], a[1]) > 1e-9:
                az = math.atan2(a[1], a[0])  # target on the axis: the approach axis picks the plane
                u_h = np.array([math.cos(az), math.sin(az), 0.0])
                lateral = 0.0
            if abs(lateral) > ORI_TOL:
                raise UnreachableError(
                    f"orientation not achievable by a 5-joint arm: the approach axis (tool +x) must lie in the "
                    f"vertical plane through the base axis and the target; the requested one leaves it by "
                    f"{math.degrees(math.asin(min(1.0, abs(lateral)))):.2f} deg",
                    "orientation", "give --pitch (and --roll) instead of --rpy, or turn the target about the vertical")
            pitch = math.atan2(-a[2], float(np.dot(a, u_h)))
        elif roll is not None:
            want_roll = float(roll)
            ri = self.arm[4]
            if not robot.lower[ri] - 1e-9 <= want_roll <= robot.upper[ri] + 1e-9:
                raise UnreachableError(
                    f"roll {math.degrees(want_roll):.1f} deg is outside the wrist-roll range "
                    f"[{math.degrees(robot.lower[ri]):.1f}, {math.degrees(robot.upper[ri]):.1f}] deg",
                    "joint_limit", "turn the roll by 180 deg: the jaws are symmetric")
        if want_roll is None:
            want_roll = float(qr[self.arm[4]]) if qr is not None else 0.0

        branches = [(az, rho, 1.0), (az + math.pi, -rho, -1.0)]
        if pitch is not None:
            phis = np.array([float(pitch)])
        else:
            phis = np.linspace(-math.pi, math.pi, PITCH_GRID)
            pref = math.pi / 2
            if qr is not None:
                a_ref = robot.kin.fk(qr)[:3, 0]
                pref = math.atan2(-a_ref[2], float(np.dot(a_ref, u_h)))

        # per branch: alternatives (configuration, the pitch it was solved for), the first that passes wins
        cands: list[list[tuple[np.ndarray, float]]] = []
        any_reach = False
        reachable: list[np.ndarray] = []  # reachable samples, to explain a joint-limit failure
        if pitch is not None:  # one pitch: the four (base, elbow) branches as one batch, in that order
            sign = np.array([1.0, 1.0, -1.0, -1.0])
            # world approach a = cos(pitch) u_h - sin(pitch) z; in a branch's plane coordinates
            # (forward = sign * u_h) its angle from vertical is atan2(sign cos(pitch), -sin(pitch)).
            phi = np.arctan2(sign * np.cos(phis), -np.sin(phis))
            s, e, w, ok = self._planar(sign * rho, z, phi, np.array([1.0, -1.0, 1.0, -1.0]))
            qs = self._branch_q(_wrap(np.array([az, az, az + math.pi, az + math.pi])), s, e, w, want_roll, grip)
            any_reach = bool(ok.any())
            reachable = [qs[:2][ok[:2]], qs[2:][ok[2:]]]
            ok &= self._in_limits(qs)
            cands.extend([(qq, float(pitch))] for qq in qs[ok])
        else:  # pitch free: each branch over the pitch grid
            for base, r_signed, sign in branches:
                phi = np.arctan2(sign * np.cos(phis), -np.sin(phis))  # as above, over the pitch grid
                for elbow in (1.0, -1.0):
                    s, e, w, ok = self._planar(r_signed, z, phi, elbow)
                    qs = self._branch_q(_wrap(base), s, e, w, want_roll, grip)
                    any_reach |= bool(ok.any())
                    reachable.append(qs[ok])
                    ok &= self._in_limits(qs)
                    # the preferred pitch itself when this branch can hold it, else a grid sample
                    exact = self._planar(r_signed, z, np.arctan2(sign * np.cos([pref]), -np.sin([pref])), elbow)
                    qe = self._branch_q(_wrap(base), *exact[:3], want_roll, grip)
                    alts = [(qe[0], pref)] if exact[3][0] and self._in_limits(qe)[0] else []
                    if ok.any():  # fallback, should the preferred pitch fail the final check
                        k = _pick_index(phis, ok, pref)
                        alts.append((qs[k], float(phis[k])))
                    if alts:
                        cands.append(alts)

        if not cands:
            if not any_reach:
                if pitch is not None:
                    phi0 = math.atan2(math.cos(pitch), -math.sin(pitch))
                    tdir = phi0 - self.a0 + self.t4
                    dw = math.hypot(rho - self.l4 * math.sin(tdir), z - self.l4 * math.cos(tdir))
                    far = dw > self.l2 + self.l3
                    raise UnreachableError(
                        f"{where} cannot be reached with pitch {math.degrees(pitch):.1f} deg: the wrist axis would be "
                        f"{dw:.3f} m from the shoulder axis, {'beyond' if far else 'inside'} the "
                        f"{(self.l2 + self.l3) if far else abs(self.l2 - self.l3):.3f} m the upper arm and forearm "
                        f"{'reach' if far else 'can fold to'}",
                        "out_of_reach", "try another pitch or leave the pitch free")
                raise UnreachableError(f"{where} is out of reach at every tool pitch", "out_of_reach")
            what = f"with pitch {math.degrees(pitch):.1f} deg " if pitch is not None else "at any pitch "
            raise UnreachableError(
                f"{where} is within reach but not {what}within the joint limits: "
                + self._violation(_first_nonempty(np.concatenate(reachable[:len(reachable) // 2]), np.concatenate(reachable[len(reachable) // 2:]))),
                "joint_limit", "try another pitch, or move the target")

        # Polish on the true FK and verify.
        out: list[np.ndarray] = []
        for alts in cands:
            for q, q_pitch in alts:
                q2 = self._finish(q, q_pitch, p, rot, u_h, qr, check_pitch=pitch is not None and rot is None)
                if q2 is not None:
                    out.append(q2)
                    break
        out = _dedupe(out, self.arm)
        if not out:
            raise UnreachableError(f"{where}: no branch survived the FK check (numerically at the edge of a limit)",
                                   "joint_limit", "move the target slightly inward")
        return out

    def _finish(self, q: np.ndarray, q_pitch: float, p: np.ndarray, rot: np.ndarray | None, u_h: np.ndarray,
                qr: np.ndarray | None, check_pitch: bool) -> np.ndarray | None:
        """Polish a closed-form candidate on the true FK, fit it into the limits and verify it (or None)."""
        robot = self.robot
        if rot is not None:  # the roll that turns the tool onto the target about its approach axis
            m = robot.kin.fk(q)[:3, :3].T @ rot
            q = q.copy()
            q[self.arm[4]] = math.atan2(m[2, 1], m[1, 1])
        return self._verify(_fit_limits(robot, self._polish(q, p, rot, u_h, q_pitch), qr), p, rot, u_h, q_pitch,
                            check_pitch)

    def _verify(self, q: np.ndarray | None, p: np.ndarray, rot: np.ndarray | None, u_h: np.ndarray, q_pitch: float,
                check_pitch: bool) -> np.ndarray | None:
        """The FK check of a polished, fitted candidate (None passes through): ``q`` if it meets the tolerances."""
        if q is None:
            return None
        t = self.robot.kin.fk(q)
        if np.linalg.norm(t[:3, 3] - p) > POS_TOL:
            return None
        if rot is not None and _rot_angle(rot.T @ t[:3, :3]) > ORI_TOL:
            return None
        if check_pitch and abs(_wrap(_pitch_of(t, u_h) - q_pitch)) > ORI_TOL:
            return None
        return q

    def line(self, points: np.ndarray, pitch: float, roll: float | None, q0: np.ndarray) -> list[list | None]:
        """``solve`` (pitch held, no ``rpy``) for every point of ``points`` (n, 3) m, batched, for ``LineIK``.

        Per point: None (solve it alone: on the base axis, beyond the reach, roll outside its range), or
        ``solve``'s branches in its order as (q, u_h, done): ``done`` q is polished, fitted into the limits
        and FK-checked (a branch that fails is left out); otherwise q is only polished, because its limit
        fit depends on the reference (``_fit_limits`` has two representatives to choose from). The
        reference is assumed to carry ``q0``'s gripper value and, ``roll`` None, its wrist roll. Every
        number is computed as ``solve`` computes it (elementwise, or per row of one batched kernel call).
        """
        robot = self.robot
        n = len(points)
        out: list[list | None] = [None] * n
        ri = self.arm[4]
        if roll is not None:
            want_roll = float(roll)
            if not robot.lower[ri] - 1e-9 <= want_roll <= robot.upper[ri] + 1e-9:
                return out
        else:
            want_roll = float(q0[ri])
        grip = _gripper_value(robot, q0)
        rows, rhos, zs, azs = [], [], [], []
        for i, p in enumerate(points):  # solve's scalar prologue, point by point
            rel = p.copy()
            rel[:2] -= self.base_xy
            rho = float(np.hypot(rel[0], rel[1]))
            z = float(p[2] - self.z_s)
            if math.hypot(rho, z) > self.reach + 1e-6 or rho < 1e-9:
                continue
            rows.append(i)
            rhos.append(rho)
            zs.append(z)
            azs.append(math.atan2(rel[1], rel[0]))
        if not rows:
            return out
        m = len(rows)
        u_h = np.zeros((m, 3))
        u_h[:, 0] = [math.cos(a) for a in azs]
        u_h[:, 1] = [math.sin(a) for a in azs]
        sign = np.array([1.0, 1.0, -1.0, -1.0])
        phis = np.array([float(pitch)])
        phi = np.arctan2(sign * np.cos(phis), -np.sin(phis))
        s, e, w, ok = self._planar(np.array(rhos)[:, None] * sign, np.array(zs)[:, None], phi,
                                   np.array([1.0, -1.0, 1.0, -1.0]))
        base = _wrap(np.array([[a, a, a + math.pi, a + math.pi] for a in azs]))
        qs = self._branch_q(base.ravel(), s.ravel(), e.ravel(), w.ravel(), want_roll, grip)
        ok = ok.ravel() & self._in_limits(qs)
        sel = np.flatnonzero(ok)  # sample-major, branch order within a sample: solve's order
        owner = sel // 4
        pts = points[np.array(rows)][owner]
        uh = u_h[owner]
        kin = self.robot.kin

        def res(qq: np.ndarray, act: np.ndarray, k1: int) -> np.ndarray:
            t = kin.frames4(qq)[:, kin.tcp_index]
            a = t[:, :3, 0]
            u = np.repeat(uh[act], k1, axis=0)
            dot = a[:, 0] * u[:, 0] + a[:, 1] * u[:, 1] + a[:, 2] * u[:, 2]  # _pitches' a @ u_h, summed in its order
            return np.column_stack([t[:, :3, 3] - np.repeat(pts[act], k1, axis=0),
                                    _wrap(np.arctan2(-a[:, 2], dot) - pitch)])

        pol = _newton_rows(res, qs[sel], self.arm[:4])
        fit, amb = _fit_limits_rows(robot, pol)
        good = ~amb & ~np.isnan(fit[:, 0])
        passed = np.zeros(len(sel), dtype=bool)
        if np.any(good):
            g = np.flatnonzero(good)
            t = kin.frames4(fit[g])[:, kin.tcp_index]
            d = t[:, :3, 3] - pts[g]
            perr = np.sqrt(np.sum(d * d, axis=1))
            a = t[:, :3, 0]
            perr_p = np.abs(_wrap(np.arctan2(-a[:, 2], a[:, 0] * uh[g, 0] + a[:, 1] * uh[g, 1] + a[:, 2] * uh[g, 2])
                                  - pitch))
            passed[g] = (perr <= POS_TOL) & (perr_p <= ORI_TOL)
            # near a tolerance the last bit matters: the scalar check decides, as in solve
            for j in np.flatnonzero((np.abs(perr - POS_TOL) < 1e-3 * POS_TOL) | (np.abs(perr_p - ORI_TOL) < 1e-3 * ORI_TOL)):
                i = g[j]
                passed[i] = self._verify(fit[i], pts[i], None, uh[i], float(pitch), True) is not None
        lists: dict[int, list] = {}
        for j, o in enumerate(owner):
            lst = lists.setdefault(int(o), [])
            if amb[j]:
                lst.append((pol[j], uh[j], False))
            elif passed[j]:
                lst.append((fit[j], uh[j], True))
        for o in range(m):
            out[rows[o]] = lists.get(o, [])
        return out

    def _polish(self, q: np.ndarray, p: np.ndarray, rot: np.ndarray | None, u_h: np.ndarray,
                pitch: float) -> np.ndarray:
        kin = self.robot.kin
        if rot is not None:
            want = _pitch_of_r(rot, u_h)

            def res(qq):
                t = kin.fk(qq)
                m = rot.T @ t[:, :3, :3]
                return np.column_stack([t[:, :3, 3] - p, _wrap(_pitches(t, u_h) - want),
                                        np.arctan2(m[:, 2, 1] - m[:, 1, 2], m[:, 1, 1] + m[:, 2, 2])])
            return _newton(res, q, self.arm)
        def res(qq):
            t = kin.fk(qq)
            return np.column_stack([t[:, :3, 3] - p, _wrap(_pitches(t, u_h) - pitch)])
        return _newton(res, q, self.arm[:4])


def _first_nonempty(*arrays: np.ndarray) -> np.ndarray:
    """The first array with rows (explain the forward branch before the base-flipped one)."""
    return next((a for a in arrays if len(a)), arrays[-1])


def _pitches(t: np.ndarray, u_h: np.ndarray) -> np.ndarray:
    """Pitch (rad) of the approach axis of a batch of TCP poses (k, 4, 4) against the outward direction."""
    a = t[:, :3, 0]
    return np.arctan2(-a[:, 2], a @ u_h)


def _pitch_of(t: np.ndarray, u_h: np.ndarray) -> float:
    return _pitch_of_r(t[:3, :3], u_h)


def _pitch_of_r(rot: np.ndarray, u_h: np.ndarray) -> float:
    a = rot[:, 0]
    return math.atan2(-a[2], float(np.dot(a, u_h)))


def _pick_index(phis: np.ndarray, ok: np.ndarray, pref: float, margin: float = math.radians(3)) -> int:
    """Index of the sample to use: ``pref`` if feasible, else the nearest feasible one moved inside."""
    d = np.abs(_wrap(phis - pref))
    k = int(np.argmin(np.where(ok, d, np.inf)))
    if d[k] < (phis[1] - phis[0]):
        return k
    # walk inward from the interval edge by the margin (or to the interval's middle if narrower)
    step = int(round(margin / (phis[1] - phis[0])))
    lo = k
    while lo - 1 >= 0 and ok[lo - 1]:
        lo -= 1
    hi = k
    while hi + 1 < len(ok) and ok[hi + 1]:
        hi += 1
    mid = (lo + hi) // 2
    if k == lo:
        return min(k + step, mid) if hi - lo > 0 else k
    return max(k - step, mid)


def takes_pitch(robot: Robot) -> bool:
    """True when every target of the robot's IK has a tool pitch: the RoArm (``roarm5``), whose plans hold
    the default pitch (straight down) and whose pitch is chosen when left out (``pitch: auto``, ``kin ik``)."""
    return (robot.ik or "") == "roarm5"


def accepts_pitch(robot: Robot) -> bool:
    """True when ``solve_ik`` takes ``pitch``/``roll``: the RoArm's closed form and the numerical IK
    (``pitch_aim``); the position-only family ``roarm3`` (three arm joints) does not."""
    return (robot.ik or "") != "roarm3"


def solve_ik_near(robot: Robot, position, q_ref, *, pitch: float | None = None,
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


class LineIK:
    """``solve_ik_near`` along a sampled straight line, with the RoArm's work batched over the samples.

    ``near(k, prev)`` returns exactly ``solve_ik_near(robot, points[k], prev, pitch=pitch, roll=roll)``
    (same solution, same bits, same errors). For the RoArm (``roarm5``) with the pitch held, every sample's
    closed form, limit test and Newton polish run as one batch up front, on the assumption that each
    ``prev`` carries ``q_start``'s gripper value and (roll left out) wrist roll, as ``cartesian_line``'s
    samples do; ``near`` then only picks the branch. A sample the batch cannot settle on its own (on the
    base axis, out of reach, a limit fit that depends on ``prev``) or a ``prev`` that breaks the assumption
    is solved one at a time by ``solve_ik_near`` itself. Other robots and a free pitch: one at a time.

    ``points`` (n, 3) m; ``q_start`` a full configuration; ``pitch``, ``roll`` rad as ``solve_ik``'s.
    """

    def __init__(self, robot: Robot, points: np.ndarray, q_start: np.ndarray, *, pitch: float | None,
                 roll: float | None) -> None:
        self.robot, self.points, self.pitch, self.roll = robot, np.asarray(points, dtype=float), pitch, roll
        self.cands: list[list | None] = [None] * len(self.points)
        self.key: tuple | None = None
        if (robot.ik or "") == "roarm5" and pitch is not None and len(self.points):
            solver = getattr(robot, "_roarm_ik", None)
            if solver is None:
                solver = robot._roarm_ik = _RoarmIK(robot)
            q0 = robot.full_q(np.asarray(q_start, dtype=float))
            self.key = self._key(q0)
            self.cands = solver.line(self.points, float(pitch), roll, q0)

    def _key(self, q: np.ndarray) -> tuple:
        """What of ``prev`` the batch assumed: the gripper value and, roll left out, the wrist roll."""
        robot = self.robot
        grip = _gripper_value(robot, q)
        return (grip, None if self.roll is not None else float(q[robot.arm_indices[4]]))

    def near(self, k: int, prev: np.ndarray) -> np.ndarray:
        robot, p = self.robot, self.points[k]
        cands = self.cands[k]
        qr = robot.full_q(np.asarray(prev, dtype=float))
        if cands is None or self._key(qr) != self.key:
            return solve_ik_near(robot, p, qr, pitch=self.pitch, roll=self.roll)
        solver: _RoarmIK = robot._roarm_ik
        out = []
        for q, u_h, done in cands:  # as _RoarmIK.solve: per branch, polished, fitted and FK-checked
            q2 = q if done else solver._verify(_fit_limits(robot, q, qr), p, None, u_h, float(self.pitch), True)
            if q2 is not None:
                out.append(q2)
        if len(out) == 1:  # one branch (the usual case): nothing to dedupe, sort or pick
            return out[0].copy()  # a fresh array, as solve_ik_near's (the kept ones stay as they are)
        out = _dedupe(out, solver.arm)
        if not out:
            return solve_ik_near(robot, p, qr, pitch=self.pitch, roll=self.roll)  # raises as one solve would
        arm = robot.arm_indices
        out.sort(key=lambda q: float(np.linalg.norm(q[arm] - qr[arm])))  # solve_ik's order, then solve_ik_near's pick
        return min(out, key=lambda s: float(np.max(np.abs(s[arm] - qr[arm])))).copy()


# ----------------------------------------------------------------------------- RoArm-M2 (3 joints)
class _Roarm3IK:
    """Closed-form position IK of a base-yaw + planar-2R arm (the RoArm-M2-S): 3 joints, 3 position
    coordinates, so the tool pitch is whatever the geometry gives (shoulder + elbow), not a choice.

    Geometry from the robot's own frames at q = 0: the shoulder point S (child of the 2nd moving
    joint), the vectors a = elbow - S and b = TCP - elbow in the arm's vertical plane, and each
    joint's turning sense in that plane. The plane must contain the base axis.
    """

    def __init__(self, robot: Robot) -> None:
        from roarmctl.errors import DescriptionError

        self.robot = robot
        self.arm = robot.arm_indices
        if len(self.arm) != 3:
            raise DescriptionError(f"{robot.name}: ik: roarm3 needs 3 arm joints (base, shoulder, elbow), found {len(self.arm)}")
        kin = robot.kin
        f0 = kin.link_frames(robot.full_q(np.zeros(3)))
        moving = [robot.joints[j] for j in kin.tcp_chain_joints if robot.joints[j].kind != "fixed"]
        axes = [f0[kin.link_index[m.child], :3, :3] @ m.axis for m in moving]
        base_pt = f0[kin.link_index[moving[0].child], :3, 3]
        if abs(abs(axes[0][2]) - 1) > 1e-6:
            raise DescriptionError(f"{robot.name}: ik: roarm3 needs a vertical base axis")
        self.sb = float(np.sign(axes[0][2]))
        up = np.array([0.0, 0.0, 1.0])
        n = np.cross(axes[1], up)  # horizontal, in the arm plane
        self.u0 = n / np.linalg.norm(n)
        self.normal = np.cross(self.u0, up)
        sh = f0[kin.link_index[moving[1].child], :3, 3]
        el = f0[kin.link_index[moving[2].child], :3, 3]
        tcp = f0[kin.tcp_index, :3, 3]
        for pt, what in ((sh, "shoulder"), (el, "elbow"), (tcp, "TCP")):
            off = float(np.dot(pt - base_pt, self.normal))
            if abs(off) > 1e-5:
                raise DescriptionError(f"{robot.name}: ik: roarm3 needs the arm's plane to contain the base axis; the "
                                       f"{what} is {off * 1000:.2f} mm off it")
        if abs(float(np.dot(axes[2], self.normal)) ** 2 - 1) > 1e-6:
            raise DescriptionError(f"{robot.name}: ik: roarm3 needs parallel shoulder and elbow axes")
        self.base_xy = base_pt[:2].copy()
        self.s_h = float(np.hypot(*(sh[:2] - base_pt[:2])) * np.sign(np.dot(sh[:2] - base_pt[:2], self.u0[:2]) or 1))
        self.s_z = float(sh[2])
        to2 = lambda v: np.array([float(np.dot(v, self.u0)), float(v[2])])  # noqa: E731
        self.a, self.b = to2(el - sh), to2(tcp - el)
        # +theta about u0 x up (= -normal) turns u toward up; a joint of axis d turns by sign(d . (u x w))
        uxw = np.cross(self.u0, up)
        self.ss, self.se = float(np.sign(np.dot(axes[1], uxw))), float(np.sign(np.dot(axes[2], uxw)))
        self.la, self.lb = float(np.linalg.norm(self.a)), float(np.linalg.norm(self.b))

    def solve(self, p: np.ndarray, qr: np.ndarray | None) -> list[np.ndarray]:
        robot = self.robot
        where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
        rel = p[:2] - self.base_xy
        rho = float(np.hypot(*rel))
        ref_base = float(qr[self.arm[0]]) if qr is not None else 0.0
        az = math.atan2(rel[1], rel[0]) if rho > 1e-9 else math.atan2(*(self._u(ref_base)[1::-1]))
        az0 = math.atan2(self.u0[1], self.u0[0])
        grip = _gripper_value(robot, qr)
        raw, reach = [], False
        for flip in (0.0, math.pi):
            base = _wrap(self.sb * (az + flip - az0))
            t = np.array([(rho if flip == 0 else -rho) - self.s_h, p[2] - self.s_z])
            c = (t @ t - self.la ** 2 - self.lb ** 2) / (2 * self.la * self.lb)
            if abs(c) > 1 + STRETCH_SLACK:
                continue
            reach = True
            off = math.atan2(self.b[1], self.b[0]) - math.atan2(self.a[1], self.a[0])
            for sgn in (1.0, -1.0):
                phi = sgn * math.acos(max(-1.0, min(1.0, c))) - off  # elbow turn in the plane
                rb = np.array([math.cos(phi) * self.b[0] - math.sin(phi) * self.b[1],
                               math.sin(phi) * self.b[0] + math.cos(phi) * self.b[1]])
                v = self.a + rb
                psi = math.atan2(t[1], t[0]) - math.atan2(v[1], v[0])
                q = robot.full_q(np.array([base, _wrap(self.ss * psi), _wrap(self.se * phi)]))
                if grip is not None:
                    q[robot.joint_index(robot.gripper.joint)] = grip
                raw.append(q)
        if not reach:
            raise UnreachableError(f"{where} is out of reach: the shoulder-to-TCP distance is outside "
                                   f"[{abs(self.la - self.lb):.3f}, {self.la + self.lb:.3f}] m", "out_of_reach",
                                   "move the target closer to the arm")

        def res(qq):
            return robot.kin.fk(qq)[:, :3, 3] - p

        out, limit_fail = [], 0
        for q in raw:
            q = _newton(res, q, list(self.arm))
            q2 = _fit_limits(robot, q, qr)
            if q2 is None:
                limit_fail += 1
                continue
            if np.linalg.norm(robot.kin.fk(q2)[:3, 3] - p) <= POS_TOL:
                out.append(q2)
        out = _dedupe(out, list(self.arm))
        if not out:
            if limit_fail:
                raise UnreachableError(f"{where} is within reach but not within the joint limits", "joint_limit",
                                       "move the target")
            raise UnreachableError(f"{where}: no solution passed the FK check", "out_of_reach")
        return out

    def _u(self, base: float) -> np.ndarray:
        c, s = math.cos(self.sb * base), math.sin(self.sb * base)
        return np.array([c * self.u0[0] - s * self.u0[1], s * self.u0[0] + c * self.u0[1], 0.0])


# ----------------------------------------------------------------------------- UR10 (modified DH)
_UR6_ALPHA = (0.0, math.pi / 2, 0.0, 0.0, -math.pi / 2, math.pi / 2)  # modified-DH alpha_{i-1} of robots/ur10.yaml


def ur6_params(robot: Robot):
    """(T_base, d1, a2, a3, d4, d5, d6, offsets, T_tool) of a UR-type arm, read from its DH table.

    Either convention is accepted. A standard row i (theta_i, d_i, a_i, alpha_i) is the modified
    row i+1's (a_i, alpha_i) (Rx and Tx commute), the last row's (a_6, alpha_6) going into the tool.
    Link twists of the opposite sign to the bundled ur10.yaml (modified alpha = 0, 90, 0, 0, -90, 90
    deg) are turned into it by adding pi to the joint angles on both sides of that twist
    (Rz(pi) Rx(alpha) Tx(a) Rz(pi) = Rx(-alpha) Tx(-a)). Anything else raises ``DescriptionError``.
    Lengths in metres, angles in radians; ``offsets`` (6,) map q to the model's theta = q + offset.
    """
    from roarmctl.errors import DescriptionError

    where = f"{robot.name} (singularity_model/ik: ur6)"
    if robot.dh is None:
        raise DescriptionError(f"{where}: the ur6 model needs a DH table ('dh:' rows), this robot has none",
                               "describe the arm as a DH table or drop singularity_model/ik: ur6")
    convention, rows = robot.dh
    if len(rows) != 6 or any(r["kind"] != "revolute" for r in rows):
        raise DescriptionError(f"{where}: dh: needs exactly 6 revolute rows, found {len(rows)}")
    chain = [robot.joints[j] for j in robot.kin.tcp_chain_joints]
    moving = [j for j in chain if j.kind != "fixed"]
    if len(moving) != 6:
        raise DescriptionError(f"{where}: the TCP chain has {len(moving)} moving joints, ur6 needs 6")
    d = [float(r["d"]) for r in rows]
    offs = np.array([float(r["offset"]) for r in rows])
    extra = np.eye(4)
    if convention == "modified":
        al = [float(r["alpha"]) for r in rows]
        a = [float(r["a"]) for r in rows]
    else:
        al = [0.0] + [float(r["alpha"]) for r in rows[:5]]
        a = [0.0] + [float(r["a"]) for r in rows[:5]]
        extra = transform((rows[5]["a"], 0, 0)) @ transform(rpy=(rows[5]["alpha"], 0, 0))
    for k in range(6):
        if abs(_wrap(al[k] - _UR6_ALPHA[k])) < 1e-6:
            continue
        if k > 0 and _UR6_ALPHA[k] != 0 and abs(_wrap(al[k] + _UR6_ALPHA[k])) < 1e-6:
            al[k], a[k] = -al[k], -a[k]
            offs[k - 1] += math.pi
            offs[k] += math.pi
            continue
        raise DescriptionError(
            f"{where}: dh[{k if convention == 'modified' else k - 1}].alpha: a twist of "
            f"{math.degrees(al[k]):.1f} deg does not fit the UR structure (twists 0, +-90, 0, 0, -+90, +-90 deg "
            f"in modified DH)", "use another singularity_model/ik, or none (numerical IK)")
    for k in (0, 1, 4, 5):
        if abs(a[k]) > 1e-9:
            raise DescriptionError(f"{where}: a link length a_{k} = {a[k]:.4g} m where the UR structure has 0 "
                                   f"(shoulder, elbow and wrist axes must meet as in a UR arm)")
    first, last = chain.index(moving[0]), chain.index(moving[-1])
    t_base = np.eye(4)
    for j in chain[:first]:
        t_base = t_base @ j.origin
    t_tool = extra
    for j in chain[last + 1:]:
        t_tool = t_tool @ j.origin
    # d2 and d3 shift the planar arm sideways like d4 does (z2, z3, z4 are parallel)
    return t_base, d[0], a[2], a[3], d[1] + d[2] + d[3], d[4], d[5], offs, t_tool


def _ur6_solve(robot: Robot, p: np.ndarray, rot: np.ndarray, qr: np.ndarray | None) -> list[np.ndarray]:
    """Every analytic IK solution (up to 8) of the UR10 (modified DH table of robots/ur10.yaml).

    Derivation for these frames (0T6 from 1.3): the flange z-axis z6 = (r13, r23, r33), so the wrist
    point p5 = p - d6 z6 satisfies p5x s1 - p5y c1 = d4 (joints 2-4 move in a plane at offset d4),
    giving theta1 = psi + asin(d4/rho) or psi + pi - asin(d4/rho). Row 2 of 1T6 is
    (c6 s5, -s6 s5, -c5, ...), so c5 = r13 s1 - r23 c1 (theta5 = +-acos) and, for s5 != 0,
    theta6 = atan2(-(r22 c1 - r12 s1)/s5, (r21 c1 - r11 s1)/s5). Row 3 gives c234 = r31 s6 + r32 c6
    and s234 = r33 s5 + c5 (r31 c6 - r32 s6). The planar 2R then has
    F2 = p5x c1 + p5y s1 + d5 s234 = a2 c2 + a3 c23 and F3 = p5z - d1 - d5 c234 = a2 s2 + a3 s23.
    At s5 = 0 (wrist singular) theta6 is free: we keep q_ref's (or 0).
    """
    t_base, d1, a2, a3, d4, d5, d6, offs, t_tool = ur6_params(robot)
    target = np.eye(4)
    target[:3, :3], target[:3, 3] = rot, p
    t = np.linalg.inv(t_base) @ target @ np.linalg.inv(t_tool)
    r, pp = t[:3, :3], t[:3, 3]
    p5 = pp - d6 * r[:, 2]
    rho = math.hypot(p5[0], p5[1])
    where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
    if rho < abs(d4) - 1e-9:
        raise UnreachableError(f"{where}: the wrist point is {rho:.4f} m from the base axis, closer than the "
                               f"shoulder offset d4 = {d4:.4f} m", "out_of_reach")
    psi = math.atan2(p5[1], p5[0])
    asn = math.asin(max(-1.0, min(1.0, d4 / rho))) if rho > 0 else 0.0
    ref = qr[robot.arm_indices] + 0.0 if qr is not None else np.zeros(6)
    raw: list[np.ndarray] = []
    planar_fail = 0
    for th1 in (psi + asn, psi + math.pi - asn):
        c1, s1 = math.cos(th1), math.sin(th1)
        c5 = max(-1.0, min(1.0, r[0, 2] * s1 - r[1, 2] * c1))
        for th5 in (math.acos(c5), -math.acos(c5)):
            s5 = math.sin(th5)
            w2, v3 = p5[0] * c1 + p5[1] * s1, p5[2] - d1
            if abs(s5) > WRIST_SINGULAR:
                th6 = math.atan2(-(r[1, 1] * c1 - r[0, 1] * s1) / s5, (r[1, 0] * c1 - r[0, 0] * s1) / s5)
                c6, s6 = math.cos(th6), math.sin(th6)
                c234 = r[2, 0] * s6 + r[2, 1] * c6
                s234 = r[2, 2] * s5 + c5 * (r[2, 0] * c6 - r[2, 1] * s6)
                th234 = math.atan2(s234, c234)
            else:  # wrist singular: only theta234 +- theta6 is fixed; pick theta234 (see _ur6_wrist)
                th5 = 0.0 if c5 > 0 else math.pi
                gam = math.atan2(r[2, 0], r[2, 1])  # c5 = 1: theta234 + theta6; c5 = -1: theta6 - theta234
                th234 = _ur6_wrist(w2, v3, a2, a3, d5, (gam - (ref[5] + offs[5])) if c5 > 0 else (ref[5] + offs[5] - gam))
                th6 = gam - th234 if c5 > 0 else gam + th234
                s234, c234 = math.sin(th234), math.cos(th234)
            f2 = w2 + d5 * s234
            f3 = v3 - d5 * c234
            c3 = (f2 * f2 + f3 * f3 - a2 * a2 - a3 * a3) / (2 * a2 * a3)
            if abs(c3) > 1 + 1e-9:
                planar_fail += 1
                continue
            c3 = max(-1.0, min(1.0, c3))
            for th3 in (math.acos(c3), -math.acos(c3)):
                th2 = math.atan2(f3, f2) - math.atan2(a3 * math.sin(th3), a2 + a3 * math.cos(th3))
                th4 = th234 - th2 - th3
                raw.append(np.array([th1, th2, th3, th4, th5, th6]) - offs)
    if not raw:
        raise UnreachableError(f"{where} is out of reach: the elbow cannot span the distance to the wrist point",
                               "out_of_reach")
    arm = robot.arm_indices
    grip = _gripper_value(robot, qr)

    def res(qq):  # position error and the small-angle rotation error (vee of the skew part)
        tt = robot.kin.fk(qq)
        m = rot.T @ tt[:, :3, :3]
        w = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
        return np.column_stack([tt[:, :3, 3] - p, w])

    out, limit_fail = [], 0
    for qa in raw:
        q = robot.full_q(_wrap(qa))
        if grip is not None:
            q[robot.joint_index(robot.gripper.joint)] = grip
        q = _newton(res, q, arm, iters=4)
        q2 = _fit_limits(robot, q, qr)
        if q2 is None:
            limit_fail += 1
            continue
        tt = robot.kin.fk(q2)
        if np.linalg.norm(tt[:3, 3] - p) <= POS_TOL and _rot_angle(rot.T @ tt[:3, :3]) <= ORI_TOL:
            out.append(q2)
    out = _dedupe(out, arm)
    if not out:
        if limit_fail:
            raise UnreachableError(f"{where}: every analytic solution violates a joint limit", "joint_limit")
        raise UnreachableError(f"{where}: no analytic solution passed the FK check", "out_of_reach")
    return out


def _ur6_wrist(w: float, v: float, a2: float, a3: float, d5: float, pref: float) -> float:
    """theta234 at a wrist singularity: nearest to ``pref`` such that the elbow can span the wrist.

    With F2 = w + d5 sin(t), F3 = v - d5 cos(t): F2^2 + F3^2 = w^2 + v^2 + d5^2 + 2 d5 (w sin t - v cos t)
    must lie in [(a2 - a3)^2, (a2 + a3)^2]. At the reach boundary (seed case B) one t remains, an
    extremum of that sinusoid, so the extrema join the sampled candidates.
    """
    xi = math.atan2(-v, w)  # w sin t - v cos t = R sin(t + xi)... written as R cos(t - (pi/2 - xi))
    ts = np.concatenate([np.linspace(-math.pi, math.pi, 3601), [math.pi / 2 - xi, -math.pi / 2 - xi]])
    f = w * w + v * v + d5 * d5 + 2 * d5 * (w * np.sin(ts) - v * np.cos(ts))
    tol = 1e-9 * (a2 + a3) ** 2
    ok = (f <= (a2 + a3) ** 2 + tol) & (f >= (a2 - a3) ** 2 - tol)
    if not ok.any():
        return pref
    if ok[:-2].any() and np.isclose(_wrap(ts[np.argmin(np.where(ok, np.abs(_wrap(ts - pref)), np.inf))] - pref), 0, atol=1e-3):
        return float(pref)
    return float(ts[np.argmin(np.where(ok, np.abs(_wrap(ts - pref)), np.inf))])


# ----------------------------------------------------------------------------- damped least squares
def _chain_reach(robot: Robot) -> tuple[np.ndarray, float]:
    """A point on the first joint's axis (root frame) and an upper bound of the TCP's distance to it (m)."""
    kin = robot.kin
    q0 = robot.full_q(np.clip(np.zeros(robot.arm_dof), robot.lower[robot.arm_indices], robot.upper[robot.arm_indices]))
    frames = kin.link_frames(q0)
    chain = kin.tcp_chain_joints
    movable = [j for j in chain if robot.joints[j].kind != "fixed"]
    first = movable[0]
    j0 = robot.joints[first]
    start = (frames[kin._parent[first]] @ j0.origin)[:3, 3]
    pts = [start] + [frames[kin._child[j]][:3, 3] for j in chain[chain.index(first):]]
    reach = float(sum(np.linalg.norm(b - a) for a, b in zip(pts[:-1], pts[1:])))
    for j in movable:
        jt = robot.joints[j]
        if jt.kind == "prismatic":
            i = robot.joint_index(jt.name)
            reach += max(abs(robot.lower[i]), abs(robot.upper[i]))
    return start, reach


DLS_CHUNKS = (1, 16, 16, 16)  # starts per batch: the reference alone, then random starts 16 at a time
DLS_POS_DONE = 0.1 * POS_TOL  # m: a start has converged within this (and ORI_TOL); the FK check allows POS_TOL
DLS_ENOUGH = 8  # all_solutions: distinct solutions after which no further batch of starts is run


@dataclass
class _Aim:
    """What the numerical IK aims at besides the position: nothing, a full TCP rotation ``rot`` (3, 3),
    or the approach axis (TCP +x) along the unit vector ``axis`` (3,) with the turn about it left free."""

    rot: np.ndarray | None = None
    axis: np.ndarray | None = None
    what: str = "the requested orientation"

    @property
    def oriented(self) -> bool:
        return self.rot is not None or self.axis is not None

    def key(self) -> tuple:
        return (None if self.rot is None else self.rot.tobytes(), None if self.axis is None else self.axis.tobytes())


def _base_point(robot: Robot) -> tuple[np.ndarray, float]:
    """``_chain_reach`` once per loaded robot (the point on the first joint's axis, the reach bound)."""
    got = getattr(robot, "_dls_reach", None)
    if got is None:
        got = robot._dls_reach = _chain_reach(robot)
    return got


def pitch_aim(robot: Robot, p: np.ndarray, pitch: float, roll: float | None, qr: np.ndarray | None) -> _Aim:
    """The numerical IK's target orientation for a tool ``pitch`` (and ``roll``), rad, at position ``p``.

    As for the RoArm: the approach axis (TCP +x) at ``pitch`` below the horizontal, in the vertical plane
    through the base axis (the vertical line through the first moving joint) and the target, pointing away
    from the base at 0. On the base axis "away" is the horizontal part of the reference's approach axis
    (``qr``, else the home pose; world +x when that is vertical). ``roll`` turns the tool about the approach
    axis, right-handed, from the pose whose +y axis is horizontal, z_up x away (the RoArm's wrist-roll
    joint value has that meaning); left out, the turn is free.
    """
    base, _ = _base_point(robot)
    rel = np.array([p[0] - base[0], p[1] - base[1], 0.0])
    if math.hypot(rel[0], rel[1]) < 1e-9:
        ref = qr if qr is not None else _default_ref(robot)
        rel = robot.kin.fk(ref)[:3, 0].copy()
        rel[2] = 0.0
        if math.hypot(rel[0], rel[1]) < 1e-9:
            rel = np.array([1.0, 0.0, 0.0])
    u_h = rel / np.linalg.norm(rel)
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(pitch) * u_h - math.sin(pitch) * up
    what = f"tool pitch {math.degrees(pitch):.1f} deg"
    if roll is None:
        return _Aim(axis=d, what=what)
    y0 = np.cross(up, u_h)
    y = math.cos(roll) * y0 + math.sin(roll) * np.cross(d, y0)
    return _Aim(rot=np.column_stack([d, y, np.cross(d, y)]), what=f"{what}, roll {math.degrees(roll):.1f} deg")


def _dls_solve(robot: Robot, p: np.ndarray, rot: np.ndarray | None, qr: np.ndarray | None,
               all_solutions: bool, restarts: int | None = None, seed: int = 0,
               aim: _Aim | None = None) -> list[np.ndarray]:
    """Damped least squares from ``q_ref`` (or home), then seeded random starts within the limits.

    The starts run as batches (``DLS_CHUNKS``: the reference alone, then 16 at a time); the search stops
    at the first batch with a solution (one wanted), or when ``DLS_ENOUGH`` distinct solutions are found
    or a batch adds none (``all_solutions``). ``aim`` replaces ``rot`` (e.g. an approach axis only).
    Every returned solution is within the limits and FK-checked (``POS_TOL``, ``ORI_TOL``).
    """
    aim = aim or _Aim(rot=rot)
    where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
    start, reach = _base_point(robot)
    dist = float(np.linalg.norm(p - start))
    if dist > reach + 1e-12:
        raise UnreachableError(f"{where} is {dist:.3f} m from the first joint; the arm reaches {reach:.3f} m",
                               "out_of_reach", "move the target closer to the arm")
    arm = robot.arm_indices
    lo, hi = robot.lower[arm], robot.upper[arm]
    rng = np.random.default_rng(seed)
    n_starts = restarts if restarts is not None else (48 if all_solutions else 24)
    starts = np.concatenate([[qr if qr is not None else _default_ref(robot)],
                             robot.full_q(rng.uniform(lo, hi, size=(n_starts, len(arm))))]).astype(float)
    grip = _gripper_value(robot, qr)
    if grip is not None:
        starts[:, robot.joint_index(robot.gripper.joint)] = grip
    # Rows after the reference start do not depend on q_ref (same seed, same random starts), so their
    # outcome is kept per robot: a target asked again from another reference (each candidate of a chain
    # in the planner, each pitch of pitch: auto) costs its reference start only. Same results.
    memo = robot.__dict__.setdefault("_dls_memo", {})
    if len(memo) > 2048:
        memo.clear()
    key = (p.tobytes(), seed, n_starts, grip)

    def run(k: int, size: int, a: _Aim, limited: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        bounds = (lo, hi) if limited else (None, None)
        parts = []
        if k == 0:
            parts.append(_dls_batch(robot, starts[:1], p, a, *bounds))
            k, size = 1, size - 1
        if size > 0 and k < len(starts):
            mk = key + (a.key(), limited, k, size)
            if mk not in memo:
                memo[mk] = _dls_batch(robot, starts[k:k + size], p, a, *bounds)
            parts.append(memo[mk])
        return tuple(np.concatenate(x) for x in zip(*parts))

    sols: list[np.ndarray] = []
    k = 0
    for size in list(DLS_CHUNKS) + [16] * len(starts):
        if k >= len(starts):
            break
        q, ep, eo = run(k, size, aim, True)
        k += size
        before = len(sols)
        sols = _dedupe(sols + _dls_accept(robot, q, ep, eo, p, aim, qr), arm, tol=1e-4)
        if sols and (not all_solutions or len(sols) >= DLS_ENOUGH or len(sols) == before):
            break
    if sols:
        return sols if all_solutions else sols[:1]  # one: the first start (in start order) that converged
    # Why not? Try again without limits: a solution with a 2 pi representative within them is one
    # (a clipped joint can stop the search short of it), else the limits are the reason (joint_limit);
    # then position only (orientation).
    q, ep, eo = run(0, 8, aim, False)
    sols = _dedupe(_dls_accept(robot, q, ep, eo, p, aim, qr), arm, tol=1e-4)
    if sols:
        return sols if all_solutions else sols[:1]
    if np.any((ep <= POS_TOL) & (eo <= ORI_TOL)):
        raise UnreachableError(f"{where} is only reachable outside the joint limits", "joint_limit",
                               "move the target or widen the limits in the description")
    if aim.oriented:
        q, ep, eo = run(0, 8, _Aim(), True)
        if np.any(ep <= POS_TOL):
            raise UnreachableError(f"{where}: the position is reachable but not with {aim.what}",
                                   "orientation", "relax the orientation or give the position only")
        q, ep, eo = run(0, 8, _Aim(), False)
        if np.any(ep <= POS_TOL):
            raise UnreachableError(f"{where}: the position alone is only reachable outside the joint limits",
                                   "joint_limit", "move the target or widen the limits in the description")
    best_free = float(np.min(ep))
    raise UnreachableError(f"{where} is out of reach (closest approach {best_free * 1000:.1f} mm)",
                           "out_of_reach", "move the target closer to the arm")


def _dls_accept(robot: Robot, q: np.ndarray, ep: np.ndarray, eo: np.ndarray, p: np.ndarray, aim: _Aim,
                qr: np.ndarray | None) -> list[np.ndarray]:
    """The converged rows of a DLS batch (start order) as solutions: each joint moved by 2 pi to the
    representative within its limits nearest to ``qr`` (or 0), then checked by FK against the tolerances.

    Converged: a tenth of ``POS_TOL`` and ``ORI_TOL`` (an orientation a rounded URDF cannot hold exactly,
    1.57079 written for pi/2 tilting an axis by 3 urad, stays a few urad off however long the search runs)."""
    out = []
    for i in np.flatnonzero((ep <= DLS_POS_DONE) & (eo <= ORI_TOL)):
        f = _fit_limits(robot, q[i], qr)
        if f is not None and robot.within_limits(f) and _dls_error_ok(robot, f, p, aim):
            out.append(f)
    return out


def _dls_error_ok(robot: Robot, q: np.ndarray, p: np.ndarray, aim: _Aim) -> bool:
    """The FK check of one returned solution: position within POS_TOL, orientation within ORI_TOL."""
    t = robot.kin.fk(q)
    if np.linalg.norm(t[:3, 3] - p) > POS_TOL:
        return False
    if aim.rot is not None:
        return _rot_angle(aim.rot.T @ t[:3, :3]) <= ORI_TOL
    if aim.axis is not None:
        a = t[:3, 0]
        return math.atan2(float(np.linalg.norm(np.cross(a, aim.axis))), float(a @ aim.axis)) <= ORI_TOL
    return True


def _dls_batch(robot: Robot, q: np.ndarray, p: np.ndarray, aim: _Aim, lo: np.ndarray | None,
               hi: np.ndarray | None, iters: int = 150) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Damped least squares from each start of ``q`` (N, dof) at once; each row runs as it would alone.

    Per row and iteration: the error e (position, and the orientation as a rotation vector: the full
    rotation error, or for an approach axis the turn that brings TCP +x onto it, with the Jacobian's
    rotation about TCP +x projected out), the step dq = J^T (J J^T + lam^2 I)^-1 e with lam 1e-2, and
    1e-3 once |e| < 1 mm (not less: a direction the target barely constrains, such as a wrist roll about
    an approach axis that a rounded URDF tilts by a few urad, would swing by radians chasing that urad),
    scaled to at most 0.5 rad; joints with a full turn of range wrap, the rest are clipped. A row stops
    when |e| < 1e-12, when it is within ``DLS_POS_DONE`` and ``ORI_TOL`` and the last step no longer
    halved |e| (the floor a rounded model leaves), or when |e| fell by less than 10 % over 25 iterations
    or by less than 0.1 % over 5 (stalled at a limit or a local minimum: the next start tries). Returns the final configurations (N, dof), position
    errors (N,) m and orientation errors (N,) rad, by FK.
    """
    arm = np.asarray(robot.arm_indices)
    kin = robot.kin
    q = np.array(q, dtype=float)
    n = len(q)
    active = np.arange(n)
    hist = np.zeros((iters, n))
    wrap = None if lo is None else (hi - lo) >= 2 * np.pi - 1e-3
    for it in range(iters):
        if not len(active):
            break
        t, jac = kin.pose_jacobian(q[active])
        e = p - t[:, :3, 3]
        ep = np.linalg.norm(e, axis=1)
        if aim.oriented:
            w, jac = _orientation_error(t[:, :3, :3], jac, aim)
            eo = np.linalg.norm(w, axis=1)
            e = np.concatenate([e, w], axis=1)
        else:
            eo = np.zeros(len(active))
            jac = jac[:, :3]
        norm = np.linalg.norm(e, axis=1)
        stop = (ep < 1e-12) & (eo < 1e-12)
        hist[it, active] = norm
        if it >= 1:  # converged as far as the model allows: within the tolerances and no longer improving
            stop |= (ep <= DLS_POS_DONE) & (eo <= ORI_TOL) & (norm > 0.5 * hist[it - 1, active])
        if it >= 25:  # stalled: history[-25] is 24 iterations back
            stop |= norm > 0.9 * hist[it - 24, active]
        if it >= 10:  # stuck: not 0.1 % better than 5 iterations ago (a local minimum; saves the wait above)
            stop |= norm > 0.999 * hist[it - 5, active]
        go = ~stop
        rows = active[go]
        jac, e, norm = jac[go], e[go], norm[go]
        lam2 = np.where(norm > 1e-3, 1e-4, 1e-6)
        jjt = jac @ jac.transpose(0, 2, 1) + lam2[:, None, None] * np.eye(jac.shape[1])
        dq = np.einsum("nji,nj->ni", jac, np.linalg.solve(jjt, e[:, :, None])[:, :, 0])
        m = np.max(np.abs(dq), axis=1)
        big = m > 0.5
        dq[big] *= (0.5 / m[big])[:, None]
        qa = q[rows][:, arm] + dq
        if lo is not None:
            v = _wrap(qa[:, wrap])
            qa[:, wrap] = np.where(v < lo[wrap], v + 2 * np.pi, np.where(v > hi[wrap], v - 2 * np.pi, v))
            qa = np.clip(qa, lo, hi)
        q[rows[:, None], arm] = qa
        active = rows
    t = kin.frames4(q)[:, kin.tcp_index]
    ep = np.linalg.norm(p - t[:, :3, 3], axis=1)
    if aim.rot is not None:
        eo = np.array([_rot_angle(aim.rot.T @ r) for r in t[:, :3, :3]])
    elif aim.axis is not None:
        a = t[:, :3, 0]
        eo = np.arctan2(np.linalg.norm(np.cross(a, aim.axis), axis=1), a @ aim.axis)
    else:
        eo = np.zeros(n)
    return q, ep, eo


def _orientation_error(r: np.ndarray, jac: np.ndarray, aim: _Aim) -> tuple[np.ndarray, np.ndarray]:
    """Rotation-vector errors (N, 3) of TCP rotations ``r`` (N, 3, 3) against ``aim`` and the matching
    Jacobians (N, 6, k): unchanged for a full rotation, angular rows projected off TCP +x for an axis."""
    if aim.rot is not None:
        m = aim.rot @ r.transpose(0, 2, 1)
        vee = np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
        ang = np.arctan2(0.5 * np.linalg.norm(vee, axis=1), 0.5 * (np.trace(m, axis1=1, axis2=2) - 1.0))
        w = np.where((ang < 1e-9)[:, None], 0.5 * vee, vee * (ang / (2.0 * np.sin(np.maximum(ang, 1e-9))))[:, None])
        for i in np.flatnonzero(ang > math.pi - 1e-6):  # near pi: the axis from the symmetric part
            w[i] = _rot_vec(m[i])
        return w, jac
    a = r[:, :, 0]
    c = cross_rows(a, aim.axis)
    s = np.sqrt(np.einsum("ij,ij->i", c, c))
    ang = np.arctan2(s, a @ aim.axis)
    w = np.where((s > 1e-12)[:, None], c * (ang / np.maximum(s, 1e-300))[:, None], c)
    flip = (s <= 1e-12) & (ang > 1.0)  # exactly opposite: turn by pi about any axis normal to TCP +x
    if np.any(flip):
        for i in np.flatnonzero(flip):
            k = int(np.argmin(np.abs(a[i])))
            perp = np.cross(a[i], np.eye(3)[k])
            w[i] = perp / np.linalg.norm(perp) * math.pi
    jw = jac[:, 3:]
    jw = jw - a[:, :, None] * np.einsum("ni,nik->nk", a, jw)[:, None, :]  # (I - a a^T) J_w
    return w, np.concatenate([jac[:, :3], jw], axis=1)
