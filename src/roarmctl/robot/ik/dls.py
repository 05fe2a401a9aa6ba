"""Numerical IK for any arm: damped least squares from the reference and seeded random starts, run as batches;
position only, position + approach axis (a tool pitch), or a full pose."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from roarmctl.errors import UnreachableError
from roarmctl.robot.ik.common import (
    ORI_TOL,
    POS_TOL,
    dedupe,
    default_ref,
    fit_limits,
    gripper_index,
    ref_gripper_q,
    rot_angle,
    rot_vec,
    wrap_angle,
)
from roarmctl.robot.kinematics import cross_rows
from roarmctl.robot.model import Robot


def chain_reach(robot: Robot) -> tuple[np.ndarray, float]:
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
    reach = float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(pts)))
    for j in movable:
        jt = robot.joints[j]
        if jt.kind == "prismatic":  # a mimic one moves |multiplier| times its leader's travel
            i = robot.joint_index(jt.mimic or jt.name)
            reach += abs(jt.multiplier) * max(abs(robot.lower[i]), abs(robot.upper[i])) + (abs(jt.offset) if jt.mimic else 0.0)
    return start, reach


DLS_CHUNKS = (1, 16, 16, 16)  # starts per batch: the reference alone, then random starts 16 at a time
DLS_POS_DONE = 0.1 * POS_TOL  # m: a start has converged within this (and ORI_TOL); the FK check allows POS_TOL
DLS_ENOUGH = 8  # all_solutions: distinct solutions after which no further batch of starts is run


@dataclass
class Aim:
    """What the numerical IK aims at besides the position: nothing, a full TCP rotation ``rot`` (3, 3),
    or the approach axis (TCP +x) along the unit vector ``axis`` (3,) with the turn about it left free."""

    rot: np.ndarray | None = None
    axis: np.ndarray | None = None
    what: str = "the requested orientation"

    @property
    def oriented(self) -> bool:
        """Whether there is an orientation to aim at."""
        return self.rot is not None or self.axis is not None

    def key(self) -> tuple:
        """A hashable form (for the per-robot memo of random starts)."""
        return (None if self.rot is None else self.rot.tobytes(), None if self.axis is None else self.axis.tobytes())


def base_point(robot: Robot) -> tuple[np.ndarray, float]:
    """``chain_reach`` once per loaded robot (the point on the first joint's axis, the reach bound)."""
    got = robot.derived.get("dls_reach")
    if got is None:
        got = robot.derived["dls_reach"] = chain_reach(robot)
    return got


def pitch_aim(robot: Robot, p: np.ndarray, pitch: float, roll: float | None, qr: np.ndarray | None) -> Aim:
    """The numerical IK's target orientation for a tool ``pitch`` (and ``roll``), rad, at position ``p``.

    As for the RoArm: the approach axis (TCP +x) at ``pitch`` below the horizontal, in the vertical plane
    through the base axis (the vertical line through the first moving joint) and the target, pointing away
    from the base at 0. On the base axis "away" is the horizontal part of the reference's approach axis
    (``qr``, else the home pose; world +x when that is vertical). ``roll`` turns the tool about the approach
    axis, right-handed, from the pose whose +y axis is horizontal, z_up x away (the RoArm's wrist-roll
    joint value has that meaning); left out, the turn is free.
    """
    base, _ = base_point(robot)
    rel = np.array([p[0] - base[0], p[1] - base[1], 0.0])
    if math.hypot(rel[0], rel[1]) < 1e-9:
        ref = qr if qr is not None else default_ref(robot)
        rel = robot.kin.fk(ref)[:3, 0].copy()
        rel[2] = 0.0
        if math.hypot(rel[0], rel[1]) < 1e-9:
            rel = np.array([1.0, 0.0, 0.0])
    u_h = rel / np.linalg.norm(rel)
    up = np.array([0.0, 0.0, 1.0])
    d = math.cos(pitch) * u_h - math.sin(pitch) * up
    what = f"tool pitch {math.degrees(pitch):.1f} deg"
    if roll is None:
        return Aim(axis=d, what=what)
    y0 = np.cross(up, u_h)
    y = math.cos(roll) * y0 + math.sin(roll) * np.cross(d, y0)
    return Aim(rot=np.column_stack([d, y, np.cross(d, y)]), what=f"{what}, roll {math.degrees(roll):.1f} deg")


def dls_solve(robot: Robot, p: np.ndarray, rot: np.ndarray | None, qr: np.ndarray | None,
               all_solutions: bool, restarts: int | None = None, seed: int = 0,
               aim: Aim | None = None) -> list[np.ndarray]:
    """Damped least squares from ``q_ref`` (or home), then seeded random starts within the limits.

    The starts run as batches (``DLS_CHUNKS``: the reference alone, then 16 at a time); the search stops
    at the first batch with a solution (one wanted), or when ``DLS_ENOUGH`` distinct solutions are found
    or a batch adds none (``all_solutions``). ``aim`` replaces ``rot`` (e.g. an approach axis only).
    Every returned solution is within the limits and FK-checked (``POS_TOL``, ``ORI_TOL``).
    """
    aim = aim or Aim(rot=rot)
    where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
    start, reach = base_point(robot)
    dist = float(np.linalg.norm(p - start))
    if dist > reach + 1e-12:
        raise UnreachableError(f"{where} is {dist:.3f} m from the first joint; the arm reaches {reach:.3f} m",
                               "out_of_reach", "move the target closer to the arm")
    arm = robot.arm_indices
    lo, hi = robot.lower[arm], robot.upper[arm]
    rng = np.random.default_rng(seed)
    n_starts = restarts if restarts is not None else (48 if all_solutions else 24)
    starts = np.concatenate([[qr if qr is not None else default_ref(robot)],
                             robot.full_q(rng.uniform(lo, hi, size=(n_starts, len(arm))))]).astype(float)
    grip = ref_gripper_q(robot, qr)
    if grip is not None:
        starts[:, gripper_index(robot)] = grip
    # Rows after the reference start do not depend on q_ref (same seed, same random starts), so their
    # outcome is kept per robot: a target asked again from another reference (each candidate of a chain
    # in the planner, each pitch of pitch: auto) costs its reference start only. Same results.
    memo = robot.derived.setdefault("dls_memo", {})
    if len(memo) > 2048:
        memo.clear()
    key = (p.tobytes(), seed, n_starts, grip)

    def run(k: int, size: int, a: Aim, limited: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        bounds = (lo, hi) if limited else (None, None)
        parts = []
        if k == 0:
            parts.append(dls_batch(robot, starts[:1], p, a, *bounds))
            k, size = 1, size - 1
        if size > 0 and k < len(starts):
            mk = key + (a.key(), limited, k, size)
            if mk not in memo:
                memo[mk] = dls_batch(robot, starts[k:k + size], p, a, *bounds)
            parts.append(memo[mk])
        q, ep, eo = (np.concatenate(x) for x in zip(*parts))
        return q, ep, eo

    sols: list[np.ndarray] = []
    k = 0
    for size in list(DLS_CHUNKS) + [16] * len(starts):
        if k >= len(starts):
            break
        q, ep, eo = run(k, size, aim, True)
        k += size
        before = len(sols)
        sols = dedupe(sols + _dls_accept(robot, q, ep, eo, p, aim, qr), arm, tol=1e-4)
        if sols and (not all_solutions or len(sols) >= DLS_ENOUGH or len(sols) == before):
            break
    if sols:
        return sols if all_solutions else sols[:1]  # one: the first start (in start order) that converged
    # Why not? Try again without limits: a solution with a 2 pi representative within them is one
    # (a clipped joint can stop the search short of it), else the limits are the reason (joint_limit);
    # then position only (orientation).
    q, ep, eo = run(0, 8, aim, False)
    sols = dedupe(_dls_accept(robot, q, ep, eo, p, aim, qr), arm, tol=1e-4)
    if sols:
        return sols if all_solutions else sols[:1]
    if np.any((ep <= POS_TOL) & (eo <= ORI_TOL)):
        raise UnreachableError(f"{where} is only reachable outside the joint limits", "joint_limit",
                               "move the target or widen the limits in the description")
    if aim.oriented:
        q, ep, eo = run(0, 8, Aim(), True)
        if np.any(ep <= POS_TOL):
            raise UnreachableError(f"{where}: the position is reachable but not with {aim.what}",
                                   "orientation", "relax the orientation or give the position only")
        q, ep, eo = run(0, 8, Aim(), False)
        if np.any(ep <= POS_TOL):
            raise UnreachableError(f"{where}: the position alone is only reachable outside the joint limits",
                                   "joint_limit", "move the target or widen the limits in the description")
    best_free = float(np.min(ep))
    raise UnreachableError(f"{where} is out of reach (closest approach {best_free * 1000:.1f} mm)",
                           "out_of_reach", "move the target closer to the arm")


def _dls_accept(robot: Robot, q: np.ndarray, ep: np.ndarray, eo: np.ndarray, p: np.ndarray, aim: Aim,
                qr: np.ndarray | None) -> list[np.ndarray]:
    """The converged rows of a DLS batch (start order) as solutions: each joint moved by 2 pi to the
    representative within its limits nearest to ``qr`` (or 0), then checked by FK against the tolerances.

    Converged: a tenth of ``POS_TOL`` and ``ORI_TOL`` (an orientation a rounded URDF cannot hold exactly,
    1.57079 written for pi/2 tilting an axis by 3 urad, stays a few urad off however long the search runs)."""
    out = []
    for i in np.flatnonzero((ep <= DLS_POS_DONE) & (eo <= ORI_TOL)):
        f = fit_limits(robot, q[i], qr)
        if f is not None and robot.within_limits(f) and _dls_error_ok(robot, f, p, aim):
            out.append(f)
    return out


def _dls_error_ok(robot: Robot, q: np.ndarray, p: np.ndarray, aim: Aim) -> bool:
    """The FK check of one returned solution: position within POS_TOL, orientation within ORI_TOL."""
    t = robot.kin.fk(q)
    if np.linalg.norm(t[:3, 3] - p) > POS_TOL:
        return False
    if aim.rot is not None:
        return rot_angle(aim.rot.T @ t[:3, :3]) <= ORI_TOL
    if aim.axis is not None:
        a = t[:3, 0]
        return math.atan2(float(np.linalg.norm(np.cross(a, aim.axis))), float(a @ aim.axis)) <= ORI_TOL
    return True


def dls_batch(robot: Robot, q: np.ndarray, p: np.ndarray, aim: Aim, lo: np.ndarray | None,
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
        if lo is not None and hi is not None:
            v = wrap_angle(qa[:, wrap])
            qa[:, wrap] = np.where(v < lo[wrap], v + 2 * np.pi, np.where(v > hi[wrap], v - 2 * np.pi, v))
            qa = np.clip(qa, lo, hi)
        q[rows[:, None], arm] = qa
        active = rows
    t = kin.frames4(q)[:, kin.tcp_index]
    ep = np.linalg.norm(p - t[:, :3, 3], axis=1)
    if aim.rot is not None:
        eo = np.array([rot_angle(aim.rot.T @ r) for r in t[:, :3, :3]])
    elif aim.axis is not None:
        a = t[:, :3, 0]
        eo = np.arctan2(np.linalg.norm(np.cross(a, aim.axis), axis=1), a @ aim.axis)
    else:
        eo = np.zeros(n)
    return q, ep, eo


def _orientation_error(r: np.ndarray, jac: np.ndarray, aim: Aim) -> tuple[np.ndarray, np.ndarray]:
    """Rotation-vector errors (N, 3) of TCP rotations ``r`` (N, 3, 3) against ``aim`` and the matching
    Jacobians (N, 6, k): unchanged for a full rotation, angular rows projected off TCP +x for an axis."""
    if aim.rot is not None:
        m = aim.rot @ r.transpose(0, 2, 1)
        vee = np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
        ang = np.arctan2(0.5 * np.linalg.norm(vee, axis=1), 0.5 * (np.trace(m, axis1=1, axis2=2) - 1.0))
        w = np.where((ang < 1e-9)[:, None], 0.5 * vee, vee * (ang / (2.0 * np.sin(np.maximum(ang, 1e-9))))[:, None])
        for i in np.flatnonzero(ang > math.pi - 1e-6):  # near pi: the axis from the symmetric part
            w[i] = rot_vec(m[i])
        return w, jac
    assert aim.axis is not None  # oriented: a rotation or an axis
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
