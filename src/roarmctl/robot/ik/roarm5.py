"""Closed-form IK of the RoArm-M3 (family ``roarm5``): base yaw, then a planar 3R arm (shoulder, elbow, wrist
pitch) and the wrist roll."""

from __future__ import annotations

import math

import numpy as np

from roarmctl.errors import InputError, UnreachableError
from roarmctl.robot.ik.common import (
    ORI_TOL,
    POS_TOL,
    STRETCH_SLACK,
    TWO_PI_SHIFTS,
    dedupe,
    fit_limits,
    fit_limits_rows,
    gripper_index,
    newton,
    newton_rows,
    ref_gripper_q,
    rot_angle,
    wrap_angle,
)
from roarmctl.robot.ik.pitch import approach_pitches, pick_index, pitch_of, pitch_of_rot
from roarmctl.robot.model import Robot

LIMIT_SLACK = 1e-2  # rad: closed-form candidates this far outside a limit are polished, then re-checked
PITCH_GRID = 721  # pitch samples over [-pi, pi] when the RoArm pitch is left free (0.5 deg)


def roarm5_solver(robot: Robot) -> Roarm5IK:
    """The robot's ``Roarm5IK``, its geometry read once per loaded robot."""
    solver = robot.derived.get("roarm5_ik")
    if solver is None:
        solver = robot.derived["roarm5_ik"] = Roarm5IK(robot)
    return solver


class Roarm5IK:
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

        def polar(v: np.ndarray) -> tuple[float, float]:  # (across=x, along=z) -> (length, angle from vertical)
            return math.hypot(v[0], v[2]), math.atan2(v[0], v[2])

        self.l2, self.t2 = polar(el - sh)
        self.l3, self.t3 = polar(wr - el)
        self.l4, self.t4 = polar(tcp[:3, 3] - wr)
        a0 = tcp[:3, 0]
        self.a0 = math.atan2(a0[0], a0[2])  # approach-axis angle from vertical at q = 0 (0 here)
        self.reach = self.l2 + self.l3 + self.l4

    # -- the planar sub-problem, vectorised over pitch (phi) -------------------------------------
    def _planar(self, r: float | np.ndarray, z: float | np.ndarray, phi: np.ndarray,
                elbow_sign: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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

    def _branch_q(self, base: float | np.ndarray, s: np.ndarray, e: np.ndarray, w: np.ndarray, roll: float,
                  grip: float | None) -> np.ndarray:
        n = np.size(s)
        q = np.zeros((n, self.robot.dof))
        q[:, self.arm[0]] = base
        q[:, self.arm[1]] = s
        q[:, self.arm[2]] = e
        q[:, self.arm[3]] = w
        q[:, self.arm[4]] = roll
        if grip is not None:
            q[:, gripper_index(self.robot)] = grip
        return q

    def _in_limits(self, q: np.ndarray) -> np.ndarray:
        """(N,) whether each full configuration of ``q`` (N, dof) has a 2pi representative of every arm
        angle within the limits (all joints and representatives in one array operation)."""
        arm = self.arm
        qa = q[:, arm]
        qa[:, 1:4] = wrap_angle(qa[:, 1:4])  # pitch joints: bring angles to (-pi, pi] before the test
        # elbow range can exceed pi (0..2.95): allow the +2pi representative too
        tol = LIMIT_SLACK  # the ideal-geometry closed form is off by ~urad; the polish settles it
        v = qa[:, :, None] + TWO_PI_SHIFTS  # (N, 5, 3)
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
        """Every branch (base either way, elbow either side) that puts the TCP at ``p`` (3,) m with the tool
        ``pitch`` (None: chosen, see ``solve_ik``), ``roll`` or full rotation ``rot`` (3, 3), within the limits,
        polished on the true FK and checked; ``qr`` the reference (full q, rad) or None."""
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
        grip = ref_gripper_q(robot, qr)

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
                    "orientation", "give a pitch (and roll) instead of a full orientation, or turn the target about the vertical")
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
            qs = self._branch_q(wrap_angle(np.array([az, az, az + math.pi, az + math.pi])), s, e, w, want_roll, grip)
            any_reach = bool(ok.any())
            reachable = [qs[:2][ok[:2]], qs[2:][ok[2:]]]
            ok &= self._in_limits(qs)
            cands.extend([(qq, float(pitch))] for qq in qs[ok])
        else:  # pitch free: each branch over the pitch grid
            for base, r_signed, side in branches:
                phi = np.arctan2(side * np.cos(phis), -np.sin(phis))  # as above, over the pitch grid
                for elbow in (1.0, -1.0):
                    s, e, w, ok = self._planar(r_signed, z, phi, elbow)
                    qs = self._branch_q(wrap_angle(base), s, e, w, want_roll, grip)
                    any_reach |= bool(ok.any())
                    reachable.append(qs[ok])
                    ok &= self._in_limits(qs)
                    # the preferred pitch itself when this branch can hold it, else a grid sample
                    exact = self._planar(r_signed, z, np.arctan2(side * np.cos([pref]), -np.sin([pref])), elbow)
                    qe = self._branch_q(wrap_angle(base), exact[0], exact[1], exact[2], want_roll, grip)
                    alts = [(qe[0], pref)] if exact[3][0] and self._in_limits(qe)[0] else []
                    if ok.any():  # fallback, should the preferred pitch fail the final check
                        k = pick_index(phis, ok, pref)
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
        out = dedupe(out, self.arm)
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
        return self._verify(fit_limits(robot, self._polish(q, p, rot, u_h, q_pitch), qr), p, rot, u_h, q_pitch,
                            check_pitch)

    def _verify(self, q: np.ndarray | None, p: np.ndarray, rot: np.ndarray | None, u_h: np.ndarray, q_pitch: float,
                check_pitch: bool) -> np.ndarray | None:
        """The FK check of a polished, fitted candidate (None passes through): ``q`` if it meets the tolerances."""
        if q is None:
            return None
        t = self.robot.kin.fk(q)
        if np.linalg.norm(t[:3, 3] - p) > POS_TOL:
            return None
        if rot is not None and rot_angle(rot.T @ t[:3, :3]) > ORI_TOL:
            return None
        if check_pitch and abs(wrap_angle(pitch_of(t, u_h) - q_pitch)) > ORI_TOL:
            return None
        return q

    def line(self, points: np.ndarray, pitch: float, roll: float | None, q0: np.ndarray) -> list[list | None]:
        """``solve`` (pitch held, no ``rpy``) for every point of ``points`` (n, 3) m, batched, for ``LineIK``.

        Per point: None (solve it alone: on the base axis, beyond the reach, roll outside its range), or
        ``solve``'s branches in its order as (q, u_h, done): ``done`` q is polished, fitted into the limits
        and FK-checked (a branch that fails is left out); otherwise q is only polished, because its limit
        fit depends on the reference (``fit_limits`` has two representatives to choose from). The
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
        grip = ref_gripper_q(robot, q0)
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
        base = wrap_angle(np.array([[a, a, a + math.pi, a + math.pi] for a in azs]))
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
            dot = a[:, 0] * u[:, 0] + a[:, 1] * u[:, 1] + a[:, 2] * u[:, 2]  # approach_pitches' a @ u_h, summed in its order
            return np.column_stack([t[:, :3, 3] - np.repeat(pts[act], k1, axis=0),
                                    wrap_angle(np.arctan2(-a[:, 2], dot) - pitch)])

        pol = newton_rows(res, qs[sel], self.arm[:4])
        fit, amb = fit_limits_rows(robot, pol)
        good = ~amb & ~np.isnan(fit[:, 0])
        passed = np.zeros(len(sel), dtype=bool)
        if np.any(good):
            g = np.flatnonzero(good)
            t = kin.frames4(fit[g])[:, kin.tcp_index]
            d = t[:, :3, 3] - pts[g]
            perr = np.sqrt(np.sum(d * d, axis=1))
            a = t[:, :3, 0]
            perr_p = np.abs(wrap_angle(np.arctan2(-a[:, 2], a[:, 0] * uh[g, 0] + a[:, 1] * uh[g, 1] + a[:, 2] * uh[g, 2])
                                  - pitch))
            passed[g] = (perr <= POS_TOL) & (perr_p <= ORI_TOL)
            # near a tolerance the last bit matters: the scalar check decides, as in solve
            for j in np.flatnonzero((np.abs(perr - POS_TOL) < 1e-3 * POS_TOL) | (np.abs(perr_p - ORI_TOL) < 1e-3 * ORI_TOL)):
                i = g[j]
                passed[i] = self._verify(fit[i], pts[i], None, uh[i], float(pitch), True) is not None
        lists: dict[int, list] = {}
        for n, o in enumerate(owner):
            lst = lists.setdefault(int(o), [])
            if amb[n]:
                lst.append((pol[n], uh[n], False))
            elif passed[n]:
                lst.append((fit[n], uh[n], True))
        for k in range(m):
            out[rows[k]] = lists.get(k, [])
        return out

    def _polish(self, q: np.ndarray, p: np.ndarray, rot: np.ndarray | None, u_h: np.ndarray,
                pitch: float) -> np.ndarray:
        kin = self.robot.kin
        if rot is not None:
            want = pitch_of_rot(rot, u_h)

            def res(qq: np.ndarray) -> np.ndarray:
                t = kin.fk(qq)
                m = rot.T @ t[:, :3, :3]
                return np.column_stack([t[:, :3, 3] - p, wrap_angle(approach_pitches(t, u_h) - want),
                                        np.arctan2(m[:, 2, 1] - m[:, 1, 2], m[:, 1, 1] + m[:, 2, 2])])
            return newton(res, q, self.arm)
        def res_pitch(qq: np.ndarray) -> np.ndarray:
            t = kin.fk(qq)
            return np.column_stack([t[:, :3, 3] - p, wrap_angle(approach_pitches(t, u_h) - pitch)])
        return newton(res_pitch, q, self.arm[:4])


def _first_nonempty(*arrays: np.ndarray) -> np.ndarray:
    """The first array with rows (explain the forward branch before the base-flipped one)."""
    return next((a for a in arrays if len(a)), arrays[-1])
