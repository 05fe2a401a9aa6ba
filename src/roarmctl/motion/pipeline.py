"""From a plan file to a checked, timed trajectory: the main job of ``roarmctl plan``.

Stages: load plan and robot -> build the scene -> expand each task into steps (IK for every target:
``planning.tasks``) -> plan each free or straight motion (OMPL + FCL, or IK along the line) and time it
with TOPP-RA (``planning.motions``) -> join the motions without a stop where the plan blends
(``planning.blending``; the gripper and its jaws: ``planning.grasp``) -> re-check the sampled result
(limits, collisions, singularity margin, TCP speed, line following) -> one ``Trajectory``
(``planning.assembly``). Nothing invalid is ever returned: a violation raises.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from roarmctl.errors import DescriptionError, InfeasibleError, InputError, PlanFileError, PlanningError
from roarmctl.motion import timing
from roarmctl.motion.planning import blending, motions, targets, tasks
from roarmctl.motion.planning.assembly import PartialPlan, assemble, partial
from roarmctl.motion.planning.context import PlanContext, robot_spec, scene_item
from roarmctl.motion.planning.grasp import gripper_action, gripper_event
from roarmctl.motion.planning.pieces import SAMPLE_DT, TaskStep, TimedPiece, UntimedMotion, dwell
from roarmctl.motion.report import motion_peaks
from roarmctl.motion.scene import Scene
from roarmctl.motion.timing import TimedPath
from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.plan.fields import DICT_NAME
from roarmctl.plan.schema import load_plan, read_plan_document
from roarmctl.plan.types import PickTask, PlaceTask, Plan
from roarmctl.robot.jaw_pieces import jaw_pieces
from roarmctl.robot.loader import load_robot
from roarmctl.robot.model import Robot
from roarmctl.robot.padding import thin_parts

__all__ = ["SAMPLE_DT", "PartialPlan", "PlanResult", "Planner", "load_planning_libraries", "plan_file"]

ProgressFn = Callable[[str, int, int], None]


@dataclass
class PlanResult:
    """The planned trajectory plus what it cost: ``timings`` in s per stage, ``warnings`` for the user."""

    trajectory: Trajectory
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    segments: int = 0
    checks: int = 0
    peaks: dict | None = None  # roarmctl.motion.report.motion_peaks: per-joint peaks and fractions of the limits
    notes: list[str] = field(default_factory=list)  # choices made for the user (pitch: auto, grip width)

    @property
    def planning_time(self) -> float:
        """Total planning time (s) over the stages."""
        return float(sum(self.timings.values()))


def plan_file(path: str | Path | dict, seed: int | None = None, progress: ProgressFn | None = None,
              base_dir: str | Path | None = None, current: Callable[[Robot], np.ndarray] | None = None,
              start_here: bool = False) -> PlanResult:
    """Load the plan at ``path`` (or a plan dict of the same form) and plan it (``seed`` overrides
    ``planner.seed``; ``base_dir`` resolves a dict's relative robot path).

    ``current(robot)`` returns the arm's measured configuration (dof,) rad for ``start: current``
    (the CLI reads it from the arm or the simulator); without it such a plan is an input error.
    ``start_here``: start from ``current(robot)`` whatever the plan's ``start`` says (execute
    --from-current plans a trajectory's plan again from the measured pose).
    """
    plan, robot = load_plan_and_robot(path, base_dir)
    if isinstance(plan.start, str) and plan.start == "current" and current is None:
        raise InputError(f"{plan.path}: start: current needs the arm to read its pose from",
                         "connect to the arm (its port, or the simulated one), or give a named pose or joint values as start")
    load_planning_libraries()  # after the plan's form is checked: a typo is reported before the heavy imports
    if start_here or (isinstance(plan.start, str) and plan.start == "current"):
        assert current is not None  # checked above for start: current; start_here comes with it
        plan = replace(plan, start=np.asarray(current(robot), dtype=float))
    if seed is not None:
        plan = replace(plan, planner=replace(plan.planner, seed=seed))  # the options check the seed
    return Planner(plan, robot, progress).run()


def load_plan_and_robot(source: str | Path | dict, base_dir: str | Path | None = None,
                        load: Callable[[str], Robot] | None = None) -> tuple[Plan, Robot]:
    """A plan (a YAML file path or a dict) and the robot it names, the plan read once: its document and ``robot``
    first (``read_plan_document``), then the robot (``load(spec)``, by default ``load_robot``, confined to the plan's
    folder and the package paths unless the plan is a dict), then every field checked against the robot's named
    poses and frames (``load_plan``). An unknown robot is a ``PlanFileError`` naming the plan's line."""
    doc = read_plan_document(source if isinstance(source, dict) else Path(source), base_dir)
    try:
        spec = robot_spec(doc)
        robot = load(spec) if load is not None else load_robot(spec, confine=doc.path.name != DICT_NAME)
    except DescriptionError:
        raise
    except InputError as exc:  # unknown robot: name the plan's line (a dict has none: say where paths start)
        if doc.path.name == DICT_NAME:
            raise PlanFileError(f"{DICT_NAME}: robot: {exc.message}",
                                f"a plan dict's relative robot path starts at base_dir (here {doc.path.parent.resolve()}); "
                                f"pass base_dir=, an absolute path, or a bundled name ({exc.hint})") from None
        raise PlanFileError(f"{doc.path}:{doc.robot_line}: robot: {exc.message}", exc.hint) from None
    return load_plan(source, named_poses=list(robot.named_poses), base_dir=base_dir, frames=robot.frames, parsed=doc), robot


_LIBRARIES_LOADED = False  # load_planning_libraries has imported them all


def load_planning_libraries() -> None:
    """Import toppra (about 1.1 s on an idle 2-core machine: scipy.interpolate and matplotlib.pyplot, which its package
    imports; docs/benchmarks.md, start-up), OMPL and FCL up front, so stage timings measure work, not imports
    (also Ruckig, the blend's corner moves: 1-2 ms that a fresh process otherwise counted as blend time; RNEA's
    module comes with this one's imports).

    A stop signal (SIGINT, SIGTERM, SIGHUP) that arrives while these native modules load is noted and raised
    again once they have loaded, for the handler that was in place: a Python handler that raises while a
    nanobind module (OMPL, Ruckig) initialises makes it call C++ terminate, so a Ctrl-C at that moment
    aborted the process instead of stopping it. (Blocking the signals would not do: numpy's BLAS threads
    receive them.) Once they have loaded, a call does nothing (every api.plan calls it)."""
    global _LIBRARIES_LOADED
    if _LIBRARIES_LOADED:
        return
    received: list[int] = []
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for name in ("SIGINT", "SIGTERM", "SIGHUP"):
            s = getattr(signal, name, None)
            if s is not None and signal.getsignal(s) is not None:  # None: a handler not set from Python, left alone
                previous[s] = signal.signal(s, lambda signum, frame: received.append(signum))
    try:
        import fcl  # noqa: F401
        import ruckig  # noqa: F401

        timing.import_toppra()
        from ompl import base, geometric  # noqa: F401

        _LIBRARIES_LOADED = True
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if received:
            signal.raise_signal(received[0])


class Planner:
    """Plans one ``Plan`` for one ``Robot``: runs the stages task by task over one ``PlanContext`` (``ctx``),
    which keeps the world state (held object, object poses) as it goes."""

    def __init__(self, plan: Plan, robot: Robot, progress: ProgressFn | None = None) -> None:
        from roarmctl.motion.collision import CollisionChecker

        if robot.gripper is None:
            needs = [t for t in plan.tasks if isinstance(t, (PickTask, PlaceTask))]
            if needs:
                at = f"{plan.path}:{needs[0].line}" if needs[0].line else f"{plan.path}: task {plan.tasks.index(needs[0]) + 1}"
                raise InfeasibleError(f"{at}: {robot.name} has no gripper, so it cannot pick or place",
                                      "give the description a gripper (the sidecar's gripper: {joint, open, closed}) or "
                                      "use move tasks")
        self.progress = progress or (lambda stage, done, total: None)
        scene = Scene([scene_item(s) for s in plan.scene + plan.objects])
        checker = CollisionChecker(robot, scene, padding=plan.planner.padding,
                                   singularity_margin=plan.planner.singularity_margin or None)
        self.plan = plan
        self.ctx = PlanContext(robot, checker, plan.limits, plan.planner, plan=plan,
                               initial_scene=scene)  # the checker copied it: nothing else moves it
        self.ctx.notes.extend(robot.notes)  # what the description lacks or leaves out, said once with the plan
        thin = thin_parts(robot, plan.planner.padding)
        if thin is not None:
            self.ctx.warnings.append(thin)

    def _jaw_pieces(self, all_tasks: list) -> None:
        """Make the convex pieces of jaw meshes the description gives as meshes before the first task, under
        a stage of their own: CoACD takes 15-60 s of CPU per mesh the first time (then they are cached), which the
        progress display would otherwise show as the first pick's IK. Also when no pick closes by them (a grasp_width, no
        pick at all): the trajectory carries the pieces (``robot.bundle``) and the physics' jaws are made of them."""
        gr = self.ctx.robot.gripper
        if gr is None or not any(m.file for m in gr.jaw_meshes):
            return
        self.progress("the jaw meshes' convex pieces (made once, then cached)", 0, len(all_tasks))
        jaw_pieces(self.ctx.robot)

    def run(self) -> PlanResult:
        """Plan every task (``cycles`` times over) and return the checked trajectory with its report."""
        ctx = self.ctx
        q = self._start_configuration()
        all_tasks = [t for _ in range(self.plan.cycles) for t in self.plan.tasks]
        tasks.warn_collinear(ctx, all_tasks)
        self._jaw_pieces(all_tasks)
        pieces: list[TimedPiece] = []
        chain: list[UntimedMotion] = []  # free and straight motions not yet timed: timed as one when blending
        for i, task in enumerate(all_tasks):
            self.progress(f"task {i + 1}/{len(all_tasks)}: {task.kind} (IK)", i, len(all_tasks))
            try:
                for step in tasks.expand(ctx, task, q, i):
                    self.progress(step.label, i, len(all_tasks))
                    if step.kind in ("free", "cartesian"):
                        motion = motions.geometry(ctx, step, q)
                        if chain:
                            _check_zone(ctx, chain[-1], motion)
                        chain.append(motion)
                        q = motion.wps[-1].copy()
                        if step.open_to is not None:
                            q[ctx.gi] = step.open_to
                        continue
                    pieces = blending.append_pieces(ctx, pieces, blending.time_chain(ctx, chain))
                    chain = []
                    held = ctx.payload
                    tp = _at_rest(ctx, step, q)
                    piece = TimedPiece(tp, [Segment(0.0, tp.duration, step.kind, step.label)],
                                       None if step.event is None else Event(tp.duration, step.event.kind, step.event.label, step.event.position),
                                       jaw_target=step.grasp_target if step.event is not None else None)
                    pieces = blending.append_pieces(ctx, pieces, [piece])  # before a grasp attaches the object: it is still in the scene
                    if step.kind == "gripper":
                        gripper_event(ctx, step, q)
                    pieces[-1].attach = ctx.payload if ctx.payload is not held else None
                    pieces[-1].detach = held is not None and ctx.payload is None
                    q = tp.q[-1].copy()
            except InfeasibleError as exc:
                exc.partial = partial(ctx, pieces, chain[0].wps[0] if chain else q, task, i)  # what was planned, for visualize-path
                raise
        try:
            pieces = blending.append_pieces(ctx, pieces, blending.time_chain(ctx, chain))
        except InfeasibleError as exc:
            exc.partial = partial(ctx, pieces, chain[0].wps[0], all_tasks[-1], len(all_tasks) - 1)
            raise
        self.progress("done", len(all_tasks), len(all_tasks))
        traj = assemble(ctx, pieces)
        traj.targets = targets.target_table(ctx.robot, traj, ctx.targets)
        if not all(row["reached"] for row in traj.targets):
            first = next(row for row in traj.targets if not row["reached"])
            missed = InfeasibleError(f"{ctx.where}: {targets.missed_text(traj.targets)}",
                                     "a target must be reached (or passed within its zone): report this plan as a bug, "
                                     "or give the target a zone")
            missed.partial = PartialPlan(traj, first["position"], first["name"])
            raise missed

        return PlanResult(traj, dict(ctx.timer.t), ctx.warnings, len(traj.segments), int(getattr(ctx.checker, "check_count", 0)),
                          motion_peaks(traj, ctx.robot), ctx.notes)

    def _start_configuration(self) -> np.ndarray:
        ctx = self.ctx
        s = self.plan.start
        if isinstance(s, str):
            if s not in ctx.robot.named_poses:
                raise InfeasibleError(f"{ctx.where}: start: '{s}' is not a named pose of {ctx.robot.name}")
            q = ctx.robot.full_q(ctx.robot.named_poses[s]).copy()
        else:
            try:
                q = ctx.robot.full_q(s).copy()
            except InputError as exc:
                raise PlanFileError(f"{ctx.where}:{self.plan.lines.get('start', 1)}: start: {exc.message}") from None
        if not ctx.robot.within_limits(q):
            raise InfeasibleError(f"{ctx.where}: start: the configuration is outside the joint limits")
        ctx.set_state(q[ctx.gi] if ctx.gi is not None else None)
        if not ctx.checker.is_valid(q[ctx.arm]):
            raise PlanningError(f"{ctx.where}: start: the start configuration is invalid: {ctx.checker.explain(q[ctx.arm])}",
                                "choose another start pose or move the obstacle")
        return q


def _check_zone(ctx: PlanContext, prev: UntimedMotion, nxt: UntimedMotion) -> None:
    """A move target's zone must not reach the next target (the end of the motion after it): else the corner could
    skip it. Raises ``PlanFileError`` (exit 2) naming the task and its line."""
    zone = prev.step.zone
    if zone is None or zone <= 0.0:
        return
    gap = float(np.linalg.norm(ctx.robot.kin.fk(nxt.wps[-1])[:3, 3] - ctx.robot.kin.fk(prev.wps[-1])[:3, 3]))
    if zone > gap:
        tgt = next((t for t in ctx.targets if t.step == prev.step.label), None)
        name, field = (tgt.name, tgt.zone_field) if tgt is not None else (prev.step.label, "zone")
        raise PlanFileError(f"{ctx.where}: {name}: {field} {zone:g} m is larger than the {gap:.4f} m to the next "
                            f"target ({nxt.step.label})", f"give it a zone of at most {gap:.4f} m, or 0 to reach it")


def _at_rest(ctx: PlanContext, step: TaskStep, q: np.ndarray) -> TimedPath:
    """A step done at rest (wait, gripper) from ``q``, timed and checked (the world update of a gripper step
    is ``grasp.gripper_event``'s)."""
    if step.kind == "wait":
        return dwell(q, step.duration)
    return gripper_action(ctx, step, q, update=False)
