"""Lean batched forward kinematics for the collision checker.

``robot.kin.link_frames`` builds and multiplies full 4x4 matrices per joint; this module does the
same maths on (rotation, translation) pairs with the fixed joint origins pre-split, and treats the
common case of a revolute joint about its local z axis (every URDF joint of the RoArm) as a
rotation of two columns. For a batch of N configurations it costs a handful of numpy operations
per joint, independent of N up to a few hundred states.

The result must equal ``robot.kin.link_frames`` to 1e-9 (tests/test_collision.py checks it).
"""

from __future__ import annotations

import math

import numpy as np

from roarmctl.robot.kinematics import axis_rotation
from roarmctl.robot.model import Robot


class FastKinematics:
    """Link frames of a robot for full configurations ``q`` (N, dof), as (N, L, 4, 4) transforms.

    A revolute joint about its local z axis contributes origin @ Rz(q), which is linear in
    (cos q, sin q): origin @ Rz(q) = cos(q) A + sin(q) B + C with A, B, C fixed 4x4 matrices, so each
    such joint costs two trig calls, three multiply-adds and one batched matmul. Links reached only
    through fixed joints from the root are constant and computed once.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        kin = robot.kin
        self.n_links = len(kin.link_names)
        self._const = np.zeros((self.n_links, 4, 4))
        self._const[0] = np.eye(4)
        is_const = [True] + [False] * (self.n_links - 1)
        self._steps = []
        for j, joint in enumerate(robot.joints):
            parent, child, qi = kin._parent[j], kin._child[j], kin._qidx[j]
            origin = joint.origin
            post = None if np.allclose(joint.post, np.eye(4)) else joint.post.copy()
            if joint.kind == "fixed" and is_const[parent]:
                self._const[child] = self._const[parent] @ origin @ (post if post is not None else np.eye(4))
                is_const[child] = True
                continue
            if joint.kind == "revolute" and np.allclose(joint.axis, (0.0, 0.0, 1.0)):
                a = np.zeros((4, 4))
                b = np.zeros((4, 4))
                c = np.zeros((4, 4))
                a[:3, 0], a[:3, 1] = origin[:3, 0], origin[:3, 1]  # cos q terms of the first two columns
                b[:3, 0], b[:3, 1] = origin[:3, 1], -origin[:3, 0]  # sin q terms
                c[:3, 2], c[:, 3] = origin[:3, 2], origin[:, 3]
                self._steps.append(("rz", parent, child, qi, float(joint.offset), (a, b, c), post))
            else:
                self._steps.append((joint.kind, parent, child, qi, float(joint.offset),
                                    (origin.copy(), np.asarray(joint.axis, dtype=float)), post))
        self._const_links = [i for i, c in enumerate(is_const) if c]
        # One configuration through 2-D arrays and Python floats: about 40 % less numpy overhead.
        self._simple = all(kind in ("rz", "fixed") and post is None for kind, *_, post in self._steps)

    def frames4(self, q: np.ndarray) -> np.ndarray:
        """Every link frame (N, L, 4, 4) in the root frame for full configurations ``q`` (N, dof)."""
        n = q.shape[0]
        if n == 1 and self._simple:
            return self._frames_one(q[0])[None]
        out = np.empty((n, self.n_links, 4, 4))
        out[:, self._const_links] = self._const[self._const_links]
        for kind, parent, child, qi, offset, data, post in self._steps:
            if kind == "rz":
                a, b, c = data
                ang = q[:, qi] + offset if offset else q[:, qi]
                m = np.cos(ang)[:, None, None] * a
                m += np.sin(ang)[:, None, None] * b
                m += c
            elif kind == "revolute":
                origin, axis = data
                m = np.zeros((n, 4, 4))
                m[:, :3, :3] = axis_rotation(axis, q[:, qi] + offset)
                m[:, 3, 3] = 1.0
                m = origin @ m
            elif kind == "prismatic":
                origin, axis = data
                m = np.broadcast_to(origin, (n, 4, 4)).copy()
                m[:, :3, 3] += (q[:, qi] + offset)[:, None] * (origin[:3, :3] @ axis)
            else:
                m = data[0]
            t = out[:, parent] @ m
            out[:, child] = t @ post if post is not None else t
        return out

    def _frames_one(self, q: np.ndarray) -> np.ndarray:
        out = np.empty((self.n_links, 4, 4))
        out[self._const_links] = self._const[self._const_links]
        for kind, parent, child, qi, offset, data, _ in self._steps:
            if kind == "rz":
                a, b, c = data
                ang = float(q[qi]) + offset
                m = math.cos(ang) * a + math.sin(ang) * b + c
            else:
                m = data[0]
            np.matmul(out[parent], m, out=out[child])
        return out

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (N, L, 3, 3) and positions (N, L, 3) of every link (views into one array)."""
        t = self.frames4(q)
        return t[..., :3, :3], t[..., :3, 3]
