"""What the IK families share: tolerances, 2 pi limit fitting, the Gauss-Newton polish on the true FK,
rotation helpers and the de-duplication of solutions."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.robot.model import Robot

STRETCH_SLACK = 1e-4  # cos(elbow) this far beyond 1 still counts as reachable (model noise; FK decides)
POS_TOL = 1e-6  # m: every returned solution reaches the target position this closely (FK-checked)
ORI_TOL = 1e-5  # rad: orientation check; covers the few-urad axis tilt of the rounded RoArm URDF


def vec3(v: npt.ArrayLike, what: str) -> np.ndarray:
    """``v`` as a finite (3,) float array; anything else raises InputError naming ``what``."""
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{what}: expected 3 finite numbers, got {v!r}")
    return a


def rot_angle(m: np.ndarray) -> float:
    """Rotation angle (rad) of a 3x3 rotation matrix, accurate near 0."""
    s = 0.5 * np.linalg.norm([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    c = 0.5 * (np.trace(m) - 1.0)
    return float(math.atan2(s, c))


def rot_vec(m: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle) of a 3x3 rotation matrix."""
    ang = rot_angle(m)
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


TWO_PI_SHIFTS = np.array([2 * np.pi * k for k in (-1, 0, 1)])


def wrap_angle(a: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Angles (rad, scalar or array) wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def default_ref(robot: Robot) -> np.ndarray:
    """The reference when none is given: the ``home`` pose, else all zeros (full configuration, rad)."""
    home = robot.named_poses.get("home")
    return robot.full_q(home) if home is not None else robot.full_q(np.zeros(robot.arm_dof))


def ref_gripper_q(robot: Robot, qr: np.ndarray | None) -> float | None:
    """The gripper joint value (rad) IK solutions carry: the reference configuration's ``qr``, else the closed
    value; None without a gripper (IK solves the arm; the gripper is copied, not chosen)."""
    if robot.gripper is None:
        return None
    gi = robot.joint_index(robot.gripper.joint)
    return float(qr[gi]) if qr is not None else robot.gripper.closed


def gripper_index(robot: Robot) -> int:
    """The gripper joint's index in the full configuration (for a robot with a gripper)."""
    assert robot.gripper is not None
    return robot.joint_index(robot.gripper.joint)


def fit_limits(robot: Robot, q: np.ndarray, ref: np.ndarray | None, tol: float = 1e-7) -> np.ndarray | None:
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


def newton(residual: Callable[[np.ndarray], np.ndarray], q: np.ndarray, idx: list[int],
            iters: int = 12, tol: float = 1e-13, h: float = 1e-7) -> np.ndarray:
    """Gauss-Newton on the joints ``idx`` of one configuration ``q`` (dof,) with a forward-difference
    Jacobian: ``newton_rows`` with one row. ``residual`` maps a batch of configurations (k, dof), q and
    its len(idx) perturbations, to residuals (k, m), so each iteration costs one batched FK call."""
    return newton_rows(lambda batch, rows, k1: residual(batch), q[None], idx, iters, tol, h)[0]


def newton_rows(residual: Callable[[np.ndarray, np.ndarray, int], np.ndarray], q: np.ndarray, idx: list[int],
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


def fit_limits_rows(robot: Robot, q: np.ndarray, tol: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """``fit_limits`` of every row of ``q`` (N, dof) where it does not depend on the reference.

    Returns (fitted (N, dof), with NaN rows where no representative is within a limit; ambiguous (N,):
    rows where some joint has two representatives within its limits, so the reference picks one)."""
    arm = robot.arm_indices
    lo, hi = robot.lower[arm], robot.upper[arm]
    v = q[:, arm, None] + 2 * np.pi * np.arange(-2, 3)  # (N, A, 5): the candidates fit_limits tries
    inside = (lo[None, :, None] - tol <= v) & (v <= hi[None, :, None] + tol)
    count = inside.sum(axis=2)
    out = q.copy()
    pick = np.take_along_axis(v, np.argmax(inside, axis=2)[:, :, None], 2)[:, :, 0]
    out[:, arm] = np.minimum(np.maximum(pick, lo), hi)
    out[np.any(count == 0, axis=1)] = np.nan
    return out, np.any(count > 1, axis=1)


def dedupe(sols: list[np.ndarray], idx: list[int], tol: float = 1e-5) -> list[np.ndarray]:
    """``sols`` without repeats: a solution within ``tol`` rad (on the joints ``idx``, 2 pi apart = equal) of an
    earlier one is dropped."""
    out: list[np.ndarray] = []
    for q in sols:
        if all(np.max(np.abs(wrap_angle(q[idx] - o[idx]))) > tol for o in out):
            out.append(q)
    return out
