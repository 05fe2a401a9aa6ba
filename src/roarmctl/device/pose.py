"""Where the arm is: open the port, connect, read validated ``T:1051`` frames and turn them into a
joint vector.

Used by ``plan --port/--sim`` for ``start: current``. The arm does not move.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from roarmctl.device.feedback import FeedbackValidator, read_valid
from roarmctl.device.link import Link
from roarmctl.device.protocol import Feedback, WireMap

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

COUNT = 2 * np.pi / 4096  # one servo step (rad)


def within_limits(robot: Robot, q: np.ndarray) -> np.ndarray:
    """(dof,) rad: a reading up to two servo counts beyond a joint limit (the 2047 middle reads 0
    as one count off; the 6-decimal rounding of pi) taken as the limit itself; anything further is
    left as it is (the planner then refuses a start outside the limits, naming the joint)."""
    lo, hi = robot.lower, robot.upper
    near = (q >= lo - 2 * COUNT) & (q <= hi + 2 * COUNT)
    return np.where(near, np.clip(q, lo, hi), q)


def configuration_from_feedback(robot: Robot, fb: Feedback) -> np.ndarray:
    """(dof,) rad in the robot's convention (URDF; gripper included) from a parsed ``T:1051``
    already accepted by the validator, with ``within_limits``."""
    return within_limits(robot, WireMap(robot).from_wire(fb.joints))


def read_configuration(port: str, robot: Robot) -> tuple[np.ndarray, Feedback]:
    """Open ``port``, connect, and return (configuration (dof,) rad, feedback) from two consecutive
    frames the validator accepted (torque may be off: the arm is not moved).

    Raises DeviceError (exit 4) for a missing, busy, silent or wrong-firmware port and for feedback
    that is refused (the message names the joint and the value); the port is always closed.
    """
    link = Link(port)
    link.expect = WireMap(robot).model or "m3"  # the firmware the description's wire fields speak (M3 or M2)
    link.require_torque = False
    try:
        link.open()
        link.connect()
        validator = FeedbackValidator(robot, firmware=link.firmware, expect_torque=None)
        reading = read_valid(link, validator, n=2)
        return within_limits(robot, reading.q), reading.feedback
    finally:
        link.close()
