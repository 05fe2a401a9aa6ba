"""From a plan file to a checked, timed trajectory: the main job of ``roarmctl plan``.

Stages: load plan and robot -> build the scene -> expand each task into motion segments (IK for
every target, free motions with OMPL + FCL, straight TCP lines) -> time every segment with
TOPP-RA -> re-check the sampled result (limits, collisions, singularity margin, TCP speed, line
following) -> one ``Trajectory``. Nothing invalid is ever returned: a violation raises.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from roarmctl.errors import DescriptionError, InfeasibleError, InputError, PlanFileError, PlanningError, UnreachableError
from roarmctl.motion.timing import TimedPath, time_parameterise
from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.plan.schema import ItemSpec, MoveTask, PickTask, Plan, PlaceTask, WaitTask, load_plan
from roarmctl.robot.model import Robot

SAMPLE_DT = 0.01  # s: 100 Hz output
RECHECK_SUBSTEPS = 4  # collision re-check at 4x the output rate
LINE_TOLERANCE = 0.001  # m: straight-line segments follow the line within this
LIMIT_TOL = 1e-6
# Sampling planners return a different detour per seed; keep the shortest of a few (deterministic).
FREE_MOTION_TRIES = 3

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
        return float(sum(self.timings.values()))


@dataclass
class PartialPlan:
    """Attached to an ``InfeasibleError`` from planning as ``exc.partial``: the ``trajectory`` planned
    before the failing task, that task's TCP ``target`` (x, y, z m, None if it has none) and ``label``."""

    trajectory: Trajectory
    target: list[float] | None
    label: str


@dataclass
class _Step:
    """One motion segment before timing."""

    kind: str  # free | cartesian | gripper | wait
    label: str
    waypoints: np.ndarray | None = None  # (K, dof) full configurations (free: arm path filled later)
    q_from: np.ndarray | None = None
    q_to: np.ndarray | None = None
    gripper_to: float | None = None
    duration: float = 0.0
    event: Event | None = None
    line: tuple[np.ndarray, np.ndarray] | None = None
    pitch: float = math.pi / 2
    roll: float | None = None
    grasp_target: str | None = None  # the object the jaws may touch during this step
    open_to: float | None = None  # free motion: the gripper opens to this during it (blended) or right after
    open_label: str = ""


@dataclass
class _Part:
    """A planned but untimed motion: ``wps`` (K, dof) full configurations, gripper at its value at the start."""

    step: _Step
    wps: np.ndarray


@dataclass
class _Piece:
    """A timed stretch of the trajectory, from rest to rest: its segments, event and blended joins (times from its start)."""

    tp: TimedPath
    segments: list[Segment]
    event: Event | None = None
    blends: list[float] = field(default_factory=list)
    attach: dict | None = None  # payload (link -> Inertial) held from this piece's end on
    detach: bool = False  # the held payload is let go at this piece's end
    jaw_target: str | None = None  # a grasp or release: the object the jaws close on or let go


class _GripperDoesNotFit(Exception):
    """The gripper cannot open within the free motion ``index`` of a chain (too short, or the jaws never clear)."""

    def __init__(self, index: int) -> None:
        super().__init__(index)
        self.index = index


class _Timer:
    def __init__(self) -> None:
        self.t: dict[str, float] = {k: 0.0 for k in ("ik", "ompl", "simplify", "toppra", "recheck", "blend")}

    def add(self, key: str, since: float) -> None:
        self.t[key] = self.t.get(key, 0.0) + time.perf_counter() - since


def plan_file(path: str | Path | dict, seed: int | None = None, progress: ProgressFn | None = None,
              base_dir: str | Path | None = None, current: Callable[[object], np.ndarray] | None = None,
              start_here: bool = False) -> PlanResult:
    """Load the plan at ``path`` (or a plan dict of the same form) and plan it (``seed`` overrides
    ``planner.seed``; ``base_dir`` resolves a dict's relative robot path).

    ``current(robot)`` returns the arm's measured configuration (dof,) rad for ``start: current``
    (the CLI reads it from the arm or the simulator); without it such a plan is an input error.
    ``start_here``: start from ``current(robot)`` whatever the plan's ``start`` says (execute
    --from-current plans a trajectory's plan again from the measured pose).
    """
    from roarmctl.robot.loader import load_robot

    path = path if isinstance(path, dict) else Path(path)
    plan = load_plan(path, base_dir=base_dir)  # form first, so typos are reported before anything heavy
    if isinstance(plan.start, str) and plan.start == "current" and current is None:
        raise InputError(f"{plan.path}: start: current needs the arm to read its pose from",
                         "pass --port PORT (or --sim), or give a named pose or joint values as start")
    load_planning_libraries()
    try:
        robot = load_robot(_robot_spec(plan))
    except DescriptionError:
        raise
    except InputError as exc:  # unknown robot: name the plan's line
        raise PlanFileError(f"{plan.path}:{plan.lines.get('robot', 1)}: robot: {exc.message}", exc.hint) from None
    plan = load_plan(path, named_poses=list(robot.named_poses), base_dir=base_dir, frames=robot.frames)
    if start_here or (isinstance(plan.start, str) and plan.start == "current"):
        plan.start = np.asarray(current(robot), dtype=float)
    if seed is not None:
        plan.planner.seed = seed
    return Planner(plan, robot, progress).run()


def load_planning_libraries() -> None:
    """Import toppra (about 0.5 s, mostly scipy), OMPL and FCL up front, so stage timings measure work, not imports
    (also Ruckig, the blend's corner moves, and RNEA's module: 1-2 ms that a fresh process otherwise counted as
    blend and toppra time).

    A stop signal (SIGINT, SIGTERM, SIGHUP) that arrives while these native modules load is noted and raised
    again once they have loaded, for the handler that was in place: a Python handler that raises while a
    nanobind module (OMPL, Ruckig) initialises makes it call C++ terminate, so a Ctrl-C at that moment
    aborted the process instead of stopping it. (Blocking the signals would not do: numpy's BLAS threads
    receive them.)"""
    import signal
    import threading

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

        import roarmctl.robot.dynamics  # noqa: F401
        from roarmctl.motion.timing import import_toppra

        import_toppra()
        from ompl import base, geometric  # noqa: F401
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        if received:
            signal.raise_signal(received[0])


def _robot_spec(plan: Plan) -> str:
    """A bundled name as is; any other name is a path relative to the plan file's directory."""
    from roarmctl.robot.loader import bundled_robots

    if plan.robot in bundled_robots():
        return plan.robot
    candidate = plan.path.parent / Path(plan.robot).expanduser()
    try:
        return str(candidate) if candidate.is_file() else plan.robot
    except (OSError, ValueError):  # a name the OS refuses as a path (too long)
        return plan.robot


class Planner:
    """Plans one ``Plan`` for one ``Robot``; keeps the world state (held object, object poses) as it goes."""

    def __init__(self, plan: Plan, robot: Robot, progress: ProgressFn | None = None) -> None:
        from roarmctl.motion.collision import CollisionChecker
        from roarmctl.motion.scene import Scene

        if robot.gripper is None:
            needs = [t for t in plan.tasks if isinstance(t, (PickTask, PlaceTask))]
            if needs:
                raise InfeasibleError(f"{plan.path}:{needs[0].line}: {robot.name} has no gripper, so it cannot pick or place")
        self.plan, self.robot = plan, robot
        self.progress = progress or (lambda stage, done, total: None)
        self.timer = _Timer()
        self.warnings: list[str] = []
        self.notes: list[str] = []
        from roarmctl.robot.ik import takes_pitch

        self._pitch_free = takes_pitch(robot)  # the IK takes a tool pitch (pitch: auto chooses it)
        self._noted_position_only = False  # "no pitch given" note (generic arms): once per plan
        self.arm = robot.arm_indices
        self.gi = robot.joint_index(robot.gripper.joint) if robot.gripper else None
        items = [_scene_item(s) for s in plan.scene + plan.objects]
        self.scene = Scene(items)
        self.checker = CollisionChecker(robot, self.scene, padding=plan.planner.padding,
                                        singularity_margin=plan.planner.singularity_margin or None)
        self.object_pose = {o.name: o.pose.copy() for o in plan.objects}
        self.held: str | None = None
        self.held_offset = np.zeros(3)  # TCP position minus object centre at grasp (world frame)
        self._pending_pick: tuple[str, np.ndarray] | None = None  # set by a pick, taken by its grasp
        self.vmax = robot.velocity_limits * plan.limits.velocity_scale
        self.amax = robot.acceleration_limits * plan.limits.acceleration_scale
        self.jmax = robot.jerk_limits  # not scaled: the scales slow the motion, the jerk bound keeps it smooth
        self.effort = robot.effort_limits
        self.payload: dict | None = None  # link -> Inertial of the held object, from grasp to release
        self.payload_label = ""
        self.free_count = 0

    # ------------------------------------------------------------------ run
    def run(self) -> PlanResult:
        q = self._start_configuration()
        tasks = [t for _ in range(self.plan.cycles) for t in self.plan.tasks]
        self._warn_collinear(tasks)
        pieces: list[_Piece] = []
        chain: list[_Part] = []  # free and straight motions not yet timed: timed as one when blending
        for i, task in enumerate(tasks):
            self.progress(f"task {i + 1}/{len(tasks)}: {task.kind} (IK)", i, len(tasks))
            try:
                for step in self._expand(task, q, i):
                    self.progress(step.label, i, len(tasks))
                    if step.kind in ("free", "cartesian"):
                        part = self._geometry(step, q)
                        chain.append(part)
                        q = part.wps[-1].copy()
                        if step.open_to is not None:
                            q[self.gi] = step.open_to
                        continue
                    pieces = self._append(pieces, self._flush(chain))
                    chain = []
                    held = self.payload
                    tp = self._realise(step, q)
                    piece = _Piece(tp, [Segment(0.0, tp.duration, step.kind, step.label)],
                                   None if step.event is None else Event(tp.duration, step.event.kind, step.event.label, step.event.position),
                                   jaw_target=step.grasp_target if step.event is not None else None)
                    pieces = self._append(pieces, [piece])  # before a grasp attaches the object: it is still in the scene
                    if step.kind == "gripper":
                        self._gripper_event(step, q)
                    pieces[-1].attach = self.payload if self.payload is not held else None
                    pieces[-1].detach = held is not None and self.payload is None
                    q = tp.q[-1].copy()
            except InfeasibleError as exc:
                exc.partial = self._partial(pieces, chain[0].wps[0] if chain else q, task, i)  # what was planned, for visualize-path
                raise
        try:
            pieces = self._append(pieces, self._flush(chain))
        except InfeasibleError as exc:
            exc.partial = self._partial(pieces, chain[0].wps[0], tasks[-1], len(tasks) - 1)
            raise
        self.progress("done", len(tasks), len(tasks))
        traj = self._assemble(pieces)
        from roarmctl.motion.report import motion_peaks

        return PlanResult(traj, dict(self.timer.t), self.warnings, len(traj.segments), int(getattr(self.checker, "check_count", 0)),
                          motion_peaks(traj, self.robot), self.notes)

    def _partial(self, pieces: list[_Piece], q: np.ndarray, task, index: int) -> PartialPlan:
        """The trajectory timed before the failure (just the pose ``q`` if nothing was) and the failing task's target."""
        if not pieces:
            z = np.zeros((1, len(q)))
            pieces = [_Piece(TimedPath(np.zeros(1), q[None, :].copy(), z, z.copy()), [Segment(0.0, 0.0, "wait", "start")])]
        target = None
        if isinstance(task, PickTask):
            target = self.object_pose[task.object][:3, 3] + np.array([0.0, 0.0, task.grasp_offset])
        elif isinstance(task, PlaceTask):
            target = np.asarray(task.xyz, dtype=float)
        elif isinstance(task, MoveTask) and task.xyz is not None:
            target = np.asarray(task.xyz, dtype=float)
        elif isinstance(task, MoveTask):
            goal = self.robot.named_poses.get(task.pose) if task.pose is not None else task.joints
            try:
                target = self.robot.kin.fk(self.robot.full_q(goal))[:3, 3] if goal is not None else None
            except Exception:  # noqa: BLE001 - a goal of the wrong length has no target to mark
                target = None
        return PartialPlan(self._assemble(pieces), None if target is None else [float(v) for v in target],
                           self._where(task, index))

    def _start_configuration(self) -> np.ndarray:
        s = self.plan.start
        if isinstance(s, str):
            if s not in self.robot.named_poses:
                raise InfeasibleError(f"{self.plan.path}: start: '{s}' is not a named pose of {self.robot.name}")
            q = self.robot.full_q(self.robot.named_poses[s]).copy()
        else:
            try:
                q = self.robot.full_q(s).copy()
            except InputError as exc:
                raise PlanFileError(f"{self.plan.path}:{self.plan.lines.get('start', 1)}: start: {exc.message}") from None
        if not self.robot.within_limits(q):
            raise InfeasibleError(f"{self.plan.path}: start: the configuration is outside the joint limits")
        self._set_state(q[self.gi] if self.gi is not None else None)
        if not self.checker.is_valid(q[self.arm]):
            raise PlanningError(f"{self.plan.path}: start: the start configuration is invalid: {self.checker.explain(q[self.arm])}",
                                "choose another start pose or move the obstacle")
        return q

    # ------------------------------------------------------------ expansion
    def _where(self, task, index: int) -> str:
        return f"task {index + 1} ({task.kind}, line {task.line})"

    def _expand(self, task, q: np.ndarray, index: int) -> list[_Step]:
        where = self._where(task, index)
        if isinstance(task, WaitTask):
            return [_Step("wait", f"{where}: wait {task.seconds:g} s", duration=task.seconds)]
        if isinstance(task, MoveTask):
            goal, label = self._move_goal(task, q, where)
            steps = [_Step("free", f"{where}: move{label}", q_to=goal)]
            g = self._gripper_value(task.gripper)
            if g is not None and abs(g - q[self.gi]) > 1e-9:
                word = {"open": "open", "closed": "close"}.get(task.gripper, "set") if isinstance(task.gripper, str) else "set"
                if np.max(np.abs(goal[self.arm] - q[self.arm])) < 1e-9:  # the arm is there already
                    steps = [_Step("gripper", f"{where}: {word} gripper", gripper_to=g)]
                else:  # during the move where the jaws are clear (blending), else right after it
                    steps[0].open_to, steps[0].open_label = g, f"{where}: {word} gripper"
            return steps
        if isinstance(task, PickTask):
            return self._expand_pick(task, q, where)
        return self._expand_place(task, q, where)

    def _gripper_value(self, value: float | str | None) -> float | None:
        """A move's ``gripper:`` as a joint value (rad), or None (keep it)."""
        if value is None:
            return None
        if self.gi is None:
            raise InfeasibleError(f"{self.plan.path}: {self.robot.name} has no gripper to open or close")
        if isinstance(value, str):
            return float(self.robot.gripper.open if value == "open" else self.robot.gripper.closed)
        lo, hi = self.robot.lower[self.gi], self.robot.upper[self.gi]
        if not lo - 1e-9 <= value <= hi + 1e-9:
            raise InfeasibleError(f"{self.plan.path}: gripper {value:.3f} rad is outside [{lo:.3f}, {hi:.3f}]")
        return float(value)

    def _move_goal(self, task: MoveTask, q: np.ndarray, where: str) -> tuple[np.ndarray, str]:
        label = ""
        if task.pose is not None:
            goal = self.robot.full_q(self.robot.named_poses[task.pose]).copy()
        elif task.joints is not None:
            try:
                goal = self.robot.full_q(task.joints).copy()
            except Exception as exc:  # wrong length
                raise InfeasibleError(f"{where}: joints: {exc}") from None
        else:
            chain, pitch = self._choose_ik_pitch([task.xyz], self._held_pitch(task, where), task.pitch_auto, None, q, where)
            goal = chain[0]
            label = _pitch_label(pitch, task.pitch_auto and pitch is not None)
        if self.gi is not None:
            goal[self.gi] = q[self.gi]
        if not self.robot.within_limits(goal):
            raise InfeasibleError(f"{where}: the goal configuration is outside the joint limits")
        return goal, label

    def _expand_pick(self, task: PickTask, q: np.ndarray, where: str) -> list[_Step]:
        if self.held is not None:
            raise InfeasibleError(f"{where}: picks '{task.object}' while still holding '{self.held}'", "place it first")
        centre = self.object_pose[task.object][:3, 3]
        grasp = centre + np.array([0.0, 0.0, task.grasp_offset])
        above = grasp + np.array([0.0, 0.0, task.approach_height])
        g_open = task.gripper_open if task.gripper_open is not None else self.robot.gripper.open
        g_closed = self._grip_value(task, g_open, where)
        self._set_state(g_open, grasp_target=task.object)
        (q_grasp, q_above), pitch = self._choose_ik_pitch([grasp, above], self._held_pitch(task, where), task.pitch_auto,
                                                          task.roll, q, where, gripper=g_open)
        self._set_state(q[self.gi])
        lab = _pitch_label(pitch, task.pitch_auto and pitch is not None)
        steps = [_Step("free", f"{where}: transit above '{task.object}'{lab}", q_to=_with(q_above, self.gi, q[self.gi]),
                       open_to=g_open if abs(q[self.gi] - g_open) > 1e-9 else None, open_label=f"{where}: open gripper")]
        steps += [
            _Step("cartesian", f"{where}: descend to '{task.object}'{lab}", q_to=q_grasp, line=(above, grasp),
                  pitch=pitch, roll=task.roll, grasp_target=task.object),
            _Step("gripper", f"{where}: grasp '{task.object}'", gripper_to=g_closed, grasp_target=task.object,
                  event=Event(0.0, "grasp", f"pick {task.object}", [float(v) for v in grasp])),
            _Step("cartesian", f"{where}: lift '{task.object}'{lab}", q_to=q_above, line=(grasp, above),
                  pitch=pitch, roll=task.roll, grasp_target=task.object),
        ]
        self._pending_pick = (task.object, grasp - centre)
        return steps

    def _expand_place(self, task: PlaceTask, q: np.ndarray, where: str) -> list[_Step]:
        if self.held is None:
            raise InfeasibleError(f"{where}: places an object but nothing is held", "add a pick task before it")
        name = self.held
        if task.object is not None and task.object != name:
            raise InfeasibleError(f"{where}: places '{task.object}' but the gripper holds '{name}'")
        target = np.asarray(task.xyz, dtype=float) + self.held_offset
        above = target + np.array([0.0, 0.0, task.approach_height])
        g_open = task.gripper_open if task.gripper_open is not None else self.robot.gripper.open
        (q_place, q_above), pitch = self._choose_ik_pitch([target, above], self._held_pitch(task, where), task.pitch_auto,
                                                          task.roll, q, where)
        lab = _pitch_label(pitch, task.pitch_auto and pitch is not None)
        return [
            _Step("free", f"{where}: transit above the place for '{name}'{lab}", q_to=q_above),
            _Step("cartesian", f"{where}: lower '{name}'{lab}", q_to=q_place, line=(above, target), pitch=pitch, roll=task.roll),
            _Step("gripper", f"{where}: release '{name}'", gripper_to=g_open, grasp_target=name,
                  event=Event(0.0, "release", f"place {name}", [float(v) for v in target])),
            _Step("cartesian", f"{where}: retreat from '{name}'{lab}", q_to=_with(q_above, self.gi, g_open), line=(target, above),
                  pitch=pitch, roll=task.roll, grasp_target=name),
        ]

    def _grip_value(self, task: PickTask, g_open: float, where: str) -> float:
        """The gripper value at the grasp; checks that the open jaws clear the object (jaw widths known)."""
        gr = self.robot.gripper
        if not gr.has_widths:
            return task.gripper_closed if task.gripper_closed is not None else gr.closed
        spec = next(o for o in self.plan.objects if o.name == task.object)
        width = _grasp_width(spec)
        opening = gr.width(g_open)
        if opening < width + gr.clearance:
            need = gr.q_for_width(width + gr.clearance)
            fix = (f"open to at least {need:.2f} rad" if width + gr.clearance <= gr.width(gr.open)
                   else f"the jaws open {gr.width(gr.open) * 1000:.0f} mm at most: give a smaller grasp_width or pick it another way")
            raise InfeasibleError(
                f"{where}: gripper_open {g_open:.3f} rad opens the jaws {opening * 1000:.1f} mm; '{task.object}' is "
                f"{width * 1000:.1f} mm wide (+{gr.clearance * 1000:.0f} mm clearance)", fix)
        if task.gripper_closed is not None:
            closed = task.gripper_closed
            if closed <= gr.closed + 1e-9 and width > gr.width(gr.closed) + 1e-6:
                self.warnings.append(
                    f"{where}: gripper_closed {closed:.3f} rad closes the jaws fully on '{task.object}' ({width * 1000:.1f} mm "
                    f"wide): the servo presses until it stalls; leave gripper_closed out to close to "
                    f"{(width - (task.squeeze if task.squeeze is not None else gr.squeeze)) * 1000:.1f} mm")
            elif gr.width(closed) >= width:
                self.warnings.append(
                    f"{where}: gripper_closed {closed:.3f} rad leaves the jaws {gr.width(closed) * 1000:.1f} mm apart on "
                    f"'{task.object}' ({width * 1000:.1f} mm wide): it would not hold; leave gripper_closed out")
            return closed
        squeeze = task.squeeze if task.squeeze is not None else gr.squeeze
        want = width - squeeze
        if want <= gr.width(gr.closed):
            self.warnings.append(f"{where}: '{task.object}' ({width * 1000:.1f} mm) is narrower than the closed jaws "
                                 f"({gr.width(gr.closed) * 1000:.1f} mm) plus the squeeze: the gripper closes fully")
            return gr.closed
        closed = gr.q_for_width(want)
        self.notes.append(f"{where}: grip '{task.object}' ({width * 1000:.1f} mm) at {want * 1000:.1f} mm: gripper {closed:.3f} rad")
        return closed

    def _held_pitch(self, task: PickTask | PlaceTask | MoveTask, where: str) -> float | None:
        """The tool pitch (rad) the IK holds for ``task``, or None (position-only IK).

        The RoArm (``ik.takes_pitch``) holds the task's pitch, straight down by default. Other arms hold the
        pitch (and roll) the plan writes, through the numerical IK's approach-axis target; a task without
        them is solved for the position only (noted once). A position-only IK family (``roarm3``) refuses
        a written pitch or roll instead of ignoring it."""
        from roarmctl.robot.ik import accepts_pitch

        written = getattr(task, "pitch_set", False) or getattr(task, "roll", None) is not None
        if isinstance(task, MoveTask):
            written = task.pitch is not None
        if self._pitch_free:
            return task.pitch if task.pitch is not None else math.pi / 2
        if not written:
            if accepts_pitch(self.robot) and not isinstance(task, MoveTask) and not self._noted_position_only:
                self._noted_position_only = True
                self.notes.append(f"{where}: no pitch given: {self.robot.name}'s grasps and placements are solved for the "
                                  f"position only (the tool's approach follows from the IK); write pitch (e.g. "
                                  f"{{deg: 90}}, straight down) to hold one")
            return None
        if not accepts_pitch(self.robot):
            raise PlanFileError(f"{where}: pitch/roll: {self.robot.name}'s IK is position only (its tool pitch follows "
                                f"from the shoulder and elbow angles), so the plan's pitch cannot be held",
                                "leave pitch and roll out for this arm")
        return task.pitch if task.pitch is not None else math.pi / 2

    def _choose_ik_pitch(self, points: list[np.ndarray], pitch: float | None, auto: bool, roll: float | None,
                         q: np.ndarray, where: str, gripper: float | None = None) -> tuple[list[np.ndarray], float | None]:
        """``_choose_ik`` for points that share one pitch (None: position only); with ``auto`` the pitch nearest
        to ``pitch`` (1 deg steps, ``ik.pitch_candidates``) at which a chain is valid (limits, collisions, margin)."""
        from roarmctl.robot.ik import pitch_candidates

        if not auto or pitch is None:  # no pitch to choose
            return self._choose_ik([(p, pitch, roll) for p in points], q, where, gripper=gripper), pitch
        first: UnreachableError | None = None
        for cand in pitch_candidates(pitch):
            try:
                chain = self._choose_ik([(p, cand, roll) for p in points], q, where, gripper=gripper)
            except UnreachableError as exc:
                first = first or exc
                continue
            self.notes.append(f"{where}: pitch auto chose {math.degrees(cand):.1f} deg (asked {math.degrees(pitch):.1f} deg)")
            return chain, cand
        why = first.message[len(where) + 2:] if first.message.startswith(f"{where}: ") else first.message
        raise UnreachableError(f"{where}: no tool pitch reaches it validly; at {math.degrees(pitch):.1f} deg: {why}",
                               first.reason, first.hint)

    def _choose_ik(self, targets: list[tuple[np.ndarray, float, float | None]], q: np.ndarray, where: str,
                   gripper: float | None = None) -> list[np.ndarray]:
        """IK for a chain of targets on one branch: valid, margin-respecting, nearest to ``q``.

        Returns one full configuration per target (gripper value of ``q`` unless ``gripper``).
        """
        from roarmctl.robot.ik import solve_ik, solve_ik_near

        t0 = time.perf_counter()
        g = q[self.gi] if gripper is None and self.gi is not None else gripper
        if g is not None:  # the chain is checked with the gripper value it carries
            self.checker.set_gripper(float(g))
        first, pitch, roll = targets[0]
        try:
            candidates = solve_ik(self.robot, first, pitch=pitch, roll=roll, q_ref=q, all_solutions=True)
        except UnreachableError as exc:
            self.timer.add("ik", t0)
            p = first
            raise UnreachableError(f"{where}: target ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is unreachable: {exc.message}",
                                   exc.reason, exc.hint) from None
        reasons: list[str] = []
        best, best_cost = None, math.inf
        for cand in candidates:
            chain = [_with(cand, self.gi, g)]
            ok = True
            for p, pt, rl in targets[1:]:
                try:
                    nxt = solve_ik_near(self.robot, p, chain[-1], pitch=pt, roll=rl)
                except UnreachableError as exc:
                    reasons.append(exc.message)
                    ok = False
                    break
                chain.append(_with(nxt, self.gi, g))
            if not ok:
                continue
            bad = next((c for c in chain if not self.checker.is_valid(c[self.arm])), None)
            if bad is not None:
                reasons.append(self.checker.explain(bad[self.arm]))
                continue
            cost = float(np.sum(np.abs(chain[-1][self.arm] - q[self.arm])))
            if cost < best_cost:
                best, best_cost = chain, cost
        self.timer.add("ik", t0)
        if best is None:
            p = first
            why = reasons[0] if reasons else "no IK solution"
            raise UnreachableError(f"{where}: no valid arm configuration reaches ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m: {why}",
                                   "collision" if reasons else "out_of_reach", "move the target or change the approach height or pitch")
        return best

    def _warn_collinear(self, tasks: list) -> None:
        """Pick and place on opposite sides of the base: the straight way between them passes over the
        base axis, where the arm is singular (a failure seen in practice on the RoArm)."""
        picks = [self.object_pose[t.object][:3, 3] for t in tasks if isinstance(t, PickTask)]
        places = [np.asarray(t.xyz) for t in tasks if isinstance(t, PlaceTask)]
        for a, b in zip(picks, places):
            if np.hypot(*a[:2]) < 1e-6 or np.hypot(*b[:2]) < 1e-6:
                continue
            angle = abs(math.remainder(math.atan2(a[1], a[0]) - math.atan2(b[1], b[0]), 2 * math.pi))
            if angle > math.radians(170):
                self.warnings.append(
                    f"pick ({a[0]:.2f}, {a[1]:.2f}) and place ({b[0]:.2f}, {b[1]:.2f}) are collinear with the base: a straight "
                    "move would cross the base-axis singularity; the planner keeps the singularity margin and turns the base instead")

    # ------------------------------------------------------------ realise
    def _set_state(self, gripper: float | None, grasp_target: str | None = None) -> None:
        if gripper is not None:
            self.checker.set_gripper(float(gripper))
        # A held object is attached to the hand (the checker ignores its contact with the jaws);
        # a grasp target is an object in the scene that the jaws may touch.
        self.checker.set_grasp_target(grasp_target if grasp_target != self.held else None)

    def _realise(self, step: _Step, q: np.ndarray) -> TimedPath:
        """Time and check a step at rest (wait, gripper) starting at ``q`` (the world update of a gripper step
        is ``_gripper_event``'s)."""
        if step.kind == "wait":
            return _dwell(q, step.duration)
        return self._gripper_step(step, q, update=False)

    def _geometry(self, step: _Step, q: np.ndarray) -> _Part:
        """The untimed path of a free or straight motion from ``q`` (OMPL + FCL, or IK along the line)."""
        from roarmctl.motion.cartesian import cartesian_line

        self._set_state(q[self.gi] if self.gi is not None else None, grasp_target=step.grasp_target)
        if step.kind == "cartesian":
            t0 = time.perf_counter()
            wps = cartesian_line(self.robot, q, step.line[1], pitch=step.pitch, roll=step.roll, label=step.label)
            self.timer.add("ik", t0)
            return _Part(step, wps)
        return _Part(step, self._free_path(step, q))

    # ------------------------------------------------------------ timing of chains
    def _flush(self, parts: list[_Part]) -> list[_Piece]:
        """Time a chain of motions: each from rest to rest, then, when ``limits.blend``, overlapped in time
        at every join (see ``_blend``) and the gripper opened during its free motion."""
        if not parts:
            return []
        singles = [self._time_chain([p]) for p in parts]
        if not self.plan.limits.blend:
            return self._at_rest(parts, singles)
        piece, bounds = self._superposed(parts, singles)
        try:
            self._gripper_column(piece.tp, parts, [b[0] for b in bounds], [b[1] for b in bounds])
        except _GripperDoesNotFit as exc:  # too short to open the gripper on the way: stop after that motion
            k = exc.index
            return self._flush(parts[:k]) + self._at_rest([parts[k]], [singles[k]]) + self._flush(parts[k + 1:])
        return [piece]

    def _append(self, pieces: list[_Piece], new: list[_Piece]) -> list[_Piece]:
        """``pieces + new``; when blending, a grasp starts closing during the straight motion before it and
        the straight motion after a release starts while the jaws still open (``_jaw_overlap``)."""
        if not new:
            return pieces
        if not pieces or not self.plan.limits.blend or self.gi is None:
            return pieces + new
        a, b = pieces[-1], new[0]
        if b.event is not None and b.event.kind == "grasp" and b.jaw_target and a.segments[-1].kind == "cartesian":
            return pieces[:-1] + self._jaw_overlap(a, b, b.jaw_target, grasp=True) + new[1:]
        if a.event is not None and a.event.kind == "release" and a.jaw_target and b.segments[0].kind == "cartesian":
            return pieces[:-1] + self._jaw_overlap(a, b, a.jaw_target, grasp=False) + new[1:]
        return pieces + new

    def _jaw_overlap(self, a: _Piece, b: _Piece, target: str, grasp: bool) -> list[_Piece]:
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
        saved = self.checker._grasp_target, self.checker._jaw_strict, float(self.checker._q_template[self.checker._gripper_index])
        self.checker.set_grasp_target(target, moving_jaw_clear=True)
        tried: dict[int, TimedPath | None] = {}

        pose = self.robot.kin.fk(ta.q[-1] if grasp else tb.q[0])[:3, 3]  # where the arm arrives / starts

        def attempt(m: int) -> TimedPath | None:
            if m not in tried:
                cand = _superpose(ta, tb, ia, m)
                lo, hi = ia + 1 - m, min(ia + 1, len(cand.times) - 1)
                tried[m] = cand if self._jaw_overlap_ok(cand, lo, hi, pose, reverse=grasp) else None
            return tried[m]

        try:
            # A necessary condition, for every overlap at once: the moving jaw is clear at the last (grasp) or first
            # (release) sample of the arm's motion that is farther than JAW_POSE_TOL from that pose, with the
            # gripper where it is then. Only the overlaps that meet it are checked in full, longest first.
            ms = np.arange(1, max(limit, 0) + 1)
            if grasp:
                far = np.flatnonzero(np.linalg.norm(self.robot.kin.fk(ta.q[:ia + 1])[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL)
                j = int(far[-1]) if len(far) else ia
                arm_q, g = np.repeat(ta.q[j:j + 1, self.arm], len(ms), axis=0), tb.q[np.clip(ms - (ia + 1 - j), 0, len(tb.times) - 1), self.gi]
            else:
                far = np.flatnonzero(np.linalg.norm(self.robot.kin.fk(tb.q)[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL)
                j = int(far[0]) if len(far) else 1
                arm_q, g = np.repeat(tb.q[j:j + 1, self.arm], len(ms), axis=0), ta.q[np.clip(ia + 1 + j - ms, 0, len(ta.times) - 1), self.gi]
            clear = self.checker.validity_batch(arm_q, gripper=g) if len(ms) else np.zeros(0, dtype=bool)
            m = next((int(k) for k in ms[clear][::-1] if attempt(int(k)) is not None), 0)
            cand = tried.get(m)
            if m and not self._jaw_near_ok(cand, ia + 1 - m, min(ia + 1, len(cand.times) - 1), pose, target):
                m, cand = 0, None
        finally:
            self.checker.set_grasp_target(saved[0], moving_jaw_clear=saved[1])
            self.checker.set_gripper(saved[2])
            self.timer.add("blend", t0)
        if not m:
            return [a, b]
        start = ia + 1 - m
        cut = ia + 1 if grasp else start  # where the arm arrives / starts
        first, second = _split(cand, cut)
        t_cut = float(cand.times[cut])
        if grasp:
            segs = a.segments[:-1] + [Segment(a.segments[-1].start, t_cut, a.segments[-1].kind, a.segments[-1].label)]
            e = b.event
            return [_Piece(first, segs, a.event, a.blends, a.attach, a.detach),
                    _Piece(second, [Segment(0.0, second.duration, sg.kind, sg.label) for sg in b.segments[:1]],
                           Event(second.duration, e.kind, e.label, e.position), b.blends, b.attach, b.detach, b.jaw_target)]
        e = a.event  # released: the jaws are clear of the object when the retreat starts
        return [_Piece(first, [Segment(0.0, t_cut, sg.kind, sg.label) for sg in a.segments[:1]],
                       Event(t_cut, e.kind, e.label, e.position), a.blends, a.attach, a.detach, a.jaw_target),
                _Piece(second, b.segments, b.event, b.blends, b.attach, b.detach, b.jaw_target)]

    def _jaw_overlap_ok(self, tp: TimedPath, lo: int, hi: int, pose: np.ndarray, reverse: bool) -> bool:
        """Samples lo..hi of a gripper action superposed with a straight motion, under the collision state set by
        ``_jaw_overlap``: collision-free (4x finer; checked from the end when ``reverse``, where a grasp's jaw is
        nearest the object) wherever the TCP is farther than JAW_POSE_TOL from ``pose`` (x, y, z m: the grasp or
        release pose; nearer, the arm is at that pose and ``_jaw_near_ok`` checks those samples as the gripper
        action itself), outside the singularity margin, within the torque limits by RNEA (nothing is held:
        before a grasp, after a release) and, for the gripper joint, within its position, velocity, acceleration
        and jerk limits (the arm's samples are the straight motion's own)."""
        from roarmctl.robot.dynamics import inverse_dynamics

        a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
        fine = _interpolate(tp.q[a:b], RECHECK_SUBSTEPS)
        fine = fine[np.linalg.norm(self.robot.kin.fk(fine)[:, :3, 3] - pose, axis=1) > JAW_POSE_TOL]
        if reverse:
            fine = fine[::-1]
        if len(fine) and self.checker.first_invalid(fine[:, self.arm], gripper=fine[:, self.gi]) is not None:  # the jaw moves at every sample
            return False
        g, c = self.gi, slice(max(a - 1, 0), min(b + 1, len(tp.times)))  # the gripper's own limits (b may move it too)
        if (np.any(np.abs(tp.qd[a:b, g]) > self.vmax[g] * (1 + 1e-6) + LIMIT_TOL)
                or np.any(np.abs(tp.qdd[a:b, g]) > self.amax[g] * (1 + 1e-6) + LIMIT_TOL)
                or np.any(tp.q[a:b, g] < self.robot.lower[g] - LIMIT_TOL) or np.any(tp.q[a:b, g] > self.robot.upper[g] + LIMIT_TOL)):
            return False
        if self.jmax is not None and np.any(np.abs(np.diff(tp.qdd[c, g]) / np.diff(tp.times[c])) > self.jmax[g] * (1 + 1e-9)):
            return False
        if self.effort is not None and np.any(np.isfinite(self.effort)) and self.robot.inertials:
            tau = inverse_dynamics(self.robot, tp.q[a:b], tp.qd[a:b], tp.qdd[a:b])
            if np.any(np.abs(tau) > self.effort):
                return False
        return True

    def _jaw_near_ok(self, tp: TimedPath, lo: int, hi: int, pose: np.ndarray, target: str) -> bool:
        """The fine samples (4x) of lo..hi whose TCP is within JAW_POSE_TOL of ``pose``, checked like the gripper
        action at that pose: every link against everything, the jaws allowed to touch ``target``."""
        a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
        fine = _interpolate(tp.q[a:b], RECHECK_SUBSTEPS)
        fine = fine[np.linalg.norm(self.robot.kin.fk(fine)[:, :3, 3] - pose, axis=1) <= JAW_POSE_TOL]
        if not len(fine):
            return True
        self.checker.set_grasp_target(target)
        return self.checker.first_invalid(fine[:, self.arm], gripper=fine[:, self.gi]) is None

    def _superposed(self, parts: list[_Part], singles: list[_Piece]) -> tuple[_Piece, list[tuple[float, float]]]:
        """The chain's motions blended join by join; also each part's (start, end) in the result."""
        piece, bounds = singles[0], [(0.0, singles[0].tp.duration)]
        for k in range(1, len(parts)):
            piece, bounds = self._blend(piece, bounds, parts[:k], parts[k], singles[k], singles[k - 1].tp)
        return piece, bounds

    def _at_rest(self, parts: list[_Part], singles: list[_Piece]) -> list[_Piece]:
        """The motions one after the other from rest to rest, the gripper opened at rest after its free motion."""
        pieces = []
        for part, piece in zip(parts, singles):
            pieces.append(piece)
            if part.step.open_to is not None:
                q = piece.tp.q[-1].copy()
                step = _Step("gripper", part.step.open_label or f"{part.step.label}: open gripper", gripper_to=part.step.open_to)
                tp = self._gripper_step(step, q)
                pieces.append(_Piece(tp, [Segment(0.0, tp.duration, "gripper", step.label)]))
        return pieces

    def _blend(self, a: _Piece, bounds: list[tuple[float, float]], a_parts: list[_Part], part: _Part, b: _Piece,
               prev_tp: TimedPath) -> tuple[_Piece, list[tuple[float, float]]]:
        """``b`` started before ``a`` ends: the two motions superposed over an overlap (velocity, acceleration and
        jerk add; both are continuous, so the sum is too). The longest overlap (on the sample grid, at most the
        shorter motion's duration) is taken whose samples keep every limit (velocity, acceleration, jerk by finite
        differences, torque by RNEA, TCP speed) and are collision-free and outside the singularity margin; a
        straight line keeps at least its last (or first) LINE_KEEP of its length exact, so the overlap only
        rounds the corner near its pre-grasp end. ``bounds`` are each part's (start, end) in ``a``; ``prev_tp`` is the
        last of them timed on its own. Where ``_bridge`` does better than the best overlap, its corner move is taken.

        (Timing the blended curve again as one TOPP-RA path gained only 0.04-0.1 s on the bundled plan,
        and the curve's dense knots made the acceleration chatter; superposing two smooth profiles does not.)"""
        dt = SAMPLE_DT
        prev = a_parts[-1]
        ta, tb = a.tp, b.tp
        on_grid = np.flatnonzero(np.abs(ta.times / dt - np.round(ta.times / dt)) < 1e-6)
        ia = int(on_grid[-1])
        limit = min(ia - int(np.ceil(bounds[-1][0] / dt - 1e-9)), len(tb.times) - 2)  # overlap stays inside both motions
        # when a straight line is (1 - LINE_KEEP) done: the line must be exact until LINE_KEEP of it is done
        lines = (self._line_time(prev, ta, bounds[-1], 1.0 - LINE_KEEP) if prev.step.kind == "cartesian" else None,
                 self._line_time(part, tb, (0.0, tb.duration), 1.0 - LINE_KEEP) if part.step.kind == "cartesian" else None)
        if lines[0] is not None:
            limit = min(limit, ia - int(np.ceil(lines[0] / dt - 1e-9)))
        if lines[1] is not None:
            limit = min(limit, int(lines[1] / dt))
        t0 = time.perf_counter()
        try:
            bridged = self._bridge(ta, tb, ia, bounds, prev, part, prev_tp, (ia + 1) * dt + tb.duration, lines)
            if bridged is not None and bridged[0].duration <= (ia + 1 - max(limit, 0)) * dt + tb.duration + 1e-9:
                return self._bridged_piece(a, b, bounds, prev, part, *bridged)  # no overlap could do better
            for m in range(limit, 0, -BLEND_STEP):
                cand = _superpose(ta, tb, ia, m)
                if self._overlap_ok(cand, ia + 1 - m, ia, prev, part):
                    break
            else:
                m, cand = 0, _superpose(ta, tb, ia, 0)
            if bridged is not None and bridged[0].duration < cand.duration - 1e-9:
                return self._bridged_piece(a, b, bounds, prev, part, *bridged)
        finally:
            self.timer.add("blend", t0)
        start = (ia + 1 - m) * dt  # b's start in the combined timeline
        # where one segment hands over to the next: a line is exact from (or until) there
        if part.step.kind == "cartesian":
            join = ta.duration if m else start
        elif prev.step.kind == "cartesian":
            join = start
        else:
            join = 0.5 * (start + max(ta.duration, start))
        segments = a.segments[:-1] + [Segment(a.segments[-1].start, join, a.segments[-1].kind, a.segments[-1].label)]
        segments += [Segment(max(start + sg.start, join), start + sg.end, sg.kind, sg.label) for sg in b.segments]
        new_bounds = bounds[:-1] + [(bounds[-1][0], join), (join, start + tb.duration)]
        return _Piece(cand, segments, None, a.blends + ([join] if m else [])), new_bounds

    def _bridge(self, ta: TimedPath, tb: TimedPath, ia: int, bounds: list[tuple[float, float]], prev: _Part, part: _Part,
                prev_tp: TimedPath, beat: float, lines: tuple[float | None, float | None]) -> tuple[TimedPath, int, int] | None:
        """The corner between ``ta`` (ending with the motion ``prev``, its last on-grid sample ``ia``) and ``tb`` (the
        motion ``part``, timed from rest) cut out and replaced by a time-optimal, jerk-limited move from sample i of
        ``ta`` to sample k of ``tb`` (Ruckig, state to state: position, velocity and acceleration at both ends, all
        joints finishing together, duration a whole number of samples).

        Where a joint reverses at the corner (the RoArm's wrist between a transit and a vertical approach), the
        superposition of ``_blend`` can overlap only the two jerk ramps, because the two motions' accelerations
        add; the bridge instead keeps decelerating through the reversal. A straight line keeps its LINE_KEEP
        exact (i and k are bounded by it); a free motion is cut at most half-way and only on its last (first)
        edge between two of its vertices (``prev_tp``: ``prev`` timed on its own), so a detour around an obstacle
        is not cut short. Candidates (i, k) are searched
        on a coarse grid, refined around the best ones, and taken shortest first; the first whose samples pass
        ``_overlap_ok`` (every limit, collisions under both motions' states) and that beats ``beat`` (s, the
        superposed result) is returned: (path, i, index of the bridge's last sample). None if none. ``lines``: the
        times (s, in ``ta`` and ``tb``) when ``prev`` and ``part`` are 1 - LINE_KEEP along their straight lines (None:
        not a line), as ``_blend`` found them."""
        from ruckig import DurationDiscretization, InputParameter, Result, Ruckig, RuckigError, Trajectory

        dt = SAMPLE_DT
        arm = self.arm
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
            if len(part.wps) > 2 and tb.s is not None:  # up to its first vertex
                first = float(np.linalg.norm(part.wps[1][arm] - part.wps[0][arm]))
                k_hi = min(k_hi, int(np.searchsorted(tb.s, first + 1e-9, side="right")) - 1)
        # the ends themselves must be valid under both motions' states (the bridge's samples are checked under both)
        # (the state the checker is in first: each switch rebuilds its collision objects)
        part_first = self.checker._grasp_target is not None and self.checker._grasp_target == self._target_of(part)
        for p in ((part, prev) if part_first else (prev, part)):
            if ia <= i_lo or k_hi <= 0:
                break
            if p is prev:
                bad = self._first_invalid_under(prev, tb.q[1:k_hi + 1] + (ta.q[-1] - tb.q[0]))
                k_hi = k_hi if bad is None else bad
            else:
                bad = self._first_invalid_under(part, ta.q[i_lo:ia + 1][::-1])
                i_lo = i_lo if bad is None else ia + 1 - bad
        if ia <= i_lo or k_hi <= 0:
            return None
        otg, traj, inp = Ruckig(len(arm), dt), Trajectory(len(arm)), InputParameter(len(arm))
        inp.duration_discretization = DurationDiscretization.Discrete
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = list(self.vmax[arm]), list(self.amax[arm]), list(self.jmax[arm])
        qb = tb.q[:, arm] + (ta.q[-1, arm] - tb.q[0, arm])  # tb starts where ta comes to rest (as in _bridged)
        # the end states as lists, (3, n) per sample: ta's samples i_lo..ia (sa[i - i_lo]), tb's 0..k_hi (sb[k])
        sa = np.stack([ta.q[i_lo:ia + 1, arm], ta.qd[i_lo:ia + 1, arm], ta.qdd[i_lo:ia + 1, arm]], axis=1).tolist()
        sb = np.stack([qb[:k_hi + 1], tb.qd[:k_hi + 1, arm], tb.qdd[:k_hi + 1, arm]], axis=1).tolist()
        totals: dict[tuple[int, int], int | None] = {}  # (i, k) -> bridge samples
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

        coarse = [(i, k) for i in range(ia, i_lo - 1, -BRIDGE_COARSE[0]) for k in range(k_hi, 0, -BRIDGE_COARSE[1])]
        # shortest first; among equals the earliest end in the second motion and the latest start in the first (a
        # straight line stays exact for longer)
        def ranked(keys) -> list[tuple[int, int]]:
            keys = list(keys)
            if not keys:
                return []
            i, k = np.array(keys).T
            n = np.array([totals[key] for key in keys])
            return [keys[j] for j in np.lexsort((n, -i, k, i + n - k))]  # total = (i + n - k) dt + tb.duration

        best = ranked(key for key in coarse if solve(*key) is not None)[:BRIDGE_REFINE]
        for i0, k0 in best:  # every sample around the best coarse ones
            for i in range(max(i0 - BRIDGE_COARSE[0] + 1, i_lo), min(i0 + BRIDGE_COARSE[0], ia + 1)):
                for k in range(max(k0 - BRIDGE_COARSE[1] + 1, 1), min(k0 + BRIDGE_COARSE[1], k_hi + 1)):
                    solve(i, k)
        # tb's samples before its end are on the grid: the result lasts (i + n - k) dt + tb.duration
        under = int(np.floor((beat - tb.duration) / dt - 1e-6))
        found = ranked(key for key, n in totals.items() if n is not None and key[0] + n - key[1] <= under)[:BRIDGE_TRIES]
        for i, k in found:
            steps = totals[(i, k)]
            set_ends(i, k)
            otg.calculate(inp, traj)
            cand = _bridged(ta, tb, i, k, steps, traj, arm)
            if self._overlap_ok(cand, i, i + steps, prev, part):
                return cand, i, i + steps
        return None

    def _target_of(self, part: _Part) -> str | None:
        """The grasp target the checker gets for ``part`` (``_set_state``: none for the held object)."""
        return part.step.grasp_target if part.step.grasp_target != self.held else None

    def _first_invalid_under(self, part: _Part, q: np.ndarray) -> int | None:
        """The first invalid row of ``q`` (M, dof) under ``part``'s collision state (its gripper value for every row,
        its grasp target); None if all are valid."""
        if not len(q):
            return None
        q = q.copy()
        if self.gi is not None:
            q[:, self.gi] = part.wps[0][self.gi]
        self._set_state(part.wps[0][self.gi] if self.gi is not None else None, grasp_target=part.step.grasp_target)
        return self._first_invalid(q)

    def _bridged_piece(self, a: _Piece, b: _Piece, bounds: list[tuple[float, float]], prev: _Part, part: _Part,
                       cand: TimedPath, i: int, e: int) -> tuple[_Piece, list[tuple[float, float]]]:
        """The piece and part bounds after ``_bridge``: samples i..e of ``cand`` are the bridge."""
        t_i, t_e = float(cand.times[i]), float(cand.times[e])
        if part.step.kind == "cartesian":
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
        return _Piece(cand, segments, None, a.blends + [join]), new_bounds

    def _line_time(self, part: _Part, tp: TimedPath, span: tuple[float, float], fraction: float) -> float:
        """Time (s, in ``tp``) when the TCP has covered ``fraction`` of the part's straight line."""
        p0, p1 = self.robot.kin.fk(part.wps[0])[:3, 3], part.step.line[1]
        sel = (tp.times >= span[0] - 1e-9) & (tp.times <= span[1] + 1e-9)
        p = self.robot.kin.fk(tp.q[sel])[:, :3, 3]
        d = p1 - p0
        done = np.clip((p - p0) @ d / max(float(d @ d), 1e-18), 0.0, 1.0)
        return float(np.interp(fraction, np.maximum.accumulate(done), tp.times[sel]))

    def _overlap_ok(self, tp: TimedPath, lo: int, hi: int, prev: _Part, part: _Part) -> bool:
        """Limits and validity of the samples lo..hi (the overlap) of a superposed motion, one sample either side."""
        a, b = max(lo - 1, 0), min(hi + 2, len(tp.times))
        q, qd, qdd = tp.q[a:b], tp.qd[a:b], tp.qdd[a:b]
        if np.any(q < self.robot.lower - LIMIT_TOL) or np.any(q > self.robot.upper + LIMIT_TOL):
            return False
        if np.any(np.abs(qd) > self.vmax * (1 + 1e-6) + LIMIT_TOL) or np.any(np.abs(qdd) > self.amax * (1 + 1e-6) + LIMIT_TOL):
            return False
        if self.jmax is not None:
            jerk = np.diff(tp.qdd[max(a - 1, 0):min(b + 1, len(tp.times))], axis=0) / np.diff(tp.times[max(a - 1, 0):min(b + 1, len(tp.times))])[:, None]
            if np.any(np.abs(jerk) > self.jmax * (1 + 1e-9)):
                return False
        if self.plan.limits.max_tcp_speed is not None:
            if np.max(np.linalg.norm(self.robot.kin.tcp_velocity(q, qd[:, self.arm]), axis=1)) > self.plan.limits.max_tcp_speed:
                return False
        model = self._torque_model(q[0], list(range(self.robot.dof)))
        if model is not None and np.any(np.abs(model.inverse_dynamics(q, qd, qdd)) > model.limits):
            return False
        fine = _interpolate(q, RECHECK_SUBSTEPS)
        current = self.checker._grasp_target
        first = part if current is not None and current == self._target_of(part) else prev  # no state switch first
        for p in (first, part if first is prev else prev):  # each motion's own collision state: the stricter one decides
            self._set_state(p.wps[0][self.gi] if self.gi is not None else None, grasp_target=p.step.grasp_target)
            if self._first_invalid(fine) is not None:
                return False
        return True

    def _time_chain(self, parts: list[_Part]) -> _Piece:
        """Time one motion from rest to rest and re-check it (``parts`` holds that one motion).

        A free motion starts as the spline through its few vertices; if a check fails, vertices are
        added along its valid polyline and the spline pulled toward it, step by step.
        """
        from roarmctl.motion.collision import densify

        (part,) = parts
        label = part.step.label
        last_error: PlanningError | None = None
        for max_step in ((None, 0.4, 0.2, 0.1, 0.05, 0.025) if part.step.kind == "free" else (None,)):
            wps = part.wps if max_step is None else densify(part.wps, max_step)
            try:  # a timing failure is retried too: denser vertices make a tamer spline
                tp = self._time(wps, label)
            except PlanningError as exc:
                last_error = exc
                continue
            t0 = time.perf_counter()
            try:
                self._check_chain(tp, parts, np.array([0.0, float(tp.s[-1])]), label)
            except PlanningError as exc:
                last_error = exc
                continue
            finally:
                self.timer.add("recheck", t0)
            return _Piece(tp, [Segment(0.0, tp.duration, part.step.kind, label)])
        raise last_error

    def _gripper_column(self, tp: TimedPath, parts: list[_Part], t_starts: list[float], t_ends: list[float]) -> None:
        """Set the gripper over the chain: each part's own value; a part with ``open_to`` opens it during that part
        (blending), starting at the first sample from which the moving jaws are clear of everything."""
        gi = self.gi
        if gi is None:
            return
        for k, part in enumerate(parts):
            sel = tp.times >= t_starts[k] - 1e-12
            tp.q[sel, gi], tp.qd[sel, gi], tp.qdd[sel, gi] = part.wps[0][gi], 0.0, 0.0
        for k, part in enumerate(parts):
            if part.step.open_to is None:
                continue
            g = self._gripper_motion(tp.q[0], part.step.open_to, part.step.open_label, start=float(part.wps[0][gi]))
            moving = g.times < g.duration - 1e-12  # the samples on the grid (the last one is at rest)
            n = int(np.count_nonzero(moving))
            first = int(np.searchsorted(tp.times, t_starts[k] - 1e-12))
            last_start = int(np.searchsorted(tp.times, t_ends[k] - g.duration + 1e-12, side="right")) - 1
            for i0 in range(first, last_start + 1, 5):  # try every 50 ms from the start of the transit
                q = tp.q.copy()
                q[i0:, gi] = part.step.open_to
                q[i0:i0 + n, gi] = g.q[moving, gi]
                self._set_state(part.wps[0][gi], grasp_target=part.step.grasp_target)
                span = q[i0:int(np.searchsorted(tp.times, t_ends[k] + 1e-12))]
                if self._first_invalid(_interpolate(span, RECHECK_SUBSTEPS)) is None:
                    tp.q[:, gi] = q[:, gi]
                    tp.qd[i0:, gi], tp.qdd[i0:, gi] = 0.0, 0.0
                    tp.qd[i0:i0 + n, gi], tp.qdd[i0:i0 + n, gi] = g.qd[moving, gi], g.qdd[moving, gi]
                    break
            else:
                raise _GripperDoesNotFit(k)

    def _first_invalid(self, qf: np.ndarray) -> int | None:
        """First invalid configuration of ``qf`` (M, dof), the gripper as given per sample (grasp target as set).

        One checker call with a gripper value per row (not one call per run of equal gripper values: while
        the jaws move, that was one call per sample); the checker's own gripper value is left as it was."""
        if self.gi is None:
            return self.checker.first_invalid(qf[:, self.arm])
        return self.checker.first_invalid(qf[:, self.arm], gripper=qf[:, self.gi])

    def _check_chain(self, tp: TimedPath, parts: list[_Part], s_bounds: np.ndarray, label: str) -> None:
        """Independent check of the sampled motion: limits, TCP speed, collisions (4x finer) and singularity
        margin with each part's own collision state, straight parts within LINE_TOLERANCE of their lines."""
        from roarmctl.motion.cartesian import line_deviation

        r = self.robot
        if np.any(tp.q < r.lower - LIMIT_TOL) or np.any(tp.q > r.upper + LIMIT_TOL):
            raise PlanningError(f"{label}: the timed motion leaves the joint limits")
        if np.any(np.abs(tp.qd) > self.vmax * (1 + 1e-6) + LIMIT_TOL):
            raise PlanningError(f"{label}: the timed motion exceeds a joint velocity limit")
        if np.any(np.abs(tp.qdd) > self.amax * (1 + 1e-6) + LIMIT_TOL):
            raise PlanningError(f"{label}: the timed motion exceeds a joint acceleration limit")
        if self.plan.limits.max_tcp_speed is not None:
            speed = np.linalg.norm(r.kin.tcp_velocity(tp.q, tp.qd[:, self.arm]), axis=1)
            if np.max(speed) > self.plan.limits.max_tcp_speed * (1 + 1e-6):
                raise PlanningError(f"{label}: the TCP speed {np.max(speed):.3f} m/s exceeds max_tcp_speed")
        for k, part in enumerate(parts):
            sel = np.flatnonzero((tp.s >= s_bounds[k] - 1e-12) & (tp.s <= s_bounds[k + 1] + 1e-12))
            lo, hi = max(int(sel[0]) - 1, 0), min(int(sel[-1]) + 1, len(tp.times) - 1)  # and the samples either side
            self._set_state(part.wps[0][self.gi] if self.gi is not None else None, grasp_target=part.step.grasp_target)
            fine = _interpolate(tp.q[lo:hi + 1], RECHECK_SUBSTEPS)
            bad = self._first_invalid(fine)
            if bad is not None:
                if self.gi is not None:
                    self.checker.set_gripper(float(fine[bad, self.gi]))
                raise PlanningError(f"{part.step.label}: the timed motion is invalid at t = {tp.times[lo] + bad / RECHECK_SUBSTEPS * SAMPLE_DT:.2f} s: "
                                    f"{self.checker.explain(fine[bad, self.arm])}")
            if part.step.kind == "cartesian":
                p0, p1 = r.kin.fk(part.wps[0])[:3, 3], part.step.line[1]
                dev = line_deviation(r, tp.q[sel], p0, p1)
                if dev > LINE_TOLERANCE:
                    raise PlanningError(f"{part.step.label}: the timed motion leaves the straight TCP line by {dev * 1000:.1f} mm")

    def _gripper_step(self, step: _Step, q: np.ndarray, update: bool = True) -> TimedPath:
        """The gripper action ``step`` at rest at ``q``, timed and its jaw sweep checked; with ``update`` also
        its world update (``_gripper_event``)."""
        a, b = float(q[self.gi]), float(step.gripper_to)
        tp = self._gripper_motion(q, b, step.label)
        if tp.duration < self.plan.limits.gripper_time:  # the jaws get at least gripper_time to settle
            tp = _concat(tp, _dwell(tp.q[-1], self.plan.limits.gripper_time - tp.duration))
        t0 = time.perf_counter()
        values = np.linspace(a, b, 5)  # the jaw sweeps: check it along the way (one batch, a gripper value per row)
        self._set_state(b, grasp_target=step.grasp_target)
        valid = self.checker.validity_batch(np.repeat(q[None, self.arm], len(values), axis=0), gripper=values)
        if not valid.all():
            self.checker.set_gripper(float(values[int(np.argmin(valid))]))
            self.timer.add("recheck", t0)
            raise PlanningError(f"{step.label}: the moving jaw collides: {self.checker.explain(q[self.arm])}")
        self.timer.add("recheck", t0)
        if update:
            self._gripper_event(step, q)
        return tp

    def _gripper_event(self, step: _Step, q: np.ndarray) -> None:
        """After the gripper action ``step`` at ``q``: a grasp attaches the object (collision model and payload),
        a release puts it back into the scene; the checker takes the new gripper value."""
        b = float(step.gripper_to)
        tcp = self.robot.kin.fk(q)[:3, 3]
        if step.event is not None:
            if step.event.kind == "grasp":
                name, offset = self._pending_pick
                self._set_state(b, grasp_target=name)
                self.checker.attach(name, q[self.arm])
                self.held, self.held_offset, self._pending_pick = name, offset, None
                self._attach_payload(name, q, step.label)
            elif step.event.kind == "release":
                name = self.held
                self.checker.detach(name, q[self.arm])
                self.object_pose[name][:3, 3] = tcp - self.held_offset
                self.held, self.held_offset = None, np.zeros(3)
                self.payload, self.payload_label = None, ""
                self._set_state(b, grasp_target=name)
        else:
            self._set_state(b)

    def _free_path(self, step: _Step, q: np.ndarray) -> np.ndarray:
        """OMPL path from ``q`` to the step's goal: the few vertices (K, dof) of the shortest of a few plans, shortcut."""
        from roarmctl.motion.ompl_planner import plan_joint_path_with_stats, simplify_path

        goal = step.q_to.copy()
        if self.gi is not None:
            goal[self.gi] = q[self.gi]
        cfg = self.plan.planner
        seed = cfg.seed + 1000 * self.free_count
        self.free_count += 1
        best = None
        for attempt in range(FREE_MOTION_TRIES):  # raw plans, only greedily pruned
            path, stats = plan_joint_path_with_stats(  # the straight move is tried once (a later try would fail it again)
                self.checker, q[self.arm], goal[self.arm], planner=cfg.name, time_budget=cfg.time_budget,
                simplify_budget=cfg.simplify_budget, seed=seed + attempt, resolution=0.01, max_step=None,
                try_direct=attempt == 0, simplify_attempts=0, max_checks=cfg.max_checks)
            self.timer.t["ompl"] += stats.solve_time
            self.timer.t["simplify"] += stats.simplify_time
            if best is None or stats.length < best[1].length:
                best = (path, stats)
            if stats.direct:  # the straight joint move is valid: nothing shorter exists
                break
        path = best[0]
        if not best[1].direct:  # shortcut only the one we keep
            t0 = time.perf_counter()
            path = simplify_path(self.checker, path, seed=seed, time_budget=cfg.simplify_budget)
            self.timer.add("simplify", t0)
        vertices = np.repeat(q[None, :], len(path), axis=0)
        vertices[:, self.arm] = path
        return vertices

    def _time(self, wps: np.ndarray, label: str) -> TimedPath:
        t0 = time.perf_counter()
        arm = self.arm
        tcpv = None
        if self.plan.limits.max_tcp_speed is not None:
            base = wps[0].copy()

            def tcpv(qa: np.ndarray, dqa: np.ndarray) -> np.ndarray:
                full = np.repeat(base[None, :], len(qa), axis=0)
                full[:, arm] = qa
                return self.robot.kin.tcp_velocity(full, dqa)

        tp_arm = time_parameterise(wps[:, arm], self.vmax[arm], self.amax[arm], None if self.jmax is None else self.jmax[arm],
                                   tcp_velocity_per_ds=tcpv, max_tcp_speed=self.plan.limits.max_tcp_speed,
                                   torque=self._torque_model(wps[0], arm), sample_dt=SAMPLE_DT, label=label)
        n = len(tp_arm.times)
        q = np.repeat(wps[0][None, :], n, axis=0)
        q[:, arm] = tp_arm.q
        qd, qdd = np.zeros_like(q), np.zeros_like(q)
        qd[:, arm], qdd[:, arm] = tp_arm.qd, tp_arm.qdd
        self.timer.add("toppra", t0)
        return TimedPath(tp_arm.times, q, qd, qdd, tp_arm.jerk_filter, tp_arm.s)

    def _gripper_motion(self, q: np.ndarray, target: float, label: str, start: float | None = None) -> TimedPath:
        """The gripper alone from ``start`` (default q[gi]) to ``target``, the arm held at ``q``: time-optimal under
        the gripper's velocity, acceleration and jerk limits."""
        gi = self.gi
        q = q.copy()
        if start is not None:
            q[gi] = start
        t0 = time.perf_counter()
        one = time_parameterise(np.array([[q[gi]], [target]]), self.vmax[gi:gi + 1], self.amax[gi:gi + 1],
                                None if self.jmax is None else self.jmax[gi:gi + 1], sample_dt=SAMPLE_DT, label=label)
        self.timer.add("toppra", t0)
        qq = np.repeat(q[None, :], len(one.times), axis=0)
        qd, qdd = np.zeros_like(qq), np.zeros_like(qq)
        qq[:, gi], qd[:, gi], qdd[:, gi] = one.q[:, 0], one.qd[:, 0], one.qdd[:, 0]
        return TimedPath(one.times, qq, qd, qdd, one.jerk_filter)

    def _torque_model(self, base: np.ndarray, idx: list[int]):
        """Torque limits of the joints ``idx`` for TOPP-RA (RNEA with the held payload); None without limits."""
        from roarmctl.motion.timing import TorqueModel
        from roarmctl.robot.dynamics import inverse_dynamics

        if self.effort is None or not np.any(np.isfinite(self.effort[idx])) or not self.robot.inertials:
            return None
        robot, payload = self.robot, self.payload

        def inv_dyn(qa: np.ndarray, qda: np.ndarray, qdda: np.ndarray) -> np.ndarray:
            full = np.repeat(base[None, :], len(qa), axis=0)
            full[:, idx] = qa
            zd = np.zeros_like(full)
            fd, fdd = zd.copy(), zd.copy()
            fd[:, idx], fdd[:, idx] = qda, qdda
            return inverse_dynamics(robot, full, fd, fdd, payload=payload)[:, idx]

        return TorqueModel(inv_dyn, self.effort[idx], [robot.joint_names[i] for i in idx], self.payload_label)

    def _attach_payload(self, name: str, q: np.ndarray, label: str) -> None:
        """The held object's mass, COM and inertia become part of the TCP link (from grasp to release)."""
        from roarmctl.motion.timing import check_holding
        from roarmctl.robot.dynamics import solid_inertia
        from roarmctl.robot.model import Inertial

        spec = next(o for o in self.plan.objects if o.name == name)
        if not spec.mass:
            return
        tcp = self.robot.kin.fk(q)
        rel = np.linalg.inv(tcp) @ self.object_pose[name]  # object frame in the TCP link frame
        com_obj = spec.com if spec.com is not None else np.zeros(3)
        inertia = spec.inertia if spec.inertia is not None else solid_inertia(spec.shape, spec.mass, spec.size, spec.radius, spec.length)
        rot = rel[:3, :3]
        self.payload = {self.robot.tcp_link: Inertial(float(spec.mass), rot @ com_obj + rel[:3, 3], rot @ inertia @ rot.T)}
        self.payload_label = f"'{name}' ({spec.mass:.2f} kg)"
        model = self._torque_model(q, self.arm)
        if model is not None:
            check_holding(model, q[None, self.arm], label)

    # ------------------------------------------------------------ assemble
    def _assemble(self, pieces: list[_Piece]) -> Trajectory:
        from roarmctl.robot.loader import bundled_robots

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
                payloads.append(_payload_entry(held[0], t_off, held[1]))
                held = None
            if piece.attach is not None:
                held = (t_off, piece.attach)
        if held is not None:
            payloads.append(_payload_entry(held[0], t_off, held[1]))
        t = np.concatenate(times)
        keep = np.concatenate([[True], np.diff(t) > 1e-9])
        p = self.plan
        traj = Trajectory(
            robot=self.robot.name if p.robot in bundled_robots() else str(Path(_robot_spec(p)).resolve()),
            joint_names=list(self.robot.joint_names),
            times=t[keep],
            positions=np.concatenate(qs)[keep],
            velocities=np.concatenate(qds)[keep],
            accelerations=np.concatenate(qdds)[keep],
            events=events,
            segments=segments,
            blends=blends,
            payloads=payloads,
            limits={
                "velocity": [float(v) for v in self.robot.velocity_limits],
                "acceleration": [float(v) for v in self.robot.acceleration_limits],
                "velocity_scale": p.limits.velocity_scale,
                "acceleration_scale": p.limits.acceleration_scale,
                "max_tcp_speed": p.limits.max_tcp_speed,
                "jerk": None if self.jmax is None else [float(v) for v in self.jmax],
                "effort": None if self.effort is None else [float(v) if np.isfinite(v) else None for v in self.effort],
                "blend": p.limits.blend,
            },
            singularity_margin={"min_singular_value": p.planner.singularity_margin} if p.planner.singularity_margin else None,
            scene=self._initial_scene_dict(),
            plan={"path": str(p.path), "sha256": p.sha256, "planner": p.planner.name, "seed": p.planner.seed,
                  "padding": p.planner.padding},
            sample_rate=1.0 / SAMPLE_DT,
        )
        return traj

    def _initial_scene_dict(self) -> dict:
        from roarmctl.motion.scene import Scene

        return Scene([_scene_item(s) for s in self.plan.scene + self.plan.objects]).to_dict()


# ------------------------------------------------------------------ helpers
def _scene_item(spec: ItemSpec):
    from roarmctl.motion.scene import SceneItem

    return SceneItem(name=spec.name, role=spec.role, shape=spec.shape, pose=spec.pose.copy(), size=tuple(spec.size),
                     radius=spec.radius, length=spec.length)


LINE_KEEP = 0.5  # a blend may round the corner over at most the first (last) half of a straight line
# m: the TCP this near the grasp (release) pose counts as there: the moving jaw may already be inside the padding
# of the object while the arm settles (arrives) or starts to leave (a tenth of a millimetre, far below what the
# RoArm's servos resolve: one step of 2 pi / 4096 rad at the shoulder moves the TCP about 0.4 mm).
JAW_POSE_TOL = 1e-4
BLEND_STEP = 2  # samples between the overlaps tried, longest first
# _bridge: corner cuts (i in the first motion, k in the second) tried every BRIDGE_COARSE samples, then every
# sample around the BRIDGE_REFINE best; at most BRIDGE_TRIES candidates are checked, shortest first.
BRIDGE_COARSE, BRIDGE_REFINE, BRIDGE_TRIES = (8, 4), 2, 16


def _payload_entry(start: float, end: float, body: dict) -> dict:
    """A trajectory-file ``payloads`` entry for a held object: {link: Inertial} from ``start`` to ``end`` (s)."""
    (link, inertial), = body.items()
    r = lambda a: [round(float(v), 9) for v in a]  # noqa: E731
    return {"start": round(start, 9), "end": round(end, 9), "link": link, "mass": round(float(inertial.mass), 9),
            "com": r(inertial.com), "inertia": [r(row) for row in np.asarray(inertial.inertia)]}


def _superpose(a: TimedPath, b: TimedPath, ia: int, m: int) -> TimedPath:
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


def _bridged(ta: TimedPath, tb: TimedPath, i: int, k: int, steps: int, traj, arm: list[int]) -> TimedPath:
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
    if steps > 1:  # the bridge's inner samples (steps - 1, 3, len(arm)): position, velocity, acceleration
        inner = np.array([traj.at_time(j * dt) for j in range(1, steps)])
        q[i + 1:i + steps, arm], qd[i + 1:i + steps, arm], qdd[i + 1:i + steps, arm] = inner[:, 0], inner[:, 1], inner[:, 2]
    shift = ta.q[-1] - tb.q[0]
    q[i + steps:] = tb.q[k:] + shift
    qd[i + steps:], qdd[i + steps:] = tb.qd[k:], tb.qdd[k:]
    return TimedPath(times, q, qd, qdd, max(ta.jerk_filter, tb.jerk_filter))


def _split(tp: TimedPath, i: int) -> tuple[TimedPath, TimedPath]:
    """``tp`` cut at sample ``i``: samples 0..i and i..end (times from the cut); both keep sample ``i``."""
    t0 = tp.times[i]
    first = TimedPath(tp.times[:i + 1].copy(), tp.q[:i + 1].copy(), tp.qd[:i + 1].copy(), tp.qdd[:i + 1].copy(), tp.jerk_filter)
    second = TimedPath(tp.times[i:] - t0, tp.q[i:].copy(), tp.qd[i:].copy(), tp.qdd[i:].copy(), tp.jerk_filter)
    return first, second


def _pitch_label(pitch: float, auto: bool) -> str:
    """Segment label suffix recording an automatically chosen pitch."""
    return f" (pitch {math.degrees(pitch):.1f} deg, auto)" if auto else ""


def _grasp_width(spec: ItemSpec) -> float:
    """Width (m) of an object across the jaws: ``grasp_width``, else the shape's narrowest horizontal
    extent (box: its smaller side in x/y; cylinder, sphere: the diameter)."""
    if spec.grasp_width is not None:
        return float(spec.grasp_width)
    if spec.shape == "box":
        return float(min(spec.size[0], spec.size[1]))
    return 2.0 * float(spec.radius)


def _with(q: np.ndarray, index: int | None, value: float | None) -> np.ndarray:
    out = np.array(q, dtype=float, copy=True)
    if index is not None and value is not None:
        out[index] = value
    return out


def _dwell(q: np.ndarray, duration: float) -> TimedPath:
    n = max(int(math.ceil(duration / SAMPLE_DT - 1e-9)), 1)  # no step longer than one sample
    times = np.linspace(0.0, duration, n + 1)
    qq = np.repeat(q[None, :], len(times), axis=0)
    return TimedPath(times, qq, np.zeros_like(qq), np.zeros_like(qq))


def _concat(a: TimedPath, b: TimedPath) -> TimedPath:
    """``b`` after ``a`` (``b`` starts where ``a`` ends; its first sample is dropped)."""
    return TimedPath(np.concatenate([a.times, b.times[1:] + a.duration]), np.concatenate([a.q, b.q[1:]]),
                     np.concatenate([a.qd, b.qd[1:]]), np.concatenate([a.qdd, b.qdd[1:]]), a.jerk_filter)


def _interpolate(q: np.ndarray, substeps: int) -> np.ndarray:
    """Linear interpolation with ``substeps`` points per sample interval (for fine re-checks)."""
    if len(q) < 2:
        return q
    t = np.linspace(0, len(q) - 1, (len(q) - 1) * substeps + 1)
    i = np.minimum(t.astype(int), len(q) - 2)
    f = (t - i)[:, None]
    return q[i] * (1 - f) + q[i + 1] * f
