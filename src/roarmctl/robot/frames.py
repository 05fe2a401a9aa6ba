"""Named Cartesian frames of a robot besides its own world frame, e.g. the RoArm firmware's.

A frame is data in the robot description (``frames:``): where its origin lies in the world frame
(m), its length unit, and optionally the device's own end point (a point fixed in a link) that the
device reports in that frame. For the RoArm-M3 the ``firmware`` frame is the one of T:1051 x/y/z,
T:104/T:1041 and roarm-sdk's ``pose_get()``/``pose_ctrl()``: mm, origin on the base axis at the
shoulder-axis height, axes as the world's (x forward, y left, z up).

The transform is one translation and one scale (``to_frame``/``from_frame``), used everywhere:
``kin fk/ik --frame``, ``frame:`` in plans, execute's display and log.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.robot.model import Robot

UNITS = {"m": 1.0, "mm": 1000.0}


@dataclass(frozen=True)
class Frame:
    """``p_frame = (p_world - origin) * scale``; ``point`` is the device's end point: (link, xyz m in that link)."""

    name: str
    origin: np.ndarray  # (3,) m, world coordinates of the frame's origin
    unit: str = "m"
    point_link: str | None = None
    point_xyz: np.ndarray | None = None  # (3,) m in ``point_link``

    @property
    def scale(self) -> float:
        """Frame units per metre (1000 for mm)."""
        return UNITS[self.unit]


def get_frame(robot: Robot, name: str) -> Frame:
    """The robot's frame ``name`` ("world" is the identity); InputError names the ones it has."""
    if name == "world":
        return Frame("world", np.zeros(3))
    frames = getattr(robot, "frames", {}) or {}
    if name not in frames:
        have = ", ".join(["world", *frames])
        raise InputError(f"robot '{robot.name}' has no frame '{name}'", f"frames of {robot.name}: {have}")
    return frames[name]


def to_frame(frame: Frame, p_world: npt.ArrayLike) -> np.ndarray:
    """World positions (..., 3) m -> frame coordinates (..., 3) in the frame's unit."""
    return (np.asarray(p_world, dtype=float) - frame.origin) * frame.scale


def from_frame(frame: Frame, p: npt.ArrayLike) -> np.ndarray:
    """Frame coordinates (..., 3) in the frame's unit -> world positions (..., 3) m."""
    return np.asarray(p, dtype=float) / frame.scale + frame.origin


def device_point(robot: Robot, frame: Frame, q: npt.ArrayLike) -> np.ndarray:
    """World position (..., 3) m of the frame's device end point at ``q`` ((dof,) or (N, dof));
    the TCP when the frame names none."""
    if frame.point_link is None:
        return robot.kin.fk(q)[..., :3, 3]
    t = robot.kin.fk(q, frame.point_link)
    return t[..., :3, :3] @ frame.point_xyz + t[..., :3, 3]


def tcp_offset(robot: Robot, frame: Frame, q: npt.ArrayLike) -> np.ndarray:
    """Device end point minus TCP (world, m) at ``q``: (3,) or (N, 3)."""
    return device_point(robot, frame, q) - robot.kin.fk(q)[..., :3, 3]
