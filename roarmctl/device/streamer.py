"""Stream a timed trajectory to the arm: the command schedule, the real-time loop, hold and log.

The schedule is pure (``build_schedule``): tick k at ``k / rate`` seconds sends one ``T:102``.
The default strategy ``timed`` makes each servo's own trapezoid follow the plan: at tick k it
commands the plan's position one interval (plus the link latency) ahead, with ``spd`` = the speed
the fastest joint needs to get there exactly when the next command arrives, and ``acc = 0`` (no
ramp: a ramp makes the servo plan a stop at every intermediate goal and fall behind). The gripper
gets its own ``T:101`` when it needs more speed than the arm, so it does not set the arm's shared
``spd``. Default rate 50 Hz: on the simulator it halves the per-interval staircase of 25 Hz (TCP RMS
0.96 vs 1.53 mm on the bundled pick-and-place) and uses at most ~80 % of the 115200 link with the
gripper lines and 25 Hz feedback polls, below the ~90 lines/s ceiling. Measured alternatives:
``bench/bench_stream.py`` (dense spd=0/acc=0: 2.8 mm RMS, 9 mm max; acc from the plan: 45 mm RMS).

The loop (``Streamer``) runs on an absolute monotonic schedule (``due = t0 + t_k``: no drift),
polls feedback between commands within the link's byte budget, aborts when the TCP tracking error
exceeds a bound or feedback stops, and on Ctrl-C, a lost link or an abort sends a hold ``T:102``
at the last measured pose (never torque off), closes the port and writes the execution log.
"""

from __future__ import annotations

import gc
import math
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.device import protocol
from roarmctl.device.protocol import WireMap, acc_register, spd_register, wire_seconds
from roarmctl.errors import DeviceError, InfeasibleError, InputError, Interrupted, signal_name
from roarmctl.fileio import atomic_write_json
from roarmctl.robot.frames import device_point, to_frame

MAX_LINK_RATE = 90.0  # T:102 lines/s the 115200 link can carry at all (about 10.4 ms each)
DEFAULT_RATE = 50.0
FEEDBACK_RATE = 25.0  # T:105 polls per second during motion (each answer is ~200 B back)
HOLD_SPD = 600  # the firmware's own ARM_SERVO_INIT_SPEED, steps/s
T102_BYTES = 125  # longest T:102 line (all six fields at 4 decimals, spd, acc, newline)
T101_BYTES = 55  # a gripper T:101 line
LINK_BUDGET = 0.85  # share of the 11520 B/s host->arm direction the stream may use


# ----------------------------------------------------------------------------- sampling
def sample(traj, t) -> np.ndarray:
    """Positions at times ``t`` (scalar or (M,), s, clamped to [0, T]) by cubic Hermite interpolation
    of the samples and their velocities: (dof,) or (M, dof)."""
    ts = traj.times
    tt = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), ts[0], ts[-1])
    if len(ts) == 1:
        out = np.repeat(traj.positions[:1], len(tt), axis=0)
    else:
        i = np.clip(np.searchsorted(ts, tt, side="right") - 1, 0, len(ts) - 2)
        h = (ts[i + 1] - ts[i])[:, None]
        u = ((tt - ts[i])[:, None]) / h
        p0, p1 = traj.positions[i], traj.positions[i + 1]
        v0, v1 = traj.velocities[i] * h, traj.velocities[i + 1] * h
        u2, u3 = u * u, u * u * u
        out = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * v0 + (-2 * u3 + 3 * u2) * p1 + (u3 - u2) * v1
    return out[0] if np.ndim(t) == 0 else out


# ----------------------------------------------------------------------------- strategies
@dataclass(frozen=True)
class Strategy:
    """How a tick's command is chosen.

    ``lookahead``: how many intervals ahead of the send time the target lies (0 or 1);
    ``spd``: ``"max"`` (0: the servo's top speed) or ``"velocity"`` (what the fastest joint needs
    to reach the target when the next command arrives, times ``margin``);
    ``acc``: ``"none"`` (0: no ramp) or ``"trajectory"`` (from the plan's accelerations).
    """

    name: str
    lookahead: int = 1
    spd: str = "velocity"
    acc: str = "none"
    margin: float = 1.05
    split_gripper: bool = False
    description: str = ""


STRATEGIES = {
    "timed": Strategy("timed", 1, "velocity", "none", split_gripper=True,
                      description="target one interval ahead, spd = needed speed of the fastest arm joint, no ramp; "
                                  "the gripper gets its own T:101 when it needs more"),
    "timed-shared": Strategy("timed-shared", 1, "velocity", "none",
                             description="as timed, but one spd for all six joints (gripper included)"),
    "timed-acc": Strategy("timed-acc", 1, "velocity", "trajectory",
                          description="as timed, but acc from the plan's acceleration"),
    "dense": Strategy("dense", 0, "max", "none", description="target = plan now, spd 0 / acc 0 (full speed)"),
    "dense-ahead": Strategy("dense-ahead", 1, "max", "none",
                            description="target one interval ahead, spd 0 / acc 0 (full speed)"),
}


def default_latency(rate: float) -> float:
    """Time (s) from handing a T:102 line to the driver until the servos get it: its ~120 bytes on
    the wire plus half a firmware loop."""
    return wire_seconds(120) + 0.002


@dataclass
class Tick:
    """One scheduled command: ``t`` s after the start (execution time), the command, and the
    planned joint vector it targets (dof,)."""

    t: float
    cmd: dict[str, Any]
    target: np.ndarray
    extra: list[dict[str, Any]] = field(default_factory=list)  # sent right after ``cmd`` (T:101 gripper)

    @property
    def commands(self) -> list[dict[str, Any]]:
        """The lines this tick sends, in order: the joints command, then any gripper command."""
        return [self.cmd, *self.extra]


def build_schedule(traj, robot, *, rate: float = DEFAULT_RATE, speed_scale: float = 1.0,
                   strategy: str | Strategy = "timed", latency: float | None = None) -> list[Tick]:
    """Every command the streamer will send for ``traj``, with its time (s from the start).

    ``speed_scale`` < 1 slows the whole motion down (times divided by it, speeds multiplied).
    """
    strat = STRATEGIES[strategy] if isinstance(strategy, str) else strategy
    if not 0 < rate <= MAX_LINK_RATE:
        raise InputError(f"--rate: {rate:g} Hz is outside (0, {MAX_LINK_RATE:g}]",
                         f"115200 baud carries at most about {MAX_LINK_RATE:g} T:102 lines/s; 20-50 Hz is sensible")
    if not 0 < speed_scale <= 1.0:
        raise InputError(f"--speed-scale: {speed_scale:g} is outside (0, 1]", "use 0.5 for half speed")
    wm = WireMap(robot)
    _check_wire_range(traj, wm)
    dt = 1.0 / rate
    lat = default_latency(rate) if latency is None else latency
    t_end = traj.duration / speed_scale
    n = int(math.ceil(t_end * rate - 1e-9)) + 1
    ts = np.minimum(np.arange(n) * dt, t_end)
    ahead = strat.lookahead * dt
    # plan times (un-scaled) of where each interval starts and ends, shifted by the link latency
    t_from = np.minimum(ts + lat, t_end) * speed_scale
    t_to = np.minimum(ts + ahead + lat, t_end) * speed_scale
    q_to = sample(traj, t_to)
    q_from = sample(traj, t_from)
    w_to, w_from = wm.to_wire_array(q_to), wm.to_wire_array(q_from)
    ticks = []
    prev_speed = 0.0
    # the gripper gets its own T:101 when it needs more speed than the arm: one shared spd would
    # otherwise make every arm joint rush ahead and wait (a staircase) while the gripper moves
    g = [k for k, w in enumerate(wm.fields) if robot.gripper is not None and w.joint == robot.gripper.joint]
    # T:101's gripper joint number is the M3's (6); the M2 gets the shared spd instead
    split = (strat.split_gripper and wm.model == "m3"
             and rate * (T102_BYTES + T101_BYTES + 11) <= LINK_BUDGET * protocol.BYTES_PER_SECOND)
    nf = len(wm.fields)
    arm = [k for k in range(nf) if k not in g]
    for k in range(n):
        extra: list[dict[str, Any]] = []
        if strat.spd == "max":
            spd = 0
        else:
            span = max(t_to[k] - t_from[k], 0.0) / speed_scale
            rates = np.abs(w_to[k] - w_from[k]) / span if span > 1e-9 else np.zeros(nf)
            need = float(np.max(rates[arm if split else slice(None)]))
            spd = spd_register(need * strat.margin, minimum=50)
            if split and g and rates[g[0]] * strat.margin > need:
                lo, hi = protocol.SAFE_WIRE_RANGE["hand"]
                extra.append({"T": 101, "joint": 6, "rad": protocol.r4(min(max(w_to[k][g[0]], lo), hi)),
                              "spd": spd_register(rates[g[0]] * strat.margin, minimum=50), "acc": 0})
        if strat.acc == "none":
            acc = 0
        else:
            i0 = np.searchsorted(traj.times, t_from[k])
            i1 = max(i0 + 1, np.searchsorted(traj.times, t_to[k], side="right"))
            a = float(np.max(np.abs(traj.accelerations[max(i0 - 1, 0):i1]))) * speed_scale ** 2
            dv = abs(spd / protocol.STEPS_PER_RAD - prev_speed) / dt
            acc = acc_register(max(a, dv) * 1.5, minimum=5)
            prev_speed = spd / protocol.STEPS_PER_RAD
        ticks.append(Tick(float(ts[k]), wm.command(q_to[k], spd, acc), q_to[k], extra))
    return ticks


def _check_wire_range(traj, wm: WireMap) -> None:
    """Refuse a trajectory the firmware would clamp: the arm would not follow the plan."""
    for w, i in zip(wm.fields, wm.index):
        raw = w.offset + w.sign * traj.positions[:, i]
        lo, hi = protocol.SAFE_WIRE_RANGE[w.field]
        lo, hi = max(lo, w.lower), min(hi, w.upper)
        bad = np.flatnonzero((raw < lo - 1e-6) | (raw > hi + 1e-6))
        if len(bad):
            k = int(bad[0])
            raise InputError(
                f"trajectory: {w.joint} = {traj.positions[k, i]:.4f} rad at t = {traj.times[k]:.2f} s is outside "
                f"the firmware's range for '{w.field}' ({lo:.4f}..{hi:.4f} rad on the wire)",
                "plan it again with the robot's joint limits")


# ----------------------------------------------------------------------------- the loop
@dataclass
class StreamConfig:
    """How to stream: rate (Hz), speed scale, strategy, and the tolerances and waits of a run."""

    rate: float = DEFAULT_RATE
    speed_scale: float = 1.0
    strategy: str = "timed"
    max_error: float = 0.03  # m of TCP position error before aborting
    start_tolerance: float = 0.05  # rad per arm joint between the measured pose and the first point
    gripper_tolerance: float = 0.35  # rad, the gripper's own
    move_to_start: bool = False  # arm elsewhere: a planned motion to the start first (needs ``replan``)
    from_current: bool = False  # arm elsewhere: the first free motion planned again from here (needs ``replan``)
    stale_after: float = 1.0  # s without feedback during motion -> link lost
    settle: float = 0.6  # s to wait for the arm to arrive after the last command
    lead: float = 0.05  # s between the start decision and the first command


@dataclass
class Status:
    """What the display shows after each tick."""

    k: int
    n: int
    t: float
    duration: float
    lateness: float
    commanded: np.ndarray
    measured: np.ndarray | None
    error: float | None  # m, TCP tracking error of the newest feedback


@dataclass
class Result:
    """How a run ended (``outcome``, ``message``), what was sent, and its lateness and tracking over time."""

    outcome: str  # "completed" | "interrupted" | "aborted" | "link_lost"
    message: str
    n_sent: int
    lateness: np.ndarray  # (n,) s
    tracking: np.ndarray  # (m,) m, TCP error of each feedback during motion
    final_error: float | None
    t0: float
    log: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The log's ``summary``: outcome, counts, lateness p50/p99 (ms), tracking RMS/max (mm)."""
        lat = self.lateness * 1e3
        trk = self.tracking * 1e3
        pct = lambda a, p: float(np.percentile(a, p)) if len(a) else None  # noqa: E731
        return {
            "outcome": self.outcome, "message": self.message, "commands": self.n_sent,
            "lateness_ms": {"p50": pct(lat, 50), "p99": pct(lat, 99), "max": float(lat.max()) if len(lat) else None},
            "tracking_mm": {"rms": float(np.sqrt(np.mean(trk ** 2))) if len(trk) else None,
                            "max": float(trk.max()) if len(trk) else None, "samples": len(trk)},
            "final_error_mm": None if self.final_error is None else self.final_error * 1e3,
        }


class Streamer:
    """Run one trajectory over an open, handshaken ``Link``.

    ``clock``/``sleep`` are injectable (tests); ``on_status(Status)`` is called after each tick
    (the live display; ``on_start()`` before the first); ``hook(k)`` is called before tick k is sent (tests raise KeyboardInterrupt
    from it); ``confirm(message) -> bool`` is asked before any motion.

    ``replan(q_measured, mode) -> (Trajectory, sentence)`` plans from the measured pose when the arm
    is not at the start (``roarmctl.motion.replan.replan_start``; modes ``gripper`` - only the
    gripper differs, always done -, ``move_to_start``, ``from_current``); ``on_note(sentence)`` says so.
    """

    def __init__(self, link, robot, traj, config: StreamConfig | None = None, *,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep,
                 on_status: Callable[[Status], None] | None = None, hook: Callable[[int], None] | None = None,
                 confirm: Callable[[str], bool] | None = None, on_start: Callable[[], None] | None = None,
                 replan: Callable[[np.ndarray, str], tuple[Any, str]] | None = None,
                 on_note: Callable[[str], None] | None = None) -> None:
        self.link = link
        self.robot = robot
        self.traj = traj
        self.cfg = config or StreamConfig()
        self.clock = clock
        self.sleep = sleep
        self.on_status = on_status
        self.hook = hook
        self.confirm = confirm
        self.on_start = on_start  # after the confirmation, before the clock starts (start a display)
        self.replan = replan
        self.on_note = on_note
        self.wm = WireMap(robot)
        self.schedule = build_schedule(traj, robot, rate=self.cfg.rate, speed_scale=self.cfg.speed_scale,
                                       strategy=self.cfg.strategy)
        self.measured: np.ndarray | None = None
        self.measured_t: float | None = None
        self.last_cmd: dict[str, Any] | None = None
        self._fk_cache: dict[float, np.ndarray] = {}
        self.t0 = math.nan
        self.sent_lateness: list[tuple[int, float]] = []
        self.tracking: list[tuple[float, float]] = []
        self.notes: list[str] = []

    # ------------------------------------------------------------------ helpers
    def _tcp(self, q: np.ndarray) -> np.ndarray:
        return self.robot.kin.fk(self.robot.full_q(q))[:3, 3]

    def _q_of(self, fb) -> np.ndarray:
        return self.wm.from_wire(fb.joints)

    def _absorb(self, received) -> float | None:
        """Take in new lines; return the TCP error (m) of the newest feedback, if any."""
        err = None
        for r in received:
            if r.feedback is None or not r.feedback.joints:
                continue
            q = self._q_of(r.feedback)
            self.measured, self.measured_t = q, r.t
            if not math.isnan(self.t0):
                # the firmware read the servos about one reply-length earlier than we got the line
                t_meas = r.t - wire_seconds(len(r.line) + 2) - 0.004 - self.t0
                if 0.0 <= t_meas <= self.schedule[-1].t:
                    plan = sample(self.traj, t_meas * self.cfg.speed_scale)
                    err = float(np.linalg.norm(self._tcp(q) - self._tcp(plan)))
                    self.tracking.append((t_meas, err))
        return err

    def _take(self, fb) -> None:
        """A feedback outside the streaming loop: update the measured pose only."""
        if fb.joints:
            self.measured, self.measured_t = self._q_of(fb), self.clock()

    def _check_start(self) -> None:
        fb = self.link.request_feedback(0.5) or self.link.request_feedback(0.5)
        if fb is None:
            raise DeviceError("device silent: no feedback before the start", "check the arm's power and cable")
        self._take(fb)
        q0 = self.traj.positions[0]
        diff = self._start_diff(self.measured, q0)
        if diff is None:
            return
        if self._start_diff(self.measured, q0, arm_only=True) is None:
            mode = "gripper"  # chained runs: the arm is there, only the gripper is not
        elif self.cfg.from_current:
            mode = "from_current"
        elif self.cfg.move_to_start:
            mode = "move_to_start"
        else:
            raise InfeasibleError(f"the arm is not at the trajectory's start: {diff}",
                                  "pass --move-to-start (a planned, collision-checked motion there first) or "
                                  "--from-current (plan the first free motion again from here)")
        if self.replan is None:
            raise InfeasibleError(f"the arm is not at the trajectory's start: {diff}", "move it there first")
        measured = np.clip(self.measured, self.robot.lower, self.robot.upper)  # one servo count outside a limit
        traj, sentence = self.replan(measured, mode)
        self.traj = traj
        self.schedule = build_schedule(traj, self.robot, rate=self.cfg.rate, speed_scale=self.cfg.speed_scale,
                                       strategy=self.cfg.strategy)
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
        outcome, message, exc_out = "completed", "", None
        gc_was_enabled = gc.isenabled()
        try:
            self._check_start()
            if self.confirm is not None and not self.confirm(
                    f"Execute {self.traj.duration / self.cfg.speed_scale:.2f} s of motion on {self.link.port}?"):
                raise Interrupted("not confirmed; the arm did not move")
            if self.on_start is not None:
                self.on_start()
            # A full cyclic garbage collection in a process with many modules loaded can stall the
            # schedule by tens of milliseconds; collect now and pause the collector while streaming.
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
            outcome, message = "aborted", str(exc)
            exc_out = DeviceError(message, "the arm holds where it was; check for a collision or a stalled joint")
        except DeviceError as exc:
            outcome, message = ("link_lost" if self.sent_lateness else "failed"), exc.message
            exc_out = DeviceError(exc.message, exc.hint)
        finally:
            if gc_was_enabled:
                gc.enable()
        if outcome != "completed":
            self._hold()
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

    def _stream(self) -> None:
        link, sched = self.link, self.schedule
        poll_every = max(1, int(round(self.cfg.rate / FEEDBACK_RATE)))
        link.poll()
        self.t0 = self.clock() + self.cfg.lead
        last_fb_t = self.clock()
        n = len(sched)
        err = None
        for k, tick in enumerate(sched):
            if self.hook is not None:
                self.hook(k)
            due = self.t0 + tick.t
            wait = due - self.clock()
            if wait > 0:
                self.sleep(wait)
            t_sent = link.send(tick.cmd)
            for extra in tick.extra:
                link.send(extra)
            self.last_cmd = tick.cmd
            self.sent_lateness.append((k, t_sent - due))
            if k % poll_every == 0:
                link.send(protocol.feedback_request())
            new = link.poll()
            e = self._absorb(new)
            if any(r.feedback is not None for r in new):
                last_fb_t = self.clock()
            elif self.clock() - last_fb_t > self.cfg.stale_after:
                raise DeviceError(f"link lost: no feedback for {self.cfg.stale_after:.1f} s during motion",
                                  "check the USB cable and the arm's power; the arm may have rebooted")
            if e is not None:
                err = e
                if e > self.cfg.max_error:
                    raise _Abort(f"tracking error {e * 1e3:.1f} mm exceeds {self.cfg.max_error * 1e3:.0f} mm "
                                 f"at t = {tick.t:.2f} s; aborted")
            if self.on_status is not None:
                self.on_status(Status(k, n, tick.t, sched[-1].t, t_sent - due, tick.target, self.measured, err))

    def _settle(self) -> None:
        end = self.clock() + self.cfg.settle
        while self.clock() < end:
            fb = self.link.request_feedback(0.1)
            if fb is not None:
                self._take(fb)
            self.sleep(0.05)

    def _hold(self) -> None:
        """Hold: T:102 at the last measured arm pose, gripper at its last command. Never torque off.

        A stop signal arriving during the hold (the first one raises ``KeyboardInterrupt``) does not
        cut it short: the hold is sent again, and the run's outcome stays what it was.
        """
        try:
            self._hold_once()
        except KeyboardInterrupt:
            self.notes.append("a stop signal arrived during the hold; hold sent again")
            self._hold_once()

    def _hold_once(self) -> None:
        try:
            if getattr(self.link, "closed", False) or getattr(self.link, "ser", True) is None:
                self.notes.append("hold not sent: the port was never opened")
                return
            try:
                fb = self.link.request_feedback(0.15)
                if fb is not None:
                    self._take(fb)
            except DeviceError:
                pass
            if self.measured is None:
                return
            wire = self.wm.to_wire(self.measured)
            if self.last_cmd is not None and self.robot.gripper is not None:
                hand = next(w.field for w in self.wm.fields if w.joint == self.robot.gripper.joint)
                wire[hand] = self.last_cmd[hand]
            self.link.send(self.wm.hold(wire, HOLD_SPD, 0), fresh_line=True)
            self.notes.append("hold sent at the last measured pose")
        except DeviceError:
            self.notes.append("hold could not be sent: the link is gone")

    def pose_in_frames(self) -> dict[str, Any] | None:
        """The last measured TCP in the world frame (m) and the robot's other frames (their units)."""
        if self.measured is None:
            return None

        out: dict[str, Any] = {"world_m": [round(float(v), 6) for v in self._tcp(self.measured)]}
        for name, fr in (getattr(self.robot, "frames", {}) or {}).items():
            out[f"{name}_{fr.unit}"] = [round(float(v), 3) for v in to_frame(fr, device_point(self.robot, fr, self.measured))]
        return out

    def result(self, outcome: str, message: str) -> Result:
        """The run's Result so far, ending with this outcome and message."""
        lat = np.array([x for _, x in self.sent_lateness])
        trk = np.array([e for _, e in self.tracking])
        final = None
        if self.measured is not None and outcome == "completed":
            final = float(np.linalg.norm(self._tcp(self.measured) - self._tcp(self.traj.positions[-1])))
        res = Result(outcome, message, len(self.sent_lateness), lat, trk, final, self.t0)
        res.log = self.log(res)
        return res

    def log(self, res: Result) -> dict[str, Any]:
        """The execution log: every command sent and every line received, times in s after t0."""
        t0 = res.t0 if not math.isnan(res.t0) else (self.link.sent[0][0] if self.link.sent else 0.0)
        lateness = {k: x for k, x in self.sent_lateness}
        sched_idx = {id(tk.cmd): k for k, tk in enumerate(self.schedule)}
        sent = []
        for t, cmd in self.link.sent:
            entry: dict[str, Any] = {"t": round(t - t0, 6), "cmd": cmd}
            k = sched_idx.get(id(cmd))
            if k is not None:
                entry["tick"] = k
                entry["lateness"] = round(lateness.get(k, math.nan), 6)
            sent.append(entry)
        received = []
        for r in self.link.received:
            e: dict[str, Any] = {"t": round(r.t - t0, 6), "line": r.line}
            if r.feedback is not None:
                e["feedback"] = r.feedback.raw  # x, y, z: the firmware's frame (mm)
                if r.feedback.joints and set(self.wm.field_names) <= set(r.feedback.joints):
                    # the same pose in the plan's world frame (m), from our FK (frames of this robot's firmware only)
                    e["tcp_world_m"] = [round(float(v), 6) for v in self._tcp(self._q_of(r.feedback))]
            received.append(e)
        return {
            "format": "roarmctl.execlog/1",
            "port": self.link.port, "firmware": self.link.firmware, "robot": self.robot.name,
            "strategy": self.cfg.strategy, "rate": self.cfg.rate, "speed_scale": self.cfg.speed_scale,
            "t0_monotonic": t0, "duration": self.schedule[-1].t,
            "summary": res.summary(), "notes": self.notes, "final_pose": self.pose_in_frames(),
            "tracking": [{"t": round(t, 6), "error_m": round(e, 6)} for t, e in self.tracking],
            "sent": sent, "received": received,
        }


class _Abort(Exception):
    """Tracking error beyond the bound (internal; becomes DeviceError after the hold)."""


def write_log(path: str | Path, log: dict[str, Any]) -> Path:
    """Write an execution log atomically (compact JSON); return its path."""
    return atomic_write_json(path, log, indent=None)
