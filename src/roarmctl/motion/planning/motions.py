"""One free or straight motion: its joint path (OMPL + FCL, or IK along the line), its timing (TOPP-RA under the
plan's limits) and the independent re-check of its samples."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import PlanningError
from roarmctl.motion.cartesian import cartesian_line, line_deviation
from roarmctl.motion.planning.payloads import torque_model
from roarmctl.motion.planning.pieces import (
    LIMIT_TOL,
    LINE_TOLERANCE,
    RECHECK_SUBSTEPS,
    SAMPLE_DT,
    TaskStep,
    TimedPiece,
    UntimedMotion,
    interpolate,
)
from roarmctl.motion.timing import TimedPath, time_parameterise
from roarmctl.motion.trajectory import Segment

if TYPE_CHECKING:
    from roarmctl.motion.planning.context import PlanContext

# Sampling planners return a different detour per seed; keep the shortest of a few (deterministic).
FREE_MOTION_TRIES = 3


def geometry(ctx: PlanContext, step: TaskStep, q: np.ndarray) -> UntimedMotion:
    """The untimed path of a free or straight motion from ``q`` (OMPL + FCL, or IK along the line)."""
    ctx.set_state(q[ctx.gi] if ctx.gi is not None else None, grasp_target=step.grasp_target)
    if step.kind == "cartesian":
        assert step.line is not None
        t0 = time.perf_counter()
        # a function of the robot, q and the line's end alone (no collision check): a plan keeps what it solved
        key = (np.asarray(q, dtype=float).tobytes(), np.asarray(step.line[1], dtype=float).tobytes(), step.pitch, step.roll)
        wps = ctx.lines.get(key)
        if wps is None:
            wps = cartesian_line(ctx.robot, q, step.line[1], pitch=step.pitch, roll=step.roll, label=step.label)
            ctx.lines.keep(key, wps)
        ctx.timer.add("ik", t0)
        return UntimedMotion(step, wps.copy())
    return UntimedMotion(step, free_path(ctx, step, q))


def free_path(ctx: PlanContext, step: TaskStep, q: np.ndarray) -> np.ndarray:
    """OMPL path from ``q`` to the step's goal: the few vertices (K, dof) of the shortest of a few plans, shortcut."""
    from roarmctl.motion.ompl_planner import plan_joint_path_with_stats, simplify_path

    assert step.q_to is not None
    goal = step.q_to.copy()
    if ctx.gi is not None:
        goal[ctx.gi] = q[ctx.gi]
    cfg = ctx.config
    seed = cfg.seed + 1000 * ctx.free_count
    ctx.free_count += 1
    best = None
    for attempt in range(FREE_MOTION_TRIES):  # raw plans, only greedily pruned
        path, stats = plan_joint_path_with_stats(  # the straight move is tried once (a later try would fail it again)
            ctx.checker, q[ctx.arm], goal[ctx.arm], planner=cfg.name, time_budget=cfg.time_budget,
            simplify_budget=cfg.simplify_budget, seed=seed + attempt, resolution=0.01, max_step=None,
            try_direct=attempt == 0, simplify_attempts=0, max_checks=cfg.max_checks)
        ctx.timer.t["ompl"] += stats.solve_time
        ctx.timer.t["simplify"] += stats.simplify_time
        if best is None or stats.length < best[1].length:
            best = (path, stats)
        if stats.direct:  # the straight joint move is valid: nothing shorter exists
            break
    assert best is not None
    path = best[0]
    if not best[1].direct:  # shortcut only the one we keep
        t0 = time.perf_counter()
        path = simplify_path(ctx.checker, path, seed=seed, time_budget=cfg.simplify_budget, pruned=True)
        ctx.timer.add("simplify", t0)
    vertices = np.repeat(q[None, :], len(path), axis=0)
    vertices[:, ctx.arm] = path
    return vertices


def _copied(tp: TimedPath) -> TimedPath:
    """``tp`` with its own arrays (a kept timing is handed out again: no caller may change the kept one)."""
    return TimedPath(tp.times.copy(), tp.q.copy(), tp.qd.copy(), tp.qdd.copy(), tp.jerk_filter,
                     None if tp.s is None else tp.s.copy())


def payload_key(ctx: PlanContext) -> tuple | None:
    """The held payload as exact bytes (None: nothing held), for keys of what a plan keeps."""
    return None if ctx.payload is None else tuple(
        (link, float(i.mass), np.asarray(i.com, dtype=float).tobytes(), np.asarray(i.inertia, dtype=float).tobytes())
        for link, i in ctx.payload.items())


def time_path(ctx: PlanContext, wps: np.ndarray, label: str) -> TimedPath:
    """TOPP-RA timing of the arm joints along the waypoints ``wps`` (K, dof), rest to rest, under the scaled
    joint limits, the jerk limits, the torque limits (with the held payload) and ``max_tcp_speed``.

    The timing is a function of these alone (the limits are fixed per plan), so a plan keeps what it timed
    (``ctx.timed``, keyed by the waypoints' bytes and the payload): a plan of several cycles meets the same
    straight approaches and retreats again in every cycle, and times them once (``label`` only names a failure,
    which is never kept)."""
    t0 = time.perf_counter()
    key = (wps.shape, np.ascontiguousarray(wps, dtype=float).tobytes(), payload_key(ctx))
    known = ctx.timed.get(key)
    if known is not None:
        ctx.timer.add("toppra", t0)
        return _copied(known)
    arm = ctx.arm
    tcpv = None
    if ctx.limits.max_tcp_speed is not None:
        base = wps[0].copy()

        def tcpv(qa: np.ndarray, dqa: np.ndarray) -> np.ndarray:
            full = np.repeat(base[None, :], len(qa), axis=0)
            full[:, arm] = qa
            return ctx.robot.kin.tcp_velocity(full, dqa)

    tp_arm = time_parameterise(wps[:, arm], ctx.vmax[arm], ctx.amax[arm], None if ctx.jmax is None else ctx.jmax[arm],
                               tcp_velocity_per_ds=tcpv, max_tcp_speed=ctx.limits.max_tcp_speed,
                               torque=torque_model(ctx, wps[0], arm), sample_dt=SAMPLE_DT, label=label)
    n = len(tp_arm.times)
    q = np.repeat(wps[0][None, :], n, axis=0)
    q[:, arm] = tp_arm.q
    qd, qdd = np.zeros_like(q), np.zeros_like(q)
    qd[:, arm], qdd[:, arm] = tp_arm.qd, tp_arm.qdd
    timed = TimedPath(tp_arm.times, q, qd, qdd, tp_arm.jerk_filter, tp_arm.s)
    ctx.timed.keep(key, _copied(timed))
    ctx.timer.add("toppra", t0)
    return timed


def time_motion(ctx: PlanContext, motion: UntimedMotion) -> TimedPiece:
    """Time one motion from rest to rest and re-check it.

    A free motion starts as the spline through its few vertices; if a check fails, vertices are
    added along its valid polyline and the spline pulled toward it, step by step.
    """
    from roarmctl.motion.collision import densify

    label = motion.step.label
    last_error: PlanningError | None = None
    for max_step in ((None, 0.4, 0.2, 0.1, 0.05, 0.025) if motion.step.kind == "free" else (None,)):
        wps = motion.wps if max_step is None else densify(motion.wps, max_step)
        try:  # a timing failure is retried too: denser vertices make a tamer spline
            tp = time_path(ctx, wps, label)
        except PlanningError as exc:
            last_error = exc
            continue
        t0 = time.perf_counter()
        try:
            check_motion(ctx, tp, motion, label)
        except PlanningError as exc:
            last_error = exc
            continue
        finally:
            ctx.timer.add("recheck", t0)
        return TimedPiece(tp, [Segment(0.0, tp.duration, motion.step.kind, label)])
    assert last_error is not None
    raise last_error


def check_motion(ctx: PlanContext, tp: TimedPath, motion: UntimedMotion, label: str) -> None:
    """Independent check of the sampled motion: limits, TCP speed, collisions (4x finer) and singularity
    margin in the motion's own collision state, a straight motion within LINE_TOLERANCE of its line."""
    r = ctx.robot
    if np.any(tp.q < r.lower - LIMIT_TOL) or np.any(tp.q > r.upper + LIMIT_TOL):
        raise PlanningError(f"{label}: the timed motion leaves the joint limits")
    if np.any(np.abs(tp.qd) > ctx.vmax * (1 + 1e-6) + LIMIT_TOL):
        raise PlanningError(f"{label}: the timed motion exceeds a joint velocity limit")
    if np.any(np.abs(tp.qdd) > ctx.amax * (1 + 1e-6) + LIMIT_TOL):
        raise PlanningError(f"{label}: the timed motion exceeds a joint acceleration limit")
    if ctx.limits.max_tcp_speed is not None:
        speed = np.linalg.norm(r.kin.tcp_velocity(tp.q, tp.qd[:, ctx.arm]), axis=1)
        if np.max(speed) > ctx.limits.max_tcp_speed * (1 + 1e-6):
            raise PlanningError(f"{label}: the TCP speed {np.max(speed):.3f} m/s exceeds max_tcp_speed")
    assert tp.s is not None  # a timed path, not a dwell
    s_bounds = np.array([0.0, float(tp.s[-1])])
    sel = np.flatnonzero((tp.s >= s_bounds[0] - 1e-12) & (tp.s <= s_bounds[1] + 1e-12))
    lo, hi = max(int(sel[0]) - 1, 0), min(int(sel[-1]) + 1, len(tp.times) - 1)  # and the samples either side
    ctx.set_state_of(motion)
    fine = interpolate(tp.q[lo:hi + 1], RECHECK_SUBSTEPS)
    bad = ctx.first_invalid(fine)
    if bad is not None:
        if ctx.gi is not None:
            ctx.checker.set_gripper(float(fine[bad, ctx.gi]))
        raise PlanningError(f"{motion.step.label}: the timed motion is invalid at t = {tp.times[lo] + bad / RECHECK_SUBSTEPS * SAMPLE_DT:.2f} s: "
                            f"{ctx.checker.explain(fine[bad, ctx.arm])}")
    if motion.step.kind == "cartesian":
        assert motion.step.line is not None
        p0, p1 = r.kin.fk(motion.wps[0])[:3, 3], motion.step.line[1]
        dev = line_deviation(r, tp.q[sel], p0, p1)
        if dev > LINE_TOLERANCE:
            raise PlanningError(f"{motion.step.label}: the timed motion leaves the straight TCP line by {dev * 1000:.1f} mm")
