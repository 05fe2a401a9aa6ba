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
      "blends": [s, ...],                      # times where one segment flows into the next without stopping
      "targets": [{"name": str, "kind": "move"|"grasp"|"release", "position": [m], "distance": m,
                   "time": s, "zone": m, "reached": bool, "orientation_error": rad (optional),
                   "joint_error": rad (optional)}],   # how close the TCP comes to each target the plan names
      "payloads": [{"start": s, "end": s, "link": str, "mass": kg, "com": [m] (link frame),
                    "inertia": [[kg m^2]] (about the COM, link axes), "label": str}],  # held objects
      "limits": {"velocity": [rad/s], "acceleration": [rad/s^2], "velocity_scale": f,
                 "acceleration_scale": f, "max_tcp_speed": m/s or null,
                 "defaults": {"acceleration"|"velocity"|"jerk": [joint, ...]} (only when the
                 description lacks some: those joints' limits are roarmctl's defaults)},
      "singularity_margin": {...} or null,
      "scene": {"items": [{"name", "role": "table"|"obstacle"|"object", "shape": "box"|
                "cylinder"|"sphere", "size": [x,y,z] | "radius", "length", "xyz", "rpy"}]},
      "plan": {"path": str, "sha256": str} or null,
      "sample_rate": Hz
    }
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import TrajectoryFileError  # noqa: F401  (re-exported)
from roarmctl.fileio import atomic_write_json

FORMAT = "roarmctl.trajectory/1"
SEGMENT_KINDS = ("free", "cartesian", "gripper", "wait")


@dataclass
class Event:
    """Something that happens at a time (s) of a trajectory: ``kind`` grasp/release, a ``label``, the TCP target."""

    time: float
    kind: str
    label: str = ""
    position: list[float] | None = None


@dataclass
class Segment:
    """A labelled time span (s) of a trajectory: ``kind`` free/cartesian/gripper/wait."""

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
    blends: list[float] = field(default_factory=list)  # s: blended joins (velocity continuous, no stop)
    payloads: list[dict[str, Any]] = field(default_factory=list)  # held objects, grasp to release (see the module doc)
    targets: list[dict[str, Any]] = field(default_factory=list)  # per named target: closest TCP distance, time, zone
    limits: dict[str, Any] = field(default_factory=dict)
    singularity_margin: dict[str, Any] | None = None
    scene: dict[str, Any] = field(default_factory=lambda: {"items": []})
    plan: dict[str, Any] | None = None
    sample_rate: float = 100.0
    robot_description: dict[str, Any] | None = None  # a non-bundled robot, carried (roarmctl.robot.bundle)

    @property
    def duration(self) -> float:
        """Length in time (s); 0 for an empty trajectory."""
        return float(self.times[-1]) if len(self.times) else 0.0

    def to_dict(self) -> dict[str, Any]:
        """The document as written (numbers rounded to 9 decimals; no float is -0.0, see ``_z``)."""
        r = lambda a: [_z(round(float(v), 9)) for v in a]  # noqa: E731  (9 decimals: nm / nrad)
        t9 = lambda v: _z(round(float(v), 9))  # noqa: E731
        return {
            "format": FORMAT,
            "robot": self.robot,
            "joint_names": list(self.joint_names),
            "sample_rate": self.sample_rate,
            "points": [
                {"time_from_start": t9(t), "positions": r(p), "velocities": r(v), "accelerations": r(a)}
                for t, p, v, a in zip(self.times, self.positions, self.velocities, self.accelerations)
            ],
            "events": [
                {"time_from_start": t9(e.time), "kind": e.kind, "label": e.label}
                | ({"position": r(e.position)} if e.position is not None else {})
                for e in self.events
            ],
            "segments": [{"start": t9(s.start), "end": t9(s.end), "kind": s.kind, "label": s.label} for s in self.segments],
            "blends": [t9(b) for b in self.blends],
            "payloads": _unsigned_zeros(self.payloads),
            "targets": [_unsigned_zeros({k: (round(v, 9) if isinstance(v, float) else [round(x, 9) for x in v] if isinstance(v, list) else v)
                                         for k, v in t.items()}) for t in self.targets],
            "limits": _unsigned_zeros(self.limits),
            "singularity_margin": _unsigned_zeros(self.singularity_margin),
            "scene": _unsigned_zeros(self.scene),
            "plan": self.plan,
        } | ({"robot_description": self.robot_description} if self.robot_description is not None else {})

    def save(self, path: str | Path) -> Path:
        """Write the trajectory atomically (temporary file, then rename)."""
        return atomic_write_json(path, self.to_dict(), indent=None)


def _z(v: float) -> float:
    """``v`` with a negative zero made positive (``-0.0 + 0.0`` is ``0.0``; every other value is unchanged):
    whether a rounding or a product leaves the sign bit on a zero must not change the file."""
    return v + 0.0


def _unsigned_zeros(x: Any) -> Any:
    """``x`` (nested dicts, lists, tuples) with ``_z`` applied to every float; other values as they are."""
    if isinstance(x, float):
        return _z(x)
    if isinstance(x, dict):
        return {k: _unsigned_zeros(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return type(x)(_unsigned_zeros(v) for v in x)
    return x


GRASP_RADIUS = 0.06  # m: an object whose centre is this close to a grasp target is the one carried


def carried_item(items: list[dict], target: np.ndarray) -> dict | None:
    """The scene object (``role: object``) of a trajectory's ``scene`` items whose centre is nearest ``target`` (3,) m,
    within ``GRASP_RADIUS``; else None: the object a grasp at ``target`` carries (``visualize-path`` and ``export``
    decide it alike)."""
    carried, best = None, GRASP_RADIUS
    for item in items:
        if not isinstance(item, dict) or item.get("role") != "object":
            continue
        try:
            d = float(np.linalg.norm(np.asarray(item.get("xyz", (0, 0, 0)), dtype=float) - target))
        except (TypeError, ValueError):
            continue
        if d <= best:
            best, carried = d, item
    return carried
