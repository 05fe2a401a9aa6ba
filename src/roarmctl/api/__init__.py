"""The documented Python surface of roarmctl (see docs/guide.md, "Python API").

    import roarmctl.api as rc

    robot = rc.load_robot("roarm_m3_pro")
    result = rc.plan("plans/pick_place.yaml")          # or a dict of the same form
    traj = result.trajectory
    rc.save_trajectory(traj, "pick_place.traj.json")
    q = rc.sample(traj, [0.0, 1.5])                    # (2, dof) joint positions, rad
    msg = rc.to_joint_trajectory(traj)                 # a trajectory_msgs/JointTrajectory-shaped dict
    summary = rc.execute(traj, sim=True)               # physics servos (servos="ideal"), or port="/dev/ttyUSB0"
    rc.draw(traj, "pick_place.png")                    # .png, .svg or .pdf
    rc.export(traj, "pick_place.mcap")                 # .mcap, .csv or a bag folder name

Single queries, as in mplib (``roarmctl.api.planner``, ``roarmctl.api.scene``):

    scene = rc.Scene()
    scene.add_box("wall", size=(0.04, 0.10, 0.15), xyz=(0.28, 0, 0.075))
    planner = rc.Planner(robot, scene, seed=1)
    goal = planner.ik(rc.Pose((0.25, 0.15, 0.06), pitch=math.pi / 2)).best
    path = planner.plan_to_joints(q_start, goal)       # or planner.plan_to_pose(q_start, pose)
    traj = planner.time(path)                          # a Trajectory, like plan()'s

Everything raises ``roarmctl.errors.RoarmError`` subclasses on bad input or failure (each with an
``exit_code`` and a one-line ``message``); nothing here prints or exits. Units: m, rad, s.
Heavy libraries (OMPL, FCL, TOPP-RA, matplotlib, rosbags) are imported only by the functions that
need them.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roarmctl.api.planner import IKResult, JointPath, Planner, Pose, Validity
from roarmctl.api.scene import Scene
from roarmctl.device.session import run_execution
from roarmctl.device.streamer import StreamConfig
from roarmctl.device.streamer import sample as _sample
from roarmctl.errors import (
    DescriptionError,
    DeviceError,
    InfeasibleError,
    InputError,
    Interrupted,
    OptionError,
    PlanFileError,
    PlanningError,
    RoarmError,
    StopRequested,
    TrajectoryFileError,
    UnreachableError,
)
from roarmctl.export import ExportOptions
from roarmctl.export import export as _export
from roarmctl.motion.options import Limits, PlannerConfig
from roarmctl.motion.pipeline import plan_file
from roarmctl.motion.scene import SceneItem
from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.motion.validate import robot_of, validate_trajectory
from roarmctl.physics.sim_servos import check_servos, sim_servos
from roarmctl.robot.loader import load_robot as _load
from roarmctl.viz.formats import picture_format

if TYPE_CHECKING:
    from roarmctl.motion.pipeline import PlanResult
    from roarmctl.robot.model import Robot

PathLike = str | os.PathLike[str]
TrajectoryLike = Trajectory | PathLike

__all__ = [
    "DescriptionError",
    "DeviceError",
    "Event",
    "IKResult",
    "InfeasibleError",
    "InputError",
    "Interrupted",
    "JointPath",
    "Limits",
    "OptionError",
    "PlanFileError",
    "Planner",
    "PlannerConfig",
    "PlanningError",
    "Pose",
    "RoarmError",
    "Scene",
    "SceneItem",
    "Segment",
    "StopRequested",
    "Trajectory",
    "TrajectoryFileError",
    "UnreachableError",
    "Validity",
    "draw",
    "execute",
    "export",
    "load_robot",
    "load_trajectory",
    "plan",
    "sample",
    "save_trajectory",
    "to_joint_trajectory",
]


def load_robot(spec: PathLike) -> Robot:
    """A bundled robot by name (``roarmctl robots`` lists them) or a description file (URDF sidecar
    ``.yaml`` or DH table). The ``Robot`` offers ``robot.kin.fk(q)`` (4x4 TCP pose), ``robot.kin.jacobian(q)``
    (6 x arm_dof), ``joint_names``, ``lower``/``upper`` limits (rad) and ``named_poses``. A sidecar's
    ``trust: true`` counts here: the caller named the file."""
    return _load(str(spec), trust_sidecar=True)


def plan(source: PathLike | Mapping[str, Any], *, seed: int | None = None, base_dir: PathLike | None = None,
         progress: Callable[[str, int, int], None] | None = None) -> PlanResult:
    """Plan a pick/place plan: a YAML file path, or a dict of the same form (see docs/reference.md, "The plan file").

    ``seed`` overrides ``planner.seed`` (same seed, same trajectory); ``base_dir`` resolves a dict's
    relative ``robot`` path; ``progress(stage, done, total)`` is called as tasks are planned.
    Returns a ``PlanResult``: ``.trajectory`` (a ``Trajectory``), ``.timings`` (s per stage),
    ``.warnings``, ``.segments``. Raises ``PlanFileError`` (exit 2) for a malformed plan and
    ``InfeasibleError`` (exit 3) when it cannot be done; the latter carries ``.partial``, the
    trajectory up to the failing task and its target.
    """
    if isinstance(source, Mapping):
        return plan_file(dict(source), seed=seed, progress=progress, base_dir=None if base_dir is None else Path(base_dir))
    return plan_file(Path(source), seed=seed, progress=progress)


def load_trajectory(path: PathLike) -> Trajectory:
    """Read a ``*.traj.json`` and check it against its robot (the validator ``execute`` uses): joint
    names, limits, speeds and steps. Raises ``TrajectoryFileError`` (exit 2) naming the point and joint."""
    return validate_trajectory(Path(path))


def save_trajectory(traj: Trajectory, path: PathLike) -> Path:
    """Write ``traj`` as ``*.traj.json`` atomically; returns the path."""
    return traj.save(Path(path))


def _trajectory(traj: TrajectoryLike) -> Trajectory:
    return traj if isinstance(traj, Trajectory) else load_trajectory(traj)


def sample(traj: Trajectory, t: float | Sequence[float] | np.ndarray) -> npt.NDArray[np.float64]:
    """Joint positions (rad) at time(s) ``t`` (s, clamped to [0, duration]): (dof,) for a scalar,
    (M, dof) for M times. Cubic Hermite interpolation of the samples and their velocities, the
    same interpolation the streamer uses to command the arm."""
    return _sample(traj, t)


def to_joint_trajectory(traj: Trajectory, frame_id: str = "") -> dict[str, Any]:
    """``traj`` as a dict shaped like ROS 2 ``trajectory_msgs/msg/JointTrajectory``:
    ``{"header": {"stamp": {"sec", "nanosec"}, "frame_id"}, "joint_names": [...], "points": [{"positions",
    "velocities", "accelerations", "effort": [], "time_from_start": {"sec", "nanosec"}}, ...]}``.
    Lists of floats, so ``json.dumps`` or a ROS 2 message constructor takes it as is."""
    def duration(t: float) -> dict[str, int]:
        ns = round(float(t) * 1e9)
        return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}

    return {
        "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": frame_id},
        "joint_names": list(traj.joint_names),
        "points": [
            {"positions": [float(v) for v in p], "velocities": [float(v) for v in v_],
             "accelerations": [float(v) for v in a], "effort": [], "time_from_start": duration(t)}
            for t, p, v_, a in zip(traj.times, traj.positions, traj.velocities, traj.accelerations, strict=True)
        ],
    }


def execute(traj: TrajectoryLike, *, port: str | None = None, sim: bool = False, rate: float = 50.0,
            speed_scale: float = 1.0, move_to_start: bool = False, max_error: float = 0.03,
            log: PathLike | None = None, confirm: Callable[[str], bool] | None = None,
            from_current: bool = False, servos: str = "physics", sag: bool | None = None) -> dict[str, Any]:
    """Stream ``traj`` to the arm on ``port`` or to the built-in firmware simulator (``sim=True``,
    over a real pseudo-terminal). Blocks until the motion is done (real time).

    ``rate`` commands/s (at most 90), ``speed_scale`` in (0, 1], ``max_error`` TCP tracking bound (m)
    beyond which the arm is told to hold and ``DeviceError`` (exit 4) is raised; ``confirm(message)``
    is asked before a real arm moves (default: refuse, so pass ``lambda m: True`` deliberately).
    When the arm is not at the start, ``move_to_start`` plans a checked motion there first and
    ``from_current`` plans the first free motion again from where it is (as ``roarmctl execute``);
    a start that differs only in the gripper is always opened/closed first.
    ``servos`` (with ``sim``), as ``execute --sim --servos``: ``"physics"`` (default: MuJoCo, the ST3235 model
    with its lag, gravity, torque limits and the trajectory's scene and payload; docs/physics.md) or
    ``"ideal"`` (each servo runs its trapezoid exactly: for a test that needs an arm doing exactly what it is told).
    ``sag``: goals offset by the servos' sag under gravity and payload (``roarmctl.device.sag``), as
    ``--sag/--no-sag``: None (default) compensates, except on ideal servos.
    Writes the execution log to ``log`` when given. Returns the summary: ``outcome``, ``commands``
    (T:102/T:101 lines sent while streaming), ``lateness_ms``, ``tracking_mm``, ``final_error_mm``, ``log``;
    with ``sim``, ``simulator``: the simulated servos' true tracking.
    """
    check_servos(servos, sim=sim)
    t = _trajectory(traj)
    robot = robot_of(t)
    factory, sagged = sim_servos(robot, t, servos, sim=sim, sag=sag)
    cfg = StreamConfig(rate=rate, speed_scale=speed_scale, max_error=max_error, move_to_start=move_to_start,
                       from_current=from_current, sag=sagged)
    if sim:
        confirm = confirm or (lambda message: True)
    run = run_execution(t, robot, cfg, port=None if port is None else str(port), sim=sim, log_path=None if log is None else Path(log),
                        confirm=confirm or (lambda message: False), sim_servos=factory)
    summary = run.result.summary() | {"log": None if log is None else str(log), "port": run.port}
    if run.simulator is not None:
        summary["simulator"] = run.simulator
    return summary


def draw(traj: TrajectoryLike, output: PathLike, *, view: str = "iso", dpi: float = 100.0,
         size: tuple[float, float] = (16.0, 10.0)) -> Path:
    """Draw ``traj`` like ``roarmctl visualize-path``: the scene and TCP path, joint curves with
    limits, TCP speed and distance from singularity. The format follows ``output``'s extension
    (.png, .svg, .pdf; anything else raises ``InputError``). ``view``: iso, top, front or side;
    ``size`` in inches. Returns the path written."""
    from roarmctl.viz.path_figure import VIEWS, visualize_trajectory

    output = Path(output)
    picture_format(output)
    if view not in VIEWS:
        raise InputError(f"view: '{view}' is not one of {', '.join(VIEWS)}")
    t = _trajectory(traj)
    return visualize_trajectory(t, output, view=view, dpi=dpi, size=size, name=output.stem)


def export(source: TrajectoryLike, output: PathLike, *, trajectory: TrajectoryLike | None = None,
           force: bool = False) -> dict[str, Any]:
    """Export a trajectory (or a trajectory / execution-log file) like ``roarmctl export``: ``.mcap``
    (ROS 2 messages for Foxglove), ``.csv``, or a name without extension (a ROS 2 bag folder).
    Returns ``{"output", "format", "topics": {topic: count}, "time_offset_s"}`` (s added to every time of the
    source in the bag) (CSV: ``"rows"``; its times are the source's). For an execution
    log, ``trajectory`` (the one it ran) adds its planned joint states and the scene. ``force`` replaces a bag
    folder roarmctl did not write (``ExportOptions``, as the CLI's ``--force``)."""
    return _export(source, output, trajectory=trajectory, options=ExportOptions(force=force))
