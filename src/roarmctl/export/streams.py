"""What an export contains, independent of the file format: timed joint states, link poses and scene poses.

``trajectory_streams(traj, robot)`` and ``log_streams(log, robot)`` turn a planned trajectory or an
execution log into plain numpy arrays that the MCAP / ROS 2 bag writer (``roarmctl.export.ros``)
and the CSV writer (``roarmctl.export.table``) both use. Units: s, rad, rad/s, m.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.protocol import M3_FIELDS, WireMap, frame_read_time, parse_feedback
from roarmctl.device.schedule import run_clock, sample
from roarmctl.errors import InputError, TrajectoryFileError
from roarmctl.motion.trajectory import carried_item
from roarmctl.robot.model import transform

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot


@dataclass
class JointStates:
    """Timed joint states: ``times`` (N,) s, ``positions`` (N, dof) rad, ``velocities`` (N, dof) rad/s or None;
    ``ticks`` (N,) int or None: for an execution log's commands, the streamer's tick each belongs to (-1: none)."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None = None
    ticks: np.ndarray | None = None


@dataclass
class ItemTrack:
    """One scene item and where it is: ``poses`` (K, 4, 4) world poses valid from ``times`` (K,) s on.

    Items that never move have one pose at time 0; a carried object gets one pose per sample while
    it is held (it moves with the TCP) and keeps its release pose afterwards. ``held``: the (grasp,
    release) time spans in s during which it moves with the TCP (the end is the last sample when it is
    never released).
    """

    item: dict[str, Any]
    times: np.ndarray
    poses: np.ndarray
    held: list[tuple[float, float]] = field(default_factory=list)


@dataclass
class Streams:
    """Everything an export writes. ``joint_states`` maps a topic suffix ('' for the plan,
    'commanded' / 'measured' for an execution log) to its states; ``frames_from`` names the one whose
    link poses go to TF."""

    robot: Robot
    joint_names: list[str]
    joint_states: dict[str, JointStates]
    frames_from: str
    trajectory: Trajectory | None = None
    items: list[ItemTrack] = field(default_factory=list)


def item_pose(item: dict[str, Any]) -> np.ndarray:
    """World pose (4, 4) of a trajectory-file scene item (``xyz`` m, ``rpy`` rad)."""
    return transform(item.get("xyz", (0, 0, 0)), item.get("rpy", (0, 0, 0)))


def item_tracks(traj: Trajectory, robot: Robot) -> list[ItemTrack]:
    """Scene items with their poses over time; a grasped object follows the TCP until its release.

    The object carried from a grasp is the one whose centre is nearest the grasp target (within
    ``motion.trajectory.GRASP_RADIUS``), as ``visualize-path`` decides; its pose relative to the TCP is fixed
    at the grasp sample.
    """
    items = [i for i in (traj.scene or {}).get("items", []) if isinstance(i, dict)]
    times = np.asarray(traj.times, dtype=float)
    current = {id(i): item_pose(i) for i in items}
    tracks = {id(i): ([0.0], [current[id(i)]]) for i in items}
    spans: dict[int, list[tuple[float, float]]] = {id(i): [] for i in items}
    events = sorted(traj.events, key=lambda e: e.time)
    tcp = robot.kin.fk(np.asarray(traj.positions, dtype=float))  # (N, 4, 4)
    held: tuple[dict, np.ndarray, int] | None = None  # (item, pose in TCP frame, grasp index)

    def index_at(t: float) -> int:
        return int(np.clip(np.searchsorted(times, t - 1e-9), 0, len(times) - 1))

    for e in events:
        i = index_at(e.time)
        if e.kind == "grasp":
            target = np.asarray(e.position, dtype=float) if e.position is not None else tcp[i, :3, 3]
            positioned = [dict(it, xyz=current[id(it)][:3, 3].tolist()) for it in items]
            pick = carried_item(positioned, target)
            if pick is not None:
                item = items[positioned.index(pick)]
                held = (item, np.linalg.inv(tcp[i]) @ current[id(item)], i)
        elif e.kind == "release" and held is not None:
            item, rel, i0 = held
            ts, ps = tracks[id(item)]
            for k in range(i0 + 1, i + 1):
                ts.append(float(times[k]))
                ps.append(tcp[k] @ rel)
            current[id(item)] = ps[-1]
            spans[id(item)].append((float(times[i0]), float(times[i])))
            held = None
    if held is not None:  # never released: carried to the end
        item, rel, i0 = held
        ts, ps = tracks[id(item)]
        for k in range(i0 + 1, len(times)):
            ts.append(float(times[k]))
            ps.append(tcp[k] @ rel)
        spans[id(item)].append((float(times[i0]), float(times[-1])))
    return [ItemTrack(i, np.array(tracks[id(i)][0]), np.array(tracks[id(i)][1]), spans[id(i)]) for i in items]


def trajectory_streams(traj: Trajectory, robot: Robot) -> Streams:
    """A planned trajectory: its sampled joint states, TF from them, and the scene."""
    states = JointStates(np.asarray(traj.times, dtype=float), np.asarray(traj.positions, dtype=float),
                         np.asarray(traj.velocities, dtype=float))
    return Streams(robot, list(traj.joint_names), {"": states}, "", traj, item_tracks(traj, robot))


def log_streams(log: dict[str, Any], robot: Robot, traj: Trajectory | None = None) -> Streams:
    """See ``_log_streams``; a malformed entry is an input error (exit 2), not a crash.

    Every stream is on the log's clock: s after the stream's start (the first scheduled command), the run's own
    time, pauses included. ``traj``: the trajectory that was executed. Its samples are added as the ``planned``
    joint states and its scene as markers, on that clock: plan time / the run's ``speed_scale`` (the log's time 0
    is the first scheduled command, which targets the plan's time 0), later by each pause of the plan for a late
    host before it (the log's ``paused``); through a pause the planned set-point stands still (a sample at each
    end of it), so the planned and the measured arm at one stamp are the plan and the arm at one instant.
    """
    try:
        streams = _log_streams(log, robot)
        scale = float(log.get("speed_scale", 1.0) or 1.0)
        paused = _pauses(log)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise TrajectoryFileError(f"execution log: malformed entry ({type(exc).__name__}: {exc})",
                                  "export a log written by 'roarmctl execute'") from None
    if traj is not None:
        if list(traj.joint_names) != list(robot.joint_names):
            raise InputError(f"its joints {traj.joint_names} are not those of the log's robot '{robot.name}'",
                             "give the trajectory this log executed", option="trajectory")
        if not 0 < scale <= 1:
            raise TrajectoryFileError(f"execution log: speed_scale {scale!r} is not in (0, 1]")
        streams.joint_states["planned"] = planned_states(traj, scale, paused)
        streams.trajectory = None  # no /joint_trajectory: the log's topics are about the run
        on_run = lambda x: _run_clock(np.asarray(x, dtype=float) / scale, paused)  # noqa: E731
        streams.items = [ItemTrack(tr.item, on_run(tr.times), tr.poses, [(float(on_run(a)), float(on_run(b))) for a, b in tr.held])
                         for tr in item_tracks(traj, robot)]
    return streams


def planned_states(traj: Trajectory, scale: float, paused: list[tuple[float, float]]) -> JointStates:
    """The plan's samples on the run's clock (s after the stream's start): plan time / ``scale``, later by each pause
    before it (``schedule.run_clock``), and the set-point held through each pause (``paused``: [(run-speed plan time
    s at which the plan's clock stopped, for how long s)]): a sample at each end of it, at the plan's pose there
    (``schedule.sample``) with velocity 0. Positions (N, dof) rad, velocities (N, dof) rad/s."""
    t = np.asarray(traj.times, dtype=float) / scale
    pos, vel = np.asarray(traj.positions, dtype=float), np.asarray(traj.velocities, dtype=float) * scale
    run_t = _run_clock(t, paused)
    at = np.array([a for a, d in paused if 0.0 <= a <= t[-1] and d > 0], dtype=float)
    if not len(at):
        return JointStates(run_t, pos, vel)
    d = np.array([d for a, d in paused if 0.0 <= a <= t[-1] and d > 0], dtype=float)
    start = _run_clock(at, paused)  # a pause's own point: when it started
    q = sample(traj, at * scale).reshape(len(at), -1)
    # the set-point where the pause starts: a plan sample already there (a tick on the plan's 10 ms grid) keeps its
    # own velocity, the clock stopping after it; otherwise one is added
    i = np.clip(np.searchsorted(t, at), 1, len(t) - 1) if len(t) > 1 else np.zeros(len(at), dtype=int)
    new = np.minimum(np.abs(t[i] - at), np.abs(t[i - 1] - at) if len(t) > 1 else np.inf) > 1e-6
    times = np.concatenate([run_t, start[new], start + d])
    order = np.argsort(times, kind="stable")
    zeros = np.zeros_like(q)
    return JointStates(times[order], np.concatenate([pos, q[new], q])[order],
                       np.concatenate([vel, zeros[new], zeros])[order])


def _run_clock(t: np.ndarray, paused: list[tuple[float, float]]) -> np.ndarray:
    """``schedule.run_clock`` of run-speed plan times ``t`` (s), a time within 1 us of a pause's start counted at it:
    the log rounds the pause's time to 1 us, and a plan sample there (a tick on the plan's grid) is the set-point
    the plan stopped at, not one after the pause."""
    return np.asarray(run_clock(t, [(a + 1e-6, d) for a, d in paused]), dtype=float)


def _pauses(log: dict[str, Any]) -> list[tuple[float, float]]:
    """The log's ``paused`` ([[plan time s, duration s], ...]: where the plan waited for a late host), checked."""
    out = []
    for e in log.get("paused", []) or []:
        at, d = float(e[0]), float(e[1])
        if not (np.isfinite(at) and np.isfinite(d) and d >= 0):
            raise ValueError(f"paused entry {e!r}")
        out.append((at, d))
    return out


def _log_streams(log: dict[str, Any], robot: Robot) -> Streams:
    """An execution log (``roarmctl.execlog/1``): commanded joints (every T:102 / T:101 sent) and
    measured joints (every T:1051 feedback received), converted from wire values with the robot's
    wire map. Times are s after the log's start of motion (negative before it); a commanded state's time is when
    its line was sent, a measured state's when the firmware read the servos (``device.protocol.frame_read_time``:
    the log's ``read_t``), not when its line arrived."""
    wm = WireMap(robot)
    cmd_t, cmd_q, cmd_tick = [], [], []
    wire: dict[str, float] | None = None
    tick = -1  # a tick's T:101 for the gripper follows its T:102, which alone carries the tick
    for entry in log.get("sent", []):
        cmd = entry.get("cmd") if isinstance(entry, dict) else None
        if not isinstance(cmd, dict):
            continue
        if cmd.get("T") == 102 and all(isinstance(cmd.get(f), (int, float)) for f in M3_FIELDS):
            wire = {f: float(cmd[f]) for f in M3_FIELDS}
            tick = int(entry["tick"]) if isinstance(entry.get("tick"), int) else -1
        elif cmd.get("T") == 101 and cmd.get("joint") == 6 and wire is not None and isinstance(cmd.get("rad"), (int, float)):
            wire = dict(wire, hand=float(cmd["rad"]))
        else:
            continue
        cmd_t.append(float(entry["t"]))
        cmd_q.append(wm.from_wire(wire))
        cmd_tick.append(tick)
    meas_t, meas_q = [], []
    for entry in log.get("received", []):
        fb = parse_feedback(entry["feedback"]) if isinstance(entry, dict) and isinstance(entry.get("feedback"), dict) else None
        if fb is None or not fb.joints:
            continue
        meas_t.append(frame_read_time(entry))
        meas_q.append(wm.from_wire(fb.joints))
    if not cmd_t and not meas_t:
        raise InputError("the execution log holds no joint commands and no feedback", "export a log of a run that moved the arm")
    dof = robot.dof
    states = {
        "commanded": JointStates(np.array(cmd_t), np.array(cmd_q).reshape(-1, dof), ticks=np.array(cmd_tick, dtype=int)),
        "measured": JointStates(np.array(meas_t), np.array(meas_q).reshape(-1, dof)),
    }
    return Streams(robot, list(robot.joint_names), states, "measured" if meas_t else "commanded")
