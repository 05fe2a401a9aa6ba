"""What a view shows, from the file the user names: a trajectory, a plan file (planned first), or an
execution log (its commanded joints, the measured arm as a ghost, and, given the trajectory it ran, that
trajectory's scene and marks on the log's clock).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.schedule import STRATEGIES, plan_clock, strategy_rate, target_offset
from roarmctl.errors import InfeasibleError, InputError, TrajectoryFileError
from roarmctl.export import load_source, run_trajectory
from roarmctl.export.streams import JointStates, log_streams
from roarmctl.motion.pipeline import plan_file
from roarmctl.motion.trajectory import Trajectory
from roarmctl.motion.validate import parse_document, validate_trajectory
from roarmctl.viz.data import robot_for
from roarmctl.viz.web.document import Ghost, view_document

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

PLAN_SUFFIXES = (".yaml", ".yml")


@dataclass
class ViewSource:
    """A trajectory to show and what goes with it.

    ``failure``: the planner's ``PartialPlan`` when planning a plan file failed (``traj`` is what was
    planned before it) and ``error`` the ``InfeasibleError`` to report after showing it; ``ghost``: the
    measured arm of a run; ``notes``: lines for the page's header.
    """

    traj: Trajectory
    robot: Robot
    name: str
    failure: Any = None
    error: InfeasibleError | None = None
    ghost: Ghost | None = None
    notes: list[str] = field(default_factory=list)


def trajectory_or_plan(path: str | os.PathLike) -> Trajectory:
    """A trajectory from a ``*.traj.json``, or planned from a plan file (``.yaml``/``.yml``).

    A plan that fails raises the planner's ``InfeasibleError`` (with ``.partial`` when part was planned)."""
    path = Path(path)
    if path.suffix.lower() in PLAN_SUFFIXES:
        return plan_file(path, seed=None).trajectory
    return validate_trajectory(path)


def slowed(traj: Trajectory, scale: float) -> Trajectory:
    """``traj`` run at ``scale`` (0 < scale <= 1) of its speed, as ``execute --speed-scale`` runs it:
    times divided by ``scale``, velocities times it, accelerations times its square."""
    if scale == 1.0:
        return traj
    return dataclasses.replace(
        traj, times=np.asarray(traj.times) / scale, velocities=np.asarray(traj.velocities) * scale,
        accelerations=np.asarray(traj.accelerations) * scale**2,
        events=[dataclasses.replace(e, time=e.time / scale) for e in traj.events],
        segments=[dataclasses.replace(s, start=s.start / scale, end=s.end / scale) for s in traj.segments],
        blends=[b / scale for b in traj.blends],
        payloads=[dict(p, start=p["start"] / scale, end=p["end"] / scale) if {"start", "end"} <= set(p) else p
                  for p in traj.payloads])


def _states_trajectory(robot: Robot, times: np.ndarray, q: np.ndarray) -> Trajectory:
    """Timed joint states (e.g. the commands of a log) as a trajectory without scene or marks; velocities by
    finite differences (for the TCP speed shown)."""
    keep = np.append(np.diff(times) > 1e-9, True)  # strictly increasing: the last command of equal times wins
    t, p = times[keep], q[keep]
    if len(t) and t[0] > 0:  # a trajectory starts at 0 s: the first command's pose stands until its time
        t, p = np.concatenate([[0.0], t]), np.concatenate([p[:1], p])
    v = np.gradient(p, t, axis=0) if len(t) > 1 else np.zeros_like(p)
    return Trajectory(robot.name, list(robot.joint_names), t, p, v, np.zeros_like(p))


def commanded_on_plan_clock(log: dict[str, Any], cmd: JointStates) -> tuple[np.ndarray, np.ndarray]:
    """The log's commands where the plan (run at the log's speed) has them: each at its target's time, its tick's
    time ``k / rate`` plus ``schedule.target_offset`` (lookahead, link latency, lead), not when its line was sent (up
    to ~80 ms earlier with timed-lead: drawn at its send time, the commanded arm runs that far ahead of the plan and
    of the measured arm). A tick's gripper T:101 belongs to its T:102 (the last of a tick wins); the commands before
    the stream's first tick (none in a log of ``execute``) keep their send times. (times (K,) s, positions (K, dof))."""
    rate = float(log.get("rate") or 0.0)
    strategy = str(log.get("strategy", ""))
    ticks = cmd.ticks if cmd.ticks is not None else np.full(len(cmd.times), -1)
    if not (np.isfinite(rate) and rate > 0) or strategy not in STRATEGIES or not np.any(ticks >= 0):
        return cmd.times, cmd.positions
    # a stream that lowered its rate for a slow firmware went on from each change's tick at the new rate (the log's
    # rate_changes: the tick, its time, the rate before and after); the log's own ``rate`` is the last one. One rate
    # for the whole run put the commands off the plan by up to seconds, and their TCP speed spiked (10 m/s drawn for a
    # 0.41 m/s plan)
    changes = sorted(_rate_changes(log), key=lambda c: c[0])
    rate = strategy_rate(strategy, changes[0][3] if changes else rate)  # the rate the stream began at
    last = np.append(ticks[1:] != ticks[:-1], True) | (ticks < 0)
    on_plan = ticks / rate + target_offset(strategy, rate)
    for tick, t0, hz, _ in changes:
        later = ticks >= tick
        on_plan[later] = t0 + (ticks[later] - tick) / hz + target_offset(strategy, hz)
    times = np.where(ticks >= 0, on_plan, cmd.times)[last]
    duration = float(log.get("duration") or 0.0)
    if np.isfinite(duration) and duration > 0:
        times = np.minimum(times, duration)
    return times, cmd.positions[last]


def _rate_changes(log: dict[str, Any]) -> list[tuple[int, float, float, float]]:
    """(tick, its time on the run's clock in s, the rate from there in Hz, the rate before it in Hz) of each
    well-formed ``rate_changes`` entry of an execution log; malformed entries are left out (the log's own reader
    checks its fields)."""
    out = []
    for c in log.get("rate_changes") or []:
        try:
            tick, t0, hz, before = int(c["tick"]), float(c["t"]), float(c["to_hz"]), float(c["from_hz"])
        except (KeyError, TypeError, ValueError):
            continue
        if tick >= 0 and all(np.isfinite(v) and v > 0 for v in (hz, before)) and np.isfinite(t0):
            out.append((tick, t0, hz, before))
    return out


def load_view_source(path: str | os.PathLike, trajectory: str | os.PathLike | None = None) -> ViewSource:
    """Read ``path`` (trajectory, plan file or execution log) for the view; ``trajectory``: for a log, the
    trajectory it ran (its scene and marks are shown, and it is the commanded arm)."""
    path = Path(path)
    name = path.name
    if path.suffix.lower() in PLAN_SUFFIXES:
        if trajectory is not None:
            raise InputError("goes with an execution log", "give the plan file alone", option="trajectory")
        try:
            traj = trajectory_or_plan(path)
        except InfeasibleError as exc:
            partial = getattr(exc, "partial", None)
            if partial is None:
                raise
            return ViewSource(partial.trajectory, robot_for(partial.trajectory), name, failure=partial, error=exc,
                              notes=[f"planning failed: {exc.message}"])
        return ViewSource(traj, robot_for(traj), name)

    kind, data = load_source(path)
    if kind == "trajectory":
        if trajectory is not None:
            raise InputError("goes with an execution log, not with a trajectory", "give the trajectory alone", option="trajectory")
        return ViewSource(data, robot_for(data), name)
    return _log_source(data, path, trajectory)


def _log_source(log: dict[str, Any], path: Path, trajectory: str | os.PathLike | None) -> ViewSource:
    traj, robot = run_trajectory(log, str(path), trajectory)  # -t's file, else the one the log carries
    streams = log_streams(log, robot, traj)
    measured = streams.joint_states["measured"]
    notes = [f"execution log {path.name}: {len(streams.joint_states['commanded'].times)} commands, {len(measured.times)} feedback frames"]
    if traj is not None:
        scale = float(log.get("speed_scale", 1.0) or 1.0)
        main = slowed(traj, scale)
        if scale != 1.0:
            notes.append(f"run at speed scale {scale:g}: times are the run's")
    else:
        cmd = streams.joint_states["commanded"]
        if not len(cmd.times):
            raise TrajectoryFileError(f"{path}: the log holds no joint commands", "view a log of a run that moved the arm")
        main = _states_trajectory(robot, *commanded_on_plan_clock(log, cmd))
        scene = log["physics"].get("scene") if isinstance(log.get("physics"), dict) else None
        if isinstance(scene, dict):  # a physics run carries its scene: drawn, checked as a trajectory's is
            main = parse_document(main.to_dict() | {"scene": scene}, f"{path}: physics")
            notes.append("no targets (a log of an older roarmctl carries no trajectory): "
                         "give -t/--trajectory with the .traj.json this run executed")
        else:
            notes.append("no scene, targets or objects (a log of an older roarmctl carries no trajectory): "
                         "give -t/--trajectory with the .traj.json this run executed")
    ghost = _physics_ghost(log, robot, path)
    if ghost is None and len(measured.times):
        times, positions = measured.times, measured.positions  # when the servos were read, on the run's clock
        paused = [(float(a), float(d)) for a, d in log.get("paused", []) or []]
        if paused:  # the plan waited for a late host: the measured arm on the plan's time, as the commands are
            times = plan_clock(times, paused)
            keep = np.concatenate([[True], np.diff(times) > 0])  # a pause's frames stand at its start
            times, positions = times[keep], positions[keep]
            notes.append(f"the run waited {sum(d for _, d in paused):.2f} s for a busy host ({len(paused)} pauses): "
                         "the measured arm is shown on the plan's time")
        ghost = Ghost("measured", times, positions)
    if ghost is not None and traj is None:  # no plan to measure against: the run's own errors (what the CLI printed)
        ghost.error = _run_tracking(log, path)
        summary = log["summary"].get("tracking_mm") if isinstance(log.get("summary"), dict) else None
        if isinstance(summary, dict) and all(isinstance(summary.get(k), (int, float)) for k in ("rms", "max")):
            notes.append(f"TCP tracking error (the run's, {ghost.label} against the plan): RMS {summary['rms']:.1f} mm, "
                         f"max {summary['max']:.1f} mm")
    if ghost is None:
        notes.append("no feedback in the log: only the commanded arm is shown")
    return ViewSource(main, robot, path.name, ghost=ghost, notes=notes)


def _run_tracking(log: dict[str, Any], path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """The log's ``tracking`` (the streamer's TCP error of each feedback frame against the plan: ``t`` s when the
    servos were read, on the run's clock, ``error_m`` m) on the plan's clock (``paused``), or None when it has none."""
    rows = log.get("tracking")
    if not isinstance(rows, list) or not rows:
        return None
    try:
        t = np.array([float(r["t"]) for r in rows])
        e = np.array([float(r["error_m"]) for r in rows])
    except (KeyError, TypeError, ValueError) as exc:
        raise TrajectoryFileError(f"{path}: tracking: malformed entry ({type(exc).__name__}: {exc})",
                                  "view a log written by 'roarmctl execute' or 'roarmctl simulate'") from None
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(e)) and np.all(e >= 0)):
        raise TrajectoryFileError(f"{path}: tracking: times and errors must be finite, errors >= 0")
    paused = [(float(a), float(d)) for a, d in log.get("paused", []) or []]
    t = plan_clock(t, paused) if paused else t
    order = np.argsort(t, kind="stable")
    return t[order], e[order]


def _physics_ghost(log: dict[str, Any], robot: Robot, path: Path) -> Ghost | None:
    """A physics run's (``roarmctl simulate``) simulated arm and objects, from its ``physics.tracks``
    (``t`` s on the run's clock, ``q`` rad per joint, ``objects``: name -> ``t``, ``xyz`` m, ``quat`` w-x-y-z);
    None when the log has none."""
    tracks = log.get("physics", {}).get("tracks") if isinstance(log.get("physics"), dict) else None
    if not isinstance(tracks, dict) or "t" not in tracks or "q" not in tracks:
        return None
    try:
        t = np.asarray(tracks["t"], dtype=float)
        q = np.asarray(tracks["q"], dtype=float).reshape(len(t), robot.dof)
        objects = {}
        for name, o in (tracks.get("objects") or {}).items():
            ot = np.asarray(o["t"], dtype=float)
            objects[str(name)] = (ot, np.asarray(o["xyz"], dtype=float).reshape(len(ot), 3),
                                  np.asarray(o["quat"], dtype=float).reshape(len(ot), 4))
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise TrajectoryFileError(f"{path}: physics.tracks: malformed ({type(exc).__name__}: {exc})",
                                  "view a run file written by 'roarmctl simulate'") from None
    if len(t) < 1 or not np.all(np.isfinite(t)) or not np.all(np.isfinite(q)) or np.any(np.diff(t) <= 0):
        raise TrajectoryFileError(f"{path}: physics.tracks: times must be finite and increasing, joints finite")
    return Ghost("simulated", t, q, objects)


def source_document(src: ViewSource) -> dict[str, Any]:
    """The view document (``document.view_document``) of ``src``."""
    return view_document(src.traj, src.robot, name=src.name, failure=src.failure, ghost=src.ghost, notes=src.notes)
