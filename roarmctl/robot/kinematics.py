"""The library's one forward kinematics, plus the geometric Jacobian and manipulability, for any
tree of joints. IK, the collision checker, timing (TCP speed), dynamics and the pictures all use it.

Everything is batched: a configuration array of shape (N, dof) goes through one numpy pass per
joint, so FK of many configurations costs little more than FK of one. Single configurations of
shape (dof,) are accepted too and give unbatched results.

How it is fast: the fixed joint origins are pre-split and links reached from the root through fixed
joints only are computed once. A revolute joint about its local z axis (every URDF joint of the
RoArm, every DH joint) contributes origin @ Rz(q), which is linear in (cos q, sin q):
origin @ Rz(q) = cos(q) A + sin(q) B + C with fixed 4x4 A, B, C, so it costs two trig calls, three
multiply-adds and one batched matmul. One configuration goes through 2-D arrays and Python floats
(about 40 % less numpy overhead than a batch of one). A revolute joint about another axis u is linear
in (cos q, sin q) too (Rodrigues: R_u(q) = cos q (I - u u^T) + sin q [u]x + u u^T): its step keeps
the general form (origin, axis) for the compiled collision checker and carries its A, B, C as a third
item, which frames4 uses. Prismatic joints take the general path (translation along the axis).
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot


@dataclass
class ManipulabilityReport:
    """Velocity-manipulability figures at one configuration.

    ``manipulability`` is the product of the singular values of the full 6 x n Jacobian (equal to
    sqrt(det(J J^T)) when n >= 6, and sqrt(det(J^T J)) for arms with fewer joints, where the former
    is identically 0). ``translational`` is the same for the 3 x n linear part (m^k). The ellipsoid
    radii (m/s per rad/s) and axes (columns, base frame) are those of the translational part (Yoshikawa).
    """

    jacobian: np.ndarray
    manipulability: float
    translational: float
    singular_values: np.ndarray
    ellipsoid_radii: np.ndarray
    ellipsoid_axes: np.ndarray


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (..., 3) arrays, the same arithmetic as ``np.cross`` (bit for bit), whose
    axis handling costs several times the maths on the small batches of the Jacobian and of RNEA."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(a.shape if a.shape == b.shape else np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


_SMALL_BATCH = 200  # states: up to here frames4 of a z-rotation chain takes _frames_simple


class Kinematics:
    """Compiled kinematic tree of a ``Robot``: link frames, TCP pose, Jacobian."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.link_names: list[str] = robot.link_names
        index = {name: i for i, name in enumerate(self.link_names)}
        self.link_index = index
        self._parent = [index[j.parent] for j in robot.joints]
        self._child = [index[j.child] for j in robot.joints]
        # q index that drives each joint (-1: fixed); a mimic joint is driven by the joint it mimics
        self._qidx = [robot.joint_names.index(j.mimic or j.name) if j.kind != "fixed" else -1 for j in robot.joints]
        self.tcp_index = index[robot.tcp_link]
        # Joints between the root and the TCP, in chain order; their q indices form the arm.
        chain: list[int] = []
        link = self.tcp_index
        while link != 0:
            j = self._child.index(link)
            chain.append(j)
            link = self._parent[j]
        self.tcp_chain_joints = list(reversed(chain))
        self.tcp_chain_indices = [self._qidx[j] for j in self.tcp_chain_joints if self._qidx[j] >= 0]

        self._compile()

    # ------------------------------------------------------------------ FK
    def _compile(self) -> None:
        """Per-joint steps (kind, parent, child, q index, offset, data, post) and the constant links."""
        robot = self.robot
        self.n_links = len(self.link_names)
        self._const = np.zeros((self.n_links, 4, 4))
        self._const[0] = np.eye(4)
        is_const = [True] + [False] * (self.n_links - 1)
        self._steps: list[tuple] = []
        for j, joint in enumerate(robot.joints):
            parent, child, qi = self._parent[j], self._child[j], self._qidx[j]
            origin = joint.origin
            post = None if np.allclose(joint.post, np.eye(4)) else joint.post.copy()
            if joint.kind == "fixed" and is_const[parent]:
                self._const[child] = self._const[parent] @ origin @ (post if post is not None else np.eye(4))
                is_const[child] = True
                continue
            if joint.kind == "revolute" and np.allclose(joint.axis, (0.0, 0.0, 1.0)):
                a, b, c = np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4))
                a[:3, 0], a[:3, 1] = origin[:3, 0], origin[:3, 1]  # cos q terms of the first two columns
                b[:3, 0], b[:3, 1] = origin[:3, 1], -origin[:3, 0]  # sin q terms
                c[:3, 2], c[:, 3] = origin[:3, 2], origin[:, 3]
                self._steps.append(("rz", parent, child, qi, float(joint.offset), (a, b, c), post))
            elif joint.kind == "revolute":
                u = np.asarray(joint.axis, dtype=float)
                ux = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
                a, b, c = np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4))
                a[:3, :3] = origin[:3, :3] @ (np.eye(3) - np.outer(u, u))
                b[:3, :3] = origin[:3, :3] @ ux
                c[:3, :3], c[:, 3] = origin[:3, :3] @ np.outer(u, u), origin[:, 3]
                self._steps.append(("revolute", parent, child, qi, float(joint.offset), (origin.copy(), u, (a, b, c)), post))
            else:
                self._steps.append((joint.kind, parent, child, qi, float(joint.offset),
                                    (origin.copy(), np.asarray(joint.axis, dtype=float)), post))
        self._const_links = [i for i, c in enumerate(is_const) if c]
        self._simple = all(kind in ("rz", "revolute", "fixed") and post is None for kind, *_, post in self._steps)
        if self._simple:  # every step as cos(q) A + sin(q) B + C (fixed: A = B = 0), for _frames_one
            k = len(self._steps)
            self._abc = np.zeros((3, k, 4, 4))
            self._one_q = np.array([max(st[3], 0) for st in self._steps], dtype=int)
            self._one_off = np.array([st[4] for st in self._steps])
            self._one_pc = [(st[1], st[2]) for st in self._steps]
            for i, (kind, *_, data, _post) in enumerate(self._steps):
                if kind == "rz":
                    self._abc[:, i] = data
                elif kind == "revolute":
                    self._abc[:, i] = data[2]
                else:
                    self._abc[2, i] = data[0]

    def frames4(self, q: np.ndarray) -> np.ndarray:
        """Every link frame (N, L, 4, 4) in the root frame for full configurations ``q`` (N, dof), rad/m.

        No conversion or checks (the checker's hot path); ``link_frames`` is the friendly form."""
        n = q.shape[0]
        if self._simple and n <= _SMALL_BATCH:
            return self._frames_one(q[0])[None] if n == 1 else self._frames_simple(q)
        out = np.empty((n, self.n_links, 4, 4))
        out[:, self._const_links] = self._const[self._const_links]
        for kind, parent, child, qi, offset, data, post in self._steps:
            if kind == "rz" or kind == "revolute":
                a, b, c = data if kind == "rz" else data[2]
                ang = q[:, qi] + offset if offset else q[:, qi]
                m = np.cos(ang)[:, None, None] * a
                m += np.sin(ang)[:, None, None] * b
                m += c
            elif kind == "prismatic":
                origin, axis = data
                m = np.broadcast_to(origin, (n, 4, 4)).copy()
                m[:, :3, 3] += (q[:, qi] + offset)[:, None] * (origin[:3, :3] @ axis)
            else:
                m = data[0]
            t = out[:, parent] @ m
            out[:, child] = t @ post if post is not None else t
        return out

    def _frames_simple(self, q: np.ndarray) -> np.ndarray:
        """``frames4`` of a chain of z rotations and fixed joints for a small batch: every joint transform of
        every state in three array operations (as ``_frames_one``), then one batched product per joint.
        Small batches (IK's Newton steps: 5 states) were mostly per-joint numpy call overhead, 37 -> 22 us
        on the RoArm; from a few hundred states on, the per-joint loop is faster. Same results bit for bit."""
        n = q.shape[0]
        ang = (q[:, self._one_q] + self._one_off).T  # (K, N)
        abc = self._abc
        m = np.cos(ang)[:, :, None, None] * abc[0][:, None]  # (K, N, 4, 4)
        m += np.sin(ang)[:, :, None, None] * abc[1][:, None]
        m += abc[2][:, None]
        out = np.empty((n, self.n_links, 4, 4))
        out[:, self._const_links] = self._const[self._const_links]
        for i, (parent, child) in enumerate(self._one_pc):
            out[:, child] = out[:, parent] @ m[i]
        return out

    def _frames_one(self, q: np.ndarray) -> np.ndarray:
        """(L, 4, 4) for one full q: all joint transforms in three array operations, then the chain."""
        ang = q[self._one_q] + self._one_off
        abc = self._abc
        m = np.cos(ang)[:, None, None] * abc[0]
        m += np.sin(ang)[:, None, None] * abc[1]
        m += abc[2]
        out = np.empty((self.n_links, 4, 4))
        out[self._const_links] = self._const[self._const_links]
        for i, (parent, child) in enumerate(self._one_pc):
            np.matmul(out[parent], m[i], out=out[child])
        return out

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (N, L, 3, 3) and positions (N, L, 3) of every link for full ``q`` (N, dof) (views)."""
        t = self.frames4(q)
        return t[..., :3, :3], t[..., :3, 3]

    def link_frames(self, q) -> np.ndarray:
        """Every link frame in the root frame: (N, n_links, 4, 4), or (n_links, 4, 4) for one q.

        ``q`` is (N, dof) or (dof,); arm-only vectors are completed with the gripper closed.
        """
        q = self.robot.full_q(q)
        if q.ndim == 1:
            return self.frames4(q[None])[0]
        return self.frames4(q)

    def fk(self, q, link: str | None = None) -> np.ndarray:
        """Pose of ``link`` (default: the TCP) in the root frame: (4, 4) or (N, 4, 4)."""
        idx = self.tcp_index if link is None else self.link_index[link]
        return self.link_frames(q)[..., idx, :, :]

    # ------------------------------------------------------------ Jacobian
    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian at the TCP in the root frame: (6, arm_dof) or (N, 6, arm_dof).

        Rows are (vx, vy, vz, wx, wy, wz); columns follow ``robot.arm_indices``.
        """
        q = self.robot.full_q(q)
        single = q.ndim == 1
        jac = self.pose_jacobian(np.atleast_2d(q))[1]
        return jac[0] if single else jac

    def pose_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """TCP poses (N, 4, 4) and geometric Jacobians (N, 6, arm_dof) of full configurations ``q``
        (N, dof), rad/m, from one FK pass (the iterative IK's hot path: no conversion or checks).

        Column k of a revolute joint is (z_k x (p_tcp - o_k), z_k), of a prismatic one (z_k, 0), with
        z_k the joint axis and o_k its origin in the root frame, both taken from the parent link's frame.
        """
        if not hasattr(self, "_jac_parents"):  # the chain's moving joints as arrays, built once
            moving = [j for j in self.tcp_chain_joints if self.robot.joints[j].kind != "fixed"]
            origins = [self.robot.joints[j].origin for j in moving]
            self._jac_parents = np.array([self._parent[j] for j in moving], dtype=int)
            self._jac_axes = np.array([o[:3, :3] @ np.asarray(self.robot.joints[j].axis, dtype=float)
                                       for o, j in zip(origins, moving)])  # (k, 3) in the parent frame
            self._jac_points = np.array([o[:3, 3] for o in origins])  # (k, 3) in the parent frame
            self._jac_revolute = np.array([self.robot.joints[j].kind == "revolute" for j in moving])
        frames = self.frames4(q)
        tcp = frames[:, self.tcp_index]
        par = frames[:, self._jac_parents]  # (N, k, 4, 4)
        rot = par[..., :3, :3]
        z = np.einsum("nkij,kj->nki", rot, self._jac_axes)
        o = np.einsum("nkij,kj->nki", rot, self._jac_points) + par[..., :3, 3]
        lin = np.where(self._jac_revolute[None, :, None], cross_rows(z, tcp[:, None, :3, 3] - o), z)
        ang = np.where(self._jac_revolute[None, :, None], z, 0.0)
        jac = np.concatenate([lin, ang], axis=2).transpose(0, 2, 1)
        return tcp, jac

    def tcp_velocity(self, q, qd_arm) -> np.ndarray:
        """Linear TCP velocity (N, 3) m/s = J_v(q) @ qd_arm, for q (N, dof or arm_dof) and
        qd_arm (N, arm_dof) rad/s (or any path derivative, giving the TCP derivative per unit)."""
        jv = self.jacobian(np.atleast_2d(q))[:, :3, :]
        return np.einsum("nij,nj->ni", jv, np.atleast_2d(qd_arm))

    def manipulability(self, q) -> ManipulabilityReport:
        """Manipulability figures at one configuration (see ``ManipulabilityReport``)."""
        jac = self.jacobian(np.asarray(q, dtype=float))
        sv = np.linalg.svd(jac, compute_uv=False)
        u, svt, _ = np.linalg.svd(jac[:3], full_matrices=False)
        k = min(3, jac.shape[1])
        return ManipulabilityReport(
            jacobian=jac,
            manipulability=float(np.prod(sv[: min(6, jac.shape[1])])),
            translational=float(np.prod(svt[:k])),
            singular_values=sv,
            ellipsoid_radii=svt[:k],
            ellipsoid_axes=u[:, :k],
        )
