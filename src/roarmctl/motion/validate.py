"""The one trajectory validator: every trajectory a command reads goes through ``validate_trajectory``.

``execute`` (before the port is opened), ``visualize-path`` and ``export`` call it, so a file that
would command a joint past its limits, jump between samples, or overload memory is refused with
exit 2 and one line naming the point index, the joint, the value and the limit.

Two stages:

* ``parse_document(data, where)``: the ``roarmctl.trajectory/1`` form (types, finite numbers, sizes,
  times from 0 strictly increasing, events/segments/scene/limits well-formed) -> ``Trajectory``.
* ``check_against_robot(traj, robot, where)``: joint names, the links payloads ride on, joint limits, velocity and acceleration
  limits (``VEL_TOL``/``ACC_TOL``), sample spacing at the declared rate, and position steps that
  agree with the velocities given the acceleration limit.

Bounds that keep memory and time small (documented in docs/reference.md, "The trajectory file"):
``MAX_FILE_BYTES``, ``MAX_POINTS``, ``MAX_DURATION``, ``SAMPLE_RATE_RANGE``.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.checks import Checker
from roarmctl.errors import InputError, TrajectoryFileError
from roarmctl.formats import MAX_DURATION, MAX_POINTS, ROLES, SHAPES, read_document
from roarmctl.motion.options import PLANNERS
from roarmctl.motion.trajectory import FORMAT, Event, Segment, Trajectory
from roarmctl.plan.fields import FIELD_BOUNDS
from roarmctl.robot.bundle import trajectory_robot
from roarmctl.robot.loader import load_robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

SAMPLE_RATE_RANGE = (0.1, 10000.0)  # Hz
MAX_EVENTS = 100_000
MAX_SCENE_ITEMS = 10_000
MAX_NAME = 255  # characters of a joint, event, segment or scene-item name
MAX_SIZE = 100.0  # m, any scene item dimension
MAX_COORD = 1000.0  # m, any scene or event coordinate
POS_TOL = 1e-6  # rad (m for prismatic): the file rounds to 1e-9, the planner clips exactly
VEL_TOL = 0.02  # relative, on the robot's velocity limits
ACC_TOL = 0.05  # relative, on the robot's acceleration limits
TIME_TOL = 1e-6  # s
SEGMENT_KINDS = ("free", "cartesian", "gripper", "wait")
EVENT_KINDS = ("grasp", "release")  # what the planner writes; replanning and the pictures act on them
MAX_MESH_PIECES, MAX_MESH_VERTICES = 256, 2_000_000  # a scene mesh item: convex pieces, vertices of all pieces
MAX_CLOUD_CELLS = 2_000_000  # a scene cloud item's occupied cells


CHECK = Checker(TrajectoryFileError, json=True, bound=math.inf, max_name=MAX_NAME)


# --------------------------------------------------------------------------- the document
def parse_document(data: Any, where: str = "trajectory") -> Trajectory:
    """A ``roarmctl.trajectory/1`` document (the parsed JSON) -> ``Trajectory``, checking its form.

    Raises ``TrajectoryFileError`` (exit 2) naming the field; nothing here needs the robot.
    """
    if not isinstance(data, dict):
        raise TrajectoryFileError(f"{where}: expected a JSON object, got {CHECK.kind(data)}")
    if data.get("format") != FORMAT:
        raise TrajectoryFileError(f"{where}: format: expected '{FORMAT}', got {CHECK.kind(data.get('format'))}",
                                  "give a trajectory file written by 'roarmctl plan' (NAME.traj.json)")
    for key in ("robot", "joint_names", "points"):
        if key not in data:
            raise TrajectoryFileError(f"{where}: '{key}' is missing")
    robot = data["robot"]
    if not isinstance(robot, str) or not robot or len(robot) > 4096 or "\0" in robot:
        CHECK.fail(where, "robot", f"expected a robot name or path, got {CHECK.kind(robot)}")
    names = data["joint_names"]
    if not isinstance(names, list) or not names or len(names) > 64:
        CHECK.fail(where, "joint_names", f"expected a list of 1 to 64 joint names, got {CHECK.kind(names)}")
    names = [CHECK.name(n, where, f"joint_names[{i}]") for i, n in enumerate(names)]
    if len(set(names)) != len(names):
        CHECK.fail(where, "joint_names", "a joint is named twice")
    rate = CHECK.number(data.get("sample_rate", 100.0), where, "sample_rate", lo=SAMPLE_RATE_RANGE[0], hi=SAMPLE_RATE_RANGE[1])
    pts = data["points"]
    if not isinstance(pts, list) or not pts:
        CHECK.fail(where, "points", f"expected a non-empty list, got {CHECK.kind(pts)}")
    if len(pts) > MAX_POINTS:
        CHECK.fail(where, "points", f"{len(pts)} points are more than {MAX_POINTS}", "split the plan into shorter ones")
    dof = len(names)
    n = len(pts)
    times = np.empty(n)
    arrays = {k: np.zeros((n, dof)) for k in ("positions", "velocities", "accelerations")}
    for i, p in enumerate(pts):
        if not isinstance(p, dict):
            CHECK.fail(where, f"points[{i}]", f"expected an object, got {CHECK.kind(p)}")
        if "time_from_start" not in p:
            CHECK.fail(where, f"points[{i}]", "'time_from_start' is missing")
        t = p["time_from_start"]
        if isinstance(t, bool) or not isinstance(t, (int, float)):
            CHECK.fail(where, f"points[{i}].time_from_start", f"expected a number, got {CHECK.kind(t)}")
        times[i] = CHECK.number(t, where, f"points[{i}].time_from_start", lo=0.0, hi=MAX_DURATION)
        for k, arr in arrays.items():
            if k not in p:
                if k == "positions":
                    CHECK.fail(where, f"points[{i}]", "'positions' is missing")
                continue
            vals = p[k]
            if not isinstance(vals, list) or len(vals) != dof:
                CHECK.fail(where, f"points[{i}].{k}", f"expected {dof} numbers (one per joint), got {CHECK.kind(vals)}")
            for j, x in enumerate(vals):
                if type(x) is not float and type(x) is not int:  # bool and str are not numbers here
                    CHECK.number(x, where, f"points[{i}].{k}[{j}] ({names[j]})")
            try:
                row = np.array(vals, dtype=float)
            except OverflowError:
                row = np.array([x if abs(x) < 1e308 else math.inf for x in vals], dtype=float)
            if not np.all(np.isfinite(row)):
                j = int(np.argmin(np.isfinite(row)))
                CHECK.fail(where, f"points[{i}].{k}[{j}] ({names[j]})", f"expected a finite number, got {vals[j]!r:.40}")
            arr[i] = row
    if abs(times[0]) > TIME_TOL:
        CHECK.fail(where, "points[0].time_from_start", f"{times[0]:g} s: the first point must be at 0 s")
    if n > 1:
        steps = np.diff(times)
        if np.any(steps <= 0):
            bad = int(np.argmax(steps <= 0)) + 1
            CHECK.fail(where, f"points[{bad}].time_from_start", f"{times[bad]:g} s: times must increase strictly "
                       f"(the point before is at {times[bad - 1]:g} s)")
    duration = float(times[-1])

    events = []
    raw_events = data.get("events", [])
    if raw_events is None:
        raw_events = []
    if not isinstance(raw_events, list) or len(raw_events) > MAX_EVENTS:
        CHECK.fail(where, "events", f"expected a list of at most {MAX_EVENTS}, got {CHECK.kind(raw_events)}")
    for i, e in enumerate(raw_events):
        f = f"events[{i}]"
        CHECK.mapping(e, where, f)
        if "time_from_start" not in e or "kind" not in e:
            CHECK.fail(where, f, "needs 'time_from_start' and 'kind'")
        t = CHECK.number(e["time_from_start"], where, f"{f}.time_from_start", lo=-TIME_TOL, hi=duration + TIME_TOL)
        pos = e.get("position")
        if pos is not None:
            pos = CHECK.numbers(pos, 3, where, f"{f}.position", lo=-MAX_COORD, hi=MAX_COORD)
        kind = CHECK.name(e["kind"], where, f"{f}.kind", choices=EVENT_KINDS)
        events.append(Event(t, kind, CHECK.name(e.get("label", ""), where, f"{f}.label", empty=True), pos))

    segments = []
    raw_segments = data.get("segments", [])
    if raw_segments is None:
        raw_segments = []
    if not isinstance(raw_segments, list) or len(raw_segments) > MAX_EVENTS:
        CHECK.fail(where, "segments", f"expected a list of at most {MAX_EVENTS}, got {CHECK.kind(raw_segments)}")
    for i, s in enumerate(raw_segments):
        f = f"segments[{i}]"
        CHECK.mapping(s, where, f)
        if "start" not in s or "end" not in s or "kind" not in s:
            CHECK.fail(where, f, "needs 'start', 'end' and 'kind'")
        a = CHECK.number(s["start"], where, f"{f}.start", lo=-TIME_TOL, hi=duration + TIME_TOL)
        b = CHECK.number(s["end"], where, f"{f}.end", lo=-TIME_TOL, hi=duration + TIME_TOL)
        if b < a:
            CHECK.fail(where, f"{f}.end", f"{b:g} s is before its start {a:g} s")
        kind = CHECK.name(s["kind"], where, f"{f}.kind")
        if kind not in SEGMENT_KINDS:
            CHECK.fail(where, f"{f}.kind", f"'{kind}' is not one of {', '.join(SEGMENT_KINDS)}")
        segments.append(Segment(a, b, kind, CHECK.name(s.get("label", ""), where, f"{f}.label", empty=True)))

    raw_blends = data.get("blends") or []
    if not isinstance(raw_blends, list) or len(raw_blends) > MAX_EVENTS:
        CHECK.fail(where, "blends", f"expected a list of at most {MAX_EVENTS} times, got {CHECK.kind(raw_blends)}")
    blends = [CHECK.number(b, where, f"blends[{i}]", lo=-TIME_TOL, hi=duration + TIME_TOL) for i, b in enumerate(raw_blends)]

    targets = _targets(data.get("targets") or [], where, duration)

    payloads = data.get("payloads") or []
    if not isinstance(payloads, list) or len(payloads) > MAX_EVENTS:
        CHECK.fail(where, "payloads", f"expected a list of at most {MAX_EVENTS}, got {CHECK.kind(payloads)}")
    for i, p in enumerate(payloads):
        f = f"payloads[{i}]"
        CHECK.mapping(p, where, f)
        for key in ("start", "end", "link", "mass", "com", "inertia"):
            if key not in p:
                CHECK.fail(where, f, f"'{key}' is missing")
        CHECK.number(p["start"], where, f"{f}.start", lo=-TIME_TOL, hi=duration + TIME_TOL)
        CHECK.number(p["end"], where, f"{f}.end", lo=-TIME_TOL, hi=duration + TIME_TOL)
        CHECK.name(p["link"], where, f"{f}.link")
        CHECK.number(p["mass"], where, f"{f}.mass", lo=0.0, hi=1e4)
        CHECK.numbers(p["com"], 3, where, f"{f}.com", lo=-MAX_COORD, hi=MAX_COORD)
        if not isinstance(p["inertia"], list) or len(p["inertia"]) != 3:
            CHECK.fail(where, f"{f}.inertia", f"expected a 3x3 matrix, got {CHECK.kind(p['inertia'])}")
        for r, row in enumerate(p["inertia"]):
            CHECK.numbers(row, 3, where, f"{f}.inertia[{r}]", lo=-1e4, hi=1e4)

    limits = data.get("limits") or {}
    CHECK.mapping(limits, where, "limits")
    for key in ("velocity", "acceleration"):
        if limits.get(key) is not None:
            CHECK.numbers(limits[key], dof, where, f"limits.{key}", lo=0.0, hi=1e6, strict_lo=True)
    for key in ("velocity_scale", "acceleration_scale"):
        if limits.get(key) is not None:
            CHECK.number(limits[key], where, f"limits.{key}", lo=0.0, hi=1.0, strict_lo=True)
    if limits.get("zone") is not None:
        lo, hi = FIELD_BOUNDS["zone"]  # the plan's bound: what a planner can record
        CHECK.number(limits["zone"], where, "limits.zone", lo=lo, hi=hi)
    if limits.get("max_tcp_speed") is not None:
        CHECK.number(limits["max_tcp_speed"], where, "limits.max_tcp_speed", lo=0.0, hi=100.0, strict_lo=True)

    margin = data.get("singularity_margin")
    if margin is not None:
        CHECK.mapping(margin, where, "singularity_margin")
        if margin.get("min_singular_value") is not None:
            lo, hi = FIELD_BOUNDS["singularity_margin"]  # the plan's and api.Planner's bound: what they can record
            CHECK.number(margin["min_singular_value"], where, "singularity_margin.min_singular_value", lo=lo, hi=hi)

    scene = data.get("scene") or {"items": []}
    CHECK.mapping(scene, where, "scene")
    items = scene.get("items", [])
    if items is None:
        items = []
    if not isinstance(items, list) or len(items) > MAX_SCENE_ITEMS:
        CHECK.fail(where, "scene.items", f"expected a list of at most {MAX_SCENE_ITEMS} items, got {CHECK.kind(items)}")
    seen: set[str] = set()
    for i, it in enumerate(items):
        _scene_item(it, where, f"scene.items[{i}]", seen)

    plan = data.get("plan")
    if plan is not None:
        _plan_meta(plan, where)
    description = data.get("robot_description")  # checked file by file when loaded (robot.bundle)
    if description is not None:
        CHECK.mapping(description, where, "robot_description")
    return Trajectory(robot=robot, joint_names=names, times=times, events=events, segments=segments, blends=blends, targets=targets, payloads=[dict(p) for p in payloads],
                      limits=dict(limits), singularity_margin=margin, scene={**scene, "items": items}, plan=plan,
                      sample_rate=rate, robot_description=description, **arrays)


TARGET_KINDS = ("move", "grasp", "release")


def _targets(raw: Any, where: str, duration: float) -> list[dict]:
    """The per-target table (``Trajectory.targets``): each row's fields checked (distances and zones in m)."""
    if not isinstance(raw, list) or len(raw) > MAX_EVENTS:
        CHECK.fail(where, "targets", f"expected a list of at most {MAX_EVENTS}, got {CHECK.kind(raw)}")
    out = []
    for i, t in enumerate(raw):
        f = f"targets[{i}]"
        CHECK.mapping(t, where, f)
        for key in ("name", "kind", "position", "distance", "time", "zone", "reached"):
            if key not in t:
                CHECK.fail(where, f, f"'{key}' is missing")
        row = {"name": CHECK.name(t["name"], where, f"{f}.name", empty=True),
               "kind": CHECK.name(t["kind"], where, f"{f}.kind", choices=TARGET_KINDS),
               "position": CHECK.numbers(t["position"], 3, where, f"{f}.position", lo=-MAX_COORD, hi=MAX_COORD),
               "distance": CHECK.number(t["distance"], where, f"{f}.distance", lo=0.0, hi=MAX_COORD),
               "time": CHECK.number(t["time"], where, f"{f}.time", lo=-TIME_TOL, hi=duration + TIME_TOL),
               "zone": CHECK.number(t["zone"], where, f"{f}.zone", lo=0.0, hi=MAX_COORD)}
        for key in ("orientation_error", "joint_error"):
            if t.get(key) is not None:
                row[key] = CHECK.number(t[key], where, f"{f}.{key}", lo=0.0, hi=1e6)
        if not isinstance(t["reached"], bool):
            CHECK.fail(where, f"{f}.reached", f"expected true or false, got {CHECK.kind(t['reached'])}")
        row["reached"] = t["reached"]
        out.append(row)
    return out


def _plan_meta(plan: Any, where: str) -> None:
    """The ``plan`` a trajectory came from (``execute --from-current`` plans it again): ``path``,
    ``sha256`` (64 hex digits), ``planner`` (one OMPL planner roarmctl offers), ``seed``, ``padding``."""
    CHECK.mapping(plan, where, "plan")
    if plan.get("path") is not None:
        CHECK.name(plan["path"], where, "plan.path", max_len=4096)
    sha = plan.get("sha256")
    if sha is not None and not (isinstance(sha, str) and len(sha) == 64 and all(c in "0123456789abcdef" for c in sha)):
        CHECK.fail(where, "plan.sha256", f"expected 64 hex digits, got {CHECK.kind(sha)}")
    if plan.get("planner") is not None:
        CHECK.name(plan["planner"], where, "plan.planner", choices=PLANNERS)
    if plan.get("seed") is not None:
        seed = plan["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2 ** 63:
            CHECK.fail(where, "plan.seed", f"expected a whole number from 0 to 2**63 - 1, got {CHECK.kind(seed)}")
    if plan.get("padding") is not None:
        lo, hi = FIELD_BOUNDS["padding"]  # what a plan or api.Planner may have used
        CHECK.number(plan["padding"], where, "plan.padding", lo=lo, hi=hi)


def _scene_item(it: Any, where: str, f: str, seen: set) -> None:
    CHECK.mapping(it, where, f)
    name = CHECK.name(it.get("name"), where, f"{f}.name")
    if name in seen:
        CHECK.fail(where, f"{f}.name", f"'{name}' is used twice")
    seen.add(name)
    role = it.get("role")
    if role not in ROLES:
        CHECK.fail(where, f"{f}.role", f"expected one of {', '.join(ROLES)}, got {CHECK.kind(role)}")
    shape = it.get("shape")
    if shape not in SHAPES:
        CHECK.fail(where, f"{f}.shape", f"expected one of {', '.join(SHAPES)}, got {CHECK.kind(shape)}")
    if shape == "mesh":
        _mesh_pieces(it.get("pieces"), where, f"{f}.pieces")
    elif shape == "cloud":
        CHECK.number(it.get("resolution"), where, f"{f}.resolution", lo=1e-4, hi=1.0)
        _int_rows(it.get("cells"), where, f"{f}.cells", MAX_CLOUD_CELLS, -2 ** 15, 2 ** 15 - 1)
    elif shape == "box":
        CHECK.numbers(it.get("size"), 3, where, f"{f}.size", lo=0.0, hi=MAX_SIZE, strict_lo=True)
    else:
        CHECK.number(it.get("radius"), where, f"{f}.radius", lo=0.0, hi=MAX_SIZE, strict_lo=True)
        if shape == "cylinder":
            CHECK.number(it.get("length"), where, f"{f}.length", lo=0.0, hi=MAX_SIZE, strict_lo=True)
    if "xyz" not in it:
        CHECK.fail(where, f"{f}.xyz", "is missing", "every scene item has a position [x, y, z] in m")
    CHECK.numbers(it["xyz"], 3, where, f"{f}.xyz", lo=-MAX_COORD, hi=MAX_COORD)
    CHECK.numbers(it.get("rpy", [0, 0, 0]), 3, where, f"{f}.rpy", lo=-100.0, hi=100.0)


def _int_rows(v: Any, where: str, f: str, most: int, lo: int, hi: int) -> np.ndarray:
    """A list of at most ``most`` rows of 3 whole numbers in [lo, hi], as an (N, 3) int64 array."""
    if not isinstance(v, list) or not 0 < len(v) <= most:
        CHECK.fail(where, f, f"expected a list of 1 to {most} rows [i, j, k], got {CHECK.kind(v)}")
    try:
        a = np.array(v, dtype=object)
        if a.ndim != 2 or a.shape[1] != 3 or any(isinstance(x, bool) or not isinstance(x, int) for x in a.ravel()):
            raise ValueError
        rows = a.astype(np.int64)
    except (ValueError, TypeError, OverflowError):
        CHECK.fail(where, f, "expected rows of 3 whole numbers")
    if rows.min() < lo or rows.max() > hi:
        CHECK.fail(where, f, f"a value lies outside {lo} .. {hi}")
    return rows


def _mesh_pieces(v: Any, where: str, f: str) -> None:
    """A mesh item's ``pieces``: [{"vertices": [[x, y, z], ...] (m), "faces": [[i, j, k], ...]}], each face naming
    vertices of its piece."""
    if not isinstance(v, list) or not 0 < len(v) <= MAX_MESH_PIECES:
        CHECK.fail(where, f, f"expected a list of 1 to {MAX_MESH_PIECES} pieces, got {CHECK.kind(v)}")
    total = 0
    for i, piece in enumerate(v):
        CHECK.mapping(piece, where, f"{f}[{i}]")
        verts = piece.get("vertices")
        if not isinstance(verts, list) or not 0 < len(verts) <= MAX_MESH_VERTICES - total:
            CHECK.fail(where, f"{f}[{i}].vertices", f"expected a list of vertices, at most {MAX_MESH_VERTICES} in all")
        total += len(verts)
        try:
            arr = np.array(verts, dtype=float)
        except (ValueError, TypeError):
            CHECK.fail(where, f"{f}[{i}].vertices", "expected rows [x, y, z] of numbers")
        if arr.ndim != 2 or arr.shape[1] != 3 or not np.all(np.abs(arr) <= MAX_COORD):
            CHECK.fail(where, f"{f}[{i}].vertices", f"expected rows [x, y, z] of finite numbers within {MAX_COORD:g} m")
        _int_rows(piece.get("faces"), where, f"{f}[{i}].faces", 4 * MAX_MESH_VERTICES, 0, len(verts) - 1)


# --------------------------------------------------------------------------- against the robot
def check_against_robot(traj: Trajectory, robot: Robot, where: str = "trajectory") -> None:
    """Joint names, limits, speeds and sample steps of ``traj`` against ``robot``; raises TrajectoryFileError."""
    if list(traj.joint_names) != list(robot.joint_names):
        CHECK.fail(where, "joint_names", f"{', '.join(traj.joint_names)} do not match robot '{robot.name}'",
                   f"expected {', '.join(robot.joint_names)}")
    links = set(robot.link_names)
    for i, p in enumerate(traj.payloads):  # a held object's mass rides on a link: simulate, sag and torques need it
        if str(p["link"]) not in links:
            CHECK.fail(where, f"payloads[{i}].link", f"'{p['link']}' is not a link of robot '{robot.name}'",
                       f"the trajectory was planned for another arm: plan it again for {robot.name}")
    names = robot.joint_names
    q, v, a, t = traj.positions, traj.velocities, traj.accelerations, traj.times
    lo, hi = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    vmax, amax = np.asarray(robot.velocity_limits, dtype=float), np.asarray(robot.acceleration_limits, dtype=float)

    def first(mask: np.ndarray) -> tuple[int, int] | None:
        if not mask.any():
            return None
        i, j = np.argwhere(mask)[0]
        return int(i), int(j)

    bad = first((q < lo - POS_TOL) | (q > hi + POS_TOL))
    if bad:
        i, j = bad
        CHECK.fail(where, f"points[{i}].positions ({names[j]})",
                   f"{q[i, j]:.4f} at t = {t[i]:.3f} s is outside the joint limits [{lo[j]:.4f}, {hi[j]:.4f}]",
                   "plan it again with the robot's joint limits")
    vlim = vmax * (1 + VEL_TOL) + 1e-6
    alim = amax * (1 + ACC_TOL) + 1e-6
    for values, limit, bound, field in ((v, vmax, vlim, "velocities"), (a, amax, alim, "accelerations")):
        bad = first(np.abs(values) > bound)
        if bad:
            i, j = bad
            kind = "velocity" if field == "velocities" else "acceleration"
            CHECK.fail(where, f"points[{i}].{field} ({names[j]})",
                       f"{values[i, j]:.4f} at t = {t[i]:.3f} s exceeds the {kind} limit {limit[j]:.4f}",
                       "plan it again; the robot's limits are in its description")
    if len(t) < 2:
        return
    dt = np.diff(t)
    step_max = 1.0 / traj.sample_rate
    k = np.flatnonzero(dt > step_max * (1 + 1e-6) + TIME_TOL)
    if len(k):
        i = int(k[0]) + 1
        CHECK.fail(where, f"points[{i}].time_from_start",
                   f"{dt[i - 1]:g} s after the point before, more than one sample at the declared sample_rate "
                   f"{traj.sample_rate:g} Hz", "a trajectory must be sampled at least at its sample_rate")
    dq = np.diff(q, axis=0)
    # Position steps must agree with the velocities: with |acceleration| <= A over the step,
    # |dq - v0 dt| and |dq - v1 dt| are at most A dt^2 / 2; the mean speed is at most the limit.
    reach = 0.5 * alim * dt[:, None] ** 2 + 1e-6
    worst = np.maximum(np.abs(dq - v[:-1] * dt[:, None]), np.abs(dq - v[1:] * dt[:, None])) - reach
    mean = np.abs(dq) / dt[:, None] - vlim
    bad = first((worst > 0) | (mean > 0))
    if bad:
        i, j = bad
        CHECK.fail(where, f"points[{i + 1}].positions ({names[j]})",
                   f"a step of {dq[i, j]:+.4f} in {dt[i]:g} s from {q[i, j]:.4f} does not follow from the velocities "
                   f"{v[i, j]:.4f} -> {v[i + 1, j]:.4f} within the acceleration limit {amax[j]:.4f}",
                   "the file was edited or damaged; plan it again")


def validate_trajectory(traj_or_doc: Any, robot: Any = None, where: str | None = None) -> Trajectory:
    """The one validator: a ``Trajectory``, a parsed document (dict) or a path -> a checked ``Trajectory``.

    ``robot``: a loaded ``Robot``, a robot name/path, or None for the trajectory's own ``robot``.
    Raises ``TrajectoryFileError`` (an ``InputError``, exit 2) with the point index, joint, value and
    limit of the first violation; ``DescriptionError``/``InputError`` if the robot cannot be loaded.
    """
    if isinstance(traj_or_doc, (str, Path)):
        where = where or str(traj_or_doc)
        traj = parse_document(read_document(traj_or_doc), where)
    elif isinstance(traj_or_doc, Trajectory):
        where = where or "trajectory"
        traj = parse_document(traj_or_doc.to_dict(), where)
    else:
        where = where or "trajectory"
        traj = parse_document(traj_or_doc, where)
    if robot is None:
        robot = robot_of(traj, where)
    elif isinstance(robot, str):
        robot = load_robot(robot)
    check_against_robot(traj, robot, where)
    return traj


def robot_of(traj: Trajectory | SimpleNamespace, where: str = "trajectory") -> Robot:
    """The ``Robot`` a trajectory (or an execution log's fields) was planned for: its carried
    ``robot_description``, else the bundled robot it names (``roarmctl.robot.bundle.trajectory_robot``);
    an unknown robot is an input error naming the file."""
    spec = str(traj.robot)
    try:
        return trajectory_robot(spec, getattr(traj, "robot_description", None), where)
    except TrajectoryFileError:
        raise
    except InputError as exc:
        if getattr(traj, "robot_description", None) is not None:
            raise
        raise type(exc)(f"{where}: robot: the trajectory was planned for robot '{spec[:80]}', which is not installed "
                        f"here ({exc.message})", exc.hint) from None
    except (OSError, ValueError) as exc:  # a name the OS refuses as a path (too long, NUL)
        raise TrajectoryFileError(f"{where}: robot: '{spec[:60]}' is neither a bundled robot nor a readable "
                                  f"file ({exc})") from None


def load_trajectory(path: str | Path) -> Trajectory:
    """Read a ``*.traj.json`` file and check its form; any problem raises ``TrajectoryFileError`` (exit 2).

    The checks against the robot (limits, speeds, steps) are ``validate_trajectory``.
    """
    return parse_document(read_document(path), str(path))


def trajectory_from_dict(data: Any, where: str = "trajectory") -> Trajectory:
    """A parsed trajectory document -> ``Trajectory`` (form only; see ``load_trajectory``)."""
    return parse_document(data, where)
