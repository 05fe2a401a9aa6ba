"""What a stream reports: its status after each tick (the live display), how it ended (``Result``) and its execution log.

The log's format is ``roarmctl.device.execlog``; this module fills it from a ``roarmctl.device.streamer.Streamer``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device import protocol
from roarmctl.device.execlog import ExecLog, trajectory_document
from roarmctl.robot.frames import device_point, to_frame

if TYPE_CHECKING:
    from roarmctl.device.streamer import Streamer


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
    """How a run ended (``outcome``, ``message``), what was sent, its lateness and tracking, and its log."""

    outcome: str  # "completed" | "interrupted" | "terminated" | "aborted" | "link_lost" | "failed"
    message: str
    n_sent: int
    lateness: np.ndarray  # (n,) s
    tracking: np.ndarray  # (m,) m, TCP error of each feedback during motion
    final_error: float | None
    t0: float
    log: dict[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The log's ``summary``: outcome, counts, lateness p50/p99 (ms), tracking RMS/max (mm) and what connecting and pacing learned."""
        lat = self.lateness * 1e3
        trk = self.tracking * 1e3
        pct = lambda a, p: float(np.percentile(a, p)) if len(a) else None  # noqa: E731
        out = {
            "outcome": self.outcome, "message": self.message, "commands": self.n_sent,
            "lateness_ms": {"p50": pct(lat, 50), "p99": pct(lat, 99), "max": float(lat.max()) if len(lat) else None},
            "tracking_mm": {"rms": float(np.sqrt(np.mean(trk ** 2))) if len(trk) else None,
                            "max": float(trk.max()) if len(trk) else None, "samples": int(len(trk))},
            "final_error_mm": None if self.final_error is None else self.final_error * 1e3,
        }
        for key in ("feedback", "waits", "firmware_lag_ms", "rate_changes", "hold", "device", "link_budget"):
            if key in self.log:
                out[key] = self.log[key]
        return out


def tcp(s: Streamer, q: np.ndarray) -> np.ndarray:
    """The TCP (m, world frame) of joint vector ``q`` (dof,) of the stream's robot."""
    return s.robot.kin.fk(s.robot.full_q(q))[:3, 3]


def pose_in_frames(s: Streamer) -> dict[str, Any] | None:
    """The last measured TCP of stream ``s`` in the world frame (m) and the robot's other frames (their units)."""
    if s.measured is None:
        return None
    out: dict[str, Any] = {"world_m": [round(float(v), 6) for v in tcp(s, s.measured)]}
    for name, fr in (getattr(s.robot, "frames", {}) or {}).items():
        out[f"{name}_{fr.unit}"] = [round(float(v), 3) for v in to_frame(fr, device_point(s.robot, fr, s.measured))]
    return out


def run_log(s: Streamer, res: Result) -> dict[str, Any]:
    """The execution log of stream ``s`` ending in ``res``: every command sent and every line received, times in s
    after t0 (format: ``roarmctl.device.execlog``)."""
    t0 = res.t0 if not math.isnan(res.t0) else (s.link.sent[0][0] if s.link.sent else 0.0)
    lateness = {k: x for k, x in s.sent_lateness}
    sched_idx = s.tick_of
    sent = []
    for t, cmd in s.link.sent:
        entry: dict[str, Any] = {"t": round(t - t0, 6), "cmd": cmd}
        k = sched_idx.get(id(cmd))
        if k is not None:
            entry["tick"] = k
            entry["lateness"] = round(lateness.get(k, math.nan), 6)
        sent.append(entry)
    received = []
    for r in s.link.received:
        e: dict[str, Any] = {"t": round(r.t - t0, 6), "line": r.line[:protocol.MAX_FEEDBACK_LINE]}
        if r.feedback is not None:
            e["feedback"] = r.feedback.raw  # x, y, z: the firmware's frame (mm)
            if id(r) in s.read_at:  # when its servos were read, as the stream judged it (s after t0)
                e["read_t"] = round(s.read_at[id(r)] - t0, 6)
            reason = s.refused_lines.get(id(r))
            if reason is not None or r.feedback.problems:
                e["refused"] = reason or r.feedback.problems[0]
            elif set(s.wm.field_names) <= set(r.feedback.joints):
                # the same pose in the plan's world frame (m), from our FK (frames of this robot's firmware only)
                e["tcp_world_m"] = [round(float(v), 6) for v in tcp(s, s.wm.from_wire(r.feedback.joints))]
        received.append(e)
    info = s.link.info
    budget = s.link_budget()
    hold = None if s.hold_info is None else dict(s.hold_info, t=round(s.hold_info["t"] - t0, 6))
    return ExecLog(
        robot=s.robot.name, port=s.link.port, firmware=s.link.firmware,
        device=None if info is None else info.as_dict(), speed_scale=s.cfg.speed_scale, t0_monotonic=t0,
        robot_description=getattr(s.traj, "robot_description", None),  # a robot not bundled, carried
        details={
            "strategy": s.cfg.strategy, "rate": s.rate, "duration": s.schedule[-1].t,
            "link_budget": budget.as_dict(), "feedback": s.validator.summary(),
            "waits": dict(s.waits), "paused": [[round(at, 6), round(d, 6)] for at, d in s.paused],
            # how much later than the round trip each poll was answered (s; the time it waited behind other lines
            # at the firmware), the firmware's time per line as measured, where the stream went on at a lower rate
            "firmware_lag_ms": s.pacer.lag_summary(),
            "firmware_lag": [[round(t - t0, 6), round(x, 6)] for t, x in s.pacer.lag],
            "firmware_line_time_s": round(s.pacer.line_time, 6), "rate_changes": s.rate_changes,
            "hold": hold, "summary": res.summary(), "notes": s.notes, "final_pose": pose_in_frames(s),
            "tracking": [{"t": round(t, 6), "error_m": round(e, 6)} for t, e in s.tracking]},
        trajectory=trajectory_document(s.traj),  # the one that ran (replanned from the arm's pose, maybe)
        sent=sent, received=received).to_dict()
