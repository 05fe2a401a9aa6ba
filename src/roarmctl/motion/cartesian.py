"""Straight-line TCP motions (approach, descent, lift) as joint-space waypoints.

The TCP line is sampled every ``step`` metres and each sample is solved by IK on the branch
closest to the previous sample, so the joint path follows the line without branch jumps.
"""

from __future__ import annotations

import math

import numpy as np

from roarmctl.errors import PlanningError, UnreachableError
from roarmctl.robot.ik import LineIK
from roarmctl.robot.model import Robot

MAX_JOINT_STEP = 0.15  # rad between neighbouring samples; more means a branch switch or singularity
STEP_SLACK = 1e-9  # of a step: a length this close above a whole number of steps counts as that number


def line_steps(length: float, step: float) -> int:
    """Number of equal segments (>= 1) of a straight line ``length`` m long, none longer than ``step`` m.

    A length within ``STEP_SLACK`` steps above a whole number of steps counts as that number: a length
    meant as 5 cm comes out of FK as 0.05000000000000006 m or 0.049999999999999996 m depending on the
    last bit of a rounding, and that must not add a waypoint (a segment longer than ``step`` by 5 pm
    changes nothing that matters)."""
    return max(int(math.ceil(length / step - STEP_SLACK)), 1)


def cartesian_line(
    robot: Robot,
    q_start: np.ndarray,
    p_goal: np.ndarray,
    *,
    pitch: float | None,
    roll: float | None = None,
    step: float = 0.005,
    label: str = "line",
) -> np.ndarray:
    """Joint waypoints (K, dof) whose TCP runs straight from FK(q_start) to ``p_goal`` (m).

    ``q_start`` is a full configuration; the gripper value is kept. The first waypoint is
    ``q_start`` itself; the tool pitch (and roll, when given) is held along the line (``pitch`` None:
    position-only IK, the pitch follows from the geometry). Each sample is solved from the previous one
    (``solve_ik_near``).
    """
    q_start = robot.full_q(q_start)
    p0 = robot.kin.fk(q_start)[:3, 3]
    p_goal = np.asarray(p_goal, dtype=float)
    n = line_steps(float(np.linalg.norm(p_goal - p0)), step)
    pts = np.array([p0 + (p_goal - p0) * (k / n) for k in range(1, n + 1)])
    # every sample's IK batched where it can be (LineIK: the same solutions as one solve_ik_near each)
    line = LineIK(robot, pts, q_start, pitch=pitch, roll=roll if pitch is not None else None)
    out = [q_start]
    prev = q_start
    arm = robot.arm_indices
    rest = [i for i in range(robot.dof) if i not in arm]  # the gripper: q_start's value all along
    for k in range(1, n + 1):
        p = pts[k - 1]
        try:
            best = line.near(k - 1, prev)
        except UnreachableError as exc:
            raise PlanningError(f"{label}: the straight line leaves the reachable space at "
                                f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m: {exc.message}") from None
        jump = float(np.max(np.abs(best[arm] - prev[arm])))
        if jump > MAX_JOINT_STEP:
            raise PlanningError(f"{label}: the straight line passes a singularity near "
                                f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m (a joint would jump {jump:.2f} rad)",
                                "move the target or change the approach height or pitch")
        best = best.copy()
        best[rest] = q_start[rest]
        out.append(best)
        prev = best
    return np.array(out)


def line_deviation(robot: Robot, q: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> float:
    """Largest distance (m) of the TCP at configurations ``q`` (N, dof) from the segment p0-p1."""
    p = robot.kin.fk(robot.full_q(q))[:, :3, 3]
    d = np.asarray(p1, dtype=float) - np.asarray(p0, dtype=float)
    length2 = float(d @ d)
    if length2 < 1e-18:
        return float(np.max(np.linalg.norm(p - p0, axis=1)))
    t = np.clip((p - p0) @ d / length2, 0.0, 1.0)
    return float(np.max(np.linalg.norm(p - (p0 + t[:, None] * d), axis=1)))
