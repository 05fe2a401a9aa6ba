"""Analytic IK of UR-type 6R arms (family ``ur6``): up to 8 solutions of a full pose, from the arm's DH table."""

from __future__ import annotations

import math

import numpy as np

from roarmctl.errors import DescriptionError, UnreachableError
from roarmctl.robot.ik.common import (
    ORI_TOL,
    POS_TOL,
    dedupe,
    fit_limits,
    gripper_index,
    newton,
    ref_gripper_q,
    rot_angle,
    wrap_angle,
)
from roarmctl.robot.model import Robot, transform

WRIST_SINGULAR = 1e-6  # |sin theta5| below this is the UR wrist singularity (theta4, theta6 coupled)
_UR6_ALPHA = (0.0, math.pi / 2, 0.0, 0.0, -math.pi / 2, math.pi / 2)  # modified-DH alpha_{i-1} of robots/ur10.yaml


def ur6_params(robot: Robot) -> tuple[np.ndarray, float, float, float, float, float, float, np.ndarray, np.ndarray]:
    """(T_base, d1, a2, a3, d4, d5, d6, offsets, T_tool) of a UR-type arm, read from its DH table.

    Either convention is accepted. A standard row i (theta_i, d_i, a_i, alpha_i) is the modified
    row i+1's (a_i, alpha_i) (Rx and Tx commute), the last row's (a_6, alpha_6) going into the tool.
    Link twists of the opposite sign to the bundled ur10.yaml (modified alpha = 0, 90, 0, 0, -90, 90
    deg) are turned into it by adding pi to the joint angles on both sides of that twist
    (Rz(pi) Rx(alpha) Tx(a) Rz(pi) = Rx(-alpha) Tx(-a)). Anything else raises ``DescriptionError``.
    Lengths in metres, angles in radians; ``offsets`` (6,) map q to the model's theta = q + offset.
    """
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
        if abs(wrap_angle(al[k] - _UR6_ALPHA[k])) < 1e-6:
            continue
        if k > 0 and _UR6_ALPHA[k] != 0 and abs(wrap_angle(al[k] + _UR6_ALPHA[k])) < 1e-6:
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


def ur6_solve(robot: Robot, p: np.ndarray, rot: np.ndarray, qr: np.ndarray | None) -> list[np.ndarray]:
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
    grip = ref_gripper_q(robot, qr)

    def res(qq: np.ndarray) -> np.ndarray:  # position error and the small-angle rotation error (vee of the skew part)
        tt = robot.kin.fk(qq)
        m = rot.T @ tt[:, :3, :3]
        w = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
        return np.column_stack([tt[:, :3, 3] - p, w])

    out, limit_fail = [], 0
    for qa in raw:
        q = robot.full_q(wrap_angle(qa))
        if grip is not None:
            q[gripper_index(robot)] = grip
        q = newton(res, q, arm, iters=4)
        q2 = fit_limits(robot, q, qr)
        if q2 is None:
            limit_fail += 1
            continue
        tt = robot.kin.fk(q2)
        if np.linalg.norm(tt[:3, 3] - p) <= POS_TOL and rot_angle(rot.T @ tt[:3, :3]) <= ORI_TOL:
            out.append(q2)
    out = dedupe(out, arm)
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
    if ok[:-2].any() and np.isclose(wrap_angle(ts[np.argmin(np.where(ok, np.abs(wrap_angle(ts - pref)), np.inf))] - pref), 0, atol=1e-3):
        return float(pref)
    return float(ts[np.argmin(np.where(ok, np.abs(wrap_angle(ts - pref)), np.inf))])
