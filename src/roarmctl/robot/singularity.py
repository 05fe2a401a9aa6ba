"""Named singularity classes for the robots that have a known structure.

``classify_singularity(robot, q)`` returns the class name (e.g. ``"elbow_stretched"``) or None;
``margin_text`` says in words why a configuration is inside the singularity margin, ``base_axis_text`` what
a TCP passing over the base axis means for an arm.
The robot description chooses the model with ``singularity_model``; robots without one are
classified as ``"unclassified"`` only when the Jacobian's smallest singular value is tiny.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from roarmctl.robot.ik import ur6_params
from roarmctl.robot.model import Robot

SIN_TOL = 0.02  # |sin| of an angle below this counts as aligned (about 1.1 deg)
AXIS_TOL = 0.01  # m: a point this close to the base axis counts as on it


def _roarm5(robot: Robot, q: np.ndarray) -> str | None:
    # shoulder, elbow and wrist-pitch frames: the children of the 2nd..4th moving joints of the TCP chain
    frames = robot.kin.link_frames(q)
    moving = [robot.joints[j] for j in robot.kin.tcp_chain_joints if robot.joints[j].kind != "fixed"]
    idx = robot.kin.link_index
    shoulder, elbow, wrist = (frames[idx[m.child], :3, 3] for m in moving[1:4])
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
    # UR-type 6R: det J = a2 a3 (a2 c2 + a3 c23 - d5 s234) s3 s5, dimensions from the robot's DH table
    # (zero at the elbow s3 = 0, wrist s5 = 0 and shoulder (wrist centre on the base axis) singularities).

    params = robot.derived.get("ur6_params")
    if params is None:
        params = robot.derived["ur6_params"] = ur6_params(robot)
    _, _, a2, a3, _, d5, _, offs, _ = params
    th = q[robot.arm_indices] + offs
    if abs(np.sin(th[2])) < SIN_TOL:
        return "elbow"
    if abs(np.sin(th[4])) < SIN_TOL:
        return "wrist"
    if abs(a2 * np.cos(th[1]) + a3 * np.cos(th[1] + th[2]) - d5 * np.sin(th[1] + th[2] + th[3])) < AXIS_TOL:
        return "shoulder"
    return None


def _planar2r(robot: Robot, q: np.ndarray) -> str | None:
    if abs(np.sin(q[1])) < SIN_TOL:
        return "elbow_stretched" if np.cos(q[1]) > 0 else "elbow_folded"
    return None


MODELS = {"roarm5": _roarm5, "ur6": _ur6, "planar2r": _planar2r}


def classify_singularity(robot: Robot, q: npt.ArrayLike) -> str | None:
    """The singularity class at configuration ``q`` (full or arm-only vector), or None."""
    q = robot.full_q(q)
    model = MODELS.get(robot.singularity_model or "")
    if model is not None:
        return model(robot, q)
    sv = np.linalg.svd(robot.kin.jacobian(q), compute_uv=False)
    return "unclassified" if sv[-1] < 1e-6 else None


def margin_text(robot: Robot, q: npt.ArrayLike, sigma: float, margin: float) -> str:
    """Why configuration ``q`` (full or arm-only, rad/m) is inside the singularity margin, in words: the measure
    the margin bounds (``sigma`` < ``margin``, m/rad: the smallest singular value of the translational
    Jacobian), and the class of the singular pose when the description's ``singularity_model`` names one here
    (e.g. "roarm5 model: tcp_on_base_axis"); an arm without one is not told which singularity it nears."""
    cls = classify_singularity(robot, q) if robot.singularity_model else None
    named = f"; {robot.singularity_model} model: {cls}" if cls else ""
    return (f"closer to a singularity than the margin (smallest singular value of the translational Jacobian "
            f"{sigma:.4f} < {margin:.4f} m/rad{named})")


#: Per singularity model, its class for the TCP on the base axis, where it has one (a singular pose there).
BASE_AXIS_CLASS = {"roarm5": "tcp_on_base_axis"}


def base_axis_text(robot: Robot) -> str:
    """What a TCP passing over the base axis means for ``robot``, in words: the class of the singular pose there
    when the description's ``singularity_model`` has one ("roarm5 model: tcp_on_base_axis"); else only that it
    may be near a singularity (which one, only a model knows)."""
    cls = BASE_AXIS_CLASS.get(robot.singularity_model or "")
    if cls:
        return f"over the base axis, a singular pose ({robot.singularity_model} model: {cls})"
    return "over the base axis, where the arm may be near a singularity"
