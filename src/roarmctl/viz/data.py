"""The numbers behind the pictures, computed apart from the drawing so they can be tested.

``path_data(traj, robot)`` turns a trajectory into everything ``visualize-path`` plots (TCP path,
speeds, limit lines, event times, manipulability, the arm at key moments);
``workspace_data(robot, ...)`` samples the reachable workspace for ``workspace``.
Only numpy here: no matplotlib.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.errors import OptionError, TrajectoryFileError
from roarmctl.motion.report import joint_torques
from roarmctl.motion.trajectory import GRASP_RADIUS, carried_item  # noqa: F401  (GRASP_RADIUS re-exported)

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

EVENT_KINDS_SHOWN = ("grasp", "release")


@dataclass
class KeyPose:
    """The arm at one moment: ``links`` (n_links, 3) link origins in m, ``label`` e.g. 'start'."""

    time: float
    label: str
    kind: str  # "start" | "grasp" | "release" | "end"
    index: int
    links: np.ndarray


@dataclass
class EventMark:
    """A grasp/release event: ``time`` s, ``target`` (3,) m (the event's TCP target, else FK there)."""

    time: float
    kind: str
    label: str
    target: np.ndarray
    target_given: bool


@dataclass
class PathData:
    """Everything ``visualize-path`` draws, in SI units.

    Shapes: N samples, dof actuated joints (gripper last), arm_dof TCP-chain joints.
    ``tcp`` (N, 3) m; ``tcp_speed`` (N,) m/s (|J_v(q) qdot|, exact for the sampled state);
    ``positions``/``velocities``/``accelerations`` (N, dof); ``velocity_limit``/``acceleration_limit``
    (dof,) already multiplied by their scale; ``sigma_min`` (N,) m/rad, the smallest singular value of
    the 3 x arm_dof translational Jacobian; ``w`` (N,) the product of its singular values (Yoshikawa).
    ``segment_kind`` (N-1,) the kind of the segment each path piece [i, i+1] lies in ('' if none).
    """

    robot_name: str
    joint_names: list[str]
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    tcp: np.ndarray
    tcp_speed: np.ndarray
    sigma_min: np.ndarray
    w: np.ndarray
    velocity_limit: np.ndarray
    acceleration_limit: np.ndarray
    velocity_scale: float
    acceleration_scale: float
    limits_source: str  # "trajectory" or "robot" (the file carried none)
    max_tcp_speed: float | None
    min_singular_value: float | None
    segment_kind: np.ndarray
    torque: np.ndarray | None = None  # (N, dof) N m by RNEA, held objects included; None without inertial data
    torque_limit: np.ndarray | None = None  # (dof,) N m, inf where none
    blends: list[float] = field(default_factory=list)  # s: blended joins
    targets: list[dict] = field(default_factory=list)  # the trajectory's per-target table (Trajectory.targets)
    events: list[EventMark] = field(default_factory=list)
    key_poses: list[KeyPose] = field(default_factory=list)
    arm_segments: list[tuple[int, int]] = field(default_factory=list)
    scene_items: list[dict] = field(default_factory=list)
    placed_items: list[dict] = field(default_factory=list)
    #: (dof,) bool: prismatic joints (m, m/s, m/s^2, N), drawn on their own axes; None: all revolute
    prismatic: np.ndarray | None = None


def placed_objects(items: list[dict], events: list[EventMark]) -> list[dict]:
    """Copies of the carried objects moved to their release targets (same offset to the TCP target).

    Pairs each release with the preceding grasp; the carried object is the scene object whose centre is
    nearest the grasp target (within ``GRASP_RADIUS``). Returns scene-item dicts with the new ``xyz``.
    """
    out, carried = [], None
    for e in events:
        if e.kind == "grasp":
            item = carried_item(items, e.target)
            carried = None if item is None else (item, np.asarray(item["xyz"], dtype=float) - e.target)
        elif e.kind == "release" and carried is not None:
            item, offset = carried
            out.append(dict(item, xyz=(e.target + offset).tolist(), name=f"{item.get('name', 'object')} (placed)"))
            carried = None
    return out


def robot_for(traj: Trajectory) -> Robot:
    """Load the trajectory's robot; a missing robot or mismatched joints is an input error (exit 2)."""
    from roarmctl.motion.validate import robot_of

    robot = robot_of(traj)
    if list(traj.joint_names) != list(robot.joint_names):
        raise TrajectoryFileError(
            f"joint_names {traj.joint_names} do not match robot '{traj.robot}' ({robot.joint_names})",
            "the file was planned for a different description; plan it again",
        )
    return robot


def arm_segments(robot: Robot) -> list[tuple[int, int]]:
    """Pairs of link indices (parent origin, child origin) to draw as the arm's links, zero-length ones dropped.

    Uses the zero configuration to drop segments whose ends coincide by construction.
    """
    kin = robot.kin
    frames = kin.link_frames(np.zeros(robot.dof))
    pairs = []
    for j in range(len(robot.joints)):
        a, b = kin._parent[j], kin._child[j]
        if np.linalg.norm(frames[a, :3, 3] - frames[b, :3, 3]) > 1e-6:
            pairs.append((a, b))
    return pairs


def _limit_vector(value: Any, default: np.ndarray, name: str) -> np.ndarray:
    if value is None:
        return default
    arr = np.asarray(value, dtype=float)
    if arr.shape != default.shape or not np.all(np.isfinite(arr)):
        raise TrajectoryFileError(f"limits.{name}: expected {default.shape[0]} finite numbers, got {value!r}")
    return arr


def _scale(value: Any, name: str) -> float:
    if value is None:
        return 1.0
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise TrajectoryFileError(f"limits.{name}: expected a number, got {value!r}") from None
    if not np.isfinite(s) or s <= 0:
        raise TrajectoryFileError(f"limits.{name}: must be a positive number, got {value!r}")
    return s


def singular_values(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Singular values (N, min(3, arm_dof)) of the translational Jacobian at configurations ``q`` (N, dof)."""
    jac = robot.kin.jacobian(np.atleast_2d(q))[:, :3, :]
    return np.linalg.svd(jac, compute_uv=False)


def path_data(traj: Trajectory, robot: Robot) -> PathData:
    """Compute the plotted data of ``traj`` on ``robot`` (see ``PathData``)."""
    q = np.asarray(traj.positions, dtype=float)
    qd = np.asarray(traj.velocities, dtype=float)
    times = np.asarray(traj.times, dtype=float)
    frames = robot.kin.link_frames(q)  # (N, n_links, 4, 4)
    origins = frames[:, :, :3, 3]
    tcp = origins[:, robot.kin.tcp_index].copy()
    jac = robot.kin.jacobian(q)  # (N, 6, arm_dof)
    jv = jac[:, :3, :]
    tcp_speed = np.linalg.norm(robot.kin.tcp_velocity(q, qd[:, robot.arm_indices]), axis=1)
    sv = np.linalg.svd(jv, compute_uv=False)
    sigma_min = sv[:, -1].copy()
    w = np.prod(sv, axis=1)

    lim = traj.limits or {}
    given = any(lim.get(k) is not None for k in ("velocity", "acceleration"))
    vs = _scale(lim.get("velocity_scale"), "velocity_scale")
    as_ = _scale(lim.get("acceleration_scale"), "acceleration_scale")
    vel = _limit_vector(lim.get("velocity"), np.asarray(robot.velocity_limits, dtype=float), "velocity")
    acc = _limit_vector(lim.get("acceleration"), np.asarray(robot.acceleration_limits, dtype=float), "acceleration")
    mts = lim.get("max_tcp_speed")
    max_tcp_speed = None if mts is None else _scale(mts, "max_tcp_speed")
    margin = traj.singularity_margin or None
    msv = None
    if margin is not None:
        if not isinstance(margin, dict) or "min_singular_value" not in margin:
            raise TrajectoryFileError(f"singularity_margin: expected {{'min_singular_value': m/rad}}, got {margin!r}")
        msv = _scale(margin["min_singular_value"], "singularity_margin.min_singular_value")

    seg_kind = np.full(max(len(times) - 1, 0), "", dtype=object)
    mids = 0.5 * (times[1:] + times[:-1])
    for s in traj.segments:
        seg_kind[(mids >= s.start) & (mids <= s.end)] = s.kind

    def index_at(t: float) -> int:
        return int(np.clip(np.searchsorted(times, t - 1e-9), 0, len(times) - 1))

    events = []
    for e in traj.events:
        if e.kind not in EVENT_KINDS_SHOWN:
            continue
        i = index_at(e.time)
        if e.position is not None:
            try:
                target = np.asarray(e.position, dtype=float).reshape(3)
            except ValueError:
                raise TrajectoryFileError(f"events: '{e.label or e.kind}' position: expected [x, y, z]") from None
            events.append(EventMark(e.time, e.kind, e.label, target, True))
        else:
            events.append(EventMark(e.time, e.kind, e.label, tcp[i].copy(), False))

    key = [(0, "start", "start")]
    key += [(index_at(e.time), e.label or e.kind, e.kind) for e in events]
    key.append((len(times) - 1, "end", "end"))
    key_poses = [KeyPose(float(times[i]), label, kind, i, origins[i].copy()) for i, label, kind in key]

    torque = joint_torques(traj, robot)
    items = (traj.scene or {}).get("items", []) if isinstance(traj.scene, dict) else []
    if not isinstance(items, list):
        raise TrajectoryFileError("scene.items: expected a list")

    return PathData(
        prismatic=robot.prismatic if robot.prismatic.any() else None,
        robot_name=robot.name,
        joint_names=list(traj.joint_names),
        times=times,
        positions=q,
        velocities=qd,
        accelerations=np.asarray(traj.accelerations, dtype=float),
        tcp=tcp,
        tcp_speed=tcp_speed,
        sigma_min=sigma_min,
        w=w,
        velocity_limit=vel * vs,
        acceleration_limit=acc * as_,
        velocity_scale=vs,
        acceleration_scale=as_,
        limits_source="trajectory" if given else "robot",
        max_tcp_speed=max_tcp_speed,
        min_singular_value=msv,
        segment_kind=seg_kind,
        torque=torque,
        torque_limit=None if robot.effort_limits is None else np.asarray(robot.effort_limits, dtype=float),
        blends=[float(b) for b in traj.blends],
        targets=[dict(t) for t in traj.targets],
        events=events,
        key_poses=key_poses,
        arm_segments=arm_segments(robot),
        scene_items=items,
        placed_items=placed_objects(items, events),
    )


# ------------------------------------------------------------------------- workspace
@dataclass
class WorkspaceData:
    """Sampled reachable TCP positions.

    ``points`` (N, 3) m; ``sigma_min`` and ``w`` (N,) as in ``PathData``; ``q`` (N, dof) the samples;
    ``home_links`` (n_links, 3) link origins at the home (or zero) pose, for scale.
    """

    robot_name: str
    points: np.ndarray
    sigma_min: np.ndarray
    w: np.ndarray
    q: np.ndarray
    seed: int
    home_links: np.ndarray
    arm_segments: list[tuple[int, int]]


def workspace_data(robot: Robot, samples: int = 80000, seed: int = 0) -> WorkspaceData:
    """Sample ``samples`` arm configurations uniformly within the joint limits (numpy ``default_rng(seed)``).

    The gripper (if any) stays closed; it does not move the TCP.
    """
    if samples < 1:
        raise OptionError("samples", f"must be at least 1, got {samples}")
    if not 0 <= seed < 2**63:  # numpy's generator refuses a negative seed with a ValueError: a bug report
        raise OptionError("seed", f"expected a whole number >= 0, got {seed}")
    rng = np.random.default_rng(seed)
    lo = np.asarray(robot.lower, dtype=float)[robot.arm_indices]
    hi = np.asarray(robot.upper, dtype=float)[robot.arm_indices]
    lo, hi = np.maximum(lo, -np.pi), np.minimum(hi, np.pi)  # 'continuous' joints: one turn is enough
    q_arm = lo + (hi - lo) * rng.random((samples, len(lo)))
    q = robot.full_q(q_arm)
    points = robot.kin.fk(q)[:, :3, 3]
    sv = singular_values(robot, q)
    home = robot.named_poses.get("home")
    home = robot.full_q(home) if home is not None else np.clip(np.zeros(robot.dof), robot.lower, robot.upper)
    return WorkspaceData(robot.name, points, sv[:, -1].copy(), np.prod(sv, axis=1), q, seed,
                         robot.kin.link_frames(home)[:, :3, 3], arm_segments(robot))
