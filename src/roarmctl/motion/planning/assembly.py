"""The timed pieces of a plan as one ``Trajectory`` (with its events, segments, blended joins, payloads, limits,
scene and plan record), and the partial trajectory an infeasible plan reports."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.motion.planning.context import robot_spec
from roarmctl.motion.planning.payloads import payload_entry
from roarmctl.motion.planning.pieces import SAMPLE_DT, TimedPiece
from roarmctl.motion.planning.tasks import where
from roarmctl.motion.timing import TimedPath
from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.plan.fields import DICT_NAME
from roarmctl.plan.types import MoveTask, PickTask, PlaceTask
from roarmctl.robot.bundle import make_bundle
from roarmctl.robot.loader import bundled_robots

if TYPE_CHECKING:
    from roarmctl.motion.planning.context import PlanContext
    from roarmctl.plan.types import WaitTask


@dataclass
class PartialPlan:
    """Attached to an ``InfeasibleError`` from planning as ``exc.partial``: the ``trajectory`` planned
    before the failing task, that task's TCP ``target`` (x, y, z m, None if it has none) and ``label``."""

    trajectory: Trajectory
    target: list[float] | None
    label: str


def assemble(ctx: PlanContext, pieces: list[TimedPiece]) -> Trajectory:
    """The pieces one after the other (each starts where the previous one ends) as the plan's trajectory."""
    times, qs, qds, qdds = [], [], [], []
    events, segments, blends, payloads = [], [], [], []
    held: tuple[float, dict] | None = None
    t_off = 0.0
    for k, piece in enumerate(pieces):
        tp = piece.tp
        skip = 1 if k > 0 else 0
        times.append(tp.times[skip:] + t_off)
        qs.append(tp.q[skip:])
        qds.append(tp.qd[skip:])
        qdds.append(tp.qdd[skip:])
        segments += [Segment(t_off + sg.start, t_off + sg.end, sg.kind, sg.label) for sg in piece.segments]
        if piece.event is not None:
            e = piece.event
            events.append(Event(t_off + e.time, e.kind, e.label, e.position))
        blends += [t_off + b for b in piece.blends]
        t_off += tp.duration
        if piece.detach and held is not None:
            payloads.append(payload_entry(held[0], t_off, held[1]))
            held = None
        if piece.attach is not None:
            held = (t_off, piece.attach)
    if held is not None:
        payloads.append(payload_entry(held[0], t_off, held[1]))
    t = np.concatenate(times)
    keep = np.concatenate([[True], np.diff(t) > 1e-9])
    p = ctx.plan
    if p is not None:
        spec, confine, sha256 = robot_spec(p), p.path.name != DICT_NAME, p.sha256
    else:  # the api's Planner: the robot its caller loaded
        spec, confine, sha256 = getattr(ctx.robot, "spec", "") or ctx.robot.name, False, ""
    traj = Trajectory(
        robot=ctx.robot.name,
        robot_description=None if (p.robot if p is not None else spec) in bundled_robots() else make_bundle(spec, confine=confine),
        joint_names=list(ctx.robot.joint_names),
        times=t[keep],
        positions=np.concatenate(qs)[keep],
        velocities=np.concatenate(qds)[keep],
        accelerations=np.concatenate(qdds)[keep],
        events=events,
        segments=segments,
        blends=blends,
        payloads=payloads,
        limits={
            "velocity": [float(v) for v in ctx.robot.velocity_limits],
            "acceleration": [float(v) for v in ctx.robot.acceleration_limits],
            "velocity_scale": ctx.limits.velocity_scale,
            "acceleration_scale": ctx.limits.acceleration_scale,
            "max_tcp_speed": ctx.limits.max_tcp_speed,
            "jerk": None if ctx.jmax is None else [float(v) for v in ctx.jmax],
            "effort": None if ctx.effort is None else [float(v) if np.isfinite(v) else None for v in ctx.effort],
            "blend": ctx.limits.blend,
            "zone": ctx.limits.zone,  # m, the default zone of a move target (each target's own is in ``targets``)
            # limit kind -> joints whose limit above is roarmctl's default (the description gives none)
            **({"defaults": {k: list(v) for k, v in ctx.robot.defaults.items()}} if ctx.robot.defaults else {}),
        },
        singularity_margin={"min_singular_value": ctx.config.singularity_margin} if ctx.config.singularity_margin else None,
        scene=initial_scene_dict(ctx),
        plan={"path": ctx.where, "sha256": sha256, "planner": ctx.config.name, "seed": ctx.config.seed,
              "padding": ctx.config.padding, **({"link_padding": dict(ctx.robot.padding)} if ctx.robot.padding else {})},
        sample_rate=1.0 / SAMPLE_DT,
    )
    return traj


def initial_scene_dict(ctx: PlanContext) -> dict:
    """The plan's scene with every object at its start pose, as the trajectory file records it."""
    return ctx.initial_scene.to_dict()


def partial(ctx: PlanContext, pieces: list[TimedPiece], q: np.ndarray, task: PickTask | PlaceTask | MoveTask | WaitTask,
            index: int) -> PartialPlan:
    """The trajectory timed before the failure (just the pose ``q`` if nothing was) and the failing task's target."""
    if not pieces:
        z = np.zeros((1, len(q)))
        pieces = [TimedPiece(TimedPath(np.zeros(1), q[None, :].copy(), z, z.copy()), [Segment(0.0, 0.0, "wait", "start")])]
    target = None
    if isinstance(task, PickTask):
        target = ctx.object_pose[task.object][:3, 3] + np.array([0.0, 0.0, task.grasp_offset])
    elif isinstance(task, PlaceTask):
        target = np.asarray(task.xyz, dtype=float)
    elif isinstance(task, MoveTask) and task.xyz is not None:
        target = np.asarray(task.xyz, dtype=float)
    elif isinstance(task, MoveTask):
        goal = ctx.robot.named_poses.get(task.pose) if task.pose is not None else task.joints
        try:
            target = ctx.robot.kin.fk(ctx.robot.full_q(goal))[:3, 3] if goal is not None else None
        except Exception:  # noqa: BLE001 - a goal of the wrong length has no target to mark
            target = None
    return PartialPlan(assemble(ctx, pieces), None if target is None else [float(v) for v in target], where(task, index))
