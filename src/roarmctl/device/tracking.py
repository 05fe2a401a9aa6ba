"""How well the simulated arm followed the plan: the TCP error of its true servo positions (the
simulator's recording) against the trajectory, raw and with the lateness that was measured.

On a busy machine the host may send a command late and the simulated firmware may wake late; both
delay the arm by a measured amount. ``aligned`` errors compare each sample with the plan anywhere in
the window of that measured delay (so they equal the raw error when nothing was late); ``lag`` is
the time shift of the plan that fits the executed path best.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.protocol import WireMap
from roarmctl.device.schedule import plan_clock, sample
from roarmctl.device.servos import JOINTS

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

WINDOW = 0.25  # s: lateness this far back still delays the arm


def recorded_joints(robot: Robot, q_rec: np.ndarray) -> np.ndarray:
    """The simulator's recording (N, 6; firmware joints in the M3's URDF view, hand = pi - q) as
    joint vectors (N, dof) of ``robot``, through its wire map."""
    wm = WireMap(robot)
    fw = np.array(q_rec, dtype=float).copy()
    fw[:, 5] = math.pi - fw[:, 5]  # back to firmware radians
    cols = [JOINTS.index(f) for f in wm.field_names]
    q = np.zeros((len(fw), robot.dof))
    for w, i, c in zip(wm.fields, wm.index, cols):
        q[:, i] = (fw[:, c] - w.offset) / w.sign
    return q


def lateness_at(t: np.ndarray, events: np.ndarray) -> np.ndarray:
    """(N,) s: the largest lateness among ``events`` ((M, 2): time, lateness) in [t - WINDOW, t]."""
    out = np.zeros(len(t))
    for te, late in np.asarray(events, dtype=float).reshape(-1, 2):
        m = (t >= te) & (t <= te + WINDOW)
        out[m] = np.maximum(out[m], late)
    return out


def host_lateness(sent: list[dict[str, Any]], rate: float) -> np.ndarray:
    """(K, 2) (s after the stream's start, lateness s) of an execution log's ``sent`` motion ticks: each tick's own
    measured lateness, and each gap in the sending beyond one period where ticks are missing (a log written before the
    plan's clock paused for a late host: the pacing skipped the ticks a busy machine made late, counted in the
    log's ``skipped``; the tick after the gap is barely late, yet nothing went out meanwhile and the arm held the
    last command), spread over the gap so that every moment of it is covered."""
    dt = 1.0 / float(rate)
    ticks = [(int(e["tick"]), float(e["t"]), float(e["lateness"])) for e in sent if "tick" in e]
    events = [(t, late) for _, t, late in ticks]
    for (ka, ta, la), (kb, tb, _) in itertools.pairwise(ticks):
        due = ta - la + dt  # when the next command was due
        if kb > ka + 1 and tb > due:  # ticks skipped in between
            events += [(t, tb - due) for t in np.arange(due, tb, WINDOW / 2)] + [(tb, tb - due)]
    return np.array(events, dtype=float).reshape(-1, 2)


def pause_events(paused: Iterable[Sequence[float]], ahead: float) -> np.ndarray:
    """(K, 2) (s after the stream's start, s) for ``true_tracking``'s ``ahead``: where the plan waited for a late host
    (``paused``: the log's [(plan time, duration)]), the servos went on to the last goal sent, which lies up to
    ``ahead`` s further on the plan (the link's latency plus the strategy's lead), and need a moment after the pause
    to fall back into their usual lag: from each pause's start to ``WINDOW`` after its end the arm may be that much
    (at most the pause's length) ahead of the plan's time."""
    events: list[tuple[float, float]] = []
    shift = 0.0
    for at, d in paused:
        start = float(at) + shift
        amount = min(float(d), ahead)
        events += [(t, amount) for t in np.arange(start, start + float(d), WINDOW / 2)] + [(start + float(d), amount)]
        shift += float(d)
    return np.array(events, dtype=float).reshape(-1, 2)


def true_tracking(robot: Robot, traj: Trajectory, recording: tuple[np.ndarray, np.ndarray, np.ndarray], t0: float,
                  speed_scale: float = 1.0, host_late: np.ndarray | None = None, device_late: np.ndarray | None = None,
                  lag: bool = False, paused: Iterable[Sequence[float]] = (),
                  ahead: np.ndarray | None = None) -> dict[str, Any]:
    """TCP error (mm) of the recorded motion against ``traj`` over the motion's span.

    ``recording``: (times s, joints (N, 6), torque (N,)) as ``PtySimulator.recording()`` gives;
    ``t0``: the stream's start on the same clock; ``host_late``: (K, 2) (s after t0, lateness s) of
    the commands sent; ``device_late``: (M, 2) (s on the recording's clock, lateness s) of the
    simulated firmware's wake-ups; ``paused``: where the plan waited for a late host (the execution
    log's ``paused``), so that each sample is compared with the plan at the plan's own time; ``ahead``: (J, 2)
    (s after t0, s) how far the arm may be ahead of the plan's time after such events (``pause_events``). Returns
    rms/max raw and aligned, the lateness used, the sample count, whether torque stayed on, and with
    ``lag`` the best-fitting delay (s).
    """
    ts, q_rec, torque = recording
    wall = np.asarray(ts, dtype=float) - t0
    tt = plan_clock(wall, paused)
    m = (wall >= 0) & (tt <= traj.duration / speed_scale)
    out: dict[str, Any] = {"rms_mm": None, "max_mm": None, "samples": int(m.sum()),
                           "torque_always_on": bool(np.asarray(torque).all())}
    if not m.any() or math.isnan(t0):
        return out
    tt, wall = tt[m], wall[m]
    q = recorded_joints(robot, np.asarray(q_rec)[m])
    p = robot.kin.fk(q)[:, :3, 3]
    e = np.linalg.norm(p - robot.kin.fk(sample(traj, tt * speed_scale))[:, :3, 3], axis=1)
    late = np.zeros(len(tt))
    if host_late is not None and len(host_late):
        late = np.maximum(late, lateness_at(wall, host_late))
    if device_late is not None and len(device_late):
        dl = np.asarray(device_late, dtype=float).reshape(-1, 2).copy()
        dl[:, 0] -= t0
        late = np.maximum(late, lateness_at(wall, dl))
    early = lateness_at(wall, ahead) if ahead is not None and len(ahead) else np.zeros(len(tt))
    aligned = e.copy()
    for frac in np.linspace(0.0, 1.0, 6)[1:]:
        for shifted in (np.maximum(tt - frac * (late + 0.002), 0.0), tt + frac * early):
            ep = np.linalg.norm(p - robot.kin.fk(sample(traj, shifted * speed_scale))[:, :3, 3], axis=1)
            aligned = np.minimum(aligned, ep)
    out |= {"rms_mm": float(np.sqrt(np.mean(e ** 2))) * 1e3, "max_mm": float(e.max()) * 1e3,
            "rms_aligned_mm": float(np.sqrt(np.mean(aligned ** 2))) * 1e3, "max_aligned_mm": float(aligned.max()) * 1e3,
            "lateness_max_ms": float(late.max()) * 1e3, "ahead_max_ms": float(early.max()) * 1e3}
    if lag:
        shifts = np.arange(0.0, 0.1501, 0.002)
        rms = [float(np.sqrt(np.mean(np.linalg.norm(
            p - robot.kin.fk(sample(traj, np.maximum(tt - s, 0.0) * speed_scale))[:, :3, 3], axis=1) ** 2))) for s in shifts]
        out["lag_s"] = float(shifts[int(np.argmin(rms))])
    return out
