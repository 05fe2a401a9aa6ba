"""Where a stream's hold goes, and sending it: the goal chosen from what the stream sent and what the firmware confirmed.

The hold stops the arm where it is, with torque on: by default at the point of the planned, collision-checked path the
arm reaches when the hold arrives (never beyond the last set-point sent; no reversal), or, when the arm is not
following its commands (tracking abort), at its last validated measured pose if that is at most ``hold_max_age`` old.
On the build that queues lines (20260701) the queue is flushed first, so the arm got only as far as the last line the
firmware ran: the hold goes to the goal of the last tick a poll answer confirmed, never ahead of it. How the hold is
made to run (the flush, two copies): ``roarmctl.device.hold``; the streamer (``roarmctl.device.streamer``) calls
``hold`` when a run ends other than completed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.device.feedback import FeedbackRefused
from roarmctl.device.hold import HOLD_SPD, flush_queue, send_hold
from roarmctl.device.protocol import wire_seconds
from roarmctl.device.schedule import default_latency, sample, target_offset
from roarmctl.device.stream_result import tcp
from roarmctl.errors import DeviceError

SETTLED = 0.0005  # m: two poses this close (TCP) in a row, the arm has stopped
SETTLE_WAIT = 0.3  # s: the longest the hold waits for the arm to stop after a flush

if TYPE_CHECKING:
    from roarmctl.device.feedback import Reading
    from roarmctl.device.link import Received
    from roarmctl.device.streamer import Streamer


def hold(s: Streamer, cause: str) -> None:
    """Hold the arm of stream ``s`` (``cause``: ``stop`` or ``tracking``). Never torque off. A stop signal arriving
    during the hold (the first one raises ``KeyboardInterrupt``) does not cut it short: the hold is sent again, and
    the run's outcome stays what it was."""
    try:
        _hold_once(s, cause)
    except KeyboardInterrupt:
        s.notes.append("a stop signal arrived during the hold; hold sent again")
        _hold_once(s, cause)


def hold_target(s: Streamer, cause: str, now: float, after_flush: Reading | None = None) -> tuple[str, np.ndarray | None]:
    """(kind, firmware radians in field order) of the hold of stream ``s`` at ``now`` (its clock, s), or
    (kind, None) for no motion hold.

    ``path``: the plan at the time the hold reaches the servos, never beyond the last set-point sent; ``setpoint``:
    the last set-point sent; ``measured``: the last validated pose if at most ``hold_max_age`` old (else the path);
    ``measured_on_path`` (a build that flushes its queue first): the plan's point nearest ``after_flush``, the pose
    read after the flush, between the last tick a poll answer confirmed and the last one sent; ``confirmed`` (the
    same without that pose): the goal of the last tick a poll answer confirmed. ``auto``
    is ``measured`` after a tracking abort (the arm is not where it was told to go: stop pushing), ``path`` otherwise.
    """
    mode = s.cfg.hold
    if mode == "auto":
        mode = "measured" if cause == "tracking" else "path"
    fresh = s.validator.fresh(now, s.cfg.hold_max_age)
    sp = s.setpoint
    if mode == "measured" and fresh is not None:
        wire = np.array([fresh.wire[f] for f in s.wm.field_names])
        if sp is not None and sp.wire is not None:
            g = gripper_field(s)
            if g is not None:
                wire[g] = sp.wire[g]  # the gripper keeps its last command (keeps a grip)
        return "measured", wire
    if sp is None or sp.wire is None:
        return ("measured", np.array([fresh.wire[f] for f in s.wm.field_names])) if fresh is not None else ("none", None)
    if mode == "setpoint" or math.isnan(s.t0):
        return "setpoint", sp.wire
    if flushes(s):
        # the queue was flushed before the goal is chosen (``_hold_once``): the lines not run yet never run, and the
        # arm got as far as the last line the firmware ran. The last one a poll answer confirmed (answers read after the
        # flush included) bounds that from below, the last line sent from above: hold at the point of the plan between
        # them nearest the pose measured after the flush (never ahead of the firmware, on the path); without that pose,
        # at the confirmed tick's goal (before any confirmation, the start)
        # (the pose after the flush stays valid however long its answer took: nothing ran after it)
        k = s.pacer.confirmed_tick
        if after_flush is not None:
            lo = s.schedule[k].t if k is not None else 0.0
            return "measured_on_path", nearest_on_plan(s, after_flush.q, lo, sp.t)
        if k is None:
            return "confirmed", s.wm.to_wire_array(s.traj.positions[0])[0]
        tick = s.schedule[k]
        return "confirmed", tick.wire if tick.wire is not None else s.wm.to_wire_array(tick.target)[0]
    # the goals ran ``lead`` ahead on the plan: the hold stops them where they would be when it arrives
    arrive = s.plan_time(now - s.t0) + default_latency(s.rate) + s.lead
    latest = min(arrive, sp.t + 1.0 / s.rate + default_latency(s.rate) + s.lead)
    q = sample(s.traj, max(0.0, latest) * s.cfg.speed_scale)
    return "path", s.wm.to_wire_array(q)[0]


MAX_HOLD_SAMPLES = 20_001  # plan points the queued build's hold compares with the measured pose


def nearest_on_plan(s: Streamer, q: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Firmware radians (field order) of the plan's point nearest joint vector ``q`` (dof,) by TCP distance, between
    the goals of ticks at schedule times ``lo`` and ``hi`` (s; a tick's goal is ``target_offset`` later on the plan:
    the strategy's lookahead, the link's latency, its lead); sampled every 0.5 ms of plan time at least (every 2 ms, a
    fast joint's plan moved 2-3 mm of TCP between samples, and the hold pulled the stopped arm back by about half that)."""
    ahead = target_offset(s.cfg.strategy, s.rate)
    a, b = (min(max(0.0, x + ahead), s.traj.duration / s.cfg.speed_scale) * s.cfg.speed_scale for x in (lo, hi))
    # at most MAX_HOLD_SAMPLES (10 s of plan at 0.5 ms): without a confirmed tick the window runs from the start, and
    # a long plan would cost the stop ~100,000 FK evaluations
    taus = np.linspace(a, max(a, b), min(MAX_HOLD_SAMPLES, max(2, int((b - a) / 0.0005) + 2)))
    qs = sample(s.traj, taus)
    tcps = s.robot.kin.fk(s.robot.full_q(qs))[:, :3, 3]
    here = s.robot.kin.fk(s.robot.full_q(q))[:3, 3]
    best = int(np.argmin(np.linalg.norm(tcps - here, axis=1)))
    return s.wm.to_wire_array(qs[best])[0]


def flushes(s: Streamer) -> bool:
    """Whether the build on the link of ``s`` queues lines and the hold flushes its queue first (20260701)."""
    return s.link.firmware == "m3-2026"


def gripper_field(s: Streamer) -> int | None:
    """The index of the gripper's field on the wire, or None for an arm without one."""
    if s.robot.gripper is None:
        return None
    return next((k for k, w in enumerate(s.wm.fields) if w.joint == s.robot.gripper.joint), None)


def settled(s: Streamer, pose: Reading | None, judge: Callable[[Received], Reading | None]) -> Reading | None:
    """After a flush the servos still run to the goal of the last line the firmware ran, and stop there: ask until two
    poses in a row are within ``SETTLED`` m of each other (TCP), at most ``SETTLE_WAIT`` s, and return the newest.
    A hold aimed at a pose read while the arm still moved pulled it back along the path (up to 11 mm at a 6 ms pass)."""
    end = s.clock() + SETTLE_WAIT
    while pose is not None and s.clock() < end:
        r = s.link.request(0.15)
        new = judge(r) if r is not None else None
        if new is None:
            break
        moved = float(np.linalg.norm(tcp(s, new.q) - tcp(s, pose.q)))
        pose = new
        if moved < SETTLED:
            break
    return pose


def confirm_answers(s: Streamer, frames: list[Received]) -> None:
    """The stream's oldest polls answered by ``frames`` (read after a flush, in order): the lines they confirm."""
    for r in frames:
        if not s.pacer.polls:
            break
        s.pacer.answered(r.t, r.t, wire_seconds(len(r.line) + 2))
    s.pacer.polls.clear()  # the others were flushed with the queue: no answer will come


def _hold_once(s: Streamer, cause: str) -> None:
    link = s.link

    def judge_quietly(r: Received) -> Reading | None:
        try:
            readings = s.judge([r])
        except FeedbackRefused:
            return None
        return readings[-1] if readings else None

    if getattr(link, "closed", False) or getattr(link, "ser", True) is None:
        s.notes.append("hold not sent: the port was never opened")
        return
    after_flush: Reading | None = None  # the newest pose read after the flush (the last frame: its own poll's answer)
    try:
        flushed = flushes(s)
        if flushed:
            # the queue first (nothing more runs), then the answers: those of the stream's polls that ran confirm lines,
            # the last one is the pose after the flush
            frames = flush_queue(link, len(s.pacer.polls), s.clock, s.sleep)
            confirm_answers(s, frames[:-1])
            for answer in frames:
                after_flush = judge_quietly(answer) or after_flush
            after_flush = settled(s, after_flush, judge_quietly)
        now = s.clock()
        kind, wire = hold_target(s, cause, now, after_flush)
        if wire is None:
            try:
                r = link.request(0.15)
                if r is not None and s.judge([r]):
                    kind, wire = hold_target(s, cause, s.clock())
            except DeviceError:
                pass
        if wire is None:
            s.notes.append("no hold sent: nothing was commanded and no valid pose was read")
            return
        spd = HOLD_SPD
        if kind != "measured" and s.setpoint is not None:
            spd = max(HOLD_SPD, int(s.setpoint.cmd.get("spd", 0) or 0))
        # the stream's own polls still unanswered are answered first (after a flush: none is still to come)
        s.hold_info = send_hold(link, s.wm, wire, spd, kind=kind, cause=cause, earlier=len(s.pacer.polls),
                                on_answer=judge_quietly, clock=s.clock, sleep=s.sleep, flushed=flushed)
        s.pacer.polls.clear()
        s.notes.append(f"hold sent ({kind}{', queue flushed first' if flushed else ''})")
    except DeviceError:
        s.notes.append("hold could not be sent: the link is gone")
