"""Named singularity classes for the robots that have a known structure.

``classify_singularity(robot, q)`` returns the class name (e.g. ``"elbow_stretched"``) or None.
The robot description chooses the model with ``singularity_model``; robots without one are
classified as ``"unclassified"`` only when the Jacobian's smallest singular value is tiny.
"""

from __future__ import annotations

import numpy as np

from roarmctl.robot.model import Robot

SIN_TOL = 0.02  # |sin| of an angle below this counts as aligned (about 1.1 deg)
AXIS_TOL = 0.01  # m: a point this close to the base axis counts as on it


def _roarm5(robot: Robot, q: np.ndarray) -> str | None:
    frames = robot.kin.link_frames(q)
    idx = robot.kin.link_index
    shoulder, elbow, wrist = (frames[idx[n], :3, 3] for n in ("link2", "link3", "link4"))
    tcp = frames[robot.kin.tcp_index, :3, 3]
    upper, fore = elbow - shoulder, wrist - elbow
    sin_elbow = np.linalg.norm(np.cross(upper, fore)) / (np.linalg.norm(upper) * np.linalg.norm(fore))
    if sin_elbow < SIN_TOL and np.dot(upper, fore) > 0:
        return "elbow_stretched"
    if np.hypot(*wrist[:2]) < AXIS_TOL:
        return "wrist_center_on_base_axis"
    if np.hypot(*tcp[:2]) < AXIS_TOL:
        return "tcp_on_base_axis"
    return None


def _ur6(robot: Robot, q: np.ndarray) -> str | None:
    # UR10 in modified DH (robots/ur10.yaml): det J = a2 a3 (a2 c2 + a3 c23 - d5 s234) s3 s5, zero at the
    # elbow (s3 = 0), wrist (s5 = 0) and shoulder (wrist centre on the base axis) singularities.
    a2, a3, d5 = 0.6129, 0.5716, 0.1157
    if abs(np.sin(q[2])) < SIN_TOL:
        return "elbow"
    if abs(np.sin(q[4])) < SIN_TOL:
        return "wrist"
    if abs(a2 * np.cos(q[1]) + a3 * np.cos(q[1] + q[2]) - d5 * np.sin(q[1] + q[2] + q[3])) < AXIS_TOL:
        return "shoulder"
    return None


def _planar2r(robot: Robot, q: np.ndarray) -> str | None:
    if abs(np.sin(q[1])) < SIN_TOL:
        return "elbow_stretched" if np.cos(q[1]) > 0 else "elbow_folded"
    return None


MODELS = {"roarm5": _roarm5, "ur6": _ur6, "planar2r": _planar2r}


def classify_singularity(robot: Robot, q) -> str | None:
    """The singularity class at configuration ``q`` (full or arm-only vector), or None."""
    q = robot.full_q(q)
    model = MODELS.get(robot.singularity_model or "")
    if model is not None:
        return model(robot, q)
    sv = np.linalg.svd(robot.kin.jacobian(q), compute_uv=False)
    return "unclassified" if sv[-1] < 1e-6 else None
