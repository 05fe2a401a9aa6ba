"""The RoArm's tool pitch: its measure on a configuration, the order ``pitch: auto`` tries pitches in, and
which IK families take one."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from roarmctl.robot.ik.common import wrap_angle
from roarmctl.robot.model import Robot


def tool_pitch(robot: Robot, q: np.ndarray, position: npt.ArrayLike | None = None) -> float:
    """RoArm tool pitch (rad) of configuration ``q``: the approach axis (TCP +x) below the horizontal,
    in the vertical plane through the base axis and ``position`` (default: the TCP), as ``solve_ik``'s
    ``pitch`` means it (pi/2 = straight down)."""
    t = robot.kin.fk(robot.full_q(q))
    p = t[:3, 3] if position is None else np.asarray(position, dtype=float)
    base = robot.kin.fk(robot.full_q(q), robot.joints[robot.kin.tcp_chain_joints[0]].child)[:3, 3]
    rel = p[:2] - base[:2]
    if math.hypot(*rel) < 1e-9:
        az = float(robot.full_q(q)[robot.arm_indices[0]])
        u_h = np.array([math.cos(az), math.sin(az), 0.0])
    else:
        u_h = np.array([rel[0], rel[1], 0.0]) / math.hypot(*rel)
    return pitch_of(t, u_h)


PITCH_STEP = math.radians(1.0)  # pitch: auto tries the preferred pitch, then +-1 deg, +-2 deg, ...


def pitch_candidates(preferred: float, step: float = PITCH_STEP) -> list[float]:
    """Pitches (rad) in the order ``pitch: auto`` tries them: ``preferred``, then alternately above
    and below it in ``step``s, over the whole circle (wrapped to [-pi, pi])."""
    out = [float(wrap_angle(preferred))]
    n = int(math.ceil(math.pi / step))
    for k in range(1, n + 1):
        for sgn in (1.0, -1.0):
            v = float(wrap_angle(preferred + sgn * k * step))
            if all(abs(wrap_angle(v - o)) > 1e-9 for o in out):
                out.append(v)
    return out


def approach_pitches(t: np.ndarray, u_h: np.ndarray) -> np.ndarray:
    """Pitch (rad) of the approach axis of a batch of TCP poses (k, 4, 4) against the outward direction."""
    a = t[:, :3, 0]
    return np.arctan2(-a[:, 2], a @ u_h)


def pitch_of(t: np.ndarray, u_h: np.ndarray) -> float:
    """Pitch (rad) of the approach axis of one TCP pose ``t`` (4, 4) against the outward direction ``u_h`` (3,)."""
    return pitch_of_rot(t[:3, :3], u_h)


def pitch_of_rot(rot: np.ndarray, u_h: np.ndarray) -> float:
    """``pitch_of`` for a TCP rotation ``rot`` (3, 3)."""
    a = rot[:, 0]
    return math.atan2(-a[2], float(np.dot(a, u_h)))


def pick_index(phis: np.ndarray, ok: np.ndarray, pref: float, margin: float = math.radians(3)) -> int:
    """Index of the sample to use: ``pref`` if feasible, else the nearest feasible one moved inside."""
    d = np.abs(wrap_angle(phis - pref))
    k = int(np.argmin(np.where(ok, d, np.inf)))
    if d[k] < (phis[1] - phis[0]):
        return k
    # walk inward from the interval edge by the margin (or to the interval's middle if narrower)
    step = int(round(margin / (phis[1] - phis[0])))
    lo = k
    while lo - 1 >= 0 and ok[lo - 1]:
        lo -= 1
    hi = k
    while hi + 1 < len(ok) and ok[hi + 1]:
        hi += 1
    mid = (lo + hi) // 2
    if k == lo:
        return min(k + step, mid) if hi - lo > 0 else k
    return max(k - step, mid)


def takes_pitch(robot: Robot) -> bool:
    """True when every target of the robot's IK has a tool pitch: the RoArm (``roarm5``), whose plans hold
    the default pitch (straight down) and whose pitch is chosen when left out (``pitch: auto``, ``kin ik``)."""
    return (robot.ik or "") == "roarm5"


def accepts_pitch(robot: Robot) -> bool:
    """True when ``solve_ik`` takes ``pitch``/``roll``: the RoArm's closed form and the numerical IK
    (``pitch_aim``); the position-only family ``roarm3`` (three arm joints) does not."""
    return (robot.ik or "") != "roarm3"
