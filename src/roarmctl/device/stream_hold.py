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
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.device.feedback import FeedbackRefused
from roarmctl.device.hold import HOLD_SPD, send_hold
from roarmctl.device.schedule import default_latency, sample
from roarmctl.errors import DeviceError

if TYPE_CHECKING:
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


def hold_target(s: Streamer, cause: str, now: float) -> tuple[str, np.ndarray | None]:
    """(kind, firmware radians in field order) of the hold of stream ``s`` at ``now`` (its clock, s), or
    (kind, None) for no motion hold.

    ``path``: the plan at the time the hold reaches the servos, never beyond the last set-point sent; ``setpoint``:
    the last set-point sent; ``measured``: the last validated pose if at most ``hold_max_age`` old (else the path);
    ``confirmed`` (a build that flushes its queue first): the goal of the last tick a poll answer confirmed. ``auto``
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
        # the queue is flushed before the hold: the lines not run yet never run, and the arm got as far as the last
        # line the firmware ran. The last one a poll answer confirmed bounds that from below, on the path: hold its
        # goal (never ahead of it; before any confirmation, a fresh measured pose or the start)
        k = s.pacer.confirmed_tick
        if k is None:
            if fresh is not None:
                return "measured", np.array([fresh.wire[f] for f in s.wm.field_names])
            return "confirmed", s.wm.to_wire_array(s.traj.positions[0])[0]
        tick = s.schedule[k]
        return "confirmed", tick.wire if tick.wire is not None else s.wm.to_wire_array(tick.target)[0]
    # the goals ran ``lead`` ahead on the plan: the hold stops them where they would be when it arrives
    arrive = s.plan_time(now - s.t0) + default_latency(s.rate) + s.lead
    latest = min(arrive, sp.t + 1.0 / s.rate + default_latency(s.rate) + s.lead)
    q = sample(s.traj, max(0.0, latest) * s.cfg.speed_scale)
    return "path", s.wm.to_wire_array(q)[0]


def flushes(s: Streamer) -> bool:
    """Whether the build on the link of ``s`` queues lines and the hold flushes its queue first (20260701)."""
    return getattr(s.link, "firmware", None) == "m3-2026"


def gripper_field(s: Streamer) -> int | None:
    """The index of the gripper's field on the wire, or None for an arm without one."""
    if s.robot.gripper is None:
        return None
    return next((k for k, w in enumerate(s.wm.fields) if w.joint == s.robot.gripper.joint), None)


def _hold_once(s: Streamer, cause: str) -> None:
    link = s.link
    if getattr(link, "closed", False) or getattr(link, "ser", True) is None:
        s.notes.append("hold not sent: the port was never opened")
        return
    try:
        now = s.clock()
        kind, wire = hold_target(s, cause, now)
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

        def judge_quietly(r: Received) -> None:
            try:
                s.judge([r])
            except FeedbackRefused:
                pass

        # the stream's own polls still unanswered are answered first
        s.hold_info = send_hold(link, s.wm, wire, spd, kind=kind, cause=cause, earlier=len(s.pacer.polls),
                                on_answer=judge_quietly, clock=s.clock, sleep=s.sleep)
        s.pacer.polls.clear()
        flushed = s.hold_info["flushed_queue"]
        s.notes.append(f"hold sent ({kind}{', queue flushed first' if flushed else ''})")
    except DeviceError:
        s.notes.append("hold could not be sent: the link is gone")
