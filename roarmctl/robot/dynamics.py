"""Rigid-body inverse dynamics by the recursive Newton-Euler algorithm, on any kinematic tree.

``inverse_dynamics(robot, q, qd, qdd) -> tau`` (N m for revolute joints, N for prismatic),
``mass_matrix(robot, q)``, ``gravity_vector(robot, q)`` and ``coriolis_vector(robot, q, qd)``, so that

    tau = M(q) qdd + C(q, qd) qd + G(q)

Gravity acts along -z of the root frame (``GRAVITY`` = 9.81 m/s^2). Vectors ``q``, ``qd``, ``qdd`` hold
every actuated joint (``robot.dof``, gripper included); arm-only vectors are accepted and completed
(gripper closed for ``q``, zero rate and acceleration). Results cover every actuated joint.

Everything is computed in root-frame coordinates: the forward pass carries each link's angular
velocity and acceleration and the linear acceleration of its frame origin (gravity enters as an
upward acceleration of the root), the backward pass sums each subtree's force and its moment about
the joint's axis point, and the torque is that moment projected on the joint axis.
"""

from __future__ import annotations

import numpy as np

from roarmctl.errors import DescriptionError, InputError
from roarmctl.robot.model import Robot

GRAVITY = 9.81  # m/s^2, along -z of the root frame


def _complete(robot: Robot, v, what: str, is_position: bool) -> np.ndarray:
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


def inverse_dynamics(robot: Robot, q, qd, qdd, *, gravity: float = GRAVITY) -> np.ndarray:
    """Joint torques/forces (robot.dof,) that produce accelerations ``qdd`` at state (``q``, ``qd``).

    Args:
        q, qd, qdd: (dof,) or (arm_dof,) in rad, rad/s, rad/s^2 (m, m/s, m/s^2 for prismatic joints).
        gravity: magnitude (m/s^2) along -z of the root frame; 0 leaves gravity out.
    """
    _require_inertials(robot)
    q = _complete(robot, q, "q", True)
    qd = _complete(robot, qd, "qd", False)
    qdd = _complete(robot, qdd, "qdd", False)
    kin = robot.kin
    frames = kin.link_frames(q)
    n_links = len(kin.link_names)
    w = np.zeros((n_links, 3))  # angular velocity of each link
    dw = np.zeros((n_links, 3))  # angular acceleration
    a = np.zeros((n_links, 3))  # linear acceleration of the link frame's origin
    a[0] = (0.0, 0.0, gravity)  # gravity as an upward acceleration of the root
    org = frames[:, :3, 3]

    def point_acc(link: int, r: np.ndarray) -> np.ndarray:
        d = r - org[link]
        return a[link] + np.cross(dw[link], d) + np.cross(w[link], np.cross(w[link], d))

    axes = np.zeros((len(robot.joints), 3))
    pivots = np.zeros((len(robot.joints), 3))
    for j, joint in enumerate(robot.joints):
        p, c, qi = kin._parent[j], kin._child[j], kin._qidx[j]
        before = frames[p] @ joint.origin
        z = before[:3, :3] @ joint.axis
        axes[j], pivots[j] = z, before[:3, 3]
        if joint.kind == "revolute":
            w[c] = w[p] + qd[qi] * z
            dw[c] = dw[p] + qdd[qi] * z + np.cross(w[p], qd[qi] * z)
            # the pivot lies on the axis: it moves with the parent and with the child alike
            a_piv = point_acc(p, pivots[j])
            d = org[c] - pivots[j]
            a[c] = a_piv + np.cross(dw[c], d) + np.cross(w[c], np.cross(w[c], d))
        elif joint.kind == "prismatic":
            w[c], dw[c] = w[p], dw[p]
            a[c] = point_acc(p, org[c]) + 2.0 * np.cross(w[p], qd[qi] * z) + qdd[qi] * z
        else:
            w[c], dw[c] = w[p], dw[p]
            a[c] = point_acc(p, org[c])

    # Each link's own inertial force (at its COM) and moment about the COM.
    force = np.zeros((n_links, 3))
    moment = np.zeros((n_links, 3))  # about the link's pivot, filled below
    com = org.copy()
    for name, inertial in robot.inertials.items():
        k = kin.link_index.get(name)
        if k is None:
            continue
        rot = frames[k, :3, :3]
        com[k] = org[k] + rot @ inertial.com
        inertia = rot @ inertial.inertia @ rot.T
        force[k] = inertial.mass * point_acc(k, com[k])
        moment[k] = inertia @ dw[k] + np.cross(w[k], inertia @ w[k])

    # Backward pass: subtree force and its moment about each joint's pivot.
    f_sub = force.copy()
    n_sub = np.zeros((n_links, 3))  # moment of the subtree about the pivot of the joint above the link
    tau = np.zeros(robot.dof)
    for j in range(len(robot.joints) - 1, -1, -1):
        joint = robot.joints[j]
        c = kin._child[j]
        n_sub[c] += moment[c] + np.cross(com[c] - pivots[j], force[c])
        p = kin._parent[j]
        if kin._qidx[j] >= 0:
            tau[kin._qidx[j]] = float(np.dot(axes[j], n_sub[c] if joint.kind == "revolute" else f_sub[c]))
        # hand the subtree's wrench to the parent, as a moment about the parent's own pivot
        jp = kin._child.index(p) if p != 0 else None
        pivot_p = pivots[jp] if jp is not None else np.zeros(3)
        f_sub[p] += f_sub[c]
        n_sub[p] += n_sub[c] + np.cross(pivots[j] - pivot_p, f_sub[c])
    return tau


def mass_matrix(robot: Robot, q) -> np.ndarray:
    """Joint-space inertia matrix M(q), (dof, dof), symmetric positive definite (kg m^2 for revolute joints)."""
    q = _complete(robot, q, "q", True)
    zero = np.zeros(robot.dof)
    cols = [inverse_dynamics(robot, q, zero, e, gravity=0.0) for e in np.eye(robot.dof)]
    m = np.stack(cols, axis=1)
    return 0.5 * (m + m.T)


def gravity_vector(robot: Robot, q, *, gravity: float = GRAVITY) -> np.ndarray:
    """Torques (dof,) that hold the robot still at ``q`` against gravity (N m)."""
    zero = np.zeros(robot.dof)
    return inverse_dynamics(robot, q, zero, zero, gravity=gravity)


def coriolis_vector(robot: Robot, q, qd) -> np.ndarray:
    """Centrifugal and Coriolis torques C(q, qd) qd, (dof,) (N m)."""
    return inverse_dynamics(robot, q, qd, np.zeros(robot.dof), gravity=0.0)
