"""What every stage of planning one plan shares: ``PlanContext``."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np

from roarmctl.errors import InputError, PlanFileError
from roarmctl.fileio import Roots
from roarmctl.kept import Kept
from roarmctl.motion.planning.pieces import UntimedMotion
from roarmctl.motion.scene import SceneItem
from roarmctl.motion.scenefiles import read_cloud_item, read_mesh_item
from roarmctl.plan.fields import DICT_NAME
from roarmctl.robot.ik import takes_pitch
from roarmctl.robot.loader import bundled_robots
from roarmctl.robot.meshes import PACKAGE_PATHS

if TYPE_CHECKING:
    from roarmctl.formats import Role, Shape
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.options import Limits, PlannerConfig
    from roarmctl.motion.planning.targets import Target
    from roarmctl.motion.scene import Scene, SceneItem
    from roarmctl.motion.timing import TimedPath
    from roarmctl.plan.schema import PlanDocument
    from roarmctl.plan.types import ItemSpec, Plan
    from roarmctl.robot.model import Robot


class StageTimer:
    """Wall time (s) spent per planning stage: ik, ompl, simplify, toppra, recheck, blend."""

    def __init__(self) -> None:
        self.t: dict[str, float] = dict.fromkeys(("ik", "ompl", "simplify", "toppra", "recheck", "blend"), 0.0)

    def add(self, key: str, since: float) -> None:
        """Add the time since ``since`` (a ``time.perf_counter()`` value) to stage ``key``."""
        self.t[key] = self.t.get(key, 0.0) + time.perf_counter() - since


API_SOURCE = "<api>"  # what a trajectory of ``roarmctl.api.Planner`` records as its plan's path


class PlanContext:
    """One plan being planned for one robot: the plan, the robot, its collision checker, the limits and planner
    options (``roarmctl.motion.options``: the plan's, or the api Planner's) and the joint limits they scale,
    the world as it is at this point of the plan (object poses, the held object, its payload), and what the
    user is told (``warnings``, ``notes``) with the stage ``timer``.

    Joint limits: ``vmax``/``amax`` (dof,) rad/s, rad/s^2 scaled by the plan; ``jmax`` (dof,) rad/s^3 and
    ``effort`` (dof,) N m as the robot has them (None: none). ``arm`` indexes the arm joints, ``gi`` the
    gripper joint (None without a gripper).
    """

    def __init__(self, robot: Robot, checker: CollisionChecker, limits: Limits, config: PlannerConfig, *,
                 plan: Plan | None = None, initial_scene: Scene | None = None) -> None:
        self.robot, self.checker, self.limits, self.config = robot, checker, limits, config
        self.plan = plan  # the plan file being planned; None for the single queries of ``roarmctl.api.Planner``
        self.objects: list[ItemSpec] = list(plan.objects) if plan is not None else []
        self.where = str(plan.path) if plan is not None else API_SOURCE  # names the source in messages
        # the plan's scene before anything moved (the trajectory records it): ``initial_scene`` when the caller hands
        # over one that nothing else moves (the scene the checker was made from: it keeps its own copy)
        self.initial_scene = checker.scene.copy() if initial_scene is None else initial_scene
        self.timer = StageTimer()
        self.warnings: list[str] = []
        self.notes: list[str] = []
        self.pitch_free = takes_pitch(robot)  # the IK takes a tool pitch (pitch: auto chooses it)
        self.noted_position_only = False  # "no pitch given" note (generic arms): once per plan
        self.arm = robot.arm_indices
        self.gi = robot.joint_index(robot.gripper.joint) if robot.gripper else None
        self.object_pose = {o.name: o.pose.copy() for o in self.objects}
        self.held: str | None = None
        self.held_offset = np.zeros(3)  # TCP position minus object centre at grasp (world frame)
        self.pending_pick: tuple[str, np.ndarray] | None = None  # set by a pick, taken by its grasp
        self.held_local: np.ndarray | None = None  # object centre in the TCP frame while held against a fixed jaw
        self.vmax = robot.velocity_limits * limits.velocity_scale
        self.amax = robot.acceleration_limits * limits.acceleration_scale
        self.jmax = robot.jerk_limits  # not scaled: the scales slow the motion, the jerk bound keeps it smooth
        self.effort = robot.effort_limits
        self.payload: dict | None = None  # link -> Inertial of the held object, from grasp to release
        self.payload_label = ""
        self.free_count = 0  # free motions planned so far (each gets its own OMPL seed)
        self.timed: Kept[TimedPath] = Kept(256)  # what motions.time_path timed, by its waypoints and payload
        self.chains: Kept[tuple] = Kept(64)  # what blending.time_chain timed, by its motions and world (chain_key)
        self.iks: Kept[list[np.ndarray]] = Kept(256)  # what tasks.choose_ik found, by its targets, q and world
        self.lines: Kept[np.ndarray] = Kept(256)  # what motions.geometry solved along straight lines, by q and the end
        self.targets: list[Target] = []  # every target the plan names, in order (``planning.targets``)
        self.jaw_targets: Kept[tuple] = Kept(256)  # what tasks.against_fixed_jaw found, by its task, poses and world

    def set_state(self, gripper: float | None, grasp_target: str | None = None) -> None:
        """Put the checker in a motion's collision state: the gripper at ``gripper`` (rad; None: as it is) and
        the object the jaws may touch (none for the held object)."""
        if gripper is not None:
            self.checker.set_gripper(float(gripper))
        # A held object is attached to the hand (the checker ignores its contact with the jaws);
        # a grasp target is an object in the scene that the jaws may touch.
        self.checker.set_grasp_target(grasp_target if grasp_target != self.held else None)

    def first_invalid(self, qf: np.ndarray) -> int | None:
        """First invalid configuration of ``qf`` (M, dof), the gripper as given per sample (grasp target as set).

        One checker call with a gripper value per row (not one call per run of equal gripper values: while
        the jaws move, that was one call per sample); the checker's own gripper value is left as it was."""
        if self.gi is None:
            return self.checker.first_invalid(qf[:, self.arm])
        return self.checker.first_invalid(qf[:, self.arm], gripper=qf[:, self.gi])

    def target_of(self, motion: UntimedMotion) -> str | None:
        """The grasp target the checker gets for ``motion`` (``set_state``: none for the held object)."""
        return motion.step.grasp_target if motion.step.grasp_target != self.held else None

    def set_state_of(self, motion: UntimedMotion) -> None:
        """The collision state of ``motion``: its gripper value at the start, its grasp target."""
        self.set_state(motion.wps[0][self.gi] if self.gi is not None else None, grasp_target=motion.step.grasp_target)


_BUNDLED: frozenset[str] | None = None


def robot_spec(plan: Plan | PlanDocument) -> str:
    """The plan's ``robot``: a bundled name as is; any other name is a path relative to the plan file's
    directory, which it may not leave (a plan reads only beside itself and in ``--package-path`` folders;
    a plan given as a dict is the caller's own and takes any path)."""
    global _BUNDLED
    if _BUNDLED is None:
        _BUNDLED = frozenset(bundled_robots())  # the package's own files: listed once per process
    if plan.robot in _BUNDLED:
        return plan.robot
    if plan.path.name == DICT_NAME:
        candidate = plan.path.parent / Path(plan.robot).expanduser()
    else:
        candidate = plan.path.parent / Path(plan.robot)
        Roots([plan.path.parent], PACKAGE_PATHS).check(
            candidate, f"'{plan.robot[:80]}'", InputError,
            "a plan names a description beside it (or under a package_path folder): copy or link the folder there")
    try:
        return str(candidate) if candidate.is_file() else plan.robot
    except (OSError, ValueError):  # a name the OS refuses as a path (too long)
        return plan.robot


def _file_of(spec: ItemSpec) -> Path:
    """The file of a mesh or cloud item that carries no data (the schema asks for one then)."""
    assert spec.file is not None
    return spec.file


def scene_item(spec: ItemSpec) -> SceneItem:
    """The scene item of a plan's table, obstacle or object (at its start pose): a primitive as written; a mesh
    or point cloud from the data it carries (a trajectory's scene) or else read from its file
    (``roarmctl.motion.scenefiles``; errors are ``PlanFileError`` naming the plan's line)."""
    # the plan's schema checked role and shape against the scene's
    role, pose = cast("Role", spec.role), spec.pose  # SceneItem keeps a copy of it
    if spec.shape == "mesh":
        mesh = spec.data or read_mesh_item(_file_of(spec), spec.scale, spec.exact, f"{spec.where}.file", PlanFileError)
        return SceneItem(name=spec.name, role=role, shape="mesh", pose=pose, mesh=mesh)
    if spec.shape == "cloud":
        cloud = spec.data or read_cloud_item(_file_of(spec), spec.resolution, f"{spec.where}.file", PlanFileError)
        return SceneItem(name=spec.name, role=role, shape="cloud", pose=pose, cloud=cloud)
    return SceneItem.checked_primitive(spec.name, role, cast("Shape", spec.shape), pose,
                                       spec.size, spec.radius, spec.length)
