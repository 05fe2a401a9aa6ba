"""The gripper and its jaws: how far to close on an object, gripper actions at rest and the world update they
make (grasp attaches, release puts back), the gripper opened during a transit, and a gripper action overlapped
with the straight motion beside it while the moving jaw stays clear of the object."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import InfeasibleError, PlanningError
from roarmctl.motion.planning.fixed_jaw import MARGIN as FIXED_JAW_MARGIN
from roarmctl.motion.planning.jaw_reach import JawReach, available
from roarmctl.motion.planning.payloads import attach_payload
from roarmctl.motion.planning.pieces import (
    LIMIT_TOL,
    RECHECK_SUBSTEPS,
    SAMPLE_DT,
    TaskStep,
    TimedPiece,
    UntimedMotion,
    concat,
    dwell,
    interpolate,
    split_at,
    superpose,
)
from roarmctl.motion.scene import settled
from roarmctl.motion.timing import TimedPath, time_parameterise
from roarmctl.motion.trajectory import Event, Segment
from roarmctl.robot.dynamics import inverse_dynamics

if TYPE_CHECKING:
    from roarmctl.motion.planning.context import PlanContext
    from roarmctl.plan.types import ItemSpec, PickTask

# m: the TCP this near the grasp (release) pose counts as there: the moving jaw may already be inside the padding
# of the object while the arm settles (arrives) or starts to leave (a tenth of a millimetre, far below what the
# RoArm's servos resolve: one step of 2 pi / 4096 rad at the shoulder moves the TCP about 0.4 mm).
JAW_POSE_TOL = 1e-4


class GripperDoesNotFit(Exception):
    """The gripper cannot open within the free motion ``index`` of a chain (too short, or the jaws never clear)."""

    def __init__(self, index: int) -> None:
        super().__init__(index)
        self.index = index


# ------------------------------------------------------------------ how far to close
def grasp_width(spec: ItemSpec) -> float:
    """Width (m) of an object across the jaws: ``grasp_width``, else the shape's narrowest horizontal
    extent (box: its smaller side in x/y; cylinder, sphere: the diameter)."""
    if spec.grasp_width is not None:
        return float(spec.grasp_width)
    if spec.shape == "box":
        return float(min(spec.size[0], spec.size[1]))
    return 2.0 * float(spec.radius)


def check_opening(ctx: PlanContext, task: PickTask, g_open: float, where: str) -> None:
    """Refuse (InfeasibleError, with the opening that would do) a ``g_open`` (rad) that does not open the jaws
    ``clearance`` wider than the picked object (jaw widths known)."""
    gr = ctx.robot.gripper
    assert gr is not None  # a plan with picks needs a gripper (checked by the Planner)
    if not gr.has_widths:
        return
    width = grasp_width(next(o for o in ctx.objects if o.name == task.object))
    opening = gr.width(g_open)
    if opening < width + gr.clearance:
        need = gr.q_for_width(width + gr.clearance)
        fix = (f"open to at least {need:.2f} rad" if width + gr.clearance <= gr.width(gr.open)
               else f"the jaws open {gr.width(gr.open) * 1000:.0f} mm at most: give a smaller grasp_width or pick it another way")
        raise InfeasibleError(
            f"{where}: gripper_open {g_open:.3f} rad opens the jaws {opening * 1000:.1f} mm; '{task.object}' is "
            f"{width * 1000:.1f} mm wide (+{gr.clearance * 1000:.0f} mm clearance)", fix)


def grasp_closed_q(ctx: PlanContext, task: PickTask, g_open: float, where: str, q_grasp: np.ndarray | None = None) -> float:
    """The gripper joint value (rad) that closes the jaws on the picked object (``gripper_closed``, else the
    object's width less the squeeze), with a warning where ``gripper_closed`` would not hold it.

    With the jaws' meshes and the grasp configuration ``q_grasp`` (dof,) rad (``jaw_reach.available``), by the
    moving jaw's own pieces where the object sits (``jaw_reach``); else by the jaw table (the fingertips' gap)."""
    gr = ctx.robot.gripper
    assert gr is not None  # a plan with picks needs a gripper (checked by the Planner)
    if not gr.has_widths:
        return task.gripper_closed if task.gripper_closed is not None else gr.closed
    spec = next(o for o in ctx.objects if o.name == task.object)
    width = grasp_width(spec)
    squeeze = task.squeeze if task.squeeze is not None else gr.squeeze
    if q_grasp is not None and available(ctx.robot, spec):
        return _closed_by_meshes(ctx, task, spec, g_open, where, q_grasp, width, squeeze)
    # a claw gripper puts the object's side MARGIN off its fixed jaw: the moving jaw meets it at the width plus that
    # margin, pushes it onto the fixed jaw, and squeezes it only below its width
    margin = FIXED_JAW_MARGIN if gr.fixed_jaw is not None else 0.0
    if task.gripper_closed is not None:
        closed = task.gripper_closed
        if closed <= gr.closed + 1e-9 and width > gr.width(gr.closed) + 1e-6:
            ctx.warnings.append(
                f"{where}: gripper_closed {closed:.3f} rad closes the jaws fully on '{task.object}' ({width * 1000:.1f} mm "
                f"wide): the servo presses until it stalls; leave gripper_closed out to close to "
                f"{(width - squeeze) * 1000:.1f} mm")
        elif gr.width(closed) >= width:
            ctx.warnings.append(
                f"{where}: gripper_closed {closed:.3f} rad leaves the jaws {gr.width(closed) * 1000:.1f} mm apart on "
                f"'{task.object}' ({width * 1000:.1f} mm wide{_held_off(gr.width(closed) - width, margin)}): it would "
                f"not hold; leave gripper_closed out")
        return closed
    want = width - squeeze
    if want <= gr.width(gr.closed):
        ctx.warnings.append(f"{where}: '{task.object}' ({width * 1000:.1f} mm) is narrower than the closed jaws "
                            f"({gr.width(gr.closed) * 1000:.1f} mm) plus the squeeze: the gripper closes fully")
        return gr.closed
    closed = gr.q_for_width(want)
    ctx.notes.append(f"{where}: grip '{task.object}' ({width * 1000:.1f} mm) at {want * 1000:.1f} mm: gripper {closed:.3f} rad")
    return closed


def _held_off(short: float, margin: float) -> str:
    """What a jaw that stops ``short`` (m, >= 0) of squeezing an object held ``margin`` (m) off the fixed jaw does."""
    if not margin:
        return ""
    if short < margin:
        return f", held {margin * 1000:.0f} mm off the fixed jaw: the moving jaw pushes it onto the fixed jaw and stops"
    return f", held {margin * 1000:.0f} mm off the fixed jaw: the moving jaw does not reach it"


def _closed_by_meshes(ctx: PlanContext, task: PickTask, spec: ItemSpec, g_open: float, where: str,
                      q_grasp: np.ndarray, width: float, squeeze: float) -> float:
    """``grasp_closed_q`` by the jaws' pieces (``jaw_reach``): the value at which the moving jaw squeezes the object,
    pressed onto the fixed jaw, by ``squeeze`` (m); a ``gripper_closed`` at which it does not touch the pressed
    object would not hold it (warned, with how far it stops: before the object's side, or after pushing it the
    fixed-jaw margin)."""
    gr = ctx.robot.gripper
    assert gr is not None
    reach = JawReach(ctx.robot, q_grasp, spec, ctx.object_pose[task.object], FIXED_JAW_MARGIN)
    if task.gripper_closed is not None:
        closed = task.gripper_closed
        if closed <= gr.closed + 1e-9:
            ctx.warnings.append(
                f"{where}: gripper_closed {closed:.3f} rad closes the jaws fully on '{task.object}' ({width * 1000:.1f} mm "
                f"wide): the servo presses until it stalls; leave gripper_closed out to squeeze it {squeeze * 1000:.1f} mm")
        elif not reach.touches(closed, 0.0):
            how = ("pushes it onto the fixed jaw and stops there" if reach.touches(closed, -FIXED_JAW_MARGIN)
                   else "does not reach it")
            ctx.warnings.append(
                f"{where}: gripper_closed {closed:.3f} rad: the moving jaw {how} ('{task.object}', {width * 1000:.1f} mm "
                f"wide, held {FIXED_JAW_MARGIN * 1000:.0f} mm off the fixed jaw; by the jaw meshes): it would not hold; "
                f"leave gripper_closed out")
        return closed
    found = reach.closing(squeeze, gr.closed, g_open)
    if found is None:
        ctx.warnings.append(f"{where}: the closed jaws do not squeeze '{task.object}' ({width * 1000:.1f} mm) by "
                            f"{squeeze * 1000:.1f} mm (by the jaw meshes): the gripper closes fully")
        return gr.closed
    ctx.notes.append(f"{where}: grip '{task.object}' ({width * 1000:.1f} mm), squeezed {squeeze * 1000:.1f} mm by the "
                     f"jaw meshes where it sits: gripper {found:.3f} rad (the fingertips {gr.width(found) * 1000:.1f} mm "
                     f"apart by the jaw table)")
    return found

# m and rad: where a released object lands is recorded to this step (``scene.settled``: repeated cycles of a plan then
# meet the same world bit for bit and reuse their timings)
PLACED_STEP = 1e-6


# ------------------------------------------------------------------ gripper actions
def gripper_motion(ctx: PlanContext, q: np.ndarray, target: float, label: str, start: float | None = None) -> TimedPath:
    """The gripper alone from ``start`` (default q[gi]) to ``target`` (rad), the arm held at ``q``: time-optimal under
    the gripper's velocity, acceleration and jerk limits."""
    gi = ctx.gi
    assert gi is not None
    q = q.copy()
    if start is not None:
        q[gi] = start
    t0 = time.perf_counter()
    one = time_parameterise(np.array([[q[gi]], [target]]), ctx.vmax[gi:gi + 1], ctx.amax[gi:gi + 1],
                            None if ctx.jmax is None else ctx.jmax[gi:gi + 1], sample_dt=SAMPLE_DT, label=label)
    ctx.timer.add("toppra", t0)
    qq = np.repeat(q[None, :], len(one.times), axis=0)
    qd, qdd = np.zeros_like(qq), np.zeros_like(qq)
    qq[:, gi], qd[:, gi], qdd[:, gi] = one.q[:, 0], one.qd[:, 0], one.qdd[:, 0]
    return TimedPath(one.times, qq, qd, qdd, one.jerk_filter)


def gripper_action(ctx: PlanContext, step: TaskStep, q: np.ndarray, update: bool = True) -> TimedPath:
    """The gripper action ``step`` at rest at ``q``, timed (at least ``gripper_time``) and its jaw sweep checked;
    with ``update`` also its world update (``gripper_event``)."""
    assert step.gripper_to is not None
    a, b = float(q[ctx.gi]), float(step.gripper_to)
    tp = gripper_motion(ctx, q, b, step.label)
    if tp.duration < ctx.limits.gripper_time:  # the jaws get at least gripper_time to settle
        tp = concat(tp, dwell(tp.q[-1], ctx.limits.gripper_time - tp.duration))
    t0 = time.perf_counter()
    values = np.linspace(a, b, 5)  # the jaw sweeps: check it along the way (one batch, a gripper value per row)
    ctx.set_state(b, grasp_target=step.grasp_target)
    valid = ctx.checker.validity_batch(np.repeat(q[None, ctx.arm], len(values), axis=0), gripper=values)
    if not valid.all():
        ctx.checker.set_gripper(float(values[int(np.argmin(valid))]))
        ctx.timer.add("recheck", t0)
        raise PlanningError(f"{step.label}: the moving jaw collides: {ctx.checker.explain(q[ctx.arm])}")
    ctx.timer.add("recheck", t0)
    if update:
        gripper_event(ctx, step, q)
    return tp


def gripper_event(ctx: PlanContext, step: TaskStep, q: np.ndarray) -> None:
    """After the gripper action ``step`` at ``q``: a grasp attaches the object (collision model and payload),
    a release puts it back into the scene; the checker takes the new gripper value."""
    assert step.gripper_to is not None
    b = float(step.gripper_to)
    tcp = ctx.robot.kin.fk(q)[:3, 3]
    if step.event is not None:
        if step.event.kind == "grasp":
            assert ctx.pending_pick is not None  # set by the pick this grasp belongs to
            name, offset = ctx.pending_pick
            ctx.set_state(b, grasp_target=name)
            ctx.checker.attach(name, q[ctx.arm])
            ctx.held, ctx.held_offset, ctx.pending_pick = name, offset, None
            attach_payload(ctx, name, q, step.label)
        elif step.event.kind == "release":
            released = ctx.held
            assert released is not None  # a release follows a grasp
            item = ctx.checker.detach(released, q[ctx.arm], step=PLACED_STEP)
            if ctx.held_local is not None:  # carried against the fixed jaw: where the jaws put it, turned with them
                ctx.object_pose[released] = item.pose.copy()
                ctx.held_local = None
            else:
                ctx.object_pose[released][:3, 3] = tcp - ctx.held_offset
                ctx.object_pose[released] = settled(ctx.object_pose[released], PLACED_STEP)
            ctx.held, ctx.held_offset = None, np.zeros(3)
            ctx.payload, ctx.payload_label = None, ""
            ctx.set_state(b, grasp_target=released)
    else:
        ctx.set_state(b)


def open_during_transit(ctx: PlanContext, tp: TimedPath, motions: list[UntimedMotion], t_starts: list[float],
                        t_ends: list[float]) -> None:
    """Set the gripper column of ``tp`` over a chain of motions (each from ``t_starts[k]`` to ``t_ends[k]`` s): each
    motion's own value; a motion with ``open_to`` opens it during that motion (blending), starting at the first
    sample from which the moving jaws are clear of everything. Raises GripperDoesNotFit where that never happens."""
    gi = ctx.gi
    if gi is None:
        return
    for k, motion in enumerate(motions):
        sel = tp.times >= t_starts[k] - 1e-12
        tp.q[sel, gi], tp.qd[sel, gi], tp.qdd[sel, gi] = motion.wps[0][gi], 0.0, 0.0
    for k, motion in enumerate(motions):
        if motion.step.open_to is None:
            continue
        g = gripper_motion(ctx, tp.q[0], motion.step.open_to, motion.step.open_label, start=float(motion.wps[0][gi]))
        moving = g.times < g.duration - 1e-12  # the samples on the grid (the last one is at rest)
        n = int(np.count_nonzero(moving))
        first = int(np.searchsorted(tp.times, t_starts[k] - 1e-12))
        last_start = int(np.searchsorted(tp.times, t_ends[k] - g.duration + 1e-12, side="right")) - 1
        for i0 in range(first, last_start + 1, 5):  # try every 50 ms from the start of the transit
            q = tp.q.copy()
            q[i0:, gi] = motion.step.open_to
            q[i0:i0 + n, gi] = g.q[moving, gi]
            ctx.set_state(motion.wps[0][gi], grasp_target=motion.step.grasp_target)
            span = q[i0:int(np.searchsorted(tp.times, t_ends[k] + 1e-12))]
            if ctx.first_invalid(interpolate(span, RECHECK_SUBSTEPS)) is None:
                tp.q[:, gi] = q[:, gi]
                tp.qd[i0:, gi], tp.qdd[i0:, gi] = 0.0, 0.0
                tp.qd[i0:i0 + n, gi], tp.qdd[i0:i0 + n, gi] = g.qd[moving, gi], g.qdd[moving, gi]
                break
        else:
            raise GripperDoesNotFit(k)


# ------------------------------------------------------------------ the jaws beside a straight motion
def overlap_jaw_action(ctx: PlanContext, a: TimedPiece, b: TimedPiece, target: str, grasp: bool) -> list[TimedPiece]:
    """Superpose a gripper action with the straight motion next to it (the gripper is its own joint):

    - grasp (``a`` ends with the descent, ``b`` closes the jaws): the jaws start closing while the arm
      still descends, for as long as the moving jaw stays clear of ``target``; the arm arrives, then the
      rest of the closing (the jaws meet the object, the squeeze) happens at rest, and the lift (the
      next piece) starts only once the closing is done;
    - release (``a`` opens the jaws, ``b`` starts with the retreat): the retreat starts once the moving
      jaw has opened clear of ``target``.

    While the arm moves, the links the gripper joint moves must stay clear of ``target`` by the padding
    (no contact allowance; ``CollisionChecker.set_grasp_target(moving_jaw_clear=True)``), and of
    everything else as always. Only the jaw links the gripper joint does not move (a fixed jaw and the link
    that carries it, which may sit inside the padding of the object at the grasp pose) keep their allowance,
    as during the straight motion itself: they do not move relative to the TCP, so closing the gripper
    cannot press them into the object. The other links are where the straight motion's own checks
    found them valid (the arm's samples are unchanged), so only the moving jaw is checked again (4x
    finer), with the singularity margin and the torques (RNEA); velocity, acceleration and jerk are
    unchanged because the two motions move different joints.
    The longest overlap (on the sample grid) that passes is taken; the result is split where the arm
    arrives (grasp) or starts (release), so segments, the event and the payload keep their places.
    """
    dt = SAMPLE_DT
    checker = ctx.checker
    ta, tb = a.tp, b.tp
    on_grid = np.flatnonzero(np.abs(ta.times / dt - np.round(ta.times / dt)) < 1e-6)
    ia = int(on_grid[-1])
    moving = int(np.count_nonzero(np.any(np.abs(tb.qd if grasp else ta.qd) > 1e-12, axis=1)))  # gripper samples in motion
    if grasp:  # the closing starts within the descent (the last segment of a)
        limit = min(moving, ia - int(np.ceil(a.segments[-1].start / dt - 1e-9)))
    else:  # the retreat starts within the opening (which may overlap a later move's close of the gripper in b:
        # their sum is checked against the gripper's limits)
        limit = min(moving, ia, len(tb.times) - 2)
    t0 = time.perf_counter()
    saved = checker._grasp_target, checker._jaw_strict, float(checker._q_template[checker._gripper_index])
    checker.set_grasp_target(target, moving_jaw_clear=True)
    tried: dict[int, TimedPath | None] = {}

    pose = ctx.robot.kin.fk(ta.q[-1] if grasp else tb.q[0])[:3, 3]  # where the arm arrives / starts

    def attempt(m: int) -> TimedPath | None:
        if m not in tried:
            cand = superpose(ta, tb, ia, m)
            lo, hi = ia + 1 - m, min(ia + 1, len(cand.times) - 1)
            tried[m] = cand if jaw_moving_samples_ok(ctx, cand, lo, hi, pose, reverse=grasp) else None
        return tried[m]

    try:
        # A necessary condition, for every overlap at once: the moving jaw is clear at the last (grasp) or first
        # (release) sample of the arm's motion that is farther than JAW_POSE_TOL from that pose, with the
        # gripper where it is then. Only the overlaps that meet it are checked in full, longest first.
        ms = np.arange(1, max(limit, 0) + 1)
        if grasp:
            far = np.flatnonzero(np.linalg.norm(ctx.robot.kin.fk(ta.q[:ia + 1])[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL)
            j = int(far[-1]) if len(far) else ia
            arm_q, g = np.repeat(ta.q[j:j + 1, ctx.arm], len(ms), axis=0), tb.q[np.clip(ms - (ia + 1 - j), 0, len(tb.times) - 1), ctx.gi]
        else:
            far = np.flatnonzero(np.linalg.norm(ctx.robot.kin.fk(tb.q)[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL)
            j = int(far[0]) if len(far) else 1
            arm_q, g = np.repeat(tb.q[j:j + 1, ctx.arm], len(ms), axis=0), ta.q[np.clip(ia + 1 + j - ms, 0, len(ta.times) - 1), ctx.gi]
        clear = checker.validity_batch(arm_q, gripper=g) if len(ms) else np.zeros(0, dtype=bool)
        m = next((int(k) for k in ms[clear][::-1] if attempt(int(k)) is not None), 0)
        cand = tried.get(m)
        if m and cand is not None and not jaw_at_pose_samples_ok(ctx, cand, ia + 1 - m, min(ia + 1, len(cand.times) - 1), pose, target):
            m, cand = 0, None
    finally:
        checker.set_grasp_target(saved[0], moving_jaw_clear=saved[1])
        checker.set_gripper(saved[2])
        ctx.timer.add("blend", t0)
    if not m:
        return [a, b]
    assert cand is not None
    start = ia + 1 - m
    cut = ia + 1 if grasp else start  # where the arm arrives / starts
    first, second = split_at(cand, cut)
    t_cut = float(cand.times[cut])
    if grasp:
        segs = a.segments[:-1] + [Segment(a.segments[-1].start, t_cut, a.segments[-1].kind, a.segments[-1].label)]
        e = b.event
        assert e is not None  # b is the grasp
        return [TimedPiece(first, segs, a.event, a.blends, a.attach, a.detach),
                TimedPiece(second, [Segment(0.0, second.duration, sg.kind, sg.label) for sg in b.segments[:1]],
                           Event(second.duration, e.kind, e.label, e.position), b.blends, b.attach, b.detach, b.jaw_target)]
    e = a.event  # released: the jaws are clear of the object when the retreat starts
    assert e is not None
    return [TimedPiece(first, [Segment(0.0, t_cut, sg.kind, sg.label) for sg in a.segments[:1]],
                       Event(t_cut, e.kind, e.label, e.position), a.blends, a.attach, a.detach, a.jaw_target),
            TimedPiece(second, b.segments, b.event, b.blends, b.attach, b.detach, b.jaw_target)]


def jaw_moving_samples_ok(ctx: PlanContext, tp: TimedPath, lo: int, hi: int, pose: np.ndarray, reverse: bool) -> bool:
    """Samples lo..hi of a gripper action superposed with a straight motion, while the TCP is still moving: under the
    collision state set by ``overlap_jaw_action``, collision-free (4x finer; checked from the end when ``reverse``,
    where a grasp's jaw is nearest the object) wherever the TCP is farther than JAW_POSE_TOL from ``pose`` (x, y, z m:
    the grasp or release pose; nearer, the arm is at that pose and ``jaw_at_pose_samples_ok`` checks those samples as
    the gripper action itself), outside the singularity margin, within the torque limits by RNEA (nothing is held:
    before a grasp, after a release) and, for the gripper joint, within its position, velocity, acceleration
    and jerk limits (the arm's samples are the straight motion's own)."""
    a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
    fine = interpolate(tp.q[a:b], RECHECK_SUBSTEPS)
    fine = fine[np.linalg.norm(ctx.robot.kin.fk(fine)[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL]
    if reverse:
        fine = fine[::-1]
    if len(fine) and ctx.checker.first_invalid(fine[:, ctx.arm], gripper=fine[:, ctx.gi]) is not None:  # the jaw moves at every sample
        return False
    g, c = ctx.gi, slice(max(a - 1, 0), min(b + 1, len(tp.times)))  # the gripper's own limits (b may move it too)
    if (np.any(np.abs(tp.qd[a:b, g]) > ctx.vmax[g] * (1 + 1e-6) + LIMIT_TOL)
            or np.any(np.abs(tp.qdd[a:b, g]) > ctx.amax[g] * (1 + 1e-6) + LIMIT_TOL)
            or np.any(tp.q[a:b, g] < ctx.robot.lower[g] - LIMIT_TOL) or np.any(tp.q[a:b, g] > ctx.robot.upper[g] + LIMIT_TOL)):
        return False
    if ctx.jmax is not None and np.any(np.abs(np.diff(tp.qdd[c, g]) / np.diff(tp.times[c])) > ctx.jmax[g] * (1 + 1e-9)):
        return False
    if ctx.effort is not None and np.any(np.isfinite(ctx.effort)) and ctx.robot.inertials:
        tau = inverse_dynamics(ctx.robot, tp.q[a:b], tp.qd[a:b], tp.qdd[a:b])
        if np.any(np.abs(tau) > ctx.effort):
            return False
    return True


def jaw_at_pose_samples_ok(ctx: PlanContext, tp: TimedPath, lo: int, hi: int, pose: np.ndarray, target: str) -> bool:
    """The fine samples (4x) of lo..hi whose TCP is within JAW_POSE_TOL of ``pose`` (the arm has arrived), checked
    like the gripper action at that pose: every link against everything, the jaws allowed to touch ``target``."""
    a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
    fine = interpolate(tp.q[a:b], RECHECK_SUBSTEPS)
    fine = fine[np.linalg.norm(ctx.robot.kin.fk(fine)[:, :3, 3] - pose, axis=1) <= JAW_POSE_TOL]
    if not len(fine):
        return True
    ctx.checker.set_grasp_target(target)
    return ctx.checker.first_invalid(fine[:, ctx.arm], gripper=fine[:, ctx.gi]) is None
