"""Where the arm is: open the port, handshake, read one ``T:1051`` and turn it into a joint vector.

Used by ``plan --port/--sim`` for ``start: current``. The arm does not move.
"""

from __future__ import annotations

import numpy as np

from roarmctl.device.link import Link
from roarmctl.device.protocol import Feedback, WireMap
from roarmctl.errors import DeviceError

COUNT = 2 * np.pi / 4096  # one servo step (rad)


def configuration_from_feedback(robot, fb: Feedback) -> np.ndarray:
    """(dof,) rad in the robot's convention (URDF; gripper included) from a parsed ``T:1051``.

    A reading up to two servo counts beyond a joint limit (the 2047 middle reads 0 as one count
    off; the 6-decimal rounding of pi) is taken as the limit itself.
    """
    q = WireMap(robot).from_wire(fb.joints)
    lo, hi = robot.lower, robot.upper
    near = (q >= lo - 2 * COUNT) & (q <= hi + 2 * COUNT)
    return np.where(near, np.clip(q, lo, hi), q)


def read_configuration(port: str, robot) -> tuple[np.ndarray, Feedback]:
    """Open ``port``, handshake (M3 firmware required) and return (configuration (dof,) rad, feedback).

    Raises DeviceError (exit 4) for a missing, busy, silent or wrong-firmware port; the port is always closed.
    """
    link = Link(port)
    link.expect = WireMap(robot).model  # the firmware the description's wire fields speak (M3 or M2)
    try:
        link.open()
        fb = link.handshake()
        newer = link.request_feedback(0.5)  # the handshake's frame may predate the quiet command
        fb = newer or fb
        if not fb.joints:
            raise DeviceError(f"{port}: the feedback has no joint values", "expected RoArm-M3 firmware")
        return configuration_from_feedback(robot, fb), fb
    finally:
        link.close()
