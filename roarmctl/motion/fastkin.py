"""Lean batched forward kinematics for the collision checker.

``robot.kin.link_frames`` builds and multiplies full 4x4 matrices per joint; this module does the
same maths on (rotation, translation) pairs with the fixed joint origins pre-split, and treats the
common case of a revolute joint about its local z axis (every URDF joint of the RoArm) as a
rotation of two columns. For a batch of N configurations it costs a handful of numpy operations
per joint, independent of N up to a few hundred states.

The result must equal ``robot.kin.link_frames`` to 1e-9 (tests/test_collision.py checks it).
"""

from __future__ import annotations

import numpy as np

from roarmctl.robot.kinematics import axis_rotation
from roarmctl.robot.model import Robot


class FastKinematics:
    """Link rotations (N, L, 3, 3) and origins (N, L, 3) of a robot, for full configurations (N, dof)."""

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        kin = robot.kin
        self.n_links = len(kin.link_names)
        self._steps = []
        for j, joint in enumerate(robot.joints):
            ro, to = joint.origin[:3, :3].copy(), joint.origin[:3, 3].copy()
            post = None if np.allclose(joint.post, np.eye(4)) else (joint.post[:3, :3].copy(), joint.post[:3, 3].copy())
            z_axis = joint.kind == "revolute" and np.allclose(joint.axis, (0.0, 0.0, 1.0))
            self._steps.append((kin._parent[j], kin._child[j], kin._qidx[j], joint.kind, z_axis,
                                ro, to, np.asarray(joint.axis, dtype=float), float(joint.offset), post))

    def frames(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Rotations (N, L, 3, 3) and positions (N, L, 3) of every link for full configurations ``q`` (N, dof)."""
        n = q.shape[0]
        rot = np.empty((n, self.n_links, 3, 3))
        pos = np.empty((n, self.n_links, 3))
        rot[:, 0] = np.eye(3)
        pos[:, 0] = 0.0
        for parent, child, qi, kind, z_axis, ro, to, axis, offset, post in self._steps:
            rp = rot[:, parent]
            a = rp @ ro  # (N, 3, 3): parent frame followed by the fixed origin
            p = pos[:, parent] + rp @ to
            if kind == "revolute":
                ang = q[:, qi] + offset if offset else q[:, qi]
                if z_axis:
                    c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
                    r = np.empty_like(a)
                    a0, a1 = a[:, :, 0], a[:, :, 1]
                    r[:, :, 0] = c * a0 + s * a1
                    r[:, :, 1] = c * a1 - s * a0
                    r[:, :, 2] = a[:, :, 2]
                else:
                    r = a @ axis_rotation(axis, ang)
            elif kind == "prismatic":
                r = a
                p = p + (a @ axis) * (q[:, qi] + offset)[:, None]
            else:
                r = a
            if post is not None:
                p = p + r @ post[1]
                r = r @ post[0]
            rot[:, child] = r
            pos[:, child] = p
        return rot, pos

    def frames4(self, q: np.ndarray) -> np.ndarray:
        """The same frames as 4x4 matrices (N, L, 4, 4), for comparison with ``robot.kin.link_frames``."""
        rot, pos = self.frames(q)
        out = np.zeros(rot.shape[:2] + (4, 4))
        out[..., :3, :3] = rot
        out[..., :3, 3] = pos
        out[..., 3, 3] = 1.0
        return out
