"""Closed-form position IK of the RoArm-M2-S (family ``roarm3``): base yaw and a planar 2R arm."""

from __future__ import annotations

import math

import numpy as np

from roarmctl.errors import DescriptionError, UnreachableError
from roarmctl.robot.ik.common import (
    POS_TOL,
    STRETCH_SLACK,
    dedupe,
    fit_limits,
    gripper_index,
    newton,
    ref_gripper_q,
    wrap_angle,
)
from roarmctl.robot.model import Robot


class Roarm3IK:
    """Closed-form position IK of a base-yaw + planar-2R arm (the RoArm-M2-S): 3 joints, 3 position
    coordinates, so the tool pitch is whatever the geometry gives (shoulder + elbow), not a choice.

    Geometry from the robot's own frames at q = 0: the shoulder point S (child of the 2nd moving
    joint), the vectors a = elbow - S and b = TCP - elbow in the arm's vertical plane, and each
    joint's turning sense in that plane. The plane must contain the base axis.
    """

    def __init__(self, robot: Robot) -> None:
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
        """Every solution (both base branches, elbow either side) that reaches ``p`` (3,) m within the limits,
        polished and FK-checked; raises UnreachableError saying why none does."""
        robot = self.robot
        where = f"target ({p[0]:.4g}, {p[1]:.4g}, {p[2]:.4g}) m"
        rel = p[:2] - self.base_xy
        rho = float(np.hypot(*rel))
        ref_base = float(qr[self.arm[0]]) if qr is not None else 0.0
        az = math.atan2(rel[1], rel[0]) if rho > 1e-9 else math.atan2(*(self._u(ref_base)[1::-1]))
        az0 = math.atan2(self.u0[1], self.u0[0])
        grip = ref_gripper_q(robot, qr)
        raw, reach = [], False
        for flip in (0.0, math.pi):
            base = wrap_angle(self.sb * (az + flip - az0))
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
                q = robot.full_q(np.array([base, wrap_angle(self.ss * psi), wrap_angle(self.se * phi)]))
                if grip is not None:
                    q[gripper_index(robot)] = grip
                raw.append(q)
        if not reach:
            raise UnreachableError(f"{where} is out of reach: the shoulder-to-TCP distance is outside "
                                   f"[{abs(self.la - self.lb):.3f}, {self.la + self.lb:.3f}] m", "out_of_reach",
                                   "move the target closer to the arm")

        def res(qq: np.ndarray) -> np.ndarray:
            return robot.kin.fk(qq)[:, :3, 3] - p

        out, limit_fail = [], 0
        for q in raw:
            q = newton(res, q, list(self.arm))
            q2 = fit_limits(robot, q, qr)
            if q2 is None:
                limit_fail += 1
                continue
            if np.linalg.norm(robot.kin.fk(q2)[:3, 3] - p) <= POS_TOL:
                out.append(q2)
        out = dedupe(out, list(self.arm))
        if not out:
            if limit_fail:
                raise UnreachableError(f"{where} is within reach but not within the joint limits", "joint_limit",
                                       "move the target")
            raise UnreachableError(f"{where}: no solution passed the FK check", "out_of_reach")
        return out

    def _u(self, base: float) -> np.ndarray:
        c, s = math.cos(self.sb * base), math.sin(self.sb * base)
        return np.array([c * self.u0[0] - s * self.u0[1], s * self.u0[0] + c * self.u0[1], 0.0])
