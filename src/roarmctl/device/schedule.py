"""What the streamer sends, and when: the pure command schedule of a timed trajectory, its spd/acc
strategies and its link budget.

The firmware writes one ``spd`` (servo steps/s) and one ``acc`` (units of 100 steps/s^2) to all
seven servos of a ``T:102``, raw, 0 included (RoArm-M3_module.h lines 764-779 of Waveshare's 0.84
example firmware); ``T:101`` moves one joint with its own (uart_ctrl.h 17-23). Each servo then runs
its own profile to its goal; the firmware neither interpolates nor waits. So the streamer chooses,
per tick, a target and the speeds that make the servos' own profiles follow the plan. The
strategies (``STRATEGIES``) are compared by ``bench/bench_stream.py``; ``docs/benchmarks.md`` holds
the table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roarmctl.device import protocol, st3235
from roarmctl.device.protocol import WireMap, acc_register, spd_register, wire_seconds
from roarmctl.device.sag import offsets as sag_offsets
from roarmctl.errors import InputError, OptionError
from roarmctl.formats import MIN_SPEED_SCALE

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

MAX_LINK_RATE = 90.0  # T:102 lines/s the 115200 link can carry at all (about 10.4 ms each)
DEFAULT_RATE = 50.0
FEEDBACK_RATE = 25.0  # T:105 polls per second during motion
T102_BYTES = 125  # longest T:102 line (all six fields at 4 decimals, spd, acc, newline)
T101_BYTES = 55  # a T:101 line
T105_BYTES = 11
LINK_BUDGET = 0.85  # share of the 11520 B/s host->arm direction the stream may use


# ----------------------------------------------------------------------------- sampling
def sample(traj: Trajectory, t: npt.ArrayLike) -> np.ndarray:
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
    """How a tick's commands are chosen.

    ``lookahead``: how many intervals ahead of the send time the target lies (0 or 1);
    ``spd``: ``"max"`` (0: the servo's business, its top speed on the ST3235) or ``"velocity"``
    (what the fastest joint needs to reach the target when the next command arrives, times
    ``margin``); ``acc``: ``"none"`` (0: no ramp) or ``"trajectory"`` (from the plan's
    acceleration, in the register's unit of 100 steps/s^2); ``per_joint``: one ``T:101`` per joint
    with its own spd instead of one ``T:102``; ``rate``: the rate this strategy is meant for (None:
    the stream's); ``lead`` (s): every target is taken this much later on the plan, so that servos
    whose position loop lags a moving goal by that much follow the plan itself (``timed-lead``).
    """

    name: str
    lookahead: int = 1
    spd: str = "velocity"
    acc: str = "none"
    margin: float = 1.05
    split_gripper: bool = False
    per_joint: bool = False
    rate: float | None = None
    lead: float = 0.0
    description: str = ""


STRATEGIES = {
    "timed": Strategy("timed", 1, "velocity", "none", split_gripper=True,
                      description="T:102 aimed one interval ahead, spd = what the fastest arm joint needs, acc 0; "
                                  "the gripper gets its own T:101 when it needs more"),
    "timed-lead": Strategy("timed-lead", 1, "velocity", "none", split_gripper=True, lead=st3235.LOOP_LAG,
                           description="as timed, aimed the servo loop's lag (46 ms) further ahead on the plan: "
                                       "the ST3235's P-only loop follows a moving goal that late"),
    "timed-acc": Strategy("timed-acc", 1, "velocity", "trajectory", split_gripper=True,
                          description="as timed, with acc from the plan's acceleration (servo units)"),
    "per-joint": Strategy("per-joint", 1, "velocity", "none", per_joint=True, rate=12.5,
                          description="one T:101 per joint with its own spd, at 12.5 Hz (six lines a tick)"),
    "timed-shared": Strategy("timed-shared", 1, "velocity", "none",
                             description="as timed, but one spd for all six joints (gripper included)"),
    "dense": Strategy("dense", 0, "max", "none", description="T:102 at the plan's position now, spd 0 / acc 0"),
    "dense-ahead": Strategy("dense-ahead", 1, "max", "none",
                            description="T:102 one interval ahead, spd 0 / acc 0"),
}
DEFAULT_STRATEGY = "timed-lead"


def default_latency(rate: float) -> float:
    """Time (s) from handing a T:102 line to the driver until the servos get it: its ~120 bytes on
    the wire plus about half a firmware loop pass."""
    return wire_seconds(120) + 0.002


@dataclass
class Tick:
    """One scheduled step: ``t`` s after the start (execution time), its first command ``cmd``
    (a T:102, or the first T:101 of a per-joint tick), the planned joint vector it targets (dof,)
    and the same target in firmware radians (fields order)."""

    t: float
    cmd: dict[str, Any]
    target: np.ndarray
    extra: list[dict[str, Any]] = field(default_factory=list)  # sent right after ``cmd``
    wire: np.ndarray | None = None

    @property
    def commands(self) -> list[dict[str, Any]]:
        """The lines this tick sends, in order."""
        return [self.cmd, *self.extra]


def target_offset(strategy: str | Strategy, rate: float, latency: float | None = None) -> float:
    """s: how far after its tick's time (the run's clock, ``k / rate``) a command's target lies on the plan run at
    its speed: the strategy's lookahead in intervals, the link latency (``default_latency``) and its lead. The arm is
    meant to stand at a command's target at that time, so a command drawn there lies on the plan's clock."""
    strat = STRATEGIES[strategy] if isinstance(strategy, str) else strategy
    rate = strategy_rate(strat, rate)
    lat = default_latency(rate) if latency is None else latency
    return strat.lookahead / rate + lat + strat.lead


def strategy_rate(strategy: str | Strategy, rate: float) -> float:
    """The tick rate (Hz) a stream of ``strategy`` runs at when ``rate`` is asked for."""
    strat = STRATEGIES[strategy] if isinstance(strategy, str) else strategy
    return strat.rate if strat.rate is not None else rate


def build_schedule(traj: Trajectory, robot: Robot, *, rate: float = DEFAULT_RATE, speed_scale: float = 1.0,
                   strategy: str | Strategy = DEFAULT_STRATEGY, latency: float | None = None,
                   sag: bool = False, start: float = 0.0) -> list[Tick]:
    """Every command the streamer will send for ``traj``, with its time (s from the start).

    ``speed_scale`` < 1 slows the whole motion down (times divided by it, speeds multiplied).
    A strategy with its own ``rate`` (per-joint) uses that instead of ``rate``. ``sag``: each goal is
    offset by the servos' sag under gravity and the held payload at its planned pose
    (``roarmctl.device.sag``), so that a P-only servo loop stands where the plan is; a tick's
    ``target`` stays the plan's. ``start`` (s, execution time): the ticks start there instead of at 0 (the rest of
    a stream going on at another rate).
    """
    strat = STRATEGIES[strategy] if isinstance(strategy, str) else strategy
    if not 0 < rate <= MAX_LINK_RATE:
        raise OptionError("rate", f"{rate:g} Hz is outside (0, {MAX_LINK_RATE:g}]",
                         f"115200 baud carries at most about {MAX_LINK_RATE:g} T:102 lines/s; 20-50 Hz is sensible")
    if not MIN_SPEED_SCALE <= speed_scale <= 1.0:  # the bound an execution log's reader holds it to (export)
        raise OptionError("speed_scale", f"{speed_scale:g} is outside [{MIN_SPEED_SCALE:g}, 1]", "use 0.5 for half speed")
    rate = strategy_rate(strat, rate)
    wm = WireMap(robot)
    _check_wire_range(traj, wm)
    dt = 1.0 / rate
    lat = default_latency(rate) if latency is None else latency
    t_end = traj.duration / speed_scale
    n = int(math.ceil(max(0.0, t_end - start) * rate - 1e-9)) + 1
    ts = np.minimum(start + np.arange(n) * dt, t_end)
    # plan times (un-scaled) of where each interval starts and ends, shifted by the link latency
    # and the strategy's lead
    t_from = np.minimum(ts + lat + strat.lead, t_end) * speed_scale
    t_to = np.minimum(ts + target_offset(strat, rate, lat), t_end) * speed_scale
    q_to, q_from = sample(traj, t_to), sample(traj, t_from)
    c_to, c_from = q_to, q_from  # what is commanded: the plan, offset by the sag when compensated
    if sag:
        c_to, c_from = q_to + sag_offsets(robot, traj, t_to, q_to), q_from + sag_offsets(robot, traj, t_from, q_from)
    w_to, w_from = wm.to_wire_array(c_to), wm.to_wire_array(c_from)
    nf = len(wm.fields)
    g = [k for k, w in enumerate(wm.fields) if robot.gripper is not None and w.joint == robot.gripper.joint]
    # the gripper gets its own T:101 when it needs more speed than the arm: one shared spd would
    # otherwise make every arm joint rush ahead and wait (a staircase) while the gripper moves.
    # T:101's gripper joint number is the M3's (6); the M2 gets the shared spd instead
    split = (strat.split_gripper and wm.model == "m3"
             and rate * (T102_BYTES + T101_BYTES + T105_BYTES) <= LINK_BUDGET * protocol.BYTES_PER_SECOND)
    arm = [k for k in range(nf) if k not in g]
    ticks = []
    prev_speed = 0.0
    for k in range(n):
        span = max(t_to[k] - t_from[k], 0.0) / speed_scale
        rates = np.abs(w_to[k] - w_from[k]) / span if span > 1e-9 else np.zeros(nf)
        if strat.per_joint and wm.model == "m3":
            cmds = [{"T": 101, "joint": j + 1, "rad": protocol.r4(_clamp(wm.field_names[j], w_to[k][j])),
                     "spd": spd_register(rates[j] * strat.margin, minimum=20), "acc": 0} for j in range(nf)]
            ticks.append(Tick(float(ts[k]), cmds[0], q_to[k], cmds[1:], w_to[k]))
            continue
        extra: list[dict[str, Any]] = []
        if strat.spd == "max":
            spd = 0
        else:
            need = float(np.max(rates[arm if split else slice(None)]))
            spd = spd_register(need * strat.margin, minimum=50)
            if split and g and rates[g[0]] * strat.margin > need:
                extra.append({"T": 101, "joint": 6, "rad": protocol.r4(_clamp("hand", w_to[k][g[0]])),
                              "spd": spd_register(rates[g[0]] * strat.margin, minimum=50), "acc": 0})
        if strat.acc == "none":
            acc = 0
        else:
            i0 = np.searchsorted(traj.times, t_from[k])
            i1 = max(i0 + 1, np.searchsorted(traj.times, t_to[k], side="right"))
            a = float(np.max(np.abs(traj.accelerations[max(i0 - 1, 0):i1, wm.index]))) * speed_scale ** 2
            dv = abs(spd / protocol.STEPS_PER_RAD - prev_speed) / dt
            acc = acc_register(max(a, dv) * 1.5, minimum=5)
            prev_speed = spd / protocol.STEPS_PER_RAD
        ticks.append(Tick(float(ts[k]), wm.command(c_to[k], spd, acc), q_to[k], extra, w_to[k]))
    return ticks


def _clamp(field_name: str, v: float) -> float:
    lo, hi = protocol.SAFE_WIRE_RANGE[field_name]
    return min(max(float(v), lo), hi)


def plan_clock(t: npt.ArrayLike, paused: Iterable[Sequence[float]]) -> Any:
    """The plan's time (s) at stream times ``t`` (s after the stream's start; scalar or (M,)) when the plan waited
    for a late host: ``paused`` is [(plan time at which its clock stopped, for how long), ...] in order (the
    execution log's ``paused``). During a pause the plan's time stands still; after it, it is that much behind."""
    tt = np.asarray(t, dtype=float)
    out = tt.copy()
    shift = 0.0
    for at, d in paused:
        start = float(at) + shift
        out = np.where(tt >= start + float(d), tt - shift - float(d), np.where(tt >= start, float(at), out))
        shift += float(d)
    return float(out) if np.ndim(t) == 0 else out


def run_clock(t: npt.ArrayLike, paused: Iterable[Sequence[float]]) -> Any:
    """The stream's time (s after its start) at which the plan, paused as ``plan_clock`` says, reached plan time ``t``
    (a pause's own point: when it started); the inverse of ``plan_clock`` outside the pauses."""
    tt = np.asarray(t, dtype=float)
    out = tt.copy()
    for at, d in paused:
        out = out + np.where(tt > float(at), float(d), 0.0)
    return float(out) if np.ndim(t) == 0 else out


def _check_wire_range(traj: Trajectory, wm: WireMap) -> None:
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


# ----------------------------------------------------------------------------- the link budget
@dataclass(frozen=True)
class LinkBudget:
    """What a stream asks of the link and the firmware, per second."""

    lines: float  # command lines/s host -> arm (motion, gripper, polls)
    up_bytes: float  # B/s host -> arm
    down_bytes: float  # B/s arm -> host (poll answers)
    firmware_share: float | None  # share of the firmware's line capacity (queued builds), None if not measured

    @property
    def up_share(self) -> float:
        """Share of the 11520 B/s host -> arm direction."""
        return self.up_bytes / protocol.BYTES_PER_SECOND

    @property
    def down_share(self) -> float:
        """Share of the 11520 B/s arm -> host direction."""
        return self.down_bytes / protocol.BYTES_PER_SECOND

    def describe(self) -> str:
        """One line for the display."""
        fw = f", {self.firmware_share:.0%} of the firmware's line rate" if self.firmware_share is not None else ""
        return (f"link budget: {self.lines:.0f} lines/s, {self.up_bytes / 1000:.1f} kB/s = {self.up_share:.0%} of "
                f"11.5 kB/s to the arm, {self.down_bytes / 1000:.1f} kB/s = {self.down_share:.0%} back{fw}")

    def as_dict(self) -> dict[str, Any]:
        """The budget as a JSON-ready dict (the execution log's ``link_budget``)."""
        return {"lines_per_s": round(self.lines, 2), "up_bytes_per_s": round(self.up_bytes, 1),
                "up_share": round(self.up_share, 4), "down_bytes_per_s": round(self.down_bytes, 1),
                "down_share": round(self.down_share, 4), "firmware_share": None if self.firmware_share is None
                else round(self.firmware_share, 4)}


def link_budget(schedule: list[Tick], poll_rate: float, reply_bytes: int = 230,
                line_time: float | None = None) -> LinkBudget:
    """The schedule's average demand: its lines and bytes over its duration, plus ``poll_rate``
    T:105 polls/s answered by ``reply_bytes``-byte lines; ``line_time`` (s per line at the firmware,
    measured at connect) gives the share of a queuing firmware's capacity."""
    duration = max(schedule[-1].t, 1e-9)
    n = sum(len(tk.commands) for tk in schedule)
    nbytes = sum(len(protocol.encode(c)) for tk in schedule for c in tk.commands)
    lines = n / duration + poll_rate
    up = nbytes / duration + poll_rate * T105_BYTES
    share = None if not line_time else lines * line_time
    return LinkBudget(lines, up, poll_rate * reply_bytes, share)
