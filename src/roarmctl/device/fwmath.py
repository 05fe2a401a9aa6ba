"""The RoArm-M3 firmware's own arithmetic: radians <-> servo steps with its clamps, its forward and
inverse kinematics, and its degree registers.

Read from Waveshare's RoArm-M3 example firmware 0.84 (public copy: github.com/jhacksman/RoArm-M3,
``leader_follower_mode/firmware/esp32/RoArm-M3_example-250108/RoArm-M3_example/``, called [fw84]
below; the 20260701 build, [fw26], is under ``deployments/2026-09-08-m3-pro/vendor/RoArm-M3_example/``
at commit af66158):

- ``calculatePosByRad`` = round(rad / 2pi * 4096) and ``calculateRadByFeedback`` (RoArm-M3_module.h
  lines 35-64); the per-joint command functions ``RoArmM3_*JointCtrlRad`` with their clamps
  (module.h 255 ff.; [fw26] raises the elbow's lower clamp from 512 to 1024 steps);
- ``RoArmM3_computePosbyJointRad`` (module.h 544-569) with the link lengths of RoArm-M3_config.h;
- ``calculatePosByDeg`` (module.h 987-989), through which T:121/T:122 pass their spd/acc.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from roarmctl.device.protocol import MIDDLE

TWO_PI = 2.0 * math.pi
# Link lengths (RoArm-M3_config.h), mm.
L2A, L2B = 236.82, 30.00
L3A = 144.49
L4A, L4B = 171.67, 13.69
L2 = math.hypot(L2A, L2B)
T2 = math.atan2(L2B, L2A)
LE = math.hypot(L4A, L4B)
TE = math.atan2(L4B, L4A)

#: The firmware's joint state after boot (``*_JOINT_RAD`` in RoArm-M3_config.h): elbow pi/2, gripper pi.
INIT_RAD = (0.0, 0.0, math.pi / 2, 0.0, 0.0, math.pi)


def steps(rad: float) -> int:
    """``calculatePosByRad``: round(rad / 2pi * 4096)."""
    return int(round(rad / TWO_PI * 4096))


def deg_register(value: float, u8: bool = False) -> float:
    """T:121/T:122 ``spd``/``acc``: ``calculatePosByDeg`` (round(deg / 360 * 4096)) written to the
    servo register; the acc register is one byte, so larger values wrap (json_cmd.h says "max: 22.5")."""
    v = int(round(abs(value) / 360.0 * 4096))
    return float(v & 0xFF) if u8 else float(min(v, 65535))


def command_to_goal(joint: int, rad: float, elbow_min_zero: bool = False) -> int:
    """Firmware joint command (rad) -> servo goal step, with the firmware's clamps."""
    if joint == 0:  # base, inverted
        return MIDDLE - steps(min(max(rad, -math.pi), math.pi))
    if joint == 1:  # shoulder (driving servo 12; 13 mirrors it)
        return MIDDLE + steps(min(max(rad, -math.pi / 2), math.pi / 2))
    if joint == 2:  # elbow, clamped in steps ([fw26]: lower clamp 1024, i.e. 0 rad)
        return min(max(1024 + steps(rad), 1024 if elbow_min_zero else 512), 3071)
    if joint == 3:  # wrist
        return MIDDLE + steps(min(max(rad, -math.pi / 2), math.pi / 2))
    if joint == 4:  # roll, inverted
        return MIDDLE - steps(min(max(rad, -math.pi), math.pi))
    return min(max(steps(rad), 700), 3396)  # gripper, no offset


def position_to_rad(joint: int, p: float) -> float:
    """``calculateRadByFeedback``: servo position (steps) -> firmware radians."""
    a = p * TWO_PI / 4096
    return (math.pi - a, a - math.pi, a - math.pi / 2, a - math.pi, math.pi - a, a)[joint]


def firmware_fk(b: float, s: float, e: float, t: float) -> tuple[float, float, float, float]:
    """``RoArmM3_computePosbyJointRad``: x, y, z (mm, origin on the base axis at shoulder height), tit."""
    r = L2 * math.sin(s + T2) + L3A * math.sin(e + s) + LE * math.sin(e + s + t + TE)
    z = L2 * math.cos(s + T2) + L3A * math.cos(e + s) + LE * math.cos(e + s + t + TE)
    return r * math.cos(b), r * math.sin(b), z, e + s + t - math.pi / 2


def firmware_ik(x: float, y: float, z: float, pitch: float) -> tuple[float, float, float, float] | None:
    """Inverse of ``firmware_fk`` (elbow-up branch): b, s, e, t, or None when out of reach."""
    b = math.atan2(y, x) if (x or y) else 0.0
    r = math.hypot(x, y)
    phi = pitch + math.pi / 2  # = e + s + t
    rw, zw = r - LE * math.sin(phi + TE), z - LE * math.cos(phi + TE)
    c = (rw * rw + zw * zw - L2 * L2 - L3A * L3A) / (2 * L2 * L3A)
    if not -1.0 <= c <= 1.0:
        return None
    g = math.acos(c)
    alpha = math.atan2(rw, zw) - math.atan2(L3A * math.sin(g), L2 + L3A * math.cos(g))
    s = alpha - T2
    e = g + T2
    return b, s, e, phi - e - s


def urdf_from_firmware(rad6: npt.ArrayLike) -> np.ndarray:
    """Firmware radians (base..hand) -> URDF joint vector of the M3 (identity, gripper pi - hand)."""
    q = np.array(rad6, dtype=float)
    q[..., 5] = math.pi - q[..., 5]
    return q
