"""The datagen template: a plan file plus a ``datagen:`` block saying what to randomise per episode.

    datagen:
      task: "put the cube on the left"          # the language instruction of every episode
      objects:                                    # per object of the plan (all keys optional)
        cube: {x: [0.20, 0.30], y: [-0.22, -0.10], yaw_deg: [-20, 20], scale: [0.9, 1.1],
               mass: [0.02, 0.05], colors: [[0.8, 0.1, 0.1], [0.1, 0.4, 0.9]]}
      places:                                     # one per place task, in order: where its object goes
        - {x: [0.20, 0.30], y: [0.10, 0.20]}
      distractors: {count: [0, 2], x: [0.15, 0.35], y: [-0.05, 0.05], size: [0.02, 0.03], mass: [0.01, 0.03]}
      obstacles:   {count: [0, 1], x: [0.30, 0.36], y: [-0.04, 0.04], size: [0.02, 0.04], height: [0.04, 0.10]}
      start_jitter_deg: 3                         # each arm joint of the start pose, uniformly within +-this

Ranges are ``[lo, hi]`` (uniform; ``lo == hi`` is a fixed value); positions are m in the world frame, the
z of every sampled item keeps its bottom on the plan's (its centre moves by half the change in height).
Distractors are boxes that are never picked (touching them is an unintended contact); obstacles are
fixed boxes standing on the table. Everything is checked here (``load_template``: exit 2 with the file,
line and field); ``check_reach`` then asks the robot's IK whether every corner of each region can be
reached, so that a region the arm cannot reach is an input error, not a thousand rejected episodes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roarmctl.errors import PlanFileError, RoarmError
from roarmctl.plan.fields import FIELD_BOUNDS
from roarmctl.plan.schema import load_plan
from roarmctl.plan.types import PickTask, PlaceTask, Plan
from roarmctl.robot.ik import solve_ik
from roarmctl.validation import LocatedDict, load_yaml

if TYPE_CHECKING:
    import numpy as np

    from roarmctl.robot.model import Robot

KEY = "datagen"
_KEYS = ("task", "objects", "places", "distractors", "obstacles", "start_jitter_deg", "fps")
_OBJECT_KEYS = ("x", "y", "yaw_deg", "scale", "mass", "colors")
_CLUTTER_KEYS = ("count", "x", "y", "size", "height", "mass")
MAX_CLUTTER = 8  # distractors or obstacles per episode
MAX_COLORS = 64
MAX_TASK = 500  # characters of the task string


@dataclass(frozen=True)
class Range:
    """A uniform range ``[lo, hi]`` (a fixed value when equal)."""

    lo: float
    hi: float

    def sample(self, rng: np.random.Generator) -> float:
        """One value drawn from ``rng`` (always one draw, also when fixed: the stream stays aligned)."""
        u = float(rng.random())
        return self.lo + (self.hi - self.lo) * u


@dataclass
class ObjectRandom:
    """How one object of the plan varies: its centre's ``x``/``y`` (m), yaw (rad), a uniform ``scale`` of its
    size, its ``mass`` (kg) and its colour (RGB 0-1, one of ``colors``)."""

    name: str
    x: Range | None = None
    y: Range | None = None
    yaw: Range | None = None
    scale: Range | None = None
    mass: Range | None = None
    colors: list[tuple[float, float, float]] = field(default_factory=list)


@dataclass
class PlaceRandom:
    """Where a place task's object goes: its centre's ``x``/``y`` (m)."""

    x: Range
    y: Range


@dataclass
class ClutterRandom:
    """Boxes added to each episode: ``count`` (lo, hi) of them, centre ``x``/``y`` (m), edge ``size`` (m),
    ``height`` (m, obstacles; distractors are cubes), ``mass`` (kg, distractors)."""

    count: tuple[int, int]
    x: Range
    y: Range
    size: Range
    height: Range | None = None
    mass: Range | None = None


@dataclass
class Template:
    """A checked template: the plan it varies (``plan``, checked; ``document``: its plain mapping, the
    ``datagen`` key removed), the task string and the randomisation."""

    path: Path
    plan: Plan
    document: dict[str, Any]
    task: str
    objects: dict[str, ObjectRandom]
    places: list[PlaceRandom]
    distractors: ClutterRandom | None = None
    obstacles: ClutterRandom | None = None
    start_jitter: float = 0.0  # rad
    fps: int = 30
    sha256: str = ""


def _plain(value: Any) -> Any:
    """Located YAML values -> plain dicts and lists (the per-episode plans are edited copies)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


class _Check:
    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, line: int, where: str, message: str, hint: str | None = None) -> Any:
        raise PlanFileError(f"{self.path}:{line}: {KEY}.{where}: {message}", hint)

    def mapping(self, value: Any, line: int, where: str, allowed: tuple[str, ...]) -> LocatedDict:
        if not isinstance(value, dict):
            self.fail(line, where, "expected a mapping")
        for k in value:
            if k not in allowed:
                self.fail(value.line_of(k) if hasattr(value, "line_of") else line, f"{where}.{k}", "unknown key",
                          f"allowed: {', '.join(allowed)}")
        return value

    def number(self, value: Any, line: int, where: str, lo: float, hi: float) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(line, where, f"expected a number, got {type(value).__name__}")
        x = float(value)
        if not math.isfinite(x):
            self.fail(line, where, f"expected a finite number, got {x}")
        if not lo <= x <= hi:
            self.fail(line, where, f"{x:g} is out of range", f"use {lo:g} to {hi:g}")
        return x

    def range(self, value: Any, line: int, where: str, lo: float, hi: float) -> Range:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            x = self.number(value, line, where, lo, hi)
            return Range(x, x)
        if not isinstance(value, list) or len(value) != 2:
            self.fail(line, where, "expected [lo, hi] (or one number)")
        a, b = (self.number(v, line, f"{where}[{i}]", lo, hi) for i, v in enumerate(value))
        if a > b:
            self.fail(line, where, f"the range [{a:g}, {b:g}] is empty", "write the smaller bound first")
        return Range(a, b)


_XY = FIELD_BOUNDS["xyz"]


def _object(c: _Check, raw: Any, line: int, where: str, name: str) -> ObjectRandom:
    d = c.mapping(raw, line, where, _OBJECT_KEYS)
    at = d.line_of if hasattr(d, "line_of") else (lambda _k: line)
    out = ObjectRandom(name)
    if "x" in d:
        out.x = c.range(d["x"], at("x"), f"{where}.x", *_XY)
    if "y" in d:
        out.y = c.range(d["y"], at("y"), f"{where}.y", *_XY)
    if "yaw_deg" in d:
        r = c.range(d["yaw_deg"], at("yaw_deg"), f"{where}.yaw_deg", -180.0, 180.0)
        out.yaw = Range(math.radians(r.lo), math.radians(r.hi))
    if "scale" in d:
        out.scale = c.range(d["scale"], at("scale"), f"{where}.scale", 0.25, 4.0)
    if "mass" in d:
        out.mass = c.range(d["mass"], at("mass"), f"{where}.mass", 1e-4, 5.0)
        if out.mass.lo <= 0:
            c.fail(at("mass"), f"{where}.mass", "a mass must be positive")
    if "colors" in d:
        cols = d["colors"]
        if not isinstance(cols, list) or not cols or len(cols) > MAX_COLORS:
            c.fail(at("colors"), f"{where}.colors", f"expected a list of 1 to {MAX_COLORS} [r, g, b] colours")
        for i, col in enumerate(cols):
            if not isinstance(col, list) or len(col) != 3:
                c.fail(at("colors"), f"{where}.colors[{i}]", "expected [r, g, b], each 0 to 1")
            rgb = tuple(c.number(v, at("colors"), f"{where}.colors[{i}]", 0.0, 1.0) for v in col)
            out.colors.append((rgb[0], rgb[1], rgb[2]))
    return out


def _clutter(c: _Check, raw: Any, line: int, where: str, obstacle: bool) -> ClutterRandom:
    d = c.mapping(raw, line, where, _CLUTTER_KEYS)
    at = d.line_of if hasattr(d, "line_of") else (lambda _k: line)
    for k in ("count", "x", "y", "size"):
        if k not in d:
            c.fail(line, f"{where}.{k}", "is missing")
    n = c.range(d["count"], at("count"), f"{where}.count", 0, MAX_CLUTTER)
    if n.lo != int(n.lo) or n.hi != int(n.hi):
        c.fail(at("count"), f"{where}.count", "expected whole numbers")
    out = ClutterRandom((int(n.lo), int(n.hi)), c.range(d["x"], at("x"), f"{where}.x", *_XY),
                        c.range(d["y"], at("y"), f"{where}.y", *_XY), c.range(d["size"], at("size"), f"{where}.size", 0.005, 0.3))
    if out.size.lo <= 0:
        c.fail(at("size"), f"{where}.size", "a size must be positive")
    if "height" in d:
        if not obstacle:
            c.fail(at("height"), f"{where}.height", "distractors are cubes: give size only")
        out.height = c.range(d["height"], at("height"), f"{where}.height", 0.005, 1.0)
    elif obstacle:
        out.height = out.size
    if "mass" in d:
        if obstacle:
            c.fail(at("mass"), f"{where}.mass", "obstacles are fixed: they have no mass")
        out.mass = c.range(d["mass"], at("mass"), f"{where}.mass", 1e-4, 5.0)
    elif not obstacle:
        out.mass = Range(0.02, 0.02)
    return out


def load_template(path: str | Path) -> Template:
    """Read and check a template (``PlanFileError``, exit 2, naming file, line and field)."""
    path = Path(path)
    raw, digest = load_yaml(path, PlanFileError, digest=True)
    c = _Check(path)
    if not isinstance(raw, dict) or KEY not in raw:
        raise PlanFileError(f"{path}: not a datagen template: the '{KEY}:' block is missing",
                            "a template is a plan file plus a 'datagen:' block (see the guide)")
    top_line = raw.line_of(KEY) if hasattr(raw, "line_of") else 1
    g = c.mapping(raw[KEY], top_line, "", _KEYS)
    at = g.line_of if hasattr(g, "line_of") else (lambda _k: top_line)
    document = _plain({k: v for k, v in raw.items() if k != KEY})
    try:
        plan = load_plan(document, base_dir=path.parent)
    except PlanFileError as exc:  # the same checks as a plan file; the message names the template
        raise PlanFileError(f"{path}: {exc.message.replace('<plan dict>: ', '')}", exc.hint) from None
    plan = replace(plan, path=path)  # the template names itself in later messages
    task = g.get("task", "")
    if not isinstance(task, str) or not task.strip() or len(task) > MAX_TASK or "\n" in task:
        c.fail(at("task"), "task", f"expected one line of text (1 to {MAX_TASK} characters)",
               "the instruction a policy is trained on, e.g. 'put the cube on the left'")
    names = {o.name for o in plan.objects}
    objects: dict[str, ObjectRandom] = {}
    objs = g.get("objects") or {}
    c.mapping(objs, at("objects"), "objects", tuple(sorted(names)) or ("(no objects in the plan)",))
    for name, spec in objs.items():
        line = objs.line_of(name) if hasattr(objs, "line_of") else at("objects")
        objects[str(name)] = _object(c, spec, line, f"objects.{name}", str(name))
    places_raw = g.get("places") or []
    n_place = sum(isinstance(t, PlaceTask) for t in plan.tasks)
    if not isinstance(places_raw, list) or len(places_raw) not in (0, n_place):
        c.fail(at("places"), "places", f"expected one region per place task ({n_place})")
    places = []
    for i, p in enumerate(places_raw):
        line = places_raw.line_of(i) if hasattr(places_raw, "line_of") else at("places")
        d = c.mapping(p, line, f"places[{i}]", ("x", "y"))
        if "x" not in d or "y" not in d:
            c.fail(line, f"places[{i}]", "give both x and y ranges")
        places.append(PlaceRandom(c.range(d["x"], line, f"places[{i}].x", *_XY), c.range(d["y"], line, f"places[{i}].y", *_XY)))
    t = Template(path, plan, document, task.strip(), objects, places, sha256=digest)
    if g.get("distractors") is not None:
        t.distractors = _clutter(c, g["distractors"], at("distractors"), "distractors", obstacle=False)
    if g.get("obstacles") is not None:
        t.obstacles = _clutter(c, g["obstacles"], at("obstacles"), "obstacles", obstacle=True)
    if "start_jitter_deg" in g:
        t.start_jitter = math.radians(c.number(g["start_jitter_deg"], at("start_jitter_deg"), "start_jitter_deg", 0.0, 30.0))
    if "fps" in g:
        fps = c.number(g["fps"], at("fps"), "fps", 1, 120)
        if fps != int(fps):
            c.fail(at("fps"), "fps", "expected a whole number of frames per second")
        t.fps = int(fps)
    return t


def _corners(x: Range, y: Range) -> list[tuple[float, float]]:
    return [(x.lo, y.lo), (x.lo, y.hi), (x.hi, y.lo), (x.hi, y.hi), ((x.lo + x.hi) / 2, (y.lo + y.hi) / 2)]


def check_reach(template: Template, robot: Robot) -> None:
    """Every corner (and the centre) of each object and place region must have an IK solution at the
    task's pitch, at the object's height and at its approach height above: else ``PlanFileError`` naming
    the region and the corner (collisions are left to the episodes: they vary with the scene)."""
    plan = template.plan
    by_name = {o.name: o for o in plan.objects}
    picks = {t.object: t for t in plan.tasks if isinstance(t, PickTask)}
    place_tasks = [t for t in plan.tasks if isinstance(t, PlaceTask)]

    def reachable(x: float, y: float, z: float, pitch: float) -> bool:
        try:
            return bool(solve_ik(robot, (x, y, z), pitch=pitch))
        except RoarmError:
            return False

    def check(where: str, x: Range, y: Range, z: float, rise: float, pitch: float, pitch_auto: bool) -> None:
        for cx, cy in _corners(x, y):
            for h in (z, z + rise):
                if not reachable(cx, cy, h, pitch) and not (pitch_auto and reachable(cx, cy, h, math.pi / 2)):
                    raise PlanFileError(f"{template.path}: {KEY}.{where}: the arm cannot reach ({cx:.3f}, {cy:.3f}, "
                                        f"{h:.3f}) m at a pitch of {math.degrees(pitch):.0f} deg",
                                        "move the region nearer to the arm or make it smaller")

    for name, o in template.objects.items():
        spec, pick = by_name[name], picks.get(name)
        if pick is None or (o.x is None and o.y is None):
            continue
        px, py = float(spec.pose[0, 3]), float(spec.pose[1, 3])
        check(f"objects.{name}", o.x or Range(px, px), o.y or Range(py, py), float(spec.pose[2, 3]) + pick.grasp_offset,
              pick.approach_height, pick.pitch, pick.pitch_auto)
    for i, (p, task) in enumerate(zip(template.places, place_tasks)):
        check(f"places[{i}]", p.x, p.y, float(task.xyz[2]), task.approach_height, task.pitch, task.pitch_auto)
