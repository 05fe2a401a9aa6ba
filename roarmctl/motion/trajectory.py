"""The timed joint trajectory and its file format (``*.traj.json``, ``roarmctl.trajectory/1``).

The layout follows ROS 2 ``trajectory_msgs/JointTrajectory`` so it exports 1:1:

    {
      "format": "roarmctl.trajectory/1",
      "robot": "roarm_m3_pro",                 # bundled name or path of the description
      "joint_names": [...],                    # every actuated joint, gripper last
      "points": [{"time_from_start": s, "positions": [rad], "velocities": [rad/s],
                  "accelerations": [rad/s^2]}, ...],      # strictly increasing times, from 0
      "events": [{"time_from_start": s, "kind": "grasp"|"release"|..., "label": str,
                  "position": [x, y, z] (m, optional: the TCP target of the event)}],
      "segments": [{"start": s, "end": s, "kind": "free"|"cartesian"|"gripper"|"wait",
                    "label": str}],
      "limits": {"velocity": [rad/s], "acceleration": [rad/s^2], "velocity_scale": f,
                 "acceleration_scale": f, "max_tcp_speed": m/s or null},
      "singularity_margin": {...} or null,
      "scene": {"items": [{"name", "role": "table"|"obstacle"|"object", "shape": "box"|
                "cylinder"|"sphere", "size": [x,y,z] | "radius", "length", "xyz", "rpy"}]},
      "plan": {"path": str, "sha256": str} or null,
      "sample_rate": Hz
    }
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import TrajectoryFileError
from roarmctl.fileio import atomic_write_json

FORMAT = "roarmctl.trajectory/1"
SEGMENT_KINDS = ("free", "cartesian", "gripper", "wait")


@dataclass
class Event:
    time: float
    kind: str
    label: str = ""
    position: list[float] | None = None


@dataclass
class Segment:
    start: float
    end: float
    kind: str
    label: str = ""


@dataclass
class Trajectory:
    """A sampled, timed joint trajectory.

    ``times`` (N,) s from 0, strictly increasing; ``positions``, ``velocities``, ``accelerations``
    (N, dof) in rad, rad/s, rad/s^2, columns in ``joint_names`` order.
    """

    robot: str
    joint_names: list[str]
    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    events: list[Event] = field(default_factory=list)
    segments: list[Segment] = field(default_factory=list)
    limits: dict[str, Any] = field(default_factory=dict)
    singularity_margin: dict[str, Any] | None = None
    scene: dict[str, Any] = field(default_factory=lambda: {"items": []})
    plan: dict[str, Any] | None = None
    sample_rate: float = 100.0

    @property
    def duration(self) -> float:
        return float(self.times[-1]) if len(self.times) else 0.0

    def to_dict(self) -> dict[str, Any]:
        r = lambda a: [round(float(v), 9) for v in a]  # noqa: E731  (9 decimals: nm / nrad)
        return {
            "format": FORMAT,
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "sample_rate": self.sample_rate,
            "points": [
                {"time_from_start": round(float(t), 9), "positions": r(p), "velocities": r(v), "accelerations": r(a)}
                for t, p, v, a in zip(self.times, self.positions, self.velocities, self.accelerations)
            ],
            "events": [
                {"time_from_start": round(e.time, 9), "kind": e.kind, "label": e.label}
                | ({"position": r(e.position)} if e.position is not None else {})
                for e in self.events
            ],
            "segments": [{"start": round(s.start, 9), "end": round(s.end, 9), "kind": s.kind, "label": s.label} for s in self.segments],
            "limits": self.limits,
            "singularity_margin": self.singularity_margin,
            "scene": self.scene,
            "plan": self.plan,
        }

    def save(self, path: str | Path) -> Path:
        """Write the trajectory atomically (temporary file, then rename)."""
        return atomic_write_json(path, self.to_dict(), indent=None)


def load_trajectory(path: str | Path) -> Trajectory:
    """Read and validate a ``*.traj.json`` file; any problem raises ``TrajectoryFileError`` (exit 2)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise TrajectoryFileError(f"{path}: no such file", "run 'roarmctl plan' first or check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TrajectoryFileError(f"{path}: cannot read ({exc})") from None
    except json.JSONDecodeError as exc:
        raise TrajectoryFileError(f"{path}:{exc.lineno}: not valid JSON ({exc.msg})", "the file is damaged; plan it again") from None
    return trajectory_from_dict(data, str(path))


def trajectory_from_dict(data: Any, where: str = "trajectory") -> Trajectory:
    if not isinstance(data, dict):
        raise TrajectoryFileError(f"{where}: expected a JSON object")
    if data.get("format") != FORMAT:
        raise TrajectoryFileError(f"{where}: format: expected '{FORMAT}', got {data.get('format')!r}")
    for key in ("robot", "joint_names", "points"):
        if key not in data:
            raise TrajectoryFileError(f"{where}: '{key}' is missing")
    names = data["joint_names"]
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise TrajectoryFileError(f"{where}: joint_names: expected a list of joint names")
    pts = data["points"]
    if not isinstance(pts, list) or len(pts) < 1:
        raise TrajectoryFileError(f"{where}: points: expected a non-empty list")
    dof = len(names)
    arrays = {k: np.empty((len(pts), dof)) for k in ("positions", "velocities", "accelerations")}
    times = np.empty(len(pts))
    for i, p in enumerate(pts):
        if not isinstance(p, dict):
            raise TrajectoryFileError(f"{where}: points[{i}]: expected an object")
        try:
            times[i] = float(p["time_from_start"])
            for k, arr in arrays.items():
                vals = p.get(k, [0.0] * dof) if k != "positions" else p[k]
                if len(vals) != dof:
                    raise TrajectoryFileError(f"{where}: points[{i}].{k}: expected {dof} values, got {len(vals)}")
                arr[i] = [float(v) for v in vals]
        except KeyError as exc:
            raise TrajectoryFileError(f"{where}: points[{i}]: '{exc.args[0]}' is missing") from None
        except (TypeError, ValueError):
            raise TrajectoryFileError(f"{where}: points[{i}]: values must be numbers") from None
    if not np.all(np.isfinite(times)) or any(not np.all(np.isfinite(a)) for a in arrays.values()):
        raise TrajectoryFileError(f"{where}: points: values must be finite numbers")
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        bad = int(np.argmax(np.diff(times) <= 0)) + 1
        raise TrajectoryFileError(f"{where}: points[{bad}].time_from_start: times must increase strictly")
    try:
        events = [Event(float(e["time_from_start"]), str(e["kind"]), str(e.get("label", "")), e.get("position")) for e in data.get("events", [])]
        segments = [Segment(float(s["start"]), float(s["end"]), str(s["kind"]), str(s.get("label", ""))) for s in data.get("segments", [])]
    except (KeyError, TypeError, ValueError) as exc:
        raise TrajectoryFileError(f"{where}: events/segments: malformed entry ({exc})") from None
    return Trajectory(
        robot=str(data["robot"]),
        joint_names=list(names),
        times=times,
        events=events,
        segments=segments,
        limits=data.get("limits") or {},
        singularity_margin=data.get("singularity_margin"),
        scene=data.get("scene") or {"items": []},
        plan=data.get("plan"),
        sample_rate=float(data.get("sample_rate", 100.0)),
        **arrays,
    )
