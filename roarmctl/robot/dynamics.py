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
from roarmctl.robot.kinematics import cross_rows
from roarmctl.robot.model import Inertial, Robot

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


def _batch(robot: Robot, v, what: str, is_position: bool) -> np.ndarray:
    """(N, dof) from (dof,), (arm_dof,), (N, dof) or (N, arm_dof)."""
    a = np.asarray(v, dtype=float)
    if a.ndim <= 1:
        return _complete(robot, a, what, is_position)[None, :]
    if a.shape[1] == robot.dof:
        return a
    return np.stack([_complete(robot, row, what, is_position) for row in a]) if a.shape[1] != robot.arm_dof else (
        robot.full_q(a) if is_position else _scatter_arm(robot, a))


def _has_post(joint) -> bool:
    """Whether the joint has a fixed transform after its motion (standard DH's d/a/alpha)."""
    return not np.array_equal(joint.post, _EYE4)


_EYE4 = np.eye(4)


def _joint_table(robot: Robot) -> list[tuple]:
    """Per joint (joint, parent link, child link, q index or -1, whether the child frame's origin and axis are
    the joint's: revolute or fixed without a DH ``post``), computed once per robot."""
    table = getattr(robot, "_rnea_joints", None)
    if table is None:
        kin = robot.kin
        table = robot._rnea_joints = [(joint, kin._parent[j], kin._child[j], kin._qidx[j],
                                       joint.kind != "prismatic" and not _has_post(joint))
                                      for j, joint in enumerate(robot.joints)]
    return table


def _scatter_arm(robot: Robot, a: np.ndarray) -> np.ndarray:
    out = np.zeros((a.shape[0], robot.dof))
    out[:, robot.arm_indices] = a
    return out


def inverse_dynamics(robot: Robot, q, qd, qdd, *, gravity: float = GRAVITY, payload: dict[str, Inertial] | None = None) -> np.ndarray:
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
    kin = robot.kin
    frames = kin.link_frames(q)
    if frames.ndim == 3:
        frames = frames[None]
    n_links = len(kin.link_names)
    w = np.zeros((n, n_links, 3))  # angular velocity of each link
    dw = np.zeros((n, n_links, 3))  # angular acceleration
    a = np.zeros((n, n_links, 3))  # linear acceleration of the link frame's origin
    a[:, 0] = (0.0, 0.0, gravity)  # gravity as an upward acceleration of the root
    org = frames[:, :, :3, 3]
    # At rest (holding torques, the gravity term of timing): no angular velocity or acceleration anywhere,
    # so every cross-product term below is zero and is skipped (same result, a fraction of the work).
    moving = bool(np.any(qd) or np.any(qdd))

    # Links whose angular velocity and acceleration are zero in every state (no moving joint between them
    # and the root, e.g. the base): the cross-product terms with their w and dw are zero and are skipped.
    spins = [False] * n_links

    def point_acc(link: int, r: np.ndarray) -> np.ndarray:
        if not moving or not spins[link]:
            return a[:, link]
        d = r - org[:, link]
        return a[:, link] + cross_rows(dw[:, link], d) + cross_rows(w[:, link], cross_rows(w[:, link], d))

    n_joints = len(robot.joints)
    axes = np.zeros((n, n_joints, 3))
    pivots = np.zeros((n, n_joints, 3))
    for j, (joint, p, c, qi, at_origin) in enumerate(_joint_table(robot)):
        if at_origin:
            # child = before @ rotation about the axis (or nothing): same origin, same axis direction
            z = frames[:, c, :3, :3] @ joint.axis
            axes[:, j], pivots[:, j] = z, org[:, c]
        else:
            before = frames[:, p] @ joint.origin
            z = before[:, :3, :3] @ joint.axis
            axes[:, j], pivots[:, j] = z, before[:, :3, 3]
        if joint.kind == "revolute" and not moving:
            a[:, c] = a[:, p]
        elif joint.kind == "revolute":
            wz = qd[:, qi, None] * z
            w[:, c] = w[:, p] + wz
            dw[:, c] = dw[:, p] + qdd[:, qi, None] * z + cross_rows(w[:, p], wz) if spins[p] else dw[:, p] + qdd[:, qi, None] * z
            spins[c] = True
            # the pivot lies on the axis: it moves with the parent and with the child alike
            a_piv = point_acc(p, pivots[:, j])
            if at_origin:  # the child's origin is the pivot
                a[:, c] = a_piv
            else:
                d = org[:, c] - pivots[:, j]
                a[:, c] = a_piv + cross_rows(dw[:, c], d) + cross_rows(w[:, c], cross_rows(w[:, c], d))
        elif joint.kind == "prismatic":
            w[:, c], dw[:, c] = w[:, p], dw[:, p]
            spins[c] = spins[p]
            a[:, c] = point_acc(p, org[:, c]) + 2.0 * cross_rows(w[:, p], qd[:, qi, None] * z) + qdd[:, qi, None] * z
        else:
            w[:, c], dw[:, c] = w[:, p], dw[:, p]
            spins[c] = spins[p]
            a[:, c] = point_acc(p, org[:, c])

    bodies = dict(robot.inertials)
    for name, extra in (payload or {}).items():
        if name not in kin.link_index:
            raise InputError(f"payload: '{name}' is not a link of {robot.name}")
        bodies[name] = combine_inertials(bodies[name], extra) if name in bodies else extra
    # Each link's own inertial force (at its COM) and moment about the COM.
    force = np.zeros((n, n_links, 3))
    moment = np.zeros((n, n_links, 3))
    com = org.copy()
    heavy = [False] * n_links  # the link or a link below it carries a body
    for name, inertial in bodies.items():
        k = kin.link_index.get(name)
        if k is None:
            continue
        heavy[k] = True
        rot = frames[:, k, :3, :3]
        com[:, k] = org[:, k] + rot @ inertial.com
        force[:, k] = inertial.mass * point_acc(k, com[:, k])
        if not moving or not spins[k]:
            continue
        inertia = rot @ inertial.inertia @ np.swapaxes(rot, 1, 2)
        iw = np.einsum("nij,nj->ni", inertia, w[:, k])
        moment[:, k] = np.einsum("nij,nj->ni", inertia, dw[:, k]) + cross_rows(w[:, k], iw)

    # Backward pass: subtree force and its moment about each joint's pivot. A subtree without a body adds
    # nothing (its torques are zero), and the root's own sums are never read.
    f_sub = force.copy()
    n_sub = np.zeros((n, n_links, 3))  # moment of the subtree about the pivot of the joint above the link
    tau = np.zeros((n, robot.dof))
    table = _joint_table(robot)
    kids = [c for _, _, c, _, _ in table]
    own = cross_rows(com[:, kids] - pivots, force[:, kids])  # (n, joints, 3): each child's own force about the pivot
    for j in range(n_joints - 1, -1, -1):
        joint, p, c, qi, _ = table[j]
        if not heavy[c]:
            continue
        heavy[p] = True
        n_sub[:, c] += moment[:, c] + own[:, j]
        if qi >= 0:  # += : a mimic joint's generalised force adds to the joint it follows
            tau[:, qi] += np.einsum("ni,ni->n", axes[:, j], n_sub[:, c] if joint.kind == "revolute" else f_sub[:, c])
        if p == 0:
            continue
        # hand the subtree's wrench to the parent, as a moment about the parent's own pivot
        pivot_p = pivots[:, kin._child.index(p)]
        f_sub[:, p] += f_sub[:, c]
        n_sub[:, p] += n_sub[:, c] + cross_rows(pivots[:, j] - pivot_p, f_sub[:, c])
    return tau[0] if single else tau


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


def solid_inertia(shape: str, mass: float, size=(0.0, 0.0, 0.0), radius: float = 0.0, length: float = 0.0) -> np.ndarray:
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
