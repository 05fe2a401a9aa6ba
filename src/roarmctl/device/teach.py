"""Teaching by hand: the arm limp, moved by a person, watched through validated feedback, with a warning
before it comes near a singular pose; waypoints and gripper actions recorded; leaving never moves the arm.

Why the warning: near a singular pose small hand motions turn into fast joint motions, and a plan through
such a pose cannot be followed. The measure is the planner's own (``CollisionChecker.margin_measure``: the
smallest singular value of the translational Jacobian, m/rad, the quantity ``planner.singularity_margin``
bounds), shown with the manipulability (product of the Jacobian's singular values, ``Kinematics.manipulability``).
Bands: ``clear`` at or above ``NEAR_FACTOR`` x the margin, ``near`` below it (warning and bell), ``inside``
below the margin itself (a waypoint recorded there is flagged, and ``roarmctl plan`` refuses it).

What the torque command does, from Waveshare's RoArm-M3 example firmware (public copies in
github.com/jhacksman/RoArm-M3): ``{"T":210,"cmd":c}`` calls ``servoTorqueCtrl(254, c)``, a broadcast to every
servo. Build 0.84 (``leader_follower_mode/firmware/esp32/RoArm-M3_example-250108/RoArm-M3_example/``,
``uart_ctrl.h`` 185, ``RoArm-M3_module.h`` 116-121) only switches torque. Build 20260701
(``deployments/2026-09-08-m3-pro/vendor/RoArm-M3_example/RoArm-M3_module.h``, ``servoTorqueCtrl``) first calls
``Move_to_location()`` when switching off: the arm folds to its rest pose (base, wrist and roll to the middle,
shoulder back, elbow up, waiting for each) and only then goes limp, with no feedback meanwhile (the loop blocks):
:data:`SURPRISES` says so before the user confirms. Switched on, a servo drives to the goal it last had
(Feetech STS), which is where the arm stood before teaching: so leaving first writes the *measured* pose as
every servo's goal (a position write also switches a limp servo's torque on), then switches torque on.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device import protocol
from roarmctl.device.execlog import ExecLog
from roarmctl.device.feedback import FeedbackValidator, Reading, read_valid
from roarmctl.device.link import LOST_HINT, Link
from roarmctl.device.pose import within_limits
from roarmctl.device.protocol import WireMap
from roarmctl.device.streamer import HOLD_SPD
from roarmctl.errors import DeviceError
from roarmctl.motion.clearance import clearance
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.frames import device_point, to_frame

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

NEAR_FACTOR = 2.0  # warn within this factor of the planning margin
TORQUE_OFF = {"T": 210, "cmd": 0}
TORQUE_ON = {"T": 210, "cmd": 1}
#: What a build's torque command does that a user would not expect (shown before confirming).
SURPRISES = {
    "m3-2026": ("this firmware build (20260701) first MOVES THE ARM TO ITS REST POSE when torque goes off "
                "(servoTorqueCtrl calls Move_to_location() in its RoArm-M3_module.h), then releases it: keep clear, "
                "and hold the arm once it stops"),
}
HAND_SPEED = 12.0  # rad/s a joint may move between frames while a hand moves it (the servos' check is 5.9)
HAND_RUN_LIMIT = 25  # refused frames in a row before teach leaves (about 0.5 s of frames)
STALE_POSE = 0.3  # s: a measured pose older than this when leaving is stale (the link failed)
STALE_HOLD_SPD = 100  # steps/s (0.15 rad/s) toward a stale pose, where the firmware's own hold speed is 600
MAX_RAW = 1_000_000  # lines kept for --raw (sent + received); beyond, the log says how many were dropped


@dataclass
class Measures:
    """The figures of one pose: ``sigma`` m/rad (the planner's margin measure), ``manipulability``,
    ``band`` (clear / near / inside), ``clearance`` m to the nearest scene item and its name (None
    without a scene), ``problem``: why the planner would refuse the pose ("" when it would not)."""

    sigma: float
    manipulability: float
    band: str
    clearance: float | None = None
    nearest: str | None = None
    problem: str = ""


class Judge:
    """The planner's view of a pose: margin measure, manipulability, band, clearance and validity.

    ``margin`` m/rad: the planning singularity margin (``planner.singularity_margin``); ``items``: the
    scene (``SceneItem``; empty: no clearance); ``padding`` m: the planner's collision padding.
    """

    def __init__(self, robot: Robot, margin: float, items: list[SceneItem] | None = None,
                 padding: float = 0.005) -> None:
        self.robot = robot
        self.margin = float(margin)
        self.items = list(items or [])
        self.checker = CollisionChecker(robot, Scene(self.items), padding=padding, singularity_margin=self.margin or None)

    def band(self, sigma: float) -> str:
        """clear / near (within NEAR_FACTOR x margin) / inside (below the margin)."""
        if sigma < self.margin:
            return "inside"
        return "near" if sigma < NEAR_FACTOR * self.margin else "clear"

    def measure(self, q: np.ndarray, validity: bool = False) -> Measures:
        """Figures at ``q`` (dof,) rad; ``validity``: also ask the checker (record time)."""
        q = np.asarray(q, dtype=float)
        arm = q[self.robot.arm_indices]
        sigma = float(self.checker.margin_measure(arm[None])[0])
        m = Measures(sigma, float(self.robot.kin.manipulability(q).manipulability), self.band(sigma))
        if self.items:
            c = clearance(self.robot, self.items, q[None])
            m.clearance = float(c.distance[0])
            m.nearest = self.items[int(c.item[0])].name if c.item[0] >= 0 else None
        if validity and not self.checker.is_valid(arm):
            m.problem = self.checker.explain(arm)
        return m


@dataclass
class Waypoint:
    """One recorded pose: ``q`` (dof,) rad, ``t`` s since torque went off, ``action`` None / "grasp" /
    "release" (the gripper's value is ``q``'s gripper joint), the measures, and ``flags`` (why the
    planner would refuse it, or that it is within the warning band)."""

    q: np.ndarray
    t: float
    action: str | None
    measures: Measures
    flags: list[str] = field(default_factory=list)


@dataclass
class Frame:
    """What the display shows about one accepted feedback frame."""

    t: float  # s since torque went off
    q: np.ndarray  # (dof,) rad, URDF convention
    tcp_world: np.ndarray  # (3,) m, the plan's world (desk) frame
    tcp_frames: dict[str, tuple[np.ndarray, str]]  # the robot's device frames: name -> (xyz, unit)
    firmware_xyz: tuple[float, float, float] | None  # mm, as the firmware itself reports it (T:1051 x y z)
    measures: Measures
    rate: float  # accepted frames per second, over the last second


class TeachSession:
    """One teaching session on a connected ``link`` (``Link.connect()`` done, ``require_torque`` off).

    Feedback is read at the rate the link sustains: one ``T:105`` in flight, the next asked as soon as its
    answer (a ``T:1051`` line) arrives, every frame through the one :class:`FeedbackValidator`.
    ``lost_after`` s without an accepted frame (``grace`` s right after torque-off, when a build may block)
    is a lost link (``DeviceError``, exit 4). Times from ``clock`` (s).
    """

    def __init__(self, link: Link, robot: Robot, judge: Judge, *, clock: Callable[[], float] = time.monotonic,
                 lost_after: float = 1.0, grace: float = 20.0, ask_again: float = 0.25, keep_raw: bool = False) -> None:
        self.link = link
        self.robot = robot
        self.judge = judge
        self.clock = clock
        self.wm = WireMap(robot)
        # a hand may move a joint faster than its servo can (a frame faster than HAND_SPEED is still refused, as
        # a failed read would be), and a refused frame costs nothing while the arm is limp: a longer run is allowed
        self.validator = FeedbackValidator(robot, firmware=link.firmware, expect_torque=None, max_speed=HAND_SPEED,
                                           run_limit=HAND_RUN_LIMIT)
        self.lost_after, self.grace, self.ask_again = lost_after, grace, ask_again
        self.keep_raw = keep_raw
        self.raw_dropped = 0
        self.t0: float | None = None  # when torque went off
        self.torque_off = False
        self.waypoints: list[Waypoint] = []
        self.holding = False  # the gripper holds something (after a grasp, until a release)
        self.frame: Frame | None = None
        self.last: Reading | None = None
        self.warned = False  # in the near/inside band now (the display rings once on entry)
        self.events: list[tuple[float, str]] = []  # (t, what happened): warnings, records, undo, save
        self.hold_sent: dict[str, Any] | None = None
        self._asked: float | None = None
        self.asked_at: float | None = None  # when the T:105 the newest accepted frame answers was sent (s, clock)
        self._since = clock()
        self._accepted: deque[float] = deque()
        self._gi = gripper_index(robot)

    # ------------------------------------------------------------------ start
    def start(self) -> None:
        """Read the arm (two agreeing frames), then switch torque off."""
        reading = read_valid(self.link, self.validator, n=2)
        self._accept(reading)
        self.link.send(TORQUE_OFF)
        self.torque_off = True
        self.t0 = self._since = self.clock()
        self._asked = None
        self.event("torque off: move the arm by hand")

    def event(self, text: str) -> None:
        """Note what happened (shown by the display, kept in the raw log)."""
        self.events.append((self.elapsed(), text))

    def elapsed(self) -> float:
        """s since torque went off (0 before)."""
        return 0.0 if self.t0 is None else self.clock() - self.t0

    # ------------------------------------------------------------------ feedback
    def fileno(self) -> int | None:
        """The serial port's file descriptor, to wait on (None for ports without one)."""
        try:
            return int(self.link.ser.fileno())
        except Exception:  # noqa: BLE001 - URL ports (loop://, socket://) may have none
            return None

    def pump(self) -> Frame | None:
        """Read what arrived (no waiting), judge it, ask for the next frame; the newest frame or None.
        Raises DeviceError when no frame was accepted for ``lost_after`` s (``FeedbackRefused`` after
        the validator's run of refused frames)."""
        now = self.clock()
        got: Frame | None = None
        for r in self.link.poll():
            if r.feedback is None:
                continue
            asked, self._asked = self._asked, None
            reading = self.validator.check(r.feedback, r.t, r.line)
            if reading is not None:
                got = self._accept(reading)
                self.asked_at = asked
        self._trim()
        now = self.clock()
        limit = self.grace if (self.last is None or (self.t0 is not None and self.last.t < self.t0)) else self.lost_after
        if now - self._since > limit:
            raise DeviceError(f"link lost: no valid feedback from {self.link.port} for {now - self._since:.1f} s",
                              LOST_HINT)
        if self._asked is None or now - self._asked > self.ask_again:
            self.link.send(protocol.feedback_request())
            self._asked = now
        return got

    def _accept(self, reading: Reading) -> Frame:
        self.last = reading
        self._since = max(self._since, reading.t)
        now = reading.t
        self._accepted.append(now)
        while self._accepted and self._accepted[0] < now - 1.0:
            self._accepted.popleft()
        q = within_limits(self.robot, reading.q)
        m = self.judge.measure(q)
        fr = {}
        for name, f in (getattr(self.robot, "frames", {}) or {}).items():
            fr[name] = (to_frame(f, device_point(self.robot, f, q)), f.unit)
        raw = reading.feedback.raw
        fw: tuple[float, float, float] | None = None
        if all(k in raw for k in "xyz"):
            x, y, z = (float(protocol.number(raw.get(k)) or 0.0) for k in "xyz")
            fw = (x, y, z)
        self.frame = Frame(self.elapsed(), q, self.robot.kin.fk(q)[:3, 3].copy(), fr, fw,
                           m, float(len(self._accepted)))
        near = m.band != "clear"
        if near and not self.warned and self.torque_off:
            self.event(f"warning: {'inside' if m.band == 'inside' else 'near'} the singularity margin "
                       f"(sigma {m.sigma:.4f} m/rad, margin {self.judge.margin:.4f}, warn below {NEAR_FACTOR:g}x)")
        elif not near and self.warned:
            self.event(f"clear of the singularity margin again (sigma {m.sigma:.4f} m/rad)")
        self.warned = near
        return self.frame

    def _trim(self) -> None:
        """Bound what the link keeps: everything up to MAX_RAW lines for --raw, else the last few."""
        rec, sent = self.link.received, self.link.sent
        if not self.keep_raw:
            if len(rec) > 200:
                del rec[:-100]
            if len(sent) > 200:
                del sent[:-100]
        elif len(rec) + len(sent) > MAX_RAW:
            self.raw_dropped += len(rec) // 2
            del rec[: len(rec) // 2]

    # ------------------------------------------------------------------ recording
    def record(self, action: str | None = None) -> Waypoint:
        """Record the newest measured pose as a waypoint (``action``: "grasp"/"release" at it).
        Raises DeviceError when there is no recent accepted frame."""
        if self.frame is None or self.last is None or self.clock() - self.last.t > 0.5:
            raise DeviceError("no recent valid feedback to record", "wait for the display to update, then retry")
        q = self.frame.q.copy()
        m = self.judge.measure(q, validity=True)
        flags = []
        if m.problem:
            flags.append(m.problem)
        elif m.band == "near":
            flags.append(f"within {NEAR_FACTOR:g}x the singularity margin (sigma {m.sigma:.4f} m/rad)")
        wp = Waypoint(q, self.elapsed(), action, m, flags)
        self.waypoints.append(wp)
        what = f"{action} {len(self.waypoints)} (gripper {q[self._gi]:.3f} rad)" if action else f"waypoint {len(self.waypoints)}"
        self.event(f"recorded {what}" + (f"  FLAGGED: {'; '.join(flags)}" if flags else ""))
        return wp

    def grasp(self) -> Waypoint:
        """Record a grasp (or, when holding, a release) at the current pose, with the gripper's value."""
        wp = self.record("release" if self.holding else "grasp")
        self.holding = not self.holding
        return wp

    def undo(self) -> Waypoint | None:
        """Drop the last waypoint (and its gripper action)."""
        if not self.waypoints:
            self.event("nothing to undo")
            return None
        wp = self.waypoints.pop()
        if wp.action is not None:
            self.holding = not self.holding
        self.event(f"undone: {wp.action or 'waypoint'} {len(self.waypoints) + 1}")
        return wp

    # ------------------------------------------------------------------ leaving
    def hold_here(self, fresh: float = 0.3) -> dict[str, Any] | None:
        """Leave without a jump: every servo's goal = the measured pose (a ``T:102`` of the newest accepted
        frame, read again for up to ``fresh`` s), then torque on; toward a pose older than ``STALE_POSE`` (a lost
        link: the hand may have moved the arm since) at ``STALE_HOLD_SPD``. Best effort on a failing link: returns what
        was sent ({pose, fresh, t}) or None when nothing could be sent (the arm then stays limp)."""
        if not self.torque_off:
            return None
        reading = self._fresh(fresh)
        if reading is None:
            return None
        stale = self.clock() - reading.t > STALE_POSE
        # a pose measured a while ago (a lost link) may no longer be where the hand holds the arm: go there slowly
        cmd = self.wm.hold(dict(reading.wire), STALE_HOLD_SPD if stale else HOLD_SPD, 0)
        try:
            t = self.link.send(cmd, fresh_line=True)
            self.link.send(TORQUE_ON)
            self.link.ser.flush()
        except Exception:  # noqa: BLE001 - a dead port: the arm stays limp, say so
            return None
        self.torque_off = False
        self.hold_sent = {"t": t, "cmd": cmd, "pose_age_s": round(t - reading.t, 4)}
        self.event(f"torque on at the measured pose (pose {self.hold_sent['pose_age_s'] * 1e3:.0f} ms old"
                   + (f"; stale: servos limited to {STALE_HOLD_SPD} steps/s)" if stale else ")"))
        return self.hold_sent

    def _fresh(self, wait: float) -> Reading | None:
        """A frame newer than the last accepted one if one comes within ``wait`` s, else the last one."""
        end = self.clock() + wait
        try:
            self.link.send(protocol.feedback_request())
            while self.clock() < end:
                for r in self.link.read_for(0.01):
                    if r.feedback is not None:
                        reading, _ = self.validator.judge(r.feedback, r.t, r.line)
                        if reading is not None:
                            self.last = reading
                            return reading
        except Exception:  # noqa: BLE001 - a failing link: the last accepted frame is the measured pose
            pass
        return self.last

    # ------------------------------------------------------------------ the raw log
    def raw_log(self, outcome: str, message: str) -> dict[str, Any]:
        """The feedback stream as an execution log (``roarmctl.execlog/1``: ``roarmctl export`` reads it):
        every command sent and line received, times in s after torque-off."""
        t0 = self.t0 if self.t0 is not None else (self.link.sent[0][0] if self.link.sent else 0.0)
        sent = [{"t": round(t - t0, 6), "cmd": cmd} for t, cmd in self.link.sent]
        received = []
        for r in self.link.received:
            e: dict[str, Any] = {"t": round(r.t - t0, 6), "line": r.line[:protocol.MAX_FEEDBACK_LINE]}
            if r.feedback is not None:
                e["feedback"] = r.feedback.raw
            received.append(e)
        info = self.link.info
        return ExecLog(
            robot=self.robot.name, port=self.link.port, firmware=self.link.firmware, kind="teach",
            device=None if info is None else info.as_dict(), speed_scale=1.0, t0_monotonic=t0,
            details={
                "outcome": outcome, "message": message,
                "singularity_margin": self.judge.margin, "warn_factor": NEAR_FACTOR,
                "feedback": self.validator.summary(), "dropped_lines": self.raw_dropped,
                "hold": None if self.hold_sent is None else dict(self.hold_sent, t=round(self.hold_sent["t"] - t0, 6)),
                "events": [{"t": round(t, 4), "text": s} for t, s in self.events],
                "waypoints": [{"t": round(w.t, 4), "q": [round(float(v), 6) for v in w.q], "action": w.action,
                               "sigma": round(w.measures.sigma, 6), "flags": w.flags} for w in self.waypoints]},
            sent=sent, received=received).to_dict()


def gripper_index(robot: Robot) -> int:
    """Index of the gripper joint in ``robot``'s joint vector (the last joint when it names none)."""
    return robot.joint_index(robot.gripper.joint) if robot.gripper is not None else robot.dof - 1
