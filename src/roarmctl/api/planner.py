"""``Planner``: single planning queries on one robot in one ``Scene``, as direct as mplib's.

    robot = load_robot("roarm_m3_pro")
    planner = Planner(robot, scene, seed=1)
    ik = planner.ik(Pose((0.25, -0.15, 0.06), pitch=math.pi / 2))      # IKResult: valid solutions, best first
    planner.is_valid(q)                                                  # Validity: truthy, with the reason
    path = planner.plan_to_joints(q_from, q_to)                          # JointPath: waypoints (K, dof)
    path = planner.plan_to_pose(q_from, Pose((0.25, 0.15, 0.06), pitch=math.pi / 2))
    traj = planner.time(path)                                            # Trajectory: save, draw, export, execute

Every query uses the library's own parts, as ``roarmctl plan`` does: the IK of ``roarmctl.robot.ik``, the
collision checker (FCL) with the planner's padding and singularity margin, OMPL for the path (the same
tries and shortcutting as a plan's free motion) and TOPP-RA for the timing, whose samples are checked
again. Joint vectors are the robot's ``joint_names`` (gripper last; the arm joints alone also do, the
gripper then closed), rad or m. Failures raise ``UnreachableError`` (no IK solution), ``PlanningError``
(no valid path, start or goal invalid, timing failed) or ``InputError``; nothing prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TypeVar

import numpy as np
import numpy.typing as npt

from roarmctl.api.scene import Scene
from roarmctl.errors import REJECTED_AS, InputError, PlanningError, UnreachableError, rejection
from roarmctl.motion.options import Limits, PlannerConfig
from roarmctl.motion.planning import motions
from roarmctl.motion.planning.assembly import assemble
from roarmctl.motion.planning.context import PlanContext
from roarmctl.motion.planning.pieces import TaskStep, UntimedMotion
from roarmctl.motion.rejection import RejectionKind, Validity, judge
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import load_robot
from roarmctl.robot.model import Robot, rpy_from_matrix

_O = TypeVar("_O", Limits, PlannerConfig)

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory


@dataclass(frozen=True)
class Pose:
    """A TCP target: ``xyz`` (m, the robot's root frame) and, optionally, its orientation as a plan writes it:
    ``pitch`` (rad, the approach axis TCP +x below the horizontal: pi/2 straight down) with ``roll`` (rad), or
    the full ``rpy`` (URDF roll-pitch-yaw, rad). Neither: the position only."""

    xyz: tuple[float, float, float]
    pitch: float | None = None
    roll: float | None = None
    rpy: tuple[float, float, float] | None = None

    def __post_init__(self) -> None:
        xyz = tuple(float(v) for v in self.xyz)
        if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
            raise InputError(f"Pose.xyz: expected 3 finite numbers (m), got {self.xyz!r}")
        object.__setattr__(self, "xyz", xyz)
        if self.rpy is not None:
            rpy = tuple(float(v) for v in self.rpy)
            if len(rpy) != 3 or not all(math.isfinite(v) for v in rpy):
                raise InputError(f"Pose.rpy: expected 3 finite numbers (rad), got {self.rpy!r}")
            if self.pitch is not None or self.roll is not None:
                raise InputError("Pose: give rpy or pitch/roll, not both")
            object.__setattr__(self, "rpy", rpy)
        for key in ("pitch", "roll"):
            v = getattr(self, key)
            if v is not None and not math.isfinite(float(v)):
                raise InputError(f"Pose.{key}: expected a finite number (rad), got {v!r}")

    @classmethod
    def from_matrix(cls, t: npt.ArrayLike) -> Pose:
        """The pose of a 4x4 homogeneous transform (m, root frame): position and full orientation."""
        t = np.asarray(t, dtype=float)
        if t.shape != (4, 4):
            raise InputError(f"Pose.from_matrix: expected a 4x4 transform, got shape {t.shape}")
        return cls(tuple(t[:3, 3]), rpy=tuple(rpy_from_matrix(t[:3, :3])))




@dataclass(frozen=True)
class IKResult:
    """What ``Planner.ik`` found: ``solutions`` (each (dof,), rad/m) that are within the joint limits,
    collision-free in the scene and clear of the singularity margin, nearest to the reference first;
    ``rejected``: why each other solution of the IK was not valid, and ``kinds`` the cause of each, in the same
    order ("joint_limit", "collision" or "singularity", as ``Validity.kind``)."""

    solutions: tuple[npt.NDArray[np.float64], ...]
    rejected: tuple[str, ...] = ()
    kinds: tuple[RejectionKind, ...] = ()

    @property
    def ok(self) -> bool:
        """True when there is at least one valid solution."""
        return bool(self.solutions)

    @property
    def best(self) -> npt.NDArray[np.float64]:
        """The first valid solution (dof,) rad/m (raises ``UnreachableError`` when there is none)."""
        if not self.solutions:
            raise self.unreachable("IK: no valid solution")
        return self.solutions[0]

    def unreachable(self, what: str) -> UnreachableError:
        """The error for no valid solution, its message starting with ``what``: ``reason`` the cause that rejected
        every solution ('collision', 'joint_limit', 'singularity'; 'mixed' when they differ), and the message
        how many each cause rejected, with what it said (the item in the way)."""
        hint = "move the target or change the orientation asked for"
        if not self.rejected:
            return UnreachableError(what, "out_of_reach", hint)
        kinds = self.kinds or ("collision",) * len(self.rejected)  # an IKResult made without kinds
        detail = {}
        for kind in dict.fromkeys(kinds):
            said = list(dict.fromkeys(r for r, k in zip(self.rejected, kinds) if k == kind))
            shown = 3 if kind == "collision" else 1  # what each collision hits; the others differ only in numbers
            more = f"; {len(said) - shown} more" if kind == "collision" and len(said) > shown else ""
            detail[kind] = f"({'; '.join(said[:shown])}{more})"
        reason, counted = rejection(kinds, detail)
        n = len(kinds)
        if len(detail) == 1:
            why = (f"{'its one IK solution is' if n == 1 else f'all {n} IK solutions are'} "
                   f"{REJECTED_AS.get(kinds[0], kinds[0])} {detail[kinds[0]]}")
        else:
            why = f"its {n} IK solutions are rejected: {counted}"
        return UnreachableError(f"{what}: {why}", reason, hint)


@dataclass(frozen=True)
class JointPath:
    """An untimed collision-free joint path: ``waypoints`` (K, dof) rad/m, from the start to the goal, every
    straight joint-space step between them checked (at 0.01 rad resolution); ``checks`` the state checks it
    took. ``Planner.time`` times it."""

    waypoints: npt.NDArray[np.float64]
    checks: int = 0
    length: float = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "length", float(np.sum(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1))))


def _options(cls: type[_O], given: _O | None, what: str, **values: object) -> _O:
    """``given`` when the caller passed the options object whole, else one made of the keyword values given
    (the rest its defaults); both at once is ambiguous."""
    values = {k: v for k, v in values.items() if v is not None}
    if given is None:
        return cls(**values)  # type: ignore[arg-type]  # each field checks its own type and bounds
    if values:
        raise InputError(f"Planner: {', '.join(values)} given beside {what}=",
                         f"set them in the {cls.__name__} you pass, or leave {what}= out")
    if not isinstance(given, cls):
        raise InputError(f"Planner: {what}: expected a {cls.__name__}, got {type(given).__name__}")
    return given


class Planner:
    """Single queries for ``robot`` (a ``Robot``, a bundled name or a description path) among ``scene``'s items.

    ``padding`` (m, 0 to 0.1) inflates the arm against the scene; ``singularity_margin`` (m/rad, 0 to 1; 0: none) is the
    smallest singular value of the TCP's translational Jacobian a valid state keeps; ``velocity_scale`` and
    ``acceleration_scale`` (0.01 to 1) scale the robot's joint limits for ``time``; ``max_tcp_speed`` (m/s, 0.001 to 5)
    caps the TCP; ``planner`` names the OMPL planner, ``seed`` makes every answer repeatable (same calls, same results)
    and ``max_checks`` is the work budget of one path search. These build the two options objects a plan file's
    ``limits`` and ``planner`` become (``roarmctl.motion.options``: ``Limits``, ``PlannerConfig``, with the bounds);
    pass ``limits=`` / ``config=`` to give them whole instead (then not their keyword arguments). A value out of its
    bounds raises ``OptionError`` naming the field. The scene may change between queries (add, remove, attach,
    detach): the next query uses it as it is then.
    """

    def __init__(self, robot: Robot | str, scene: Scene | None = None, *, padding: float | None = None,
                 singularity_margin: float | None = None, velocity_scale: float | None = None,
                 acceleration_scale: float | None = None, max_tcp_speed: float | None = None, planner: str | None = None,
                 seed: int | None = None, max_checks: int | None = None, limits: Limits | None = None,
                 config: PlannerConfig | None = None) -> None:
        self._limits = _options(Limits, limits, "limits", velocity_scale=velocity_scale,
                                acceleration_scale=acceleration_scale, max_tcp_speed=max_tcp_speed)
        self._config = _options(PlannerConfig, config, "config", padding=padding, singularity_margin=singularity_margin,
                                name=planner, seed=seed, max_checks=max_checks)
        if not isinstance(robot, Robot):
            robot = load_robot(str(robot))
        self.robot = robot
        self.scene = scene if scene is not None else Scene()
        if self.scene.robot is None:
            self.scene.robot = robot
        elif self.scene.robot is not robot:
            raise InputError("Planner: the scene belongs to another robot's planner", "give each robot its own Scene")
        self._ctx: PlanContext | None = None
        self._version = -1

    # ------------------------------------------------------------------ the shared state
    def _context(self) -> PlanContext:
        """The planning context (checker, limits) for the scene as it is now; rebuilt when the scene changed."""
        if self._ctx is not None and self._version == self.scene.version:
            return self._ctx
        from roarmctl.motion.collision import CollisionChecker

        r = self.robot
        rest = np.clip(np.zeros(r.dof), r.lower, r.upper)
        world = self.scene.world(rest)  # carried items where the TCP holds them at ``rest``
        checker = CollisionChecker(r, world, padding=self._config.padding,
                                   singularity_margin=self._config.singularity_margin or None)
        for name in self.scene.carried:
            checker.attach(name, rest[r.arm_indices])
        free_count = self._ctx.free_count if self._ctx is not None else 0
        self._ctx = PlanContext(r, checker, self._limits, self._config)
        self._ctx.free_count = free_count  # the OMPL seeds go on where they were: same calls, same answers
        self._version = self.scene.version
        return self._ctx

    def _full(self, q: npt.ArrayLike, what: str) -> np.ndarray:
        try:
            return self.robot.full_q(np.asarray(q, dtype=float)).copy()
        except InputError as exc:
            raise InputError(f"{what}: {exc.message}", exc.hint) from None

    # ------------------------------------------------------------------ queries
    def is_valid(self, q: npt.ArrayLike, *, touching: str | None = None) -> Validity:
        """Whether configuration ``q`` (dof or arm joints, rad/m) is within the joint limits, free of collisions
        with itself and the scene (carried items included) and clear of the singularity margin. ``touching``:
        an object of the scene the jaws may touch (the one being grasped)."""
        r = self.robot
        full = self._full(q, "is_valid: q")
        bad = np.flatnonzero((full < r.lower - 1e-9) | (full > r.upper + 1e-9))
        if len(bad):
            i = int(bad[0])
            return Validity(False, f"{r.joint_names[i]} = {full[i]:.4g} {r.joint_unit(i)} is outside its limits "
                                   f"[{r.lower[i]:.4g}, {r.upper[i]:.4g}]", "joint_limit")
        ctx = self._context()
        if touching is not None:
            self.scene[touching]  # noqa: B018 - names the items when it is not one
        ctx.set_state(full[ctx.gi] if ctx.gi is not None else None, grasp_target=touching)
        return judge(ctx.checker, full[ctx.arm])  # in limits: checked above (the gripper too, which the checker leaves)

    def ik(self, pose: Pose, q_ref: npt.ArrayLike | None = None, *, touching: str | None = None) -> IKResult:
        """Every IK solution for ``pose`` that ``is_valid`` (with ``touching``), nearest to ``q_ref`` (dof or arm
        joints, rad/m; its gripper value is kept) first. Raises ``UnreachableError`` when the pose has no solution
        at all (out of reach, only outside the limits, orientation not reachable)."""
        if not isinstance(pose, Pose):
            raise InputError(f"ik: expected a Pose, got {type(pose).__name__}", "e.g. Pose((0.25, 0, 0.1), pitch=math.pi / 2)")
        ref = None if q_ref is None else self._full(q_ref, "ik: q_ref")
        sols = solve_ik(self.robot, pose.xyz, pitch=pose.pitch, roll=pose.roll, rpy=pose.rpy, q_ref=ref, all_solutions=True)
        good: list[npt.NDArray[np.float64]] = []
        rejected: list[Validity] = []
        for q in sols:
            v = self.is_valid(q, touching=touching)
            if v:
                good.append(np.asarray(q, dtype=float))
            else:
                rejected.append(v)
        return IKResult(tuple(good), tuple(v.reason for v in rejected), tuple(v.kind for v in rejected))

    def plan_to_joints(self, q_from: npt.ArrayLike, q_to: npt.ArrayLike, *, touching: str | None = None) -> JointPath:
        """A collision-free joint path from ``q_from`` to ``q_to`` (dof or arm joints, rad/m): the straight joint
        move when it is valid, else OMPL's (the shortest of a few tries, shortcut). The gripper stays at
        ``q_from``'s value; ``touching`` as for ``is_valid``. Raises ``PlanningError`` when either end is
        invalid or no path is found."""
        qf, qt = self._full(q_from, "plan_to_joints: q_from"), self._full(q_to, "plan_to_joints: q_to")
        ctx = self._context()
        if ctx.gi is not None:
            qt[ctx.gi] = qf[ctx.gi]
        for what, q in (("start", qf), ("goal", qt)):
            v = self.is_valid(q, touching=touching)
            if not v:
                raise PlanningError(f"plan_to_joints: the {what} configuration is invalid: {v.reason}",
                                    "choose another configuration or change the scene")
        ctx.set_state(qf[ctx.gi] if ctx.gi is not None else None, grasp_target=touching)
        before = int(getattr(ctx.checker, "check_count", 0))
        wps = motions.free_path(ctx, TaskStep("free", "plan_to_joints", q_to=qt, grasp_target=touching), qf)
        return JointPath(wps, int(getattr(ctx.checker, "check_count", 0)) - before)

    def plan_to_pose(self, q_from: npt.ArrayLike, pose: Pose, *, touching: str | None = None) -> JointPath:
        """A collision-free joint path from ``q_from`` (dof or arm joints, rad/m) to a configuration that puts the
        TCP at ``pose``: the IK's valid solutions are tried nearest first. Raises ``UnreachableError`` when no valid
        solution exists and ``PlanningError`` when no solution can be reached."""
        qf = self._full(q_from, "plan_to_pose: q_from")
        found = self.ik(pose, q_ref=qf, touching=touching)
        if not found.ok:
            raise found.unreachable(f"plan_to_pose: no valid IK solution for {pose.xyz} m")
        last: PlanningError | None = None
        for q in found.solutions:
            try:
                return self.plan_to_joints(qf, q, touching=touching)
            except PlanningError as exc:
                last = exc
        assert last is not None
        raise last

    def time(self, path: JointPath) -> Trajectory:
        """``path`` timed from rest to rest by TOPP-RA under the scaled joint limits (jerk, torque and TCP speed
        limits included), sampled at 100 Hz and every sample checked again: a ``Trajectory`` (``save``,
        ``roarmctl.api.draw``/``export``/``execute`` take it). Raises ``PlanningError`` when it cannot be timed."""

        if not isinstance(path, JointPath):
            raise InputError(f"time: expected a JointPath, got {type(path).__name__}")
        wps = np.asarray(path.waypoints, dtype=float)
        if wps.ndim != 2 or wps.shape[1] != self.robot.dof or len(wps) < 2:
            raise InputError(f"time: the path's waypoints must be (K >= 2, {self.robot.dof}), got {wps.shape}")
        ctx = self._context()
        piece = motions.time_motion(ctx, UntimedMotion(TaskStep("free", "timed path", q_to=wps[-1]), wps))
        traj = assemble(ctx, [piece])
        traj.scene = self.scene.world(wps[0]).to_dict()
        traj.plan = None
        return traj
