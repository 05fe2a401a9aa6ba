"""Test trajectories for the device tests (the planner is separate): minimum-jerk joint moves."""

from __future__ import annotations

import itertools

import numpy as np

from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.robot.loader import load_robot

HOME = np.array([0.0, 0.0, 1.5708, 0.0, 0.0, 0.0])


def min_jerk(waypoints: list, durations: list[float], rate: float = 100.0, robot: str = "roarm_m3_pro") -> Trajectory:
    """Piecewise minimum-jerk (quintic, zero end velocity/acceleration) joint moves through ``waypoints``."""
    r = load_robot(robot)
    wps = [r.full_q(np.asarray(w, dtype=float)) for w in waypoints]
    ts, qs, vs, as_ = [], [], [], []
    t_off = 0.0
    for k, dur in enumerate(durations):
        a, b = wps[k], wps[k + 1]
        n = int(round(dur * rate))
        u = np.arange(0 if k == 0 else 1, n + 1) / n
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        ds = (30 * u**2 - 60 * u**3 + 30 * u**4) / dur
        dds = (60 * u - 180 * u**2 + 120 * u**3) / dur**2
        ts.append(t_off + u * dur)
        qs.append(a + np.outer(s, b - a))
        vs.append(np.outer(ds, b - a))
        as_.append(np.outer(dds, b - a))
        t_off += dur
    seg = [Segment(sum(durations[:k]), sum(durations[: k + 1]), "free", f"move {k}") for k in range(len(durations))]
    return Trajectory(robot=robot, joint_names=list(r.joint_names), times=np.concatenate(ts),
                      positions=np.vstack(qs), velocities=np.vstack(vs), accelerations=np.vstack(as_),
                      segments=seg, events=[Event(durations[0], "grasp", "test")] if len(durations) > 1 else [])


def pick_place(robot: str = "roarm_m3_pro") -> Trajectory:
    """A pick-and-place-like motion at the arm's planning limits: home, above, down, grasp, up, over, down, release, home."""
    above = [0.6, 0.35, 1.9, -0.7, 0.0, 1.2]
    down = [0.6, 0.6, 1.95, -0.95, 0.0, 1.2]
    grasp = [0.6, 0.6, 1.95, -0.95, 0.0, 0.3]
    up = [0.6, 0.3, 1.9, -0.6, 0.0, 0.3]
    over = [-0.7, 0.3, 1.9, -0.6, 0.5, 0.3]
    down2 = [-0.7, 0.55, 1.95, -0.9, 0.5, 0.3]
    rel = [-0.7, 0.55, 1.95, -0.9, 0.5, 1.2]
    wps = [HOME, above, down, grasp, up, over, down2, rel, HOME]
    durs = [1.1, 0.65, 0.95, 0.7, 1.3, 0.65, 0.95, 1.1]  # each within the M3 Pro's velocity and acceleration limits
    return min_jerk(wps, durs, robot=robot)


def host_lateness(log: dict) -> float:
    """The largest lateness (s) the streaming host measured in a run's execution log: each motion tick's own,
    and each gap in the sending beyond one period (a busy machine stalled the process: the plan paused, and the
    tick after the stall is less than a period late, but nothing went out meanwhile), up to the hold (the last T:102)."""
    dt = 1.0 / float(log["rate"])
    ticks = [s for s in log["sent"] if "tick" in s]
    late = max((s["lateness"] for s in ticks), default=0.0)
    for a, b in itertools.pairwise(ticks):
        late = max(late, b["t"] - (a["t"] - a["lateness"] + dt))
    holds = [s for s in log["sent"] if s["cmd"].get("T") == 102 and "tick" not in s]
    if ticks and holds:
        late = max(late, holds[-1]["t"] - (ticks[-1]["t"] + dt))  # a stall before the hold
    return late
