"""The library's one forward kinematics, plus the geometric Jacobian and manipulability, for any
tree of joints. IK, the collision checker, timing (TCP speed), dynamics and the pictures all use it.

The FK runs in the compiled kernel (``src/roarmctl/_kernel.c``, function ``fk``) from tables that
``Kinematics`` builds once per robot (``_pack``): links reached from the root through fixed joints
only are constant; every other joint is one step, origin @ motion(q) @ post, with a revolute joint
about its local z axis (every URDF joint of the RoArm, every DH joint) as cos(q) A + sin(q) B + C
(fixed 4x4 A, B, C), one about another unit axis u as origin @ Rodrigues(u, q), a prismatic one as
the origin moved along its axis, and a DH ``post`` as a fixed product after the motion. A mimic joint
reads the value of the joint it follows: its value is multiplier * q + offset (URDF ``<mimic>``; the
step's multiplier is 1 for every other joint); a continuous joint is a revolute joint without limits. The
Jacobian has one column per arm joint; a mimic joint between the root and the TCP adds multiplier times its own
column to its leader's (the chain rule). The collision
checker, the Jacobian and the inverse dynamics (robot/dynamics.py) run on the same tables and the
same C function.

Everything is batched: a configuration array of shape (N, dof) is one call into the kernel. Single
configurations of shape (dof,) are accepted by the friendly forms and give unbatched results.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl import _kernel

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


# Kind codes of the kernel's step and joint records (src/roarmctl/_kernel.c: STEPI, JOINTI).
_STEP_KIND = {"fixed": 0, "rz": 1, "revolute": 2, "prismatic": 3}
_JOINT_KIND = {"fixed": 0, "revolute": 1, "prismatic": 2}


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
        # the arm: the q indices that move the TCP, once each (a mimic joint of the chain moves with its leader)
        self.tcp_chain_indices = list(dict.fromkeys(self._qidx[j] for j in self.tcp_chain_joints if self._qidx[j] >= 0))
        self.n_links = len(self.link_names)
        self._pack()

    # ------------------------------------------------------------------ FK
    def _pack(self) -> None:
        """The kernel's kinematic tables ``_ki`` (int64) and ``_kf`` (float64), layout as in src/roarmctl/_kernel.c:
        constant link frames, one step per joint that moves a link (kind, parent, child, q index, post;
        offset and the 4 x 4 A, B, C, post), the TCP chain (parent link, revolute or prismatic; axis and
        origin point in the parent frame) and every joint for the dynamics (kind, parent, child, q index,
        axis at the child's origin, joint above the parent; axis, origin)."""
        robot = self.robot
        eye = np.eye(4)
        const = np.zeros((self.n_links, 4, 4))
        const[0] = eye
        is_const = [True] + [False] * (self.n_links - 1)
        steps_i: list[int] = []
        steps_f: list[np.ndarray] = []
        for j, joint in enumerate(robot.joints):
            parent, child, qi = self._parent[j], self._child[j], self._qidx[j]
            origin = joint.origin
            post = None if np.allclose(joint.post, eye) else joint.post
            if joint.kind == "fixed" and is_const[parent]:
                const[child] = const[parent] @ origin @ (post if post is not None else eye)
                is_const[child] = True
                continue
            rec = np.zeros((4, 16))  # A, B, C, post
            u = np.asarray(joint.axis, dtype=float)
            if joint.kind == "revolute" and np.allclose(u, (0.0, 0.0, 1.0)):
                kind = "rz"
                a, b, c = np.zeros((4, 4)), np.zeros((4, 4)), np.zeros((4, 4))
                a[:3, 0], a[:3, 1] = origin[:3, 0], origin[:3, 1]  # cos q terms of the first two columns
                b[:3, 0], b[:3, 1] = origin[:3, 1], -origin[:3, 0]  # sin q terms
                c[:3, 2], c[:, 3] = origin[:3, 2], origin[:, 3]
                rec[0], rec[1], rec[2] = a.ravel(), b.ravel(), c.ravel()
            elif joint.kind == "revolute":
                kind = "revolute"
                rec[0, :3], rec[2] = u, origin.ravel()
            elif joint.kind == "prismatic":
                kind = "prismatic"
                rec[0, :3], rec[2] = origin[:3, :3] @ u, origin.ravel()
            else:
                kind = "fixed"
                rec[2] = origin.ravel()
            if post is not None:
                rec[3] = post.ravel()
            steps_i += [_STEP_KIND[kind], parent, child, max(qi, 0), int(post is not None)]
            steps_f += [np.array([float(joint.offset)]), rec.ravel(), np.array([float(joint.multiplier)])]
        const_links = [i for i, c in enumerate(is_const) if c]
        chain_i: list[int] = []
        chain_f: list[float] = []
        for j in self.tcp_chain_joints:
            joint = robot.joints[j]
            if joint.kind == "fixed":
                continue
            o, ax = joint.origin, [float(v) for v in joint.axis]
            # the axis in the parent frame, summed as the kernel sums (no FMA, this order); the Jacobian column
            # the joint's motion adds to (its leader's for a mimic joint, multiplier times)
            chain_i += [self._parent[j], 0 if joint.kind == "revolute" else 1, self.tcp_chain_indices.index(self._qidx[j])]
            chain_f += [float(o[r, 0]) * ax[0] + float(o[r, 1]) * ax[1] + float(o[r, 2]) * ax[2] for r in range(3)]
            chain_f += [float(v) for v in o[:3, 3]] + [float(joint.multiplier)]
        joints_i: list[int] = []
        joints_f: list[np.ndarray] = []
        for j, joint in enumerate(robot.joints):
            p = self._parent[j]
            at_origin = joint.kind != "prismatic" and np.array_equal(joint.post, eye)
            joints_i += [_JOINT_KIND[joint.kind], p, self._child[j], self._qidx[j], int(at_origin),
                         self._child.index(p) if p != 0 else -1]
            # a mimic joint turns multiplier times as fast as the joint it follows, and its load counts
            # multiplier times on that joint (virtual work): both are the axis scaled by the multiplier
            joints_f += [np.asarray(joint.axis, dtype=float) * float(joint.multiplier), joint.origin.ravel()]
        n_chain = len(chain_i) // 3
        ints = [robot.dof, self.n_links, len(steps_i) // 5, len(const_links), n_chain, self.tcp_index, len(robot.joints)]
        self._ki = np.array(ints + const_links + steps_i + chain_i + joints_i, dtype=np.int64)
        self._kf = np.concatenate([const[const_links].ravel(), *steps_f, np.array(chain_f, dtype=float),
                                   *joints_f]).astype(float)
        self._n_chain = n_chain
        self._views()

    def _views(self) -> None:
        self._kim, self._kfm = self._ki.data, self._kf.data  # cheaper to pass than the arrays

    def __getstate__(self) -> dict:
        """Picklable (a robot can go to another process, or be deep-copied): the memoryviews are left out."""
        state = dict(self.__dict__)
        del state["_kim"], state["_kfm"]
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._views()

    def frames4(self, q: np.ndarray) -> np.ndarray:
        """Every link frame (N, L, 4, 4) in the root frame for full configurations ``q`` (N, dof), rad/m.

        No conversion or checks (the checker's hot path); ``link_frames`` is the friendly form."""
        q = np.ascontiguousarray(q, dtype=float)
        out = np.empty((q.shape[0], self.n_links, 4, 4))
        _kernel.fk(self._kfm, self._kim, q, out)
        return out

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (N, L, 3, 3) and positions (N, L, 3) of every link for full ``q`` (N, dof) (views)."""
        t = self.frames4(q)
        return t[..., :3, :3], t[..., :3, 3]

    def link_frames(self, q: npt.ArrayLike) -> np.ndarray:
        """Every link frame in the root frame: (N, n_links, 4, 4), or (n_links, 4, 4) for one q.

        ``q`` is (N, dof) or (dof,); arm-only vectors are completed with the gripper closed.
        """
        q = self.robot.full_q(q)
        if q.ndim == 1:
            return self.frames4(q[None])[0]
        return self.frames4(q)

    def fk(self, q: npt.ArrayLike, link: str | None = None) -> np.ndarray:
        """Pose of ``link`` (default: the TCP) in the root frame: (4, 4) or (N, 4, 4)."""
        idx = self.tcp_index if link is None else self.link_index[link]
        return self.link_frames(q)[..., idx, :, :]

    # ------------------------------------------------------------ Jacobian
    def jacobian(self, q: npt.ArrayLike) -> np.ndarray:
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
        z_k the joint axis and o_k its origin in the root frame, both taken from the parent link's frame; a mimic
        joint of the chain adds multiplier times its own to its leader's column (the chain rule).
        """
        q = np.ascontiguousarray(q, dtype=float)
        tcp = np.empty((q.shape[0], 4, 4))
        jac = np.empty((q.shape[0], 6, len(self.tcp_chain_indices)))
        _kernel.jacobian(self._kfm, self._kim, q, tcp, jac)
        return tcp, jac

    def tcp_velocity(self, q: npt.ArrayLike, qd_arm: npt.ArrayLike) -> np.ndarray:
        """Linear TCP velocity (N, 3) m/s = J_v(q) @ qd_arm, for q (N, dof or arm_dof) and
        qd_arm (N, arm_dof) rad/s (or any path derivative, giving the TCP derivative per unit)."""
        q = self.robot.full_q(np.atleast_2d(q))
        qd = np.atleast_2d(qd_arm)
        if len(q) != len(qd):
            n = max(len(q), len(qd))
            q, qd = np.broadcast_to(q, (n, q.shape[1])), np.broadcast_to(qd, (n, qd.shape[1]))
        q, qd = np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float)
        out = np.empty((len(q), 3))
        _kernel.tcp_velocity(self._kfm, self._kim, q, qd, out)
        return out

    def manipulability(self, q: npt.ArrayLike) -> ManipulabilityReport:
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
