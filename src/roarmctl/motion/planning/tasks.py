"""Tasks to steps: a pick, place, move or wait of the plan becomes the ``TaskStep``s that do it (free transit,
straight descent and lift, gripper action), with the IK choice of every target: within the limits,
collision-free, outside the singularity margin, nearest the previous pose, at the tool pitch the task asks
(or the nearest valid one with ``pitch: auto``)."""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import InfeasibleError, PlanFileError, UnreachableError, UnreachableReason, rejection
from roarmctl.motion.planning import fixed_jaw as jaws
from roarmctl.motion.planning.grasp import check_opening, grasp_closed_q, grasp_width
from roarmctl.motion.planning.pieces import TaskStep, with_value
from roarmctl.motion.planning.targets import Target
from roarmctl.motion.rejection import judge
from roarmctl.motion.trajectory import Event
from roarmctl.plan.types import MoveTask, PickTask, PlaceTask, WaitTask
from roarmctl.robot.ik import accepts_pitch, pitch_candidates, solve_ik, solve_ik_near, takes_pitch
from roarmctl.robot.ik.common import wrap_angle
from roarmctl.robot.singularity import base_axis_text

if TYPE_CHECKING:
    from roarmctl.motion.planning.context import PlanContext


def where(task: PickTask | PlaceTask | MoveTask | WaitTask, index: int) -> str:
    """How messages name a task: ``task 2 (place, line 14)`` (counted from 1); a plan given as a dict (no
    lines) ``task 2 (place)``."""
    return f"task {index + 1} ({task.kind}" + (f", line {task.line})" if task.line else ")")


def pitch_label(pitch: float | None, auto: bool) -> str:
    """Segment label suffix recording an automatically chosen pitch (none for a pitch not chosen or None)."""
    return f" (pitch {math.degrees(pitch):.1f} deg, auto)" if auto and pitch is not None else ""


def expand(ctx: PlanContext, task: PickTask | PlaceTask | MoveTask | WaitTask, q: np.ndarray,
           index: int) -> list[TaskStep]:
    """The steps of ``task`` (the ``index``-th, counted from 0) starting at ``q`` (dof,) rad."""
    at = where(task, index)
    if isinstance(task, WaitTask):
        return [TaskStep("wait", f"{at}: wait {task.seconds:g} s", duration=task.seconds)]
    if isinstance(task, MoveTask):
        goal, label, pitch = move_goal(ctx, task, q, at)
        zone = task.zone if task.zone is not None else ctx.limits.zone
        steps = [TaskStep("free", f"{at}: move{label}", q_to=goal, zone=zone)]
        g = move_gripper_q(ctx, task.gripper)
        if g is not None and abs(g - q[ctx.gi]) > 1e-9:
            word = {"open": "open", "closed": "close"}.get(task.gripper, "set") if isinstance(task.gripper, str) else "set"
            if np.max(np.abs(goal[ctx.arm] - q[ctx.arm])) < 1e-9:  # the arm is there already
                steps = [TaskStep("gripper", f"{at}: {word} gripper", gripper_to=g)]
            else:  # during the move where the jaws are clear (blending), else right after it
                steps[0].open_to, steps[0].open_label = g, f"{at}: {word} gripper"
        ctx.targets.append(move_target(ctx, task, goal, pitch, at, steps[0].label, zone))
        return steps
    if isinstance(task, PickTask):
        return expand_pick(ctx, task, q, at)
    return expand_place(ctx, task, q, at)


def move_gripper_q(ctx: PlanContext, value: float | str | None) -> float | None:
    """A move's ``gripper:`` (``open``, ``closed`` or a joint value in rad) as a gripper joint value (rad), or None
    (keep it)."""
    if value is None:
        return None
    if ctx.gi is None:
        raise InfeasibleError(f"{ctx.where}: {ctx.robot.name} has no gripper to open or close")
    if isinstance(value, str):
        gr = ctx.robot.gripper
        assert gr is not None  # gi is set
        return float(gr.open if value == "open" else gr.closed)
    lo, hi = ctx.robot.lower[ctx.gi], ctx.robot.upper[ctx.gi]
    if not lo - 1e-9 <= value <= hi + 1e-9:
        raise InfeasibleError(f"{ctx.where}: gripper {value:.3f} rad is outside [{lo:.3f}, {hi:.3f}]")
    return float(value)


def move_target(ctx: PlanContext, task: MoveTask, goal: np.ndarray, pitch: float | None, at: str, step: str,
                zone: float) -> Target:
    """The target a move names: its position (m) and the pitch held there, or a joint target's joints and pose."""
    field = "zone" if task.zone is not None else "limits.zone"
    if task.xyz is not None:
        return Target("move", at, step, np.asarray(task.xyz, dtype=float).copy(), zone, pitch=pitch, zone_field=field)
    t = ctx.robot.kin.fk(goal)
    return Target("move", at, step, t[:3, 3].copy(), zone, joints=goal[ctx.arm].copy(), rotation=t[:3, :3].copy(),
                  zone_field=field)


def move_goal(ctx: PlanContext, task: MoveTask, q: np.ndarray, at: str) -> tuple[np.ndarray, str, float | None]:
    """A move's goal configuration (dof,) rad, the gripper as at ``q``, a label suffix (the pitch chosen) and the
    pitch (rad) its IK held (None: a joint target, or position only)."""
    label, pitch = "", None
    if task.pose is not None:
        goal = ctx.robot.full_q(ctx.robot.named_poses[task.pose]).copy()
    elif task.joints is not None:
        try:
            goal = ctx.robot.full_q(task.joints).copy()
        except Exception as exc:  # wrong length
            raise InfeasibleError(f"{at}: joints: {exc}") from None
    else:
        assert task.xyz is not None  # a move names a pose, joints or a position
        chain, pitch = choose_ik_pitch(ctx, [task.xyz], held_pitch(ctx, task, at), task.pitch_auto, None, q, at)
        goal = chain[0]
        label = pitch_label(pitch, task.pitch_auto and pitch is not None)
    if ctx.gi is not None:
        goal[ctx.gi] = q[ctx.gi]
    if not ctx.robot.within_limits(goal):
        raise InfeasibleError(f"{at}: the goal configuration is outside the joint limits")
    return goal, label, pitch


def expand_pick(ctx: PlanContext, task: PickTask, q: np.ndarray, at: str) -> list[TaskStep]:
    """A pick: transit above the object (the gripper opening on the way), straight descent, grasp, straight lift."""
    if ctx.held is not None:
        raise InfeasibleError(f"{at}: picks '{task.object}' while still holding '{ctx.held}'", "place it first")
    gi, gr = ctx.gi, ctx.robot.gripper
    assert gi is not None and gr is not None  # a plan with picks needs a gripper (checked by the Planner)
    centre = ctx.object_pose[task.object][:3, 3]
    grasp = centre + np.array([0.0, 0.0, task.grasp_offset])
    above = grasp + np.array([0.0, 0.0, task.approach_height])
    g_open = task.gripper_open if task.gripper_open is not None else gr.open
    check_opening(ctx, task, g_open, at)
    ctx.set_state(g_open, grasp_target=task.object)
    (q_grasp, q_above), pitch = choose_ik_pitch(ctx, [grasp, above], held_pitch(ctx, task, at), task.pitch_auto,
                                                task.roll, q, at, gripper=g_open)
    roll = task.roll
    if jaw_fixed(ctx, task.object):
        q_grasp, q_above, grasp, above, roll = against_fixed_jaw(ctx, task, centre, q_grasp, pitch, q, at, g_open)
    g_closed = grasp_closed_q(ctx, task, g_open, at, q_grasp if jaw_fixed(ctx, task.object) else None)
    ctx.set_state(q[gi])
    lab = pitch_label(pitch, task.pitch_auto and pitch is not None)
    steps = [TaskStep("free", f"{at}: transit above '{task.object}'{lab}", q_to=with_value(q_above, gi, q[gi]),
                      open_to=g_open if abs(q[gi] - g_open) > 1e-9 else None, open_label=f"{at}: open gripper")]
    steps += [
        TaskStep("cartesian", f"{at}: descend to '{task.object}'{lab}", q_to=q_grasp, line=(above, grasp),
                 pitch=pitch, roll=roll, grasp_target=task.object),
        TaskStep("gripper", f"{at}: grasp '{task.object}'", gripper_to=g_closed, grasp_target=task.object,
                 event=Event(0.0, "grasp", f"pick {task.object}", [float(v) for v in grasp])),
        TaskStep("cartesian", f"{at}: lift '{task.object}'{lab}", q_to=q_above, line=(grasp, above),
                 pitch=pitch, roll=roll, grasp_target=task.object),
    ]
    ctx.targets.append(Target("grasp", at, steps[1].label, np.asarray(grasp, dtype=float).copy(), pitch=pitch))
    ctx.pending_pick = (task.object, grasp - centre)
    if jaw_fixed(ctx, task.object):  # the object's centre in the TCP frame, carried to the place
        ctx.held_local = ctx.robot.kin.fk(q_grasp)[:3, :3].T @ (centre - grasp)
    return steps


def jaw_fixed(ctx: PlanContext, name: str) -> bool:
    """Picks of this robot put the object against a fixed jaw (the description gives its face)."""
    gr = ctx.robot.gripper
    return gr is not None and gr.fixed_jaw is not None and any(o.name == name for o in ctx.objects)


def against_fixed_jaw(ctx: PlanContext, task: PickTask, centre: np.ndarray, q_grasp: np.ndarray, pitch: float | None,
                      q: np.ndarray, at: str,
                      g_open: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
    """The grasp and approach configurations (and points) that put the object's side ``fixed_jaw.MARGIN`` from
    the fixed jaw's face, the jaws closing across a box's narrow side (``roarmctl.motion.planning.fixed_jaw``):
    (q_grasp, q_above, grasp point, above point, roll).

    A function of the task, the object's pose, the first IK answer ``q_grasp``, ``q``, the gripper and the collision
    world alone: a plan keeps what it found (``ctx.jaw_targets``), as ``choose_ik`` keeps its answers."""
    t0 = time.perf_counter()
    key = (task.object, task.grasp_offset, task.approach_height, task.roll, pitch, float(g_open),
           *(np.asarray(v, dtype=float).tobytes() for v in (centre, ctx.object_pose[task.object], q_grasp, q)),
           ctx.checker._state_key())
    known = ctx.jaw_targets.get(key)
    if known is None:
        known = _against_fixed_jaw(ctx, task, centre, q_grasp, pitch, q, at, g_open)
        ctx.jaw_targets.keep(key, known)
    else:
        ctx.checker.set_gripper(float(g_open))  # as the last IK of the search left it
        ctx.timer.add("ik", t0)
    q_grasp, q_above, grasp, above, roll = known
    ctx.notes.append(f"{at}: '{task.object}' against the fixed jaw: TCP {np.linalg.norm(grasp - centre - np.array([0.0, 0.0, task.grasp_offset])) * 1e3:.1f} mm "
                     f"from its centre" + (f", roll {math.degrees(roll):.1f} deg" if roll is not None else ""))
    return q_grasp.copy(), q_above.copy(), grasp.copy(), above.copy(), roll


def _against_fixed_jaw(ctx: PlanContext, task: PickTask, centre: np.ndarray, q_grasp: np.ndarray, pitch: float | None,
                       q: np.ndarray, at: str,
                       g_open: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float | None]:
    """``against_fixed_jaw`` itself (not kept, no note)."""
    roll = task.roll
    up = np.array([0.0, 0.0, task.approach_height])
    first_roll = roll
    for cheap in (True, False):
        roll = first_roll
        grasp, roll, q_settled = _settle_against_jaw(ctx, task, centre, q_grasp, pitch, roll, q, at, g_open, cheap)
        grasp = jaws.rounded(grasp)
        if roll is not None and task.roll is None:  # a roll the plan gives is kept as written
            roll = float(jaws.rounded(roll))
        (q_chosen, q_above), _ = choose_ik_pitch(ctx, [grasp, grasp + up], pitch, False, roll, q, at, gripper=g_open)
        # The cheap rounds followed the first answer's branch; the chosen chain must be on it (its jaw offset gives
        # the same target), else the target is settled again on the chosen branches, as it always was before.
        if not cheap or float(np.max(np.abs(wrap_angle(q_chosen[ctx.arm] - q_settled[ctx.arm])))) < 1e-3:
            return q_chosen, q_above, grasp, grasp + up, roll
    raise AssertionError("unreachable: the second pass returns")


def _settle_against_jaw(ctx: PlanContext, task: PickTask, centre: np.ndarray, q_grasp: np.ndarray, pitch: float | None,
                        roll: float | None, q: np.ndarray, at: str, g_open: float,
                        cheap: bool) -> tuple[np.ndarray, float | None, np.ndarray]:
    """Rounds of "move the target by the jaw offset at the grasp configuration, solve the IK again" until the target
    settles (``jaws.ITERATIONS``, ``jaws.SETTLE``): (grasp point, roll, the configuration it settled at).

    ``cheap``: each round solves the grasp alone on the branch of the round before (``solve_ik_near``: no approach
    point, no collision check; the caller checks the chain it chooses at the end), about a quarter of a chain's
    ``choose_ik``; otherwise each round chooses the valid grasp-and-approach chain nearest to ``q``."""
    spec = next(o for o in ctx.objects if o.name == task.object)
    width = grasp_width(spec)
    pose = ctx.object_pose[task.object]
    lift = np.array([0.0, 0.0, task.grasp_offset])
    up = np.array([0.0, 0.0, task.approach_height])
    roll_index = ctx.arm[-1] if takes_pitch(ctx.robot) else None
    grasp = None
    for _ in range(jaws.ITERATIONS):  # until the target settles (jaws.ITERATIONS), then rounded and solved once more
        new_roll = roll
        if task.roll is None and roll_index is not None and spec.shape == "box":
            aligned = jaws.aligned_roll(ctx.robot, q_grasp, roll_index, pose[:3, :3], spec.size, width)
            new_roll = aligned if aligned is not None else roll
            if new_roll is not None:
                new_roll = math.remainder(new_roll, 2 * math.pi)
        new_grasp = centre + lift - jaws.object_offset(ctx.robot, q_grasp, width)
        settled = grasp is not None and float(np.max(np.abs(new_grasp - grasp))) < jaws.SETTLE and (
            new_roll is None or roll is None or abs(new_roll - roll) < jaws.SETTLE)
        grasp, roll = new_grasp, new_roll
        if settled:
            break
        if cheap:
            t0 = time.perf_counter()
            try:
                q_grasp = with_value(solve_ik_near(ctx.robot, grasp, q_grasp, pitch=pitch, roll=roll), ctx.gi, g_open)
                continue
            except UnreachableError:
                pass  # the branch left its reach: choose as below, which names why if nothing reaches it
            finally:
                ctx.timer.add("ik", t0)
        (q_grasp, _), _ = choose_ik_pitch(ctx, [grasp, grasp + up], pitch, False, roll, q, at, gripper=g_open)
    assert grasp is not None  # jaws.ITERATIONS > 0
    return grasp, roll, q_grasp


def expand_place(ctx: PlanContext, task: PlaceTask, q: np.ndarray, at: str) -> list[TaskStep]:
    """A place: transit above the target, straight lowering, release, straight retreat."""
    if ctx.held is None:
        raise InfeasibleError(f"{at}: places an object but nothing is held", "add a pick task before it")
    name = ctx.held
    gr = ctx.robot.gripper
    assert gr is not None  # something is held
    if task.object is not None and task.object != name:
        raise InfeasibleError(f"{at}: places '{task.object}' but the gripper holds '{name}'")
    if ctx.held_local is None:
        target = np.asarray(task.xyz, dtype=float) + ctx.held_offset
    else:  # held against a fixed jaw, the object's centre turns with the TCP: start from the TCP's turn now
        target = np.asarray(task.xyz, dtype=float) - ctx.robot.kin.fk(q)[:3, :3] @ ctx.held_local
    above = target + np.array([0.0, 0.0, task.approach_height])
    g_open = task.gripper_open if task.gripper_open is not None else gr.open
    try:
        (q_place, q_above), pitch = choose_ik_pitch(ctx, [target, above], held_pitch(ctx, task, at), task.pitch_auto,
                                                    task.roll, q, at)
    except UnreachableError as exc:
        if ctx.held_local is None:
            raise
        xyz = ", ".join(f"{v:.3f}" for v in task.xyz)
        raise UnreachableError(f"{at}: '{name}' placed at ({xyz}) m: {exc.message.removeprefix(at + ': ')}",
                               exc.reason, exc.hint) from None
    if ctx.held_local is not None:

        up = np.array([0.0, 0.0, task.approach_height])
        for _ in range(jaws.ITERATIONS):  # until the target settles, then rounded and solved once more (as a pick's)
            new_target = np.asarray(task.xyz, dtype=float) - ctx.robot.kin.fk(q_place)[:3, :3] @ ctx.held_local
            settled = float(np.max(np.abs(new_target - target))) < jaws.SETTLE
            target = new_target
            if settled:
                break
            (q_place, q_above), _ = choose_ik_pitch(ctx, [target, target + up], pitch, False, task.roll, q, at)
        target = jaws.rounded(target)
        (q_place, q_above), _ = choose_ik_pitch(ctx, [target, target + up], pitch, False, task.roll, q, at)
        above = target + up
    lab = pitch_label(pitch, task.pitch_auto and pitch is not None)
    ctx.targets.append(Target("release", at, f"{at}: lower '{name}'{lab}", np.asarray(target, dtype=float).copy(), pitch=pitch))
    return [
        TaskStep("free", f"{at}: transit above the place for '{name}'{lab}", q_to=q_above),
        TaskStep("cartesian", f"{at}: lower '{name}'{lab}", q_to=q_place, line=(above, target), pitch=pitch, roll=task.roll),
        TaskStep("gripper", f"{at}: release '{name}'", gripper_to=g_open, grasp_target=name,
                 event=Event(0.0, "release", f"place {name}", [float(v) for v in target])),
        TaskStep("cartesian", f"{at}: retreat from '{name}'{lab}", q_to=with_value(q_above, ctx.gi, g_open), line=(target, above),
                 pitch=pitch, roll=task.roll, grasp_target=name),
    ]


def held_pitch(ctx: PlanContext, task: PickTask | PlaceTask | MoveTask, at: str) -> float | None:
    """The tool pitch (rad) the IK holds for ``task``, or None (position-only IK).

    The RoArm (``ik.takes_pitch``) holds the task's pitch, straight down by default. Other arms hold the
    pitch (and roll) the plan writes, through the numerical IK's approach-axis target; a task without
    them is solved for the position only (noted once). A position-only IK family (``roarm3``) refuses
    a written pitch or roll instead of ignoring it."""
    written = getattr(task, "pitch_set", False) or getattr(task, "roll", None) is not None
    if isinstance(task, MoveTask):
        written = task.pitch is not None
    if ctx.pitch_free:
        return task.pitch if task.pitch is not None else math.pi / 2
    if not written:
        if accepts_pitch(ctx.robot) and not isinstance(task, MoveTask) and not ctx.noted_position_only:
            ctx.noted_position_only = True
            ctx.notes.append(f"{at}: no pitch given: {ctx.robot.name}'s grasps and placements are solved for the "
                             f"position only (the tool's approach follows from the IK); write pitch (e.g. "
                             f"{{deg: 90}}, straight down) to hold one")
        return None
    if not accepts_pitch(ctx.robot):
        raise PlanFileError(f"{at}: pitch/roll: {ctx.robot.name}'s IK is position only (its tool pitch follows "
                            f"from the shoulder and elbow angles), so the plan's pitch cannot be held",
                            "leave pitch and roll out for this arm")
    return task.pitch if task.pitch is not None else math.pi / 2


def choose_ik_pitch(ctx: PlanContext, points: list[np.ndarray], pitch: float | None, auto: bool, roll: float | None,
                    q: np.ndarray, at: str, gripper: float | None = None) -> tuple[list[np.ndarray], float | None]:
    """``choose_ik`` for points that share one pitch (None: position only); with ``auto`` the pitch nearest
    to ``pitch`` (1 deg steps, ``ik.pitch_candidates``) at which a chain is valid (limits, collisions, margin)."""
    if not auto or pitch is None:  # no pitch to choose
        return choose_ik(ctx, [(p, pitch, roll) for p in points], q, at, gripper=gripper), pitch
    first: UnreachableError | None = None  # the preferred pitch's (tried first)
    rejected: list[UnreachableReason] = []  # the cause of each pitch whose IK solutions were all rejected
    for cand in pitch_candidates(pitch):
        try:
            chain = choose_ik(ctx, [(p, cand, roll) for p in points], q, at, gripper=gripper)
        except UnreachableError as exc:
            first = first or exc
            if exc.reason in _REJECTIONS:
                rejected.append(exc.reason)
            continue
        ctx.notes.append(f"{at}: pitch auto chose {math.degrees(cand):.1f} deg (asked {math.degrees(pitch):.1f} deg)")
        return chain, cand
    assert first is not None  # every candidate pitch failed
    why = first.message[len(at) + 2:] if first.message.startswith(f"{at}: ") else first.message
    reason: UnreachableReason = first.reason
    also = ""
    if rejected:  # some pitches reach it: what rejected them is the cause, not the preferred pitch's failure
        reason, counted = rejection(rejected)
        also = f"; the {len(rejected)} pitches that reach it are rejected ({counted})"
    raise UnreachableError(f"{at}: no tool pitch reaches it validly{also}; at {math.degrees(pitch):.1f} deg: {why}",
                           reason, first.hint)


#: The reasons ``choose_ik`` gives when a pitch's IK solutions exist but are all rejected.
_REJECTIONS = ("collision", "singularity", "mixed")


def choose_ik(ctx: PlanContext, targets: list[tuple[np.ndarray, float | None, float | None]], q: np.ndarray, at: str,
              gripper: float | None = None) -> list[np.ndarray]:
    """IK for a chain of targets (position m, pitch, roll rad) on one branch: valid, margin-respecting, nearest
    to ``q``. Returns one full configuration per target (gripper value of ``q`` unless ``gripper``).
    """
    t0 = time.perf_counter()
    g = q[ctx.gi] if gripper is None and ctx.gi is not None else gripper
    if g is not None:  # the chain is checked with the gripper value it carries
        ctx.checker.set_gripper(float(g))
    # the answer is a function of the targets, q, g and the collision world alone: a plan keeps what it found
    key = (tuple((np.asarray(p, dtype=float).tobytes(), pt, rl) for p, pt, rl in targets), np.asarray(q, dtype=float).tobytes(),
           None if g is None else float(g), ctx.checker._state_key())
    known = ctx.iks.get(key)
    if known is not None:
        ctx.timer.add("ik", t0)
        return [c.copy() for c in known]
    try:
        best = _choose_ik(ctx, targets, q, at, g)
    finally:
        ctx.timer.add("ik", t0)
    ctx.iks.keep(key, [c.copy() for c in best])
    return best



def _choose_ik(ctx: PlanContext, targets: list[tuple[np.ndarray, float | None, float | None]], q: np.ndarray, at: str,
               g: float | None) -> list[np.ndarray]:
    """``choose_ik`` itself (not kept), the gripper at ``g`` (None: no gripper)."""
    first, pitch, roll = targets[0]
    try:
        candidates = solve_ik(ctx.robot, first, pitch=pitch, roll=roll, q_ref=q, all_solutions=True)
    except UnreachableError as exc:
        p = first
        raise UnreachableError(f"{at}: target ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is unreachable: {exc.message}",
                               exc.reason, exc.hint) from None
    reasons: list[str] = []
    causes: list[UnreachableReason] = []  # of each rejected candidate, for the error's reason
    best, best_cost = None, math.inf
    for cand in candidates:
        chain = [with_value(cand, ctx.gi, g)]
        ok = True
        for p, pt, rl in targets[1:]:
            try:
                nxt = solve_ik_near(ctx.robot, p, chain[-1], pitch=pt, roll=rl)
            except UnreachableError as exc:
                reasons.append(exc.message)
                causes.append(exc.reason)
                ok = False
                break
            chain.append(with_value(nxt, ctx.gi, g))
        if not ok:
            continue
        bad = next((v for v in (judge(ctx.checker, c[ctx.arm]) for c in chain) if not v), None)
        if bad is not None:
            reasons.append(bad.reason)
            causes.append(bad.kind or "collision")  # an invalid verdict always has its cause
            continue
        cost = float(np.sum(np.abs(chain[-1][ctx.arm] - q[ctx.arm])))
        if cost < best_cost:
            best, best_cost = chain, cost
    if best is None:
        p = first
        why = reasons[0] if reasons else "no IK solution"
        raise UnreachableError(f"{at}: no valid arm configuration reaches ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m: {why}",
                               rejection(causes)[0] if causes else "out_of_reach",
                               "move the target or change the approach height or pitch")
    return best


def warn_collinear(ctx: PlanContext, tasks: list) -> None:
    """Pick and place on opposite sides of the base: the straight way between them passes over the
    base axis, a singular pose where the description's singularity model says so (the RoArm's, a failure
    seen in practice), else possibly near one (``robot.singularity.base_axis_text``)."""
    picks = [ctx.object_pose[t.object][:3, 3] for t in tasks if isinstance(t, PickTask)]
    places = [np.asarray(t.xyz) for t in tasks if isinstance(t, PlaceTask)]
    for a, b in zip(picks, places):
        if np.hypot(*a[:2]) < 1e-6 or np.hypot(*b[:2]) < 1e-6:
            continue
        angle = abs(math.remainder(math.atan2(a[1], a[0]) - math.atan2(b[1], b[0]), 2 * math.pi))
        if angle > math.radians(170):
            ctx.warnings.append(
                f"pick ({a[0]:.2f}, {a[1]:.2f}) and place ({b[0]:.2f}, {b[1]:.2f}) are collinear with the base: a straight "
                f"move would pass {base_axis_text(ctx.robot)}; the planner keeps the singularity margin")
