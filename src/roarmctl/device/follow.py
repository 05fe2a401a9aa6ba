"""Follow a live source: targets from a leader arm or a policy, judged by the guard, followed with jerk-limited
motion over the link, at the firmware's pace; the one hold when anything goes wrong.

Each pass of the loop (``rate`` passes per second on an absolute schedule): the source's new frames, each through
the :class:`~roarmctl.device.follow_guard.Guard` (whose last check is the jerk-limited motion it would start:
:class:`~roarmctl.device.follow_motion.Smoother`); then, unless the firmware is behind, the motion's next set-point
as a ``T:102`` (``spd`` from the set-point's speed, as the streamer's timed strategy); a ``T:105`` poll every few
passes, its answers through the follower's own :class:`~roarmctl.device.feedback.FeedbackValidator`.

Pacing, as the streamer's (``roarmctl.device.streamer``): the firmware answers polls in order, so the lines each
answer confirms are counted; with more than ``max_unconfirmed`` lines unconfirmed, or a poll answered later than the
round trip measured at connect, no set-point is sent that pass and the motion's clock waits (the servos, which go
straight from goal to goal, never cut a corner of the checked motion).

Ends: the source's clean end (end of its stream) lets the motion finish at the last accepted target (completed);
``SourceLost`` (too many refusals in a row, silence), a refused follower feedback run, silent follower feedback,
a lost link or a stop signal hold the arm at the last set-point sent (``roarmctl.device.hold``) and raise.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from roarmctl.checks import Bound, check_options
from roarmctl.device import protocol
from roarmctl.device.feedback import FeedbackRefused, FeedbackValidator, read_valid
from roarmctl.device.follow_guard import Guard, GuardLimits, SourceLost, Target, Verdict
from roarmctl.device.follow_motion import Motion, Smoother
from roarmctl.device.hold import HOLD_SPD, send_hold
from roarmctl.device.protocol import WireMap, spd_register
from roarmctl.errors import DeviceError, Interrupted, signal_name

if TYPE_CHECKING:
    from roarmctl.device.link import LinkLike, Received
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.robot.model import Robot

#: A set-point's spd: its fastest joint's speed x this (the servo arrives within the interval); its acc is 0 (no ramp
#: of the servo's own: the set-points are jerk-limited already). On the simulated arm following a leader, acc from the
#: motion's acceleration (x 1.5, at least 5, as the streamer's timed strategy) lagged the set-points by 0.135 s, acc 0
#: by 0.06 s (tests/device/followsim.py's swing).
SPD_MARGIN = 1.2


class SourceEnded(Exception):  # noqa: N818 - a clean end, not an error
    """The source ended cleanly (its stream closed): the arm finishes at the last accepted target."""


class Source(Protocol):
    """Where targets come from: ``poll(now)`` returns the frames that arrived (never waits; raises SourceEnded at
    a clean end, SourceLost or DeviceError when it is gone); ``refusals()`` the frames it refused itself since the
    last call, as (host time s, reason); ``close()`` gives back what it holds."""

    name: str

    def poll(self, now: float) -> list[Target]:
        """The frames that arrived by ``now`` (s, host clock); never waits."""

    def refusals(self) -> list[tuple[float, str]]:
        """Frames refused by the source itself since the last call: (host time s, reason)."""

    def close(self) -> None:
        """Give back what the source holds (a port, a socket)."""


#: FollowConfig's bounds (``roarmctl.checks.check_options``): rates in 1/s, times in s.
FOLLOW_BOUNDS = {
    "rate": Bound(1.0, 90.0, strict_lo=True),  # T:102 lines/s: 115200 baud carries about 90
    "feedback_rate": Bound(1.0, 90.0, strict_lo=True),
    "first_frame": Bound(0.0, 3600.0, strict_lo=True),
    "stale_after": Bound(0.0, 60.0, strict_lo=True),
    "max_unconfirmed": Bound(1, 100, whole=True),
    "behind_after": Bound(0.0, 10.0, strict_lo=True),
    "duration": Bound(0.0, 86400.0, strict_lo=True, optional=True),
    "guard": Bound(instance=GuardLimits),
}


@dataclass(frozen=True)
class FollowConfig:
    """The follower's options, each checked on creation (``FOLLOW_BOUNDS``). ``rate``: set-points per second;
    ``feedback_rate``: ``T:105`` polls per second; ``first_frame``: s to wait for the source's first frame (a policy
    may load a model first); ``stale_after``: s a poll may stay unanswered (plus the round trip) before the
    follower's link counts as lost; ``max_unconfirmed``, ``behind_after``: the firmware's pacing (see the module
    docstring); ``guard``: the checks every target passes."""

    rate: float = 50.0
    feedback_rate: float = 25.0
    first_frame: float = 30.0
    stale_after: float = 0.3
    max_unconfirmed: int = 12
    behind_after: float = 0.04
    duration: float | None = None  # s: stop taking targets after this long (None: until the source ends)
    guard: GuardLimits = field(default_factory=GuardLimits)

    def __post_init__(self) -> None:
        check_options(self, FOLLOW_BOUNDS)


@dataclass
class FollowResult:
    """How following ended (``outcome``: completed / aborted / interrupted / terminated / link_lost / failed,
    ``message``), and the log (``log``)."""

    outcome: str
    message: str
    log: dict[str, Any]

    def summary(self) -> dict[str, Any]:
        """The log's summary."""
        return dict(self.log.get("summary", {}))


class Follower:
    """Follow ``source`` with the arm on ``link`` (open, connected) for ``robot``, every target judged against
    ``checker`` (the scene, padding and singularity margin). ``clock``/``sleep``/``timer`` are injectable (tests
    run on a virtual clock; ``timer`` measures the computation per target, s). ``on_event(text)`` hears every
    refusal and end (the screen). ``extra_lateness() -> s``: how late the device itself is (the simulator
    measures its own), added to the time a poll may stay unanswered. ``on_tick()`` is called once a pass, after the
    wait for it (what it raises ends the following and holds the arm: the CLI checks for a stop there)."""

    def __init__(self, link: LinkLike, robot: Robot, checker: CollisionChecker, source: Source,
                 config: FollowConfig | None = None, *, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, timer: Callable[[], float] = time.perf_counter,
                 on_event: Callable[[str], None] | None = None,
                 extra_lateness: Callable[[], float] | None = None, on_tick: Callable[[], None] | None = None) -> None:
        self.link, self.robot, self.checker, self.source = link, robot, checker, source
        self.cfg = config or FollowConfig()
        self.clock, self.sleep, self.timer, self.on_event = clock, sleep, timer, on_event
        self.extra_lateness, self.on_tick = extra_lateness, on_tick
        self.wm = WireMap(robot)
        self.dt = 1.0 / self.cfg.rate
        self.validator = FeedbackValidator(robot, firmware=link.firmware)
        self.guard: Guard | None = None
        self.smoother: Smoother | None = None
        self.t0 = math.nan
        self.events: list[tuple[float, str]] = []
        self.targets: list[dict[str, Any]] = []  # every frame: when, its stamp, q, verdict
        self.commanded: list[tuple[float, np.ndarray]] = []  # (host time s, set-point (dof,) rad)
        self.measured: list[tuple[float, np.ndarray]] = []  # (arrival s, accepted follower pose (dof,) rad)
        self.cost: list[float] = []  # s of computation per target (guard + motion)
        self.waits = 0  # passes without a set-point: the firmware was behind
        self.hold_info: dict[str, Any] | None = None
        self._last_cmd: dict[str, Any] | None = None
        self._wire: np.ndarray | None = None  # the last set-point sent, firmware radians
        self._polls: deque[tuple[float, int]] = deque()
        self._planned: Motion | None = None  # the motion the guard's last check planned

    # ------------------------------------------------------------------ run
    def run(self) -> FollowResult:
        """Follow until the source ends (completed) or something goes wrong (the arm holds, then
        SourceLost / DeviceError / Interrupted is raised with the result as its ``result``)."""
        outcome, message = "completed", "the source ended; the arm stands at its last accepted target"
        exc_out: Exception | None = None
        try:
            self._start()
            self._loop()
        except KeyboardInterrupt as exc:
            signum = getattr(exc, "signum", 2)
            outcome = "interrupted" if signum == 2 else "terminated"
            message = f"stopped by {signal_name(signum)}; the arm holds where it was"
            exc_out = Interrupted(message, signum=signum)
        except SourceLost as exc:
            outcome, message = "aborted", exc.message
            exc_out = SourceLost(exc.message, exc.hint)
        except FeedbackRefused as exc:
            outcome, message = "aborted", f"the arm's own feedback: {exc.message}"
            exc_out = DeviceError(message, exc.hint)
        except DeviceError as exc:
            outcome, message = ("link_lost" if self.commanded else "failed"), exc.message
            exc_out = DeviceError(exc.message, exc.hint)
        if outcome != "completed":
            self._hold(outcome)
        self.event(message)
        result = FollowResult(outcome, message, self.log(outcome, message))
        if exc_out is not None:
            exc_out.result = result  # type: ignore[attr-defined]
            raise exc_out
        return result

    def event(self, text: str) -> None:
        """Note what happened (the log and ``on_event``)."""
        t = 0.0 if math.isnan(self.t0) else self.clock() - self.t0
        self.events.append((t, text))
        if self.on_event is not None:
            self.on_event(text)

    def _start(self) -> None:
        self.validator.firmware = self.link.firmware
        reading = read_valid(self.link, self.validator, 2)
        start = np.clip(reading.q, self.robot.lower, self.robot.upper)
        g = self.cfg.guard
        self.guard = Guard(self.robot, self.checker, g, start=start)
        self.smoother = Smoother(self.robot, start, self.dt, velocity_scale=g.velocity_scale,
                                 acceleration_scale=g.acceleration_scale)
        self.t0 = self.clock()
        self.event(f"following {self.source.name}")

    def _loop(self) -> None:
        assert self.guard is not None and self.smoother is not None
        cfg, link = self.cfg, self.link
        info = link.info
        rtt = info.rtt if info is not None else 0.03
        poll_every = max(1, round(cfg.rate / cfg.feedback_rate))
        lines, confirmed, k = 0, 0, 0
        ended = False
        link.poll()
        while True:
            due = self.t0 + k * self.dt
            wait = due - self.clock()
            if wait > 0:
                self.sleep(wait)
            if self.on_tick is not None:
                self.on_tick()
            now = self.clock()
            if not ended and cfg.duration is not None and now - self.t0 >= cfg.duration:
                ended = True
                self.event(f"{cfg.duration:g} s followed: finishing the motion to the last accepted target")
            if not ended:
                try:
                    self._take(self.source.poll(now))
                except SourceEnded:
                    ended = True
                    self.event("the source ended: finishing the motion to its last accepted target")
                self._refused_by_source()
                if ended:  # a clean end is not silence (frames that queued up may have come long before it)
                    pass
                elif self.guard.heard is None:
                    if now - self.t0 > cfg.first_frame:
                        raise SourceLost(f"source lost: no frame in the first {cfg.first_frame:g} s",
                                         "start the source (the policy process, the leader) and follow again")
                else:
                    self.guard.check_silence(now)
            polls = self._polls
            behind = lines - confirmed > cfg.max_unconfirmed or bool(polls and now - polls[0][0] > rtt + cfg.behind_after)
            moving = self.smoother.moving
            if moving and behind:
                self.waits += 1
            elif moving:
                lines += self._send_setpoint(now)
            if (k % poll_every == 0 or not polls) and len(polls) < 2:
                t_poll = link.send(protocol.feedback_request())
                lines += 1
                polls.append((t_poll, lines))
            polled = self.clock()
            for r in link.poll():
                if r.feedback is not None and polls:
                    confirmed = polls.popleft()[1]
                self._judge(r)
            # overdue when unanswered at the last read (a host stopped before the read does not blame the arm), beyond
            # what the device itself says it is late (the simulator measures its own)
            late = self.extra_lateness() if self.extra_lateness is not None else 0.0
            if polls and polled - polls[0][0] > cfg.stale_after + rtt + late:
                raise DeviceError(f"link lost: the arm did not answer for {polled - polls[0][0]:.2f} s",
                                  "check the USB cable and the arm's power; the arm may have rebooted")
            if ended and not self.smoother.moving:
                return
            k += 1
            late = self.clock() - (self.t0 + k * self.dt)
            if late > self.dt:  # a stalled host: the schedule goes on from now (the motion's clock waited too)
                k += int(late / self.dt)

    def _take(self, frames: list[Target]) -> None:
        """Judge each frame; an accepted one starts its motion."""
        assert self.guard is not None and self.smoother is not None
        for tg in frames:
            started = self.timer()
            self._planned = None
            try:
                verdict = self.guard.check(tg, self._motion_ok)
            except SourceLost:
                self._note(tg, self.guard.refusals[-1]["reason"])
                raise
            finally:
                self.cost.append(self.timer() - started)
            self._note(tg, verdict.reason)
            if verdict.accepted:
                assert self._planned is not None
                self.smoother.take(self._planned)
            else:
                self.event(f"refused: {verdict.reason}")

    def _motion_ok(self, q: np.ndarray) -> Verdict | None:
        """The guard's last check: the jerk-limited motion to ``q`` that would be commanded (kept in ``_planned``)."""
        assert self.smoother is not None
        m = self.smoother.plan(q)
        if isinstance(m, str):
            return Verdict("motion", m)
        self._planned = m
        return self.smoother.check(m, self.checker, self.cfg.guard.resolution)

    def _note(self, tg: Target, reason: str) -> None:
        q = np.asarray(tg.q, dtype=float)
        self.targets.append({"t": round(tg.received - self.t0, 6), "stamp": tg.t if math.isfinite(tg.t) else None,
                             "q": [round(float(v), 6) if math.isfinite(v) else None for v in q.ravel()],
                             **({"refused": reason} if reason else {})})

    def _refused_by_source(self) -> None:
        """Frames the source refused itself (a leader's feedback the validator refused, a line that is not JSON)
        count as refusals too."""
        assert self.guard is not None
        for t, reason in self.source.refusals():
            self.targets.append({"t": round(t - self.t0, 6), "refused": reason})
            self.event(f"refused: {reason}")
            self.guard.refuse_frame(t, "source", reason)

    def _send_setpoint(self, now: float) -> int:
        assert self.smoother is not None
        before = self.smoother.position.copy()
        q = self.smoother.step()
        wire = self.wm.to_wire_array(q)[0]
        prev = self.wm.to_wire_array(before)[0]
        speed = float(np.max(np.abs(wire - prev))) / self.dt
        cmd = self.wm.command(q, spd_register(speed * SPD_MARGIN, minimum=50), 0)
        t = self.link.send(cmd)
        self.commanded.append((t, q.copy()))
        self._last_cmd, self._wire = cmd, wire
        return 1

    def _judge(self, r: Received) -> None:
        if r.feedback is None:
            return
        reading = self.validator.check(r.feedback, r.t, r.line)
        if reading is not None:
            self.measured.append((reading.t, reading.q))

    # ------------------------------------------------------------------ the hold
    def _hold(self, outcome: str) -> None:
        """Hold at the last set-point sent (on the checked motion), or at the measured pose before any."""
        link = self.link
        if getattr(link, "closed", False) or getattr(link, "ser", True) is None:
            return
        try:
            wire = self._wire
            kind = "setpoint"
            if wire is None:
                last = self.validator.last
                if last is None:
                    self.event("no hold sent: nothing was commanded and no valid pose was read")
                    return
                wire, kind = np.array([last.wire[f] for f in self.wm.field_names]), "measured"
            spd = max(HOLD_SPD, int((self._last_cmd or {}).get("spd", 0) or 0))
            self.hold_info = send_hold(link, self.wm, wire, spd, kind=kind, cause=outcome, earlier=len(self._polls),
                                       on_answer=self._judge_quietly)
        except KeyboardInterrupt:  # a second signal during the hold: send it again, once
            try:
                if self._wire is not None:
                    self.hold_info = send_hold(link, self.wm, self._wire, HOLD_SPD, kind="setpoint", cause=outcome)
            except DeviceError:
                self.event("hold could not be sent: the link is gone")
        except DeviceError:
            self.event("hold could not be sent: the link is gone")

    def _judge_quietly(self, r: Received) -> None:
        try:
            self._judge(r)
        except FeedbackRefused:
            pass

    # ------------------------------------------------------------------ the log
    def log(self, outcome: str, message: str) -> dict[str, Any]:
        """The follow log (JSON-ready): times in s after the start."""
        t0 = 0.0 if math.isnan(self.t0) else self.t0
        cost = np.array(self.cost) * 1e3
        pct = (lambda p: round(float(np.percentile(cost, p)), 4)) if len(cost) else (lambda p: None)  # noqa: E731
        hold = None if self.hold_info is None else dict(self.hold_info, t=round(self.hold_info["t"] - t0, 6))
        return {
            "format": "roarmctl.followlog/1", "robot": self.robot.name, "source": self.source.name,
            "port": self.link.port, "firmware": self.link.firmware,
            "rate": self.cfg.rate, "joint_names": list(self.robot.joint_names), "t0_monotonic": t0,
            "summary": {"outcome": outcome, "message": message, "setpoints": len(self.commanded),
                        "targets": self.guard.summary() if self.guard is not None else None,
                        "cost_ms": {"p50": pct(50), "p99": pct(99), "max": round(float(cost.max()), 4) if len(cost) else None,
                                    "targets": len(cost)},
                        "waits": self.waits, "feedback": self.validator.summary()},
            "hold": hold, "events": [[round(t, 6), e] for t, e in self.events],
            "targets": self.targets,
            "commanded": [[round(t - t0, 6), *(round(float(v), 6) for v in q)] for t, q in self.commanded],
            "measured": [[round(t - t0, 6), *(round(float(v), 6) for v in q)] for t, q in self.measured],
        }
