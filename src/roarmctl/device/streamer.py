"""Stream a timed trajectory to the arm: the real-time loop, the feedback it trusts, the hold, the log.

The loop (``Streamer``) runs on an absolute monotonic schedule (``due = t0 + t_k``: no drift) from
``roarmctl.device.schedule``. It paces itself to the firmware: it polls ``T:105`` between commands,
counts the command lines each answer confirms (the firmware answers in order), and waits while the
firmware is behind (answers later than the round trip measured at connect), so no backlog can build on
either build. Every tick is sent, in order: when the host (or a behind firmware) made a tick so late that
the next one is due too, the plan waits (its clock pauses: ``paused``) rather than the stream jumping to
the tick due by the clock. The servos run straight from one goal to the next (one ``spd`` for every
joint), so a jump across a stall cut the planned path (a 0.3 s stall in a detour round a post touched the
post); with the pause the arm stops on the path and goes on along it, late but where it was planned.
Every feedback frame goes through the one validator (``roarmctl.device.feedback``); a run of refused
frames, a tracking error beyond the bound (measured against the plan with the lateness the loop
measured), lost feedback, Ctrl-C/SIGTERM/SIGHUP or a lost link end the stream with a hold.

The hold stops the arm where it is, with torque on: where it goes is chosen in ``roarmctl.device.stream_hold``
(by default the point of the planned path the arm reaches when the hold arrives; on the 20260701 build the goal of
the last line the firmware confirmed), how it is made to run in ``roarmctl.device.hold``. What a run reports
(``Status``, ``Result``, the execution log): ``roarmctl.device.stream_result``.
The choice and its figures: ``docs/guide.md``, "Talking to the firmware".
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device import protocol, st3235, stream_hold
from roarmctl.device.feedback import FeedbackRefused, FeedbackValidator, Reading, read_valid
from roarmctl.device.hold import HOLD_SPD
from roarmctl.device.options import HOLD_MODES, StreamConfig
from roarmctl.device.pacing import Pacer
from roarmctl.device.pose import within_limits
from roarmctl.device.protocol import WireMap, wire_seconds
from roarmctl.device.schedule import (
    DEFAULT_RATE,
    FEEDBACK_RATE,
    MAX_LINK_RATE,
    STRATEGIES,
    T105_BYTES,
    LinkBudget,
    Strategy,
    Tick,
    build_schedule,
    default_latency,
    link_budget,
    plan_clock,
    sample,
    strategy_rate,
)
from roarmctl.device.stream_result import Result, Status, run_log, tcp
from roarmctl.errors import DeviceError, InfeasibleError, Interrupted, signal_name

if TYPE_CHECKING:
    from roarmctl.device.link import LinkLike, Received
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

__all__ = [
    "DEFAULT_RATE",
    "FEEDBACK_RATE",
    "HOLD_SPD",
    "MAX_LINK_RATE",
    "STRATEGIES",
    "Result",
    "Status",
    "Strategy",
    "StreamConfig",
    "Streamer",
    "Tick",
    "build_schedule",
    "default_latency",
    "sample",
]

#: How far behind its goal a servo may be (s): the ST3235's P-only position loop follows a goal moving
#: at constant speed ``st3235.LOOP_LAG`` (46 ms) late, and more while it accelerates or carries a load
#: (1.5 x). The tracking check compares the arm with the plan anywhere in that window (less what the
#: strategy's lead already makes up), so a lagging arm is not a fault and a stalled one still is.
SERVO_LAG = 1.5 * st3235.LOOP_LAG
CONFIRM_EVERY = 0.1  # s: the longest a stream goes without a poll (while the firmware keeps up)
#: Polls per second once the firmware is the bottleneck (``Streamer.firmware_bound``): on the 20260701 build each poll's
#: 324-byte answer holds the loop while the UART drains, so a poll costs the firmware more than a motion line; at 12.5
#: polls/s they took most of a 22 ms loop, the rate fell to 10 Hz, and a hold had up to 97 ms of line left to run
FIRMWARE_BOUND_POLL_RATE = 5.0
READ_EVERY = 0.005  # s: the stream reads the link at least this often while it waits
READ_BEFORE_PRINT = protocol.READ_BEFORE_PRINT  # s between the firmware's servo reads and the start of its T:1051 line



class _Abort(Exception):
    """Tracking error beyond the bound (internal; becomes DeviceError after the hold)."""


class Streamer:
    """Run one trajectory over an open, connected link (``LinkLike``: a ``Link``, or a ``VirtualLink`` in tests).

    ``clock``/``sleep`` are injectable (tests); ``on_status(Status)`` is called after each tick
    (the live display; ``on_start()`` before the first); ``hook(k)`` is called before tick k is sent
    (tests raise KeyboardInterrupt from it); ``confirm(message) -> bool`` is asked before any motion.
    ``replan(q_measured, mode) -> (Trajectory, sentence)`` plans from the measured pose when the arm
    is not at the start (``roarmctl.motion.replan.replan_start``; modes ``gripper`` - only the
    gripper differs, always done -, ``move_to_start``, ``from_current``); ``on_note(sentence)`` says
    so. ``extra_lateness() -> s``: lateness of the device itself (the simulator measures its own; a
    real ESP32 has none), added to the tracking check's time window. ``shield()``: a context manager that keeps a
    stop signal out of a block (the CLI's); each tick's send and its bookkeeping run inside it, so that the log's
    count of motion commands is the count its ``sent`` list shows, whenever the signal comes.
    """

    def __init__(self, link: LinkLike, robot: Robot, traj: Trajectory, config: StreamConfig | None = None, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_status: Callable[[Status], None] | None = None, hook: Callable[[int], None] | None = None,
                 confirm: Callable[[str], bool] | None = None, on_start: Callable[[], None] | None = None,
                 replan: Callable[[np.ndarray, str], tuple[Any, str]] | None = None,
                 on_note: Callable[[str], None] | None = None,
                 extra_lateness: Callable[[], float] | None = None,
                 shield: Callable[[], AbstractContextManager[Any]] = contextlib.nullcontext) -> None:
        self.link = link
        self.robot = robot
        self.traj = traj
        self.cfg = config or StreamConfig()
        if self.cfg.hold not in HOLD_MODES:
            raise ValueError(f"hold must be one of {HOLD_MODES}")
        self.clock = clock
        self.sleep = sleep
        self.on_status = on_status
        self.hook = hook
        self.confirm = confirm
        self.on_start = on_start  # after the confirmation, before the clock starts (start a display)
        self.replan = replan
        self.on_note = on_note
        self.extra_lateness = extra_lateness
        self.shield = shield
        self.wm = WireMap(robot)
        self.rate = strategy_rate(self.cfg.strategy, self.cfg.rate)
        strat = self.cfg.strategy
        # s the targets lie ahead on the plan (timed-lead)
        self.lead = (STRATEGIES[strat] if isinstance(strat, str) else strat).lead
        self.schedule = self._schedule(traj)
        self.validator = FeedbackValidator(robot, firmware=link.firmware)
        self.measured: np.ndarray | None = None
        self.setpoint: Tick | None = None  # the last tick sent
        self.t0 = math.nan
        self.sent_lateness: list[tuple[int, float]] = []
        self.tracking: list[tuple[float, float]] = []
        self.notes: list[str] = []
        # (plan time s at which the plan's clock stopped, for how long s): where the host, or a firmware behind, made a
        # tick so late that the next was due too; the stream went on from that tick, everything after it that late
        self.paused: list[tuple[float, float]] = []
        self.shift = 0.0  # s: the pauses so far (tick k is due at t0 + shift + t_k)
        self.waits = {"late": 0, "behind": 0}  # ticks waited for: the host came after the next was due; the firmware was behind
        self.hold_info: dict[str, Any] | None = None
        self.pacer = Pacer(0.03, 0.0, self.cfg.in_flight)  # lines and polls in flight (replaced when streaming starts)
        self.poll_every = 1  # a T:105 with every this many ticks
        self.firmware_bound = False  # the firmware's time per line limits the stream: fewer polls, no gripper line
        self.rate_changes: list[dict[str, Any]] = []  # where the stream went on at a lower rate, and why
        self.refused_lines: dict[int, str] = {}  # id(Received) -> reason, for the log
        self.tick_of: dict[int, int] = {}  # id(first command sent for a tick) -> tick
        self.read_at: dict[int, float] = {}  # id(Received) -> when its servos were read (s, clock): the log's read_t
        self._reading_at: dict[int, float] = {}  # the same by id(Reading), for the tracking check
        self.device_late: deque[tuple[float, float]] = deque(maxlen=1000)  # (when seen, how late) of poll answers

    def _schedule(self, traj: Trajectory) -> list[Tick]:
        return build_schedule(traj, self.robot, rate=self.cfg.rate, speed_scale=self.cfg.speed_scale, sag=self.cfg.sag,
                              strategy=self.cfg.strategy)

    def link_budget(self) -> LinkBudget:
        """The schedule's ``LinkBudget`` on this link: its poll rate, the length of the feedback lines it
        has seen (0.84: about 230 bytes; 20260701: about 324) and, on a queuing build, its line time."""
        info = self.link.info
        seen = [len(r.line) + 2 for r in self.link.received[-20:] if r.feedback is not None]
        return link_budget(self.schedule, self.poll_rate(), reply_bytes=max(seen) if seen else 230,
                           line_time=info.line_time if info is not None and info.queued else None)

    # ------------------------------------------------------------------ helpers
    def poll_rate(self) -> float:
        """T:105 polls per second during motion: ``feedback_rate`` if set, else ``FEEDBACK_RATE`` (25), halved
        on a build that runs one queued line per loop pass (20260701): each of its 324-byte answers blocks
        its loop while the UART drains, and the commands wait behind it. On the physics servos (pick_place,
        timed-lead, three runs each) 12.5 polls/s there gave 3.9-4.0 mm TCP RMS and 12 ms of lag, 25 polls/s
        5.3-5.9 mm and 20-22 ms. Once the firmware is the bottleneck (``firmware_bound``): ``FIRMWARE_BOUND_POLL_RATE``."""
        if self.cfg.feedback_rate is not None:
            return self.cfg.feedback_rate
        if self.firmware_bound:
            return FIRMWARE_BOUND_POLL_RATE
        info = self.link.info
        return FEEDBACK_RATE / 2 if info is not None and info.queued else FEEDBACK_RATE

    def judge(self, received: Iterable[Received], asked: dict[int, float] | None = None) -> list[Reading]:
        """Every T:1051 of ``received`` through the validator (raises FeedbackRefused on a run).
        ``asked``: id(Received) -> when the T:105 it answers was sent (its servo reads are dated from that)."""
        out = []
        for r in received:
            if r.feedback is None:
                continue
            reading = self.validator.check(r.feedback, r.t, r.line)
            if reading is None:
                self.refused_lines[id(r)] = self.validator.refusals[-1].reason
                continue
            self.read_at[id(r)] = self._reading_at[id(reading)] = self._servos_read_at(reading, (asked or {}).get(id(r)))
            self.measured = reading.q
            out.append(reading)
        return out

    def _read_frames(self, n: int) -> Reading:
        """``n`` accepted frames in a row; the last (refused ones are marked in the log)."""
        reading = read_valid(self.link, self.validator, n,
                             on_refused=lambda r, why: self.refused_lines.__setitem__(id(r), why.reason))
        self.measured = reading.q
        return reading

    def _check_start(self) -> None:
        self.validator.firmware = self.link.firmware
        reading = self._read_frames(2)
        q0 = self.traj.positions[0]
        diff = self._start_diff(reading.q, q0)
        if diff is None:
            return
        if self._start_diff(reading.q, q0, arm_only=True) is None:
            mode = "gripper"  # chained runs: the arm is there, only the gripper is not
        elif self.cfg.from_current:
            mode = "from_current"
        elif self.cfg.move_to_start:
            mode = "move_to_start"
        else:
            raise InfeasibleError(f"the arm is not at the trajectory's start: {diff}",
                                  "pass move_to_start (a planned, collision-checked motion there first) or "
                                  "from_current (plan the first free motion again from here)")
        if self.replan is None:
            raise InfeasibleError(f"the arm is not at the trajectory's start: {diff}", "move it there first")
        traj, sentence = self.replan(within_limits(self.robot, reading.q), mode)
        self.traj = traj
        self.schedule = self._schedule(traj)
        self.notes.append(sentence)
        if self.on_note is not None:
            self.on_note(sentence)

    def _start_diff(self, q: np.ndarray, q0: np.ndarray, arm_only: bool = False) -> str | None:
        g = self.robot.joint_index(self.robot.gripper.joint) if self.robot.gripper else None
        worst = []
        for i, name in enumerate(self.robot.joint_names):
            if arm_only and i == g:
                continue
            tol = self.cfg.gripper_tolerance if i == g else self.cfg.start_tolerance
            if abs(q[i] - q0[i]) > tol:
                worst.append(f"{name} is {math.degrees(q[i]):.1f} deg, the start is {math.degrees(q0[i]):.1f} deg")
        return "; ".join(worst[:3]) if worst else None

    # ------------------------------------------------------------------ run
    def run(self) -> Result:
        """Check the start, confirm, stream, settle. Raises Interrupted/DeviceError/InfeasibleError
        after holding; the Result (also on failure, as ``exc.result``) carries the log.

        Any ``KeyboardInterrupt`` (Ctrl-C, or SIGTERM/SIGHUP as ``StopRequested``) from the start
        check on, including a move to the start, makes the arm hold before ``Interrupted`` is raised.
        """
        outcome, message, cause = "completed", "", "stop"
        exc_out: Exception | None = None
        gc_was_enabled = gc.isenabled()
        try:
            self._check_start()
            if self.confirm is not None and not self.confirm(
                    f"Execute {self.traj.duration / self.cfg.speed_scale:.2f} s of motion on {self.link.port}?"):
                raise Interrupted("not confirmed; the arm did not move")
            if self.on_start is not None:
                self.on_start()
            # A full cyclic garbage collection in a process with many modules loaded can stall the
            # schedule by tens of milliseconds; collect now and pause the collector while streaming. On any clock
            # but the real one (a virtual clock) a collection stalls nothing, and a big process pays for it.
            if self.sleep is time.sleep:
                gc.collect()
            gc.disable()
            self._stream()
            self._settle()
        except KeyboardInterrupt as exc:
            signum = getattr(exc, "signum", signal.SIGINT)
            what = signal_name(signum)
            outcome = "interrupted" if signum == signal.SIGINT else "terminated"
            message = f"{'interrupted by' if outcome == 'interrupted' else 'stopped by'} {what} {self._progress()}; " \
                      "the arm holds where it was"
            exc_out = Interrupted(message, signum=signum)
        except _Abort as exc:
            outcome, message, cause = "aborted", str(exc), "tracking"
            exc_out = DeviceError(message, "the arm holds where it was; check for a collision or a stalled joint")
        except FeedbackRefused as exc:
            moving = bool(self.sent_lateness)
            outcome, message = ("aborted" if moving else "failed"), f"{exc.message} {self._progress()}"
            exc_out = DeviceError(message, (exc.hint or "") if moving else
                                  "the arm did not move; check the servo power (12 V) and cables, then the log's refused frames")
        except DeviceError as exc:
            outcome, message = ("link_lost" if self.sent_lateness else "failed"), exc.message
            exc_out = DeviceError(exc.message, exc.hint)
        finally:
            if gc_was_enabled:
                gc.enable()
        if outcome != "completed":
            self._hold(cause)
        result = self.result(outcome, message)
        if exc_out is not None:
            exc_out.result = result  # type: ignore[attr-defined]
            raise exc_out
        return result

    def _progress(self) -> str:
        """Where the run stopped, for the log's message: 'after 151 of 336 motion commands'."""
        n = len(self.sent_lateness)
        if n == 0:
            return "before streaming (no motion command sent)" if "moved to the start first" not in self.notes \
                else "before streaming"
        return f"after {n} of {len(self.schedule)} motion commands"

    def _lateness_window(self, t_meas: float) -> float:
        """How far behind the plan the arm may be at ``t_meas`` (s after t0) for reasons measured
        here: the host's own lateness on the ticks of the last 0.25 s, plus the device's."""
        recent = [x for k, x in self.sent_lateness[-40:] if t_meas - 0.25 <= self.schedule[k].t <= t_meas + 0.02]
        late = max(recent, default=0.0)
        return max(0.0, late) + self._device_late()

    def _device_late(self) -> float:
        """How late the device itself has been lately (s): its answers to T:105 that came later than the
        round trip measured at connect (a lower bound: the last read before they were there), or what
        ``extra_lateness`` reports (the simulator measures its own)."""
        now = self.clock()
        while self.device_late and self.device_late[0][0] < now - 0.3:
            self.device_late.popleft()
        seen = max((x for _, x in self.device_late), default=0.0)
        return max(seen, self.extra_lateness() if self.extra_lateness is not None else 0.0)

    def plan_time(self, t: float) -> float:
        """The plan's time (s) at ``t`` s after t0: the clock's, less every pause before ``t`` (frozen during one)."""
        return plan_clock(t, self.paused)

    def _servos_read_at(self, reading: Reading, asked: float | None) -> float:
        """When (s, on the clock) the firmware read the servos a frame reports: before its line's wire time and
        the firmware's work; for an answer to a T:105 sent at ``asked``, at most one round trip after the
        question (a busy host reads the answer late; the firmware did not read the servos later)."""
        t = reading.t - wire_seconds(reading.nbytes) - READ_BEFORE_PRINT
        if asked is not None:
            info = self.link.info
            rtt = info.rtt if info is not None else 0.03
            t = min(t, asked + rtt - wire_seconds(reading.nbytes) - READ_BEFORE_PRINT / 2)
        return t

    def _track(self, reading: Reading) -> tuple[float, float] | None:
        """(TCP error against the plan at the frame's measurement time, the same with the plan
        allowed to be up to the measured lateness later), m; None outside the motion. Times are the plan's
        (``plan_time``): where the plan waited for a late host, the arm stopped on the path."""
        t_meas = self._reading_at.pop(id(reading)) - self.t0
        tp = self.plan_time(t_meas)
        if not 0.0 <= tp <= self.schedule[-1].t:
            return None
        s = self.cfg.speed_scale
        p = tcp(self, reading.q)
        err = float(np.linalg.norm(p - tcp(self, sample(self.traj, tp * s))))
        self.tracking.append((t_meas, err))
        slack = self._lateness_window(tp) + max(0.0, SERVO_LAG - self.lead)
        lo, hi = max(0.0, tp - slack - 0.01), tp + self.lead + 0.005
        return err, min(err, self._path_error(p, lo, hi))

    def _path_error(self, p: np.ndarray, lo: float, hi: float) -> float:
        """The least distance (m) of TCP ``p`` from the plan's TCP at times ``lo..hi`` (s after t0, every 10 ms at least)."""
        taus = np.linspace(lo, hi, max(12, int((hi - lo) / 0.01) + 2)) * self.cfg.speed_scale
        plans = self.robot.kin.fk(self.robot.full_q(sample(self.traj, taus)))[:, :3, 3]
        return float(np.min(np.linalg.norm(plans - p, axis=1)))

    def _stream(self) -> None:
        link, cfg = self.link, self.cfg
        self.poll_every = self._poll_every(self.rate)
        self._polled_tick = 0
        info = link.info
        rtt = info.rtt if info is not None else 0.03
        pacer = self.pacer = Pacer(rtt, info.line_time if info is not None else 0.0, cfg.in_flight)
        link.poll()
        self.t0 = self.clock() + cfg.lead
        self._fit_rate(0)  # a firmware measured at connect as too slow for the asked rate: start lower
        err: float | None = None
        wire_free = 0.0  # when the bytes sent so far will have left the host (115200 baud)
        self._polled = self.clock()
        k, hooked, waited, host_late, samples = 0, -1, -1, False, 0
        while k < len(self.schedule):
            sched = self.schedule
            n = len(sched)
            tick = sched[k]
            first = hooked != k
            if first:
                hooked = k
                if self.hook is not None:
                    self.hook(k)
            due = self.t0 + self.shift + tick.t
            wait = due - self.clock()
            while wait > 0:
                # the link is read while waiting, not only once a tick: an answer's time says when the firmware had
                # run the lines it confirms, and the queue model (pacing) is only as good as that time
                self.sleep(min(wait, READ_EVERY))
                wait = due - self.clock()
                if wait > 0:
                    err = self._read_answers(tick, err)
            now = self.clock()
            if first:
                host_late = k + 1 < n and now >= due + sched[k + 1].t - tick.t  # the host came after the next was due
            # the firmware has not caught up when the lines it has not run yet would make a new one wait longer than
            # in_flight, or a poll is overdue by more than behind_after (fixed: it does not grow with the lag measured)
            send = k + 1 >= n or (pacer.may_send(now, len(tick.commands)) and not pacer.overdue(now, cfg.behind_after))
            if not send and waited != k and not host_late:
                waited = k
                self.waits["behind"] += 1  # add nothing to its backlog, wait
            if not send and not pacer.polls:
                # nothing asks the firmware how far it got: ask (else nothing would ever confirm the lines in flight)
                t_poll = link.send(protocol.feedback_request())
                on_wire, wire_free = max(t_poll, wire_free), max(wire_free, t_poll) + wire_seconds(T105_BYTES)
                pacer.poll_sent(on_wire, wire_free, now)
            if send:
                if k + 1 < n and now >= due + sched[k + 1].t - tick.t:
                    # so late that the next tick is due too: the plan waits here (its clock pauses) and this tick goes
                    # out now. Jumping to the tick due by the clock would send the servos straight across the plan
                    self.paused.append((tick.t, now - due))
                    self.shift += now - due
                    due = now
                    if host_late:
                        self.waits["late"] += 1
                cmds = tick.commands
                # a signal between the line going out and its record would leave a command in the log's sent list
                # that its count of motion commands leaves out (seen: 41 ticks sent, 'after 40 of ...')
                with self.shield():
                    t_sent = link.send(cmds[0])
                    self.tick_of[id(cmds[0])] = k
                    self.sent_lateness.append((k, t_sent - due))
                    wire_free = max(wire_free, t_sent) + wire_seconds(len(protocol.encode(cmds[0])))
                    for extra in cmds[1:]:  # a tick's commands go out together
                        wire_free = max(wire_free, link.send(extra)) + wire_seconds(len(protocol.encode(extra)))
                pacer.sent(len(cmds), wire_free, k)
                self.setpoint = tick
                # a poll every poll_every ticks (each costs the firmware a line and its answer's time on the wire); at a
                # rate lowered for a slow firmware, still one at least every CONFIRM_EVERY s: the hold of a queuing build
                # goes back to the last line an answer confirmed
                if (k - self._polled_tick >= self.poll_every or not self.sent_lateness[:-1]) and len(pacer.polls) < 2:
                    self._polled_tick = k
                    # the T:105 leaves the host's UART after the command bytes still in flight ahead of it:
                    # its round trip starts then (the one measured at connect had nothing ahead of it)
                    t_poll = link.send(protocol.feedback_request())
                    on_wire, wire_free = max(t_poll, wire_free), max(wire_free, t_poll) + wire_seconds(T105_BYTES)
                    pacer.poll_sent(on_wire, wire_free, t_poll)
            err = self._read_answers(tick, err)
            if self.on_status is not None:
                self.on_status(Status(k, n, tick.t, sched[-1].t, now - due, tick.target, self.measured, err))
            if send:
                k += 1
            else:
                self.sleep(min(0.25 / self.rate, READ_EVERY))
            if pacer.samples != samples:
                samples = pacer.samples
                self._fit_rate(k)

    def _read_answers(self, tick: Tick, err: float | None) -> float | None:
        """Read the link: poll answers confirm lines (pacing), feedback is judged and tracked; raises on a stale link
        or a tracking error beyond the bound. Returns the newest tracking error (m), or ``err`` when none came."""
        rtt = self.pacer.rtt
        polled_before, polled = self._polled, self.clock()
        self._polled = polled
        new = self.link.poll()
        asked: dict[int, float] = {}
        for r in new:
            if r.feedback is not None and self.pacer.polls:
                t_poll = self.pacer.answered(polled, polled_before, wire_seconds(len(r.line) + 2))
                asked[id(r)] = t_poll
                # the answer was not there yet at the previous read: it is late by at least this much
                late = polled_before - t_poll - rtt
                if late > 0.002:
                    self.device_late.append((polled, late))
        readings = self.judge(new, asked)
        # feedback is overdue when a question had gone unanswered too long when the link was last read, not
        # when the host itself did not ask or did not look: a busy machine that stopped this process for
        # 0.33 s between two polls, or for 0.36 s between reading the link and this check, ended runs here as
        # "link lost" while the arm had answered every question in time
        polls, cfg = self.pacer.polls, self.cfg
        if polls and polled - polls[0][0] > cfg.stale_after + self._lateness_window(self.plan_time(polled - self.t0)):
            raise DeviceError(f"link lost: no feedback for {polled - polls[0][0]:.2f} s during motion",
                              "check the USB cable and the arm's power; the arm may have rebooted")
        for reading in readings:
            tracked = self._track(reading)
            if tracked is None:
                continue
            err, err_window = tracked
            if err_window > self.cfg.max_error:
                raise _Abort(f"tracking error {err * 1e3:.1f} mm exceeds {self.cfg.max_error * 1e3:.0f} mm "
                             f"at t = {tick.t:.2f} s; aborted")
        return err

    def _poll_every(self, rate: float) -> int:
        """Ticks from one T:105 to the next at ``rate``: ``poll_rate()`` polls/s, and one at least every
        ``CONFIRM_EVERY`` s (once the firmware is the bottleneck: every 1 / ``FIRMWARE_BOUND_POLL_RATE`` s)."""
        longest = 1.0 / FIRMWARE_BOUND_POLL_RATE if self.firmware_bound else CONFIRM_EVERY
        return max(1, min(int(round(rate / self.poll_rate())), int(rate * longest)))

    def _fit_rate(self, k: int) -> None:
        """Go on from tick ``k`` at a lower rate when the firmware's time per line (measured at connect, then from
        the poll answers) says the stream needs more than its share of it (``roarmctl.device.pacing``). Ticks before
        ``k`` keep their times; the new ones start one new interval after the last tick sent."""
        strat = STRATEGIES[self.cfg.strategy] if isinstance(self.cfg.strategy, str) else self.cfg.strategy
        sched = self.schedule
        if strat.rate is not None or k >= len(sched) - 1:
            return  # a strategy with its own rate (per-joint) keeps it
        # the busiest half second ahead sets the demand: a gripper moving beside the arm doubles the lines of its ticks
        # (its own T:101), and a rate that fits only on average makes the plan wait there
        lines = np.array([len(tk.commands) for tk in sched[k:]], dtype=float)
        w = max(1, min(len(lines), int(round(0.5 * self.rate))))
        peak = float(np.convolve(lines, np.ones(w) / w, mode="valid").max())
        if self.pacer.fitting_rate(self.rate, peak + 1.0 / self.poll_every) is None:
            return
        if not self.firmware_bound:
            # the firmware is the bottleneck: from here its time goes to motion lines. Fewer polls (each 324-byte answer
            # holds the 20260701 loop while the UART drains: it cost more than a motion line), no line of the gripper's
            # own (one T:102 a tick, the spd of the fastest joint, the gripper included) and servos fast enough to
            # keep up with a queue that drains
            self.firmware_bound = True
            self.notes.append(f"the firmware is the bottleneck ({self.pacer.line_time * 1e3:.1f} ms a line): from t = "
                              f"{sched[k].t:.2f} s a poll every {1.0 / self.poll_rate():.1f} s, the gripper in the "
                              "T:102 (no T:101 of its own), spd for a tick's plan in one of its passes")
        fit = self.rate
        for _ in range(4):  # fewer ticks a second: a poll with more of them
            fit = self.pacer.fitting_rate(fit, 1.0 + 1.0 / self._poll_every(fit), lower_by=1.0) or fit
        self.poll_every = self._poll_every(fit)
        start = sched[k - 1].t + 1.0 / fit if k > 0 else 0.0
        # a line that waited in the queue runs one pass after the one before it when the queue drains: its servos must
        # run a tick's plan in one pass to keep up. With the strategy's 5 % they fell 5.5 ms behind a line at 14 ms a
        # pass, and a Ctrl-C after such a catch-up let the arm run 58 ms of plan to the last goal the firmware took
        margin = max(strat.margin, 1.0 / (fit * self.pacer.line_time))
        tail = build_schedule(self.traj, self.robot, rate=fit, speed_scale=self.cfg.speed_scale, sag=self.cfg.sag,
                              strategy=dataclasses.replace(strat, split_gripper=False, margin=margin),
                              start=min(start, sched[-1].t))
        self.schedule = sched[:k] + tail
        if fit < self.rate:
            self.rate_changes.append({"tick": k, "t": round(self.schedule[k].t, 6), "from_hz": round(self.rate, 3),
                                      "to_hz": round(fit, 3), "line_time_s": round(self.pacer.line_time, 5)})
            self.notes.append(f"rate lowered from {self.rate:.0f} to {fit:.0f} Hz at t = {self.schedule[k].t:.2f} s: "
                              f"the firmware takes {self.pacer.line_time * 1e3:.1f} ms a line")
        self.rate = fit

    def _settle(self) -> None:
        end = self.clock() + self.cfg.settle
        while self.clock() < end:
            r = self.link.request(0.1)
            if r is not None:
                self.judge([r])
            self.sleep(0.05)

    # ------------------------------------------------------------------ the hold and the results
    def _hold(self, cause: str) -> None:
        stream_hold.hold(self, cause)

    def hold_target(self, cause: str, now: float) -> tuple[str, np.ndarray | None]:
        """The hold's (kind, firmware radians in field order) at ``now``: ``roarmctl.device.stream_hold.hold_target``."""
        return stream_hold.hold_target(self, cause, now)

    def result(self, outcome: str, message: str) -> Result:
        """The run's Result with its log, as it stands now."""
        lat = np.array([x for _, x in self.sent_lateness])
        trk = np.array([e for _, e in self.tracking])
        final = None
        if self.measured is not None and outcome == "completed":
            final = float(np.linalg.norm(tcp(self, self.measured) - tcp(self, self.traj.positions[-1])))
        res = Result(outcome, message, len(self.sent_lateness), lat, trk, final, self.t0)
        res.log = run_log(self, res)
        return res
