"""The RoArm's straight lines: ``solve_ik_near`` along a sampled line with the closed form batched over the
samples (``LineIK``)."""

from __future__ import annotations

import numpy as np

from roarmctl.robot.ik.common import dedupe, fit_limits, ref_gripper_q
from roarmctl.robot.ik.roarm5 import roarm5_solver
from roarmctl.robot.ik.solve import solve_ik_near
from roarmctl.robot.model import Robot


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
            solver = roarm5_solver(robot)
            q0 = robot.full_q(np.asarray(q_start, dtype=float))
            self.key = self._key(q0)
            self.cands = solver.line(self.points, float(pitch), roll, q0)

    def _key(self, q: np.ndarray) -> tuple:
        """What of ``prev`` the batch assumed: the gripper value and, roll left out, the wrist roll."""
        robot = self.robot
        grip = ref_gripper_q(robot, q)
        return (grip, None if self.roll is not None else float(q[robot.arm_indices[4]]))

    def near(self, k: int, prev: np.ndarray) -> np.ndarray:
        """``solve_ik_near(robot, points[k], prev, pitch=pitch, roll=roll)``: the solution (full q, rad) at sample ``k``
        that continues ``prev``."""
        robot, p = self.robot, self.points[k]
        cands = self.cands[k]
        qr = robot.full_q(np.asarray(prev, dtype=float))
        if cands is None or self._key(qr) != self.key:
            return solve_ik_near(robot, p, qr, pitch=self.pitch, roll=self.roll)
        solver = roarm5_solver(robot)
        assert self.pitch is not None  # the batch is for a held pitch
        out = []
        for q, u_h, done in cands:  # as Roarm5IK.solve: per branch, polished, fitted and FK-checked
            q2 = q if done else solver._verify(fit_limits(robot, q, qr), p, None, u_h, float(self.pitch), True)
            if q2 is not None:
                out.append(q2)
        if len(out) == 1:  # one branch (the usual case): nothing to dedupe, sort or pick
            return out[0].copy()  # a fresh array, as solve_ik_near's (the kept ones stay as they are)
        out = dedupe(out, solver.arm)
        if not out:
            return solve_ik_near(robot, p, qr, pitch=self.pitch, roll=self.roll)  # raises as one solve would
        arm = robot.arm_indices
        out.sort(key=lambda q: float(np.linalg.norm(q[arm] - qr[arm])))  # solve_ik's order, then solve_ik_near's pick
        return min(out, key=lambda s: float(np.max(np.abs(s[arm] - qr[arm])))).copy()
