"""The three forms a motion takes while a plan is planned, and the helpers that cut and join timed paths.

A task expands into ``TaskStep``s (what to do: a free move, a straight line, a gripper action, a wait);
a free or straight step gets its joint path and becomes an ``UntimedMotion``; timing turns one or more
motions into a ``TimedPiece`` (a stretch of the trajectory from rest to rest). All times in s, joint
values in rad, arrays (N, dof) over every actuated joint.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from roarmctl.motion.timing import TimedPath
from roarmctl.motion.trajectory import Event, Segment

SAMPLE_DT = 0.01  # s: 100 Hz output
RECHECK_SUBSTEPS = 4  # collision re-check at 4x the output rate
LINE_TOLERANCE = 0.001  # m: straight-line segments follow the line within this
LIMIT_TOL = 1e-6


@dataclass
class TaskStep:
    """One step a task expands into, before any path is planned: ``kind`` free | cartesian | gripper | wait."""

    kind: str  # free | cartesian | gripper | wait
    label: str
    waypoints: np.ndarray | None = None  # (K, dof) full configurations (free: arm path filled later)
    q_from: np.ndarray | None = None
    q_to: np.ndarray | None = None
    gripper_to: float | None = None
    duration: float = 0.0
    event: Event | None = None
    line: tuple[np.ndarray, np.ndarray] | None = None
    pitch: float | None = math.pi / 2  # None: position-only IK
    roll: float | None = None
    grasp_target: str | None = None  # the object the jaws may touch during this step
    open_to: float | None = None  # free motion: the gripper opens to this during it (blended) or right after
    open_label: str = ""
    zone: float | None = None  # m: a move target the plan names ends this step (0: reached); None: a join the planner made


@dataclass
class UntimedMotion:
    """A free or straight step with its joint path, not yet timed: ``wps`` (K, dof) full configurations,
    the gripper at its value at the start."""

    step: TaskStep
    wps: np.ndarray


@dataclass
class TimedPiece:
    """A timed stretch of the trajectory, from rest to rest: its segments, event and blended joins (times from its start)."""

    tp: TimedPath
    segments: list[Segment]
    event: Event | None = None
    blends: list[float] = field(default_factory=list)
    attach: dict | None = None  # payload (link -> Inertial) held from this piece's end on
    detach: bool = False  # the held payload is let go at this piece's end
    jaw_target: str | None = None  # a grasp or release: the object the jaws close on or let go


def with_value(q: np.ndarray, index: int | None, value: float | None) -> np.ndarray:
    """A copy of ``q`` with ``q[index] = value`` (unchanged when either is None)."""
    out = np.array(q, dtype=float, copy=True)
    if index is not None and value is not None:
        out[index] = value
    return out


def dwell(q: np.ndarray, duration: float) -> TimedPath:
    """Standing still at ``q`` for ``duration`` s, sampled no coarser than SAMPLE_DT."""
    n = max(int(math.ceil(duration / SAMPLE_DT - 1e-9)), 1)  # no step longer than one sample
    times = np.linspace(0.0, duration, n + 1)
    qq = np.repeat(q[None, :], len(times), axis=0)
    return TimedPath(times, qq, np.zeros_like(qq), np.zeros_like(qq))


def concat(a: TimedPath, b: TimedPath) -> TimedPath:
    """``b`` after ``a`` (``b`` starts where ``a`` ends; its first sample is dropped)."""
    return TimedPath(np.concatenate([a.times, b.times[1:] + a.duration]), np.concatenate([a.q, b.q[1:]]),
                     np.concatenate([a.qd, b.qd[1:]]), np.concatenate([a.qdd, b.qdd[1:]]), a.jerk_filter)


def split_at(tp: TimedPath, i: int) -> tuple[TimedPath, TimedPath]:
    """``tp`` cut at sample ``i``: samples 0..i and i..end (times from the cut); both keep sample ``i``."""
    t0 = tp.times[i]
    first = TimedPath(tp.times[:i + 1].copy(), tp.q[:i + 1].copy(), tp.qd[:i + 1].copy(), tp.qdd[:i + 1].copy(), tp.jerk_filter)
    second = TimedPath(tp.times[i:] - t0, tp.q[i:].copy(), tp.qd[i:].copy(), tp.qdd[i:].copy(), tp.jerk_filter)
    return first, second


def superpose(a: TimedPath, b: TimedPath, ia: int, m: int) -> TimedPath:
    """``b`` started ``m`` samples before ``a``'s last on-grid sample ``ia`` ends it, both at rest at their ends.

    Positions add as displacements from the common point (``b``'s start, where ``a`` comes to rest);
    velocities and accelerations add. Samples stay on the SAMPLE_DT grid (``a``'s off-grid last sample
    is dropped: ``a`` is at rest from then on) and end with ``b``'s last sample.
    """
    dt = SAMPLE_DT
    start = ia + 1 - m
    nb = len(b.times)
    n = start + nb
    times = np.arange(n) * dt
    times[start:] = start * dt + b.times
    q = np.repeat(a.q[-1][None, :], n, axis=0)
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    k = min(ia + 1, n)
    q[:k], qd[:k], qdd[:k] = a.q[:k], a.qd[:k], a.qdd[:k]
    q[start:] += b.q - b.q[0]
    qd[start:] += b.qd
    qdd[start:] += b.qdd
    return TimedPath(times, q, qd, qdd, max(a.jerk_filter, b.jerk_filter))


def interpolate(q: np.ndarray, substeps: int) -> np.ndarray:
    """Linear interpolation with ``substeps`` points per sample interval (for fine re-checks)."""
    if len(q) < 2:
        return q
    t = np.linspace(0, len(q) - 1, (len(q) - 1) * substeps + 1)
    i = np.minimum(t.astype(int), len(q) - 2)
    f = (t - i)[:, None]
    return q[i] * (1 - f) + q[i + 1] * f
