"""Joining timed motions without a stop: a chain of free and straight motions is timed motion by motion, then
each join is either an overlap in time (the next motion starts before the previous one ends; the two add) or,
where a joint reverses at the join, a corner move (the corner cut out and replaced by a time-optimal,
jerk-limited Ruckig move). Every blended sample keeps every limit and is collision-free."""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.motion.planning.grasp import GripperDoesNotFit, gripper_action, open_during_transit, overlap_jaw_action
from roarmctl.motion.planning.motions import _copied, payload_key, time_motion
from roarmctl.motion.planning.payloads import torque_model
from roarmctl.motion.planning.pieces import (
    LIMIT_TOL,
    RECHECK_SUBSTEPS,
    SAMPLE_DT,
    TaskStep,
    TimedPiece,
    UntimedMotion,
    interpolate,
    superpose,
)
from roarmctl.motion.timing import TimedPath
from roarmctl.motion.trajectory import Segment

if TYPE_CHECKING:
    import ruckig

    from roarmctl.motion.planning.context import PlanContext

LINE_KEEP = 0.5  # a blend may round the corner over at most the first (last) half of a straight line
BLEND_STEP = 2  # samples between the overlaps tried, longest first
# corner_move: corner cuts (i in the first motion, k in the second) tried every CORNER_COARSE samples, then every
# sample around the CORNER_REFINE best; at most CORNER_TRIES candidates are checked, shortest first.
CORNER_COARSE, CORNER_REFINE, CORNER_TRIES = (8, 4), 2, 16

Bounds = list[tuple[float, float]]  # each motion's (start, end) s in a blended piece


def time_chain(ctx: PlanContext, motions: list[UntimedMotion]) -> list[TimedPiece]:
    """Time a chain of motions: each from rest to rest, then, when ``limits.blend``, joined without a stop at
    every join (``blend_join``) and the gripper opened during its free motion.

    The result is a function of the motions (their kinds, lines, grasp targets, gripper openings and exact
    waypoints), of the collision world (the checker's scene, attached objects and state) and of the held payload:
    the limits are fixed per plan. A plan keeps what it timed (``ctx.chains``, keyed by all of these, its labels
    aside): the cycles of a plan that repeat a chain in the same world (a cube carried there and back, cycle after
    cycle) take its pieces, checked when they were made, relabelled with the new motions' labels."""
    if not motions:
        return []
    key = chain_key(ctx, motions)
    known = ctx.chains.get(key) if key is not None else None
    if known is not None:
        pieces, labels, (gripper, target) = known
        ctx.set_state(gripper, grasp_target=target)  # the collision state the chain was left in
        names = dict(zip(labels, chain_labels(motions)))
        return [replace(p, tp=_copied(p.tp), blends=list(p.blends),
                        segments=[replace(sg, label=names.get(sg.label, sg.label)) for sg in p.segments]) for p in pieces]
    out = _time_chain(ctx, motions)
    labels = chain_labels(motions)
    if key is not None and len(set(labels)) == len(labels):  # relabelling needs each label once
        c = ctx.checker
        state = (None if c._gripper_index is None else float(c._q_template[c._gripper_index]), c._grasp_target)
        ctx.chains.keep(key, ([replace(p, tp=_copied(p.tp), blends=list(p.blends), segments=list(p.segments)) for p in out],
                              labels, state))
    return out



def chain_labels(motions: list[UntimedMotion]) -> list[str]:
    """Every label a chain's pieces can carry: each motion's, and its gripper opening's (at rest, ``at_rest``)."""
    return [lab for m in motions for lab in (m.step.label, m.step.open_label or f"{m.step.label}: open gripper")]


def chain_key(ctx: PlanContext, motions: list[UntimedMotion]) -> tuple | None:
    """What ``time_chain``'s result depends on, as exact bytes (labels aside); None if a motion's step holds what
    the key does not cover (its own waypoints, times or events: not a free or straight motion's)."""
    parts = []
    for m in motions:
        s = m.step
        if s.waypoints is not None or s.q_from is not None or s.event is not None or s.kind not in ("free", "cartesian"):
            return None
        line = None if s.line is None else (np.asarray(s.line[0], dtype=float).tobytes(), np.asarray(s.line[1], dtype=float).tobytes())
        parts.append((s.kind, s.grasp_target, s.open_to, s.zone, line, m.wps.shape, np.ascontiguousarray(m.wps, dtype=float).tobytes()))
    return (tuple(parts), payload_key(ctx), ctx.held, ctx.checker._state_key())


def _time_chain(ctx: PlanContext, motions: list[UntimedMotion]) -> list[TimedPiece]:
    """``time_chain`` itself (not kept)."""
    singles = [time_motion(ctx, m) for m in motions]
    if not ctx.limits.blend:
        return at_rest(ctx, motions, singles)
    piece, bounds = blend_chain(ctx, motions, singles)
    try:
        open_during_transit(ctx, piece.tp, motions, [b[0] for b in bounds], [b[1] for b in bounds])
    except GripperDoesNotFit as exc:  # too short to open the gripper on the way: stop after that motion
        k = exc.index
        return time_chain(ctx, motions[:k]) + at_rest(ctx, [motions[k]], [singles[k]]) + time_chain(ctx, motions[k + 1:])
    return [piece]


def append_pieces(ctx: PlanContext, pieces: list[TimedPiece], new: list[TimedPiece]) -> list[TimedPiece]:
    """``pieces + new``; when blending, a grasp starts closing during the straight motion before it and
    the straight motion after a release starts while the jaws still open (``grasp.overlap_jaw_action``)."""
    if not new:
        return pieces
    if not pieces or not ctx.limits.blend or ctx.gi is None:
        return pieces + new
    a, b = pieces[-1], new[0]
    if b.event is not None and b.event.kind == "grasp" and b.jaw_target and a.segments[-1].kind == "cartesian":
        return pieces[:-1] + overlap_jaw_action(ctx, a, b, b.jaw_target, grasp=True) + new[1:]
    if a.event is not None and a.event.kind == "release" and a.jaw_target and b.segments[0].kind == "cartesian":
        return pieces[:-1] + overlap_jaw_action(ctx, a, b, a.jaw_target, grasp=False) + new[1:]
    return pieces + new


def blend_chain(ctx: PlanContext, motions: list[UntimedMotion], singles: list[TimedPiece]) -> tuple[TimedPiece, Bounds]:
    """The chain's motions (each timed alone in ``singles``) blended join by join; also each motion's (start, end) in the result."""
    piece, bounds = singles[0], [(0.0, singles[0].tp.duration)]
    for k in range(1, len(motions)):
        piece, bounds = blend_join(ctx, piece, bounds, motions[:k], motions[k], singles[k], singles[k - 1].tp)
    return piece, bounds


def at_rest(ctx: PlanContext, motions: list[UntimedMotion], singles: list[TimedPiece]) -> list[TimedPiece]:
    """The motions one after the other from rest to rest, the gripper opened at rest after its free motion."""
    pieces = []
    for motion, piece in zip(motions, singles):
        pieces.append(piece)
        if motion.step.open_to is not None:
            q = piece.tp.q[-1].copy()
            step = TaskStep("gripper", motion.step.open_label or f"{motion.step.label}: open gripper", gripper_to=motion.step.open_to)
            tp = gripper_action(ctx, step, q)
            pieces.append(TimedPiece(tp, [Segment(0.0, tp.duration, "gripper", step.label)]))
    return pieces


def blend_join(ctx: PlanContext, a: TimedPiece, bounds: Bounds, a_motions: list[UntimedMotion], motion: UntimedMotion,
               b: TimedPiece, prev_tp: TimedPath) -> tuple[TimedPiece, Bounds]:
    """``b`` (``motion`` timed alone) started before ``a`` ends: the two motions superposed over an overlap
    (velocity, acceleration and jerk add; both are continuous, so the sum is too). The longest overlap (on the
    sample grid, at most the shorter motion's duration) is taken whose samples keep every limit (velocity,
    acceleration, jerk by finite differences, torque by RNEA, TCP speed) and are collision-free and outside the
    singularity margin; a straight line keeps at least its last (or first) LINE_KEEP of its length exact, so the
    overlap only rounds the corner near its pre-grasp end. ``bounds`` are each motion's (start, end) in ``a``;
    ``prev_tp`` is the last of them timed on its own. Where ``corner_move`` does better than the best overlap, its
    corner move is taken.

    (Timing the blended curve again as one TOPP-RA path gained only 0.04-0.1 s on the bundled plan,
    and the curve's dense knots made the acceleration chatter; superposing two smooth profiles does not.)"""
    dt = SAMPLE_DT
    prev = a_motions[-1]
    ta, tb = a.tp, b.tp
    on_grid = np.flatnonzero(np.abs(ta.times / dt - np.round(ta.times / dt)) < 1e-6)
    ia = int(on_grid[-1])
    limit = min(ia - int(np.ceil(bounds[-1][0] / dt - 1e-9)), len(tb.times) - 2)  # overlap stays inside both motions
    # when a straight line is (1 - LINE_KEEP) done: the line must be exact until LINE_KEEP of it is done
    lines = (line_time(ctx, prev, ta, bounds[-1], 1.0 - LINE_KEEP) if prev.step.kind == "cartesian" else None,
             line_time(ctx, motion, tb, (0.0, tb.duration), 1.0 - LINE_KEEP) if motion.step.kind == "cartesian" else None)
    if lines[0] is not None:
        limit = min(limit, ia - int(np.ceil(lines[0] / dt - 1e-9)))
    if lines[1] is not None:
        limit = min(limit, int(lines[1] / dt))
    zone = prev.step.zone  # a target the plan names ends prev: the corner is rounded inside its zone only
    span = None if zone is None or zone <= 0.0 else zone_limits(ctx, ta, tb, ia, int(np.ceil(bounds[-1][0] / dt - 1e-9)), zone)
    if span is not None:
        limit = min(limit, ia + 1 - span[0], span[1] + 1)
    t0 = time.perf_counter()
    try:
        cornered = None
        if zone is None or zone > 0.0:
            cornered = corner_move(ctx, ta, tb, ia, bounds, prev, motion, prev_tp, (ia + 1) * dt + tb.duration, lines, span)
        if cornered is not None and cornered[0].duration <= (ia + 1 - max(limit, 0)) * dt + tb.duration + 1e-9:
            return corner_piece(a, b, bounds, prev, motion, *cornered)  # no overlap could do better
        for m in (range(limit, 0, -BLEND_STEP) if zone is None or zone > 0.0 else ()):
            cand = superpose(ta, tb, ia, m)
            if join_samples_ok(ctx, cand, ia + 1 - m, ia, prev, motion):
                break
        else:
            m, cand = 0, superpose(ta, tb, ia, 0)
        if cornered is not None and cornered[0].duration < cand.duration - 1e-9:
            return corner_piece(a, b, bounds, prev, motion, *cornered)
    finally:
        ctx.timer.add("blend", t0)
    start = (ia + 1 - m) * dt  # b's start in the combined timeline
    # where one segment hands over to the next: a line is exact from (or until) there
    if motion.step.kind == "cartesian":
        join = ta.duration if m else start
    elif prev.step.kind == "cartesian":
        join = start
    else:
        join = 0.5 * (start + max(ta.duration, start))
    segments = a.segments[:-1] + [Segment(a.segments[-1].start, join, a.segments[-1].kind, a.segments[-1].label)]
    segments += [Segment(max(start + sg.start, join), start + sg.end, sg.kind, sg.label) for sg in b.segments]
    new_bounds = bounds[:-1] + [(bounds[-1][0], join), (join, start + tb.duration)]
    return TimedPiece(cand, segments, None, a.blends + ([join] if m else [])), new_bounds


def corner_move(ctx: PlanContext, ta: TimedPath, tb: TimedPath, ia: int, bounds: Bounds, prev: UntimedMotion,
                motion: UntimedMotion, prev_tp: TimedPath, beat: float,
                lines: tuple[float | None, float | None],
                span: tuple[int, int] | None = None) -> tuple[TimedPath, int, int] | None:
    """The corner between ``ta`` (ending with the motion ``prev``, its last on-grid sample ``ia``) and ``tb`` (the
    motion ``motion``, timed from rest) cut out and replaced by a time-optimal, jerk-limited move from sample i of
    ``ta`` to sample k of ``tb`` (Ruckig, state to state: position, velocity and acceleration at both ends, all
    joints finishing together, duration a whole number of samples).

    Where a joint reverses at the corner (the RoArm's wrist between a transit and a vertical approach), the
    superposition of ``blend_join`` can overlap only the two jerk ramps, because the two motions' accelerations
    add; the corner move instead keeps decelerating through the reversal. A straight line keeps its LINE_KEEP
    exact (i and k are bounded by it); a free motion is cut at most half-way and only on its last (first)
    edge between two of its vertices (``prev_tp``: ``prev`` timed on its own), so a detour around an obstacle
    is not cut short. Candidates (i, k) are searched
    on a coarse grid, refined around the best ones, and taken shortest first; the first whose samples pass
    ``join_samples_ok`` (every limit, collisions under both motions' states) and that beats ``beat`` (s, the
    superposed result) is returned: (path, i, index of the corner move's last sample). None if none. ``lines``:
    the times (s, in ``ta`` and ``tb``) when ``prev`` and ``motion`` are 1 - LINE_KEEP along their straight lines
    (None: not a line), as ``blend_join`` found them. ``span``: ``zone_limits`` of a target with a zone at the
    corner (the corner move starts and ends inside the zone), or None (a join the planner made)."""
    from ruckig import DurationDiscretization, InputParameter, Result, Ruckig, RuckigError, Trajectory

    dt = SAMPLE_DT
    arm = ctx.arm
    i_lo = int(np.ceil(bounds[-1][0] / dt - 1e-9))
    if lines[0] is not None:
        i_lo = max(i_lo, int(np.ceil(lines[0] / dt - 1e-9)))
    elif len(prev.wps) > 2 and prev_tp.s is not None:  # from its last vertex on (prev ends where ta does)
        last = float(np.sum(np.linalg.norm(np.diff(prev.wps[:-1][:, arm], axis=0), axis=1)))
        t_v = float(prev_tp.times[min(int(np.searchsorted(prev_tp.s, last - 1e-9)), len(prev_tp.times) - 1)])
        i_lo = max(i_lo, int(np.ceil((t_v + ta.duration - prev_tp.duration) / dt - 1e-9)))
    k_hi = len(tb.times) - 2
    if lines[1] is not None:
        k_hi = min(k_hi, int(lines[1] / dt))
    else:
        k_hi = min(k_hi, int(0.5 * tb.duration / dt))
        if len(motion.wps) > 2 and tb.s is not None:  # up to its first vertex
            first = float(np.linalg.norm(motion.wps[1][arm] - motion.wps[0][arm]))
            k_hi = min(k_hi, int(np.searchsorted(tb.s, first + 1e-9, side="right")) - 1)
    # the ends themselves must be valid under both motions' states (the corner move's samples are checked under both)
    # (the state the checker is in first: each switch rebuilds its collision objects)
    motion_first = ctx.checker._grasp_target is not None and ctx.checker._grasp_target == ctx.target_of(motion)
    for p in ((motion, prev) if motion_first else (prev, motion)):
        if ia <= i_lo or k_hi <= 0:
            break
        if p is prev:
            bad = first_invalid_under(ctx, prev, tb.q[1:k_hi + 1] + (ta.q[-1] - tb.q[0]))
            k_hi = k_hi if bad is None else bad
        else:
            bad = first_invalid_under(ctx, motion, ta.q[i_lo:ia + 1][::-1])
            i_lo = i_lo if bad is None else ia + 1 - bad
    if span is not None:
        i_lo, k_hi = max(i_lo, span[0]), min(k_hi, span[1])
    if ia <= i_lo or k_hi <= 0:
        return None
    otg, traj, inp = Ruckig(len(arm), dt), Trajectory(len(arm)), InputParameter(len(arm))
    inp.duration_discretization = DurationDiscretization.Discrete
    assert ctx.jmax is not None  # blending is for jerk-limited robots (every loaded robot has jerk limits)
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = list(ctx.vmax[arm]), list(ctx.amax[arm]), list(ctx.jmax[arm])
    qb = tb.q[:, arm] + (ta.q[-1, arm] - tb.q[0, arm])  # tb starts where ta comes to rest (as in splice_corner)
    # the end states as lists, (3, n) per sample: ta's samples i_lo..ia (sa[i - i_lo]), tb's 0..k_hi (sb[k])
    sa = np.stack([ta.q[i_lo:ia + 1, arm], ta.qd[i_lo:ia + 1, arm], ta.qdd[i_lo:ia + 1, arm]], axis=1).tolist()
    sb = np.stack([qb[:k_hi + 1], tb.qd[:k_hi + 1, arm], tb.qdd[:k_hi + 1, arm]], axis=1).tolist()
    totals: dict[tuple[int, int], int | None] = {}  # (i, k) -> corner-move samples
    at = [-1, -1]  # the ends inp holds now

    def set_ends(i: int, k: int) -> None:
        if at[0] != i:
            inp.current_position, inp.current_velocity, inp.current_acceleration = sa[i - i_lo]
        if at[1] != k:
            inp.target_position, inp.target_velocity, inp.target_acceleration = sb[k]
        at[:] = i, k

    def solve(i: int, k: int) -> int | None:
        if (i, k) not in totals:
            set_ends(i, k)
            try:
                ok = otg.calculate(inp, traj) in (Result.Working, Result.Finished)
            except RuckigError:  # an end state on or over a limit (Ruckig validates its input)
                ok = False
            totals[(i, k)] = int(round(traj.duration / dt)) if ok else None
        return totals[(i, k)]

    coarse = [(i, k) for i in range(ia, i_lo - 1, -CORNER_COARSE[0]) for k in range(k_hi, 0, -CORNER_COARSE[1])]

    # shortest first; among equals the earliest end in the second motion and the latest start in the first (a
    # straight line stays exact for longer)
    def ranked(keys: Iterable[tuple[int, int]]) -> list[tuple[int, int]]:
        keys = list(keys)
        if not keys:
            return []
        i, k = np.array(keys).T
        n = np.array([totals[key] for key in keys])
        return [keys[j] for j in np.lexsort((n, -i, k, i + n - k))]  # total = (i + n - k) dt + tb.duration

    best = ranked(key for key in coarse if solve(*key) is not None)[:CORNER_REFINE]
    for i0, k0 in best:  # every sample around the best coarse ones
        for i in range(max(i0 - CORNER_COARSE[0] + 1, i_lo), min(i0 + CORNER_COARSE[0], ia + 1)):
            for k in range(max(k0 - CORNER_COARSE[1] + 1, 1), min(k0 + CORNER_COARSE[1], k_hi + 1)):
                solve(i, k)
    # tb's samples before its end are on the grid: the result lasts (i + n - k) dt + tb.duration
    under = int(np.floor((beat - tb.duration) / dt - 1e-6))
    found = ranked(key for key, n in totals.items() if n is not None and key[0] + n - key[1] <= under)[:CORNER_TRIES]
    for i, k in found:
        steps = totals[(i, k)]
        assert steps is not None  # found holds solved keys only
        set_ends(i, k)
        otg.calculate(inp, traj)
        cand = splice_corner(ta, tb, i, k, steps, traj, arm)
        if join_samples_ok(ctx, cand, i, i + steps, prev, motion):
            return cand, i, i + steps
    return None


def zone_limits(ctx: PlanContext, ta: TimedPath, tb: TimedPath, ia: int, lo: int, zone: float) -> tuple[int, int]:
    """Where a blend may round the corner at a target with a ``zone`` (m) that ``ta`` ends at: the first sample of
    ``ta`` (from ``lo`` to ``ia``) from which its TCP stays within the zone of the target, and the last of ``tb``
    (started where ``ta`` ends) up to which its TCP stays within it. A blend that leaves ``ta`` and joins ``tb``
    inside them passes the target within the zone: its first sample is one of ``ta``'s (``ia + 1`` when no
    sample is inside, -1 likewise for ``tb``)."""
    point = ctx.robot.kin.fk(ta.q[-1])[:3, 3]
    near_a = np.linalg.norm(ctx.robot.kin.fk(ta.q[lo:ia + 1])[:, :3, 3] - point, axis=1) <= zone
    out_a = np.flatnonzero(~near_a)
    first = lo + (int(out_a[-1]) + 1 if len(out_a) else 0)
    near_b = np.linalg.norm(ctx.robot.kin.fk(tb.q + (ta.q[-1] - tb.q[0]))[:, :3, 3] - point, axis=1) <= zone
    out_b = np.flatnonzero(~near_b)
    last = (int(out_b[0]) if len(out_b) else len(near_b)) - 1
    return first, last


def splice_corner(ta: TimedPath, tb: TimedPath, i: int, k: int, steps: int, traj: ruckig.Trajectory,
                  arm: list[int]) -> TimedPath:
    """``ta`` up to its sample ``i``, then the Ruckig trajectory ``traj`` (``steps`` samples of SAMPLE_DT, joints
    ``arm``; the others held), then ``tb`` from its sample ``k`` on (displaced to start where ``ta`` ends: ``tb``
    starts at rest at ``ta``'s last sample)."""
    dt = SAMPLE_DT
    nb = len(tb.times) - k - 1
    m = i + steps + nb + 1
    times = np.empty(m)
    times[:i + 1] = ta.times[:i + 1]
    times[i + 1:i + steps + 1] = ta.times[i] + dt * np.arange(1, steps + 1)
    times[i + steps + 1:] = times[i + steps] + tb.times[k + 1:] - tb.times[k]
    q = np.repeat(ta.q[i][None, :], m, axis=0)
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    q[:i + 1], qd[:i + 1], qdd[:i + 1] = ta.q[:i + 1], ta.qd[:i + 1], ta.qdd[:i + 1]
    if steps > 1:  # the corner move's inner samples (steps - 1, 3, len(arm)): position, velocity, acceleration
        inner = np.array([traj.at_time(j * dt) for j in range(1, steps)])
        q[i + 1:i + steps, arm], qd[i + 1:i + steps, arm], qdd[i + 1:i + steps, arm] = inner[:, 0], inner[:, 1], inner[:, 2]
    shift = ta.q[-1] - tb.q[0]
    q[i + steps:] = tb.q[k:] + shift
    qd[i + steps:], qdd[i + steps:] = tb.qd[k:], tb.qdd[k:]
    return TimedPath(times, q, qd, qdd, max(ta.jerk_filter, tb.jerk_filter))


def corner_piece(a: TimedPiece, b: TimedPiece, bounds: Bounds, prev: UntimedMotion, motion: UntimedMotion,
                 cand: TimedPath, i: int, e: int) -> tuple[TimedPiece, Bounds]:
    """The piece and motion bounds after ``corner_move``: samples i..e of ``cand`` are the corner move."""
    t_i, t_e = float(cand.times[i]), float(cand.times[e])
    if motion.step.kind == "cartesian":
        join = t_e
    elif prev.step.kind == "cartesian":
        join = t_i
    else:
        join = 0.5 * (t_i + t_e)
    off = float(cand.duration - b.tp.duration)  # b's time origin in the combined timeline
    segments = a.segments[:-1] + [Segment(a.segments[-1].start, join, a.segments[-1].kind, a.segments[-1].label)]
    segments += [Segment(join if n == 0 else max(off + sg.start, join), off + sg.end, sg.kind, sg.label)
                 for n, sg in enumerate(b.segments)]
    new_bounds = bounds[:-1] + [(bounds[-1][0], join), (join, float(cand.duration))]
    return TimedPiece(cand, segments, None, a.blends + [join]), new_bounds


def first_invalid_under(ctx: PlanContext, motion: UntimedMotion, q: np.ndarray) -> int | None:
    """The first invalid row of ``q`` (M, dof) under ``motion``'s collision state (its gripper value for every row,
    its grasp target); None if all are valid."""
    if not len(q):
        return None
    q = q.copy()
    if ctx.gi is not None:
        q[:, ctx.gi] = motion.wps[0][ctx.gi]
    ctx.set_state_of(motion)
    return ctx.first_invalid(q)


def line_time(ctx: PlanContext, motion: UntimedMotion, tp: TimedPath, span: tuple[float, float],
              fraction: float) -> float:
    """Time (s, in ``tp``) when the TCP has covered ``fraction`` of the motion's straight line."""
    assert motion.step.line is not None
    p0, p1 = ctx.robot.kin.fk(motion.wps[0])[:3, 3], motion.step.line[1]
    sel = (tp.times >= span[0] - 1e-9) & (tp.times <= span[1] + 1e-9)
    p = ctx.robot.kin.fk(tp.q[sel])[:, :3, 3]
    d = p1 - p0
    done = np.clip((p - p0) @ d / max(float(d @ d), 1e-18), 0.0, 1.0)
    return float(np.interp(fraction, np.maximum.accumulate(done), tp.times[sel]))


def join_samples_ok(ctx: PlanContext, tp: TimedPath, lo: int, hi: int, prev: UntimedMotion,
                    motion: UntimedMotion) -> bool:
    """Limits and validity of the samples lo..hi (the join: an overlap or a corner move) of two joined motions, one
    sample either side: joint limits, velocity, acceleration, jerk, TCP speed, torque, and collisions (4x finer)
    under each motion's own collision state (the stricter one decides)."""
    a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
    q, qd, qdd = tp.q[a:b], tp.qd[a:b], tp.qdd[a:b]
    if np.any(q < ctx.robot.lower - LIMIT_TOL) or np.any(q > ctx.robot.upper + LIMIT_TOL):
        return False
    if np.any(np.abs(qd) > ctx.vmax * (1 + 1e-6) + LIMIT_TOL) or np.any(np.abs(qdd) > ctx.amax * (1 + 1e-6) + LIMIT_TOL):
        return False
    if ctx.jmax is not None:
        jerk = np.diff(tp.qdd[max(a - 1, 0):min(b + 1, len(tp.times))], axis=0) / np.diff(tp.times[max(a - 1, 0):min(b + 1, len(tp.times))])[:, None]
        if np.any(np.abs(jerk) > ctx.jmax * (1 + 1e-9)):
            return False
    if ctx.limits.max_tcp_speed is not None:
        if np.max(np.linalg.norm(ctx.robot.kin.tcp_velocity(q, qd[:, ctx.arm]), axis=1)) > ctx.limits.max_tcp_speed:
            return False
    model = torque_model(ctx, q[0], list(range(ctx.robot.dof)))
    if model is not None and np.any(np.abs(model.inverse_dynamics(q, qd, qdd)) > model.limits):
        return False
    fine = interpolate(q, RECHECK_SUBSTEPS)
    current = ctx.checker._grasp_target
    first = motion if current is not None and current == ctx.target_of(motion) else prev  # no state switch first
    for p in (first, motion if first is prev else prev):  # each motion's own collision state: the stricter one decides
        ctx.set_state_of(p)
        if ctx.first_invalid(fine) is not None:
            return False
    return True
