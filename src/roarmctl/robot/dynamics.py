"""Rigid-body inverse dynamics by the recursive Newton-Euler algorithm, on any kinematic tree.

``inverse_dynamics(robot, q, qd, qdd) -> tau`` (N m for revolute joints, N for prismatic),
``mass_matrix(robot, q)``, ``gravity_vector(robot, q)`` and ``coriolis_vector(robot, q, qd)``, so that

    tau = M(q) qdd + C(q, qd) qd + G(q)

Gravity acts along -z of the root frame (``GRAVITY`` = 9.81 m/s^2). Vectors ``q``, ``qd``, ``qdd`` hold
every actuated joint (``robot.dof``, gripper included); arm-only vectors are accepted and completed
(gripper closed for ``q``, zero rate and acceleration). Results cover every actuated joint.

The recursion runs in the compiled kernel (``src/roarmctl/_kernel.c``, function ``rnea``) on the kinematic
tables of ``robot.kin`` and the library's FK, in root-frame coordinates: the forward pass carries each
link's angular velocity and acceleration and the linear acceleration of its frame origin (gravity enters
as an upward acceleration of the root), the backward pass sums each subtree's force and its moment about
the joint's axis point, and the torque is that moment projected on the joint axis (the force, for a
prismatic joint). A mimic joint's share adds to the joint it follows. Bodies are the links' inertials,
with any payload combined into its link (``combine_inertials``).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt

from roarmctl import _kernel
from roarmctl.errors import DescriptionError, InputError
from roarmctl.robot.model import Inertial, Robot

GRAVITY = 9.81  # m/s^2, along -z of the root frame


def _complete(robot: Robot, v: npt.ArrayLike, what: str, is_position: bool) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(-1)
    if a.size == robot.dof:
        return a
    if a.size == robot.arm_dof:
        if is_position:
            return robot.full_q(a)
        out = np.zeros(robot.dof)
        out[robot.arm_indices] = a
        return out
    counts = f"{robot.arm_dof} or {robot.dof}" if robot.arm_dof != robot.dof else f"{robot.dof}"
    raise InputError(f"{what}: {robot.name} takes {counts} values, got {a.size}")


def _require_inertials(robot: Robot) -> None:
    """Every link moved directly by an actuated joint needs mass data; say which ones do not have it."""
    moved = [j.child for j in robot.joints if j.kind != "fixed"]
    missing = [link for link in moved if link not in robot.inertials]
    if missing:
        raise DescriptionError(
            f"{robot.name}: no inertial data for link(s) {', '.join(missing)}; dynamics needs mass, centre of mass "
            "and inertia of every moving link",
            "add <inertial> to the URDF links, or an 'inertials' list (link, mass, com, inertia) to the DH YAML",
        )


def combine_inertials(a: Inertial, b: Inertial) -> Inertial:
    """Two rigid bodies fixed in the same link frame as one (parallel-axis theorem); units as ``Inertial``."""
    m = a.mass + b.mass
    if m <= 0:
        return Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
    com = (a.mass * np.asarray(a.com) + b.mass * np.asarray(b.com)) / m

    def shifted(x: Inertial) -> np.ndarray:
        d = np.asarray(x.com) - com
        return np.asarray(x.inertia) + x.mass * (np.dot(d, d) * np.eye(3) - np.outer(d, d))

    return Inertial(float(m), com, shifted(a) + shifted(b))


def _batch(robot: Robot, v: npt.ArrayLike, what: str, is_position: bool) -> np.ndarray:
    """(N, dof) from (dof,), (arm_dof,), (N, dof) or (N, arm_dof)."""
    a = np.asarray(v, dtype=float)
    if a.ndim <= 1:
        return _complete(robot, a, what, is_position)[None, :]
    if a.shape[1] == robot.dof:
        return a
    return np.stack([_complete(robot, row, what, is_position) for row in a]) if a.shape[1] != robot.arm_dof else (
        robot.full_q(a) if is_position else _scatter_arm(robot, a))




def _bodies(robot: Robot, payload: dict[str, Inertial] | None) -> np.ndarray:
    """The kernel's body table (n_links, 14) of the robot's inertials with ``payload`` combined in; the table
    without payload, and the last few with one, are kept on the robot."""
    kin = robot.kin
    cache = robot.derived.setdefault("rnea_bodies", {})
    key: tuple = ()
    if payload:
        for name, extra in payload.items():
            if name not in kin.link_index:
                raise InputError(f"payload: '{name}' is not a link of {robot.name}")
            key += ((name, float(extra.mass), np.asarray(extra.com, dtype=float).tobytes(),
                     np.asarray(extra.inertia, dtype=float).tobytes()),)
    table = cache.get(key)
    if table is not None:
        return table
    bodies = dict(robot.inertials)
    for name, extra in (payload or {}).items():
        bodies[name] = combine_inertials(bodies[name], extra) if name in bodies else extra
    table = np.zeros((kin.n_links, _kernel.BODYF))  # per link: has a body, mass, com (3), inertia (9)
    for name, inertial in bodies.items():
        k = kin.link_index.get(name)
        if k is None:
            continue
        table[k, 0], table[k, 1] = 1.0, float(inertial.mass)
        table[k, 2:5] = np.asarray(inertial.com, dtype=float)
        table[k, 5:] = np.asarray(inertial.inertia, dtype=float).ravel()
    if len(cache) > 16:
        cache.clear()
    cache[key] = table
    return table


def _scatter_arm(robot: Robot, a: np.ndarray) -> np.ndarray:
    out = np.zeros((a.shape[0], robot.dof))
    out[:, robot.arm_indices] = a
    return out


def inverse_dynamics(robot: Robot, q: npt.ArrayLike, qd: npt.ArrayLike, qdd: npt.ArrayLike, *, gravity: float = GRAVITY,
                     payload: dict[str, Inertial] | None = None) -> np.ndarray:
    """Joint torques/forces that produce accelerations ``qdd`` at state (``q``, ``qd``).

    Args:
        q, qd, qdd: (dof,) or (arm_dof,) in rad, rad/s, rad/s^2 (m, m/s, m/s^2 for prismatic joints),
            or batches (N, dof) / (N, arm_dof) of states: then the result is (N, dof).
        gravity: magnitude (m/s^2) along -z of the root frame; 0 leaves gravity out.
        payload: extra rigid bodies fixed to links (link name -> Inertial in that link's frame), such as
            a held object; they add to the link's own inertial.
    Returns:
        (dof,) torques for one state, (N, dof) for a batch (N m for revolute joints, N for prismatic).
    """
    _require_inertials(robot)
    single = np.asarray(q).ndim <= 1
    q = _batch(robot, q, "q", True)
    qd = _batch(robot, qd, "qd", False)
    qdd = _batch(robot, qdd, "qdd", False)
    n = q.shape[0]
    if qd.shape[0] != n or qdd.shape[0] != n:
        raise InputError(f"q, qd, qdd: batches of different lengths ({n}, {qd.shape[0]}, {qdd.shape[0]})")
    tau = np.empty((n, robot.dof))
    kin = robot.kin
    _kernel.rnea(kin._kfm, kin._kim, _bodies(robot, payload), np.ascontiguousarray(q), np.ascontiguousarray(qd),
                 np.ascontiguousarray(qdd), float(gravity), tau)
    return tau[0] if single else tau


def mass_matrix(robot: Robot, q: npt.ArrayLike) -> np.ndarray:
    """Joint-space inertia matrix M(q), (dof, dof), symmetric positive definite (kg m^2 for revolute joints)."""
    q = _complete(robot, q, "q", True)
    zero = np.zeros((robot.dof, robot.dof))
    m = inverse_dynamics(robot, np.repeat(q[None], robot.dof, axis=0), zero, np.eye(robot.dof), gravity=0.0).T
    return 0.5 * (m + m.T)


def gravity_vector(robot: Robot, q: npt.ArrayLike, *, gravity: float = GRAVITY) -> np.ndarray:
    """Torques (dof,) that hold the robot still at ``q`` against gravity (N m)."""
    zero = np.zeros(robot.dof)
    return inverse_dynamics(robot, q, zero, zero, gravity=gravity)


def coriolis_vector(robot: Robot, q: npt.ArrayLike, qd: npt.ArrayLike) -> np.ndarray:
    """Centrifugal and Coriolis torques C(q, qd) qd, (dof,) (N m)."""
    return inverse_dynamics(robot, q, qd, np.zeros(robot.dof), gravity=0.0)


def solid_inertia(shape: str, mass: float, size: Iterable[float] = (0.0, 0.0, 0.0), radius: float = 0.0,
                  length: float = 0.0) -> np.ndarray:
    """(3, 3) inertia (kg m^2) of a uniform solid about its centre, in its own axes.

    box ``size`` (x, y, z) m: m/12 (y^2 + z^2, x^2 + z^2, x^2 + y^2); cylinder along z:
    m (3 r^2 + l^2)/12 about x and y, m r^2/2 about z; sphere: 2/5 m r^2.
    """
    if shape == "box":
        x, y, z = (float(v) for v in size)
        return mass / 12.0 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
    if shape == "cylinder":
        side = mass * (3 * radius**2 + length**2) / 12.0
        return np.diag([side, side, mass * radius**2 / 2.0])
    if shape == "sphere":
        return np.eye(3) * 0.4 * mass * radius**2
    raise ValueError(f"unknown shape {shape!r}")
