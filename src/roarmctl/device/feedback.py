"""The one judge of arm feedback: every reader of ``T:1051`` frames (``plan --port``, ``execute``'s
start check, ``--from-current``, ``--move-to-start``, the streaming loop, the hold, ``teach``) takes
joint values only through :class:`FeedbackValidator`.

Feedback is not truth. What the firmware can report besides the arm's pose, read from Waveshare's
RoArm-M3 example firmware (public copy github.com/jhacksman/RoArm-M3; 0.84 build under
``leader_follower_mode/firmware/esp32/RoArm-M3_example-250108/RoArm-M3_example/``):

- a servo read that fails keeps the previous position, which is 0 steps until one read succeeded
  (``getFeedback``, RoArm-M3_module.h lines 71-96): 0 steps converts to +pi on base and wrist roll,
  -pi on shoulder and wrist pitch, -pi/2 on the elbow and 0 on the gripper (lines 41-64);
- the 20260701 build also reports per servo the torque-enable byte, which a failed read sets to 0,
  and the INA219 supply voltage ``v`` in centivolts (0 with the servo supply off);
- a frame can be garbled on the wire, and any program on the port can print anything.

A frame is refused, never clamped, when a joint value is not a finite number of sane size, lies
outside the joint's firmware range (its command clamps, ``protocol.SAFE_WIRE_RANGE``, widened by
``range_margin``), moved faster than the servos can since the last accepted frame, looks like a
failed read (+pi on base or roll after a value away from +-pi; a torque flag of 0 while torque must
be on; a supply of 0 V or below the firmware's own 6.00 V alarm). Refused frames are counted and
kept; ``run_limit`` of them in a row raise :class:`FeedbackRefused` (exit 4), whose message names
the joint and the value.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device import protocol
from roarmctl.device.protocol import SAFE_WIRE_RANGE, STEPS_PER_RAD, Feedback, WireMap, wire_seconds
from roarmctl.errors import DeviceError

if TYPE_CHECKING:
    from roarmctl.device.link import LinkLike
    from roarmctl.robot.model import Robot

COUNT = 1.0 / STEPS_PER_RAD  # one servo step, rad
#: The servos' top speed with margin: ST3235 no-load 0.222 s per 60 deg at 12 V = 4.72 rad/s, x 1.25.
MAX_JOINT_SPEED = 5.9
#: Voltage below which the 20260701 build itself says the servos cannot work (Protective_voltage_min 600 cV).
MIN_SUPPLY_V = 6.0
MAX_SUPPLY_V = 12.9
TORQUE_KEYS = {"base": "torswitchB", "shoulder": "torswitchS", "elbow": "torswitchE", "wrist": "torswitchT",
               "roll": "torswitchR", "hand": "torswitchG"}


class FeedbackRefused(DeviceError):
    """Too many refused frames in a row (exit 4): the arm must hold; ``refusals`` are the run."""

    def __init__(self, message: str, hint: str | None = None, refusals: list[Refusal] | None = None) -> None:
        super().__init__(message, hint)
        self.refusals = refusals or []


@dataclass(frozen=True)
class Refusal:
    """Why one frame was refused: ``t`` (s, host clock), the firmware joint (field name) or None
    for the frame as a whole, and the one-line reason."""

    t: float
    joint: str | None
    reason: str


@dataclass(frozen=True)
class Reading:
    """An accepted frame: ``t`` (s, host clock, when its line arrived), ``q`` (dof,) rad in the
    robot's convention, ``wire`` firmware radians by field, and the parsed ``feedback``."""

    t: float
    q: np.ndarray
    wire: dict[str, float]
    feedback: Feedback
    nbytes: int = 230

    def age(self, now: float) -> float:
        """How old the pose is at ``now`` (s): since the line arrived, plus its own wire time
        (the firmware read the servos before it printed the line)."""
        return now - self.t + wire_seconds(self.nbytes)


class FeedbackValidator:
    """Judge the frames of one device for one robot.

    ``firmware``: the build (``Link.firmware``; ``m3-0.84``, ``m3-2026`` or ``m2``), for the elbow
    range and which flags the frames carry. ``expect_torque``: True while the arm must be holding
    (execute: a torque flag 0 is refused), False or None when limp is fine (teach).
    ``max_speed``: rad/s a joint may move between frames; ``run_limit``: refused frames in a row
    before :class:`FeedbackRefused`.
    """

    def __init__(self, robot: Robot, *, firmware: str | None = None, expect_torque: bool | None = True,
                 max_speed: float = MAX_JOINT_SPEED, run_limit: int = 5, range_margin: float = 0.1,
                 slack: float = 0.03, keep: int = 1000) -> None:
        self.robot = robot
        self.wm = WireMap(robot)
        self.firmware = firmware
        self.expect_torque = expect_torque
        self.max_speed = float(max_speed)
        self.run_limit = int(run_limit)
        self.margin = float(range_margin)
        self.slack = float(slack)
        self.last: Reading | None = None
        self.accepted = 0
        self.refused = 0
        self.run = 0
        self.refused_since: float | None = None  # time of the first refused frame since the last accepted one
        self.refusals: deque[Refusal] = deque(maxlen=keep)

    # ------------------------------------------------------------------ ranges
    def wire_range(self, field: str) -> tuple[float, float]:
        """The firmware range (rad) a reading of ``field`` may lie in."""
        lo, hi = SAFE_WIRE_RANGE[field]
        if field in ("base", "roll"):
            lo, hi = -math.pi, math.pi  # the feedback conversion spans (-pi, pi]
        if field == "elbow" and self.firmware == "m3-2026":
            lo = 0.0  # its clamp is 1024 steps
        return lo - self.margin, hi + self.margin

    # ------------------------------------------------------------------ judging
    def judge(self, fb: Feedback | None, t: float, line: str = "") -> tuple[Reading | None, Refusal | None]:
        """Judge one frame without counting it: (reading, None) or (None, refusal)."""
        if fb is None:
            return None, Refusal(t, None, f"not a feedback frame: {line[:60]!r}")
        if fb.problems:
            return None, Refusal(t, _field_of(fb.problems[0]), fb.problems[0])
        if set(self.wm.field_names) - set(fb.joints):
            missing = sorted(set(self.wm.field_names) - set(fb.joints))
            return None, Refusal(t, None, f"the frame lacks {', '.join(missing)} (firmware {fb.firmware})")
        wire = {f: float(fb.joints[f]) for f in self.wm.field_names}
        for f, v in wire.items():
            lo, hi = self.wire_range(f)
            if not lo <= v <= hi:
                sym = f"+-{hi - self.margin:.2f}" if f in ("base", "roll") else f"{lo + self.margin:.2f}..{hi - self.margin:.2f}"
                hint = ": a failed servo read?"
                return None, Refusal(t, f, f"{f} read {v:.3f} rad, outside {sym}{hint}")
        refusal = self._flags(fb, t)
        if refusal is not None:
            return None, refusal
        last = self.last
        for f in ("base", "roll"):
            if f in wire and _is_step_zero(f, wire[f]):
                before = None if last is None else last.wire.get(f)
                if before is None or abs(abs(before) - math.pi) > 0.2:
                    after = "" if before is None else f" after {before:.3f}"
                    return None, Refusal(t, f, f"{f} read +{math.pi:.3f} rad (servo step 0){after}: a failed servo read?")
        if last is not None:
            # after a refused frame the arm's time to move stops at that frame: what came since was
            # impossible, so a later frame must come back near the last accepted one, not merely be
            # reachable from it in the time that has passed (a value that jumped and stayed is refused)
            seen = t if self.refused_since is None else min(t, self.refused_since)
            dt = max(seen - last.t, wire_seconds(len(line) + 2) if line else 0.0) + self.slack
            for f, v in wire.items():
                allowed = self.max_speed * dt + 4 * COUNT
                if abs(v - last.wire[f]) > allowed:
                    return None, Refusal(t, f, f"{f} read {v:.3f} rad, {abs(v - last.wire[f]):.3f} rad from {last.wire[f]:.3f} "
                                               f"{t - last.t:.3f} s before: faster than the servos can move")
        return Reading(t, self.wm.from_wire(wire), wire, fb, len(line) + 2 if line else 230), None

    def _flags(self, fb: Feedback, t: float) -> Refusal | None:
        """The 20260701 build's torque flags and supply voltage."""
        raw = fb.raw
        if "v" in raw:
            v = protocol.number(raw.get("v"))
            if v is None or v / 100.0 < MIN_SUPPLY_V:
                shown = "?" if v is None else f"{v / 100.0:.2f} V"
                return Refusal(t, None, f"supply {shown}: below {MIN_SUPPLY_V:.2f} V, the servos are unpowered "
                                        "(their reads fail)")
        if self.expect_torque:
            for f in self.wm.field_names:
                key = TORQUE_KEYS.get(f)
                if key in raw and protocol.number(raw.get(key)) == 0:
                    return Refusal(t, f, f"{f} torque flag {key} = 0: torque off or a failed servo read")
        return None

    def check(self, fb: Feedback | None, t: float, line: str = "") -> Reading | None:
        """Judge and count one frame: the reading, or None when refused. Raises FeedbackRefused when
        this is the ``run_limit``-th refused frame in a row."""
        reading, refusal = self.judge(fb, t, line)
        if reading is not None:
            self.accepted += 1
            self.run = 0
            self.refused_since = None
            self.last = reading
            return reading
        assert refusal is not None
        self.refused += 1
        self.run += 1
        if self.refused_since is None:
            self.refused_since = t
        self.refusals.append(refusal)
        if self.run >= self.run_limit:
            raise FeedbackRefused(f"feedback refused {self.run} times in a row: {refusal.reason}",
                                  "the arm holds; check the servo power (12 V) and cables, then the log's refused frames",
                                  list(self.refusals)[-self.run:])
        return None

    def fresh(self, now: float, max_age: float) -> Reading | None:
        """The last accepted reading if it is at most ``max_age`` s old at ``now``, else None."""
        if self.last is None or self.last.age(now) > max_age:
            return None
        return self.last

    def summary(self) -> dict[str, Any]:
        """Counts and the last refusals, for the execution log."""
        return {"accepted": self.accepted, "refused": self.refused,
                "refusals": [{"t": r.t, "joint": r.joint, "reason": r.reason} for r in list(self.refusals)[-20:]]}


def _is_step_zero(field: str, v: float) -> bool:
    """Whether ``v`` is what a servo position of 0 steps converts to for ``field`` (a failed first read)."""
    zero = {"base": math.pi, "roll": math.pi, "shoulder": -math.pi, "wrist": -math.pi, "elbow": -math.pi / 2,
            "hand": 0.0}.get(field)
    return zero is not None and abs(v - zero) < 0.5 * COUNT + 1e-6


def _field_of(problem: str) -> str | None:
    head = problem.split(" ", 1)[0]
    return head if head in protocol.M3_FIELDS else None


def read_valid(link: LinkLike, validator: FeedbackValidator, n: int = 2, tries: int = 8, timeout: float = 0.5,
               on_refused: Callable[[Any, Refusal], None] | None = None) -> Reading:
    """Ask ``link`` (``request(timeout) -> Received | None``) for frames until ``n`` in a row were
    accepted (the speed check makes consecutive frames agree); return the last. ``on_refused``
    hears of each refused frame (the received line and why).

    Raises FeedbackRefused (the validator's run, or "no valid feedback" naming the last refusal)
    or DeviceError (device silent).
    """
    got = 0
    last: Reading | None = None
    for _ in range(tries):
        r = link.request(timeout)
        if r is None:
            continue
        before = validator.refused
        try:
            reading = validator.check(r.feedback, r.t, r.line)
        finally:
            if validator.refused > before and on_refused is not None:
                on_refused(r, validator.refusals[-1])
        got = got + 1 if reading is not None else 0
        last = reading or last
        if got >= n and last is not None:
            return last
    if validator.run and validator.refusals:
        raise FeedbackRefused(f"no valid feedback: {validator.refusals[-1].reason}",
                              "check the servo power (12 V) and cables; the arm did not move", list(validator.refusals))
    raise DeviceError("device silent: no feedback when asked (T:105)", "check the arm's power and cable")
