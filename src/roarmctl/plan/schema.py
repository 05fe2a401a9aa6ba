"""The pick/place plan file's reader: schema and validation; the ``Plan`` it becomes is ``roarmctl.plan.types``.

Every mistake of form (unknown key, wrong type, impossible value, missing reference) raises
``PlanFileError`` naming the file, the line and the field. docs/reference.md documents every field.
Lengths are metres; angles radians, or degrees when written as ``{deg: value}`` / ``{deg: [..]}``.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import math
from pathlib import Path
from typing import Any, NoReturn, TypeVar

import numpy as np

from roarmctl.errors import PlanFileError, describe_value
from roarmctl.formats import MAX_DURATION, PRIMITIVES, SHAPES
from roarmctl.motion.options import LIMITS_BOUNDS, PLANNER_BOUNDS, Limits, PlannerConfig
from roarmctl.plan.types import ItemSpec, MoveTask, PickTask, PlaceTask, Plan, WaitTask
from roarmctl.robot.frames import from_frame
from roarmctl.robot.model import transform
from roarmctl.validation import Bound, Checker, LocatedDict, LocatedList, closest, load_yaml, locate

DICT_NAME = "<plan dict>"  # stands for the file name in errors about a plan given as a dict
MESH_COLLISION = ("convex", "exact")
_O = TypeVar("_O", Limits, PlannerConfig)


class _Ctx:
    """Where we are in the file, for error messages; the field checks are ``roarmctl.validation``'s."""

    check = Checker(PlanFileError)

    def __init__(self, path: Path) -> None:
        self.path = path
        self.is_dict = path.name == DICT_NAME  # a dict's messages name no file and line
        self._file = str(path)
        self.known: dict = {}  # id(raw item) -> ItemSpec validated before (a frame-free item is the same again)
        self.specs: dict = {}  # what this reading validated, for the next

    def where(self, line: int) -> str:
        return DICT_NAME if self.is_dict else f"{self._file}:{line}"

    def fail(self, line: int, field_path: str, message: str, hint: str | None = None) -> NoReturn:
        self.check.fail(self.where(line), field_path or "plan", message, hint)

    def mapping(self, value: Any, line: int, where: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> LocatedDict:
        self.check.mapping(value, self.where(line), where or "plan")
        self.check.known_keys(value, allowed, self.where(line), where or None,
                              line_of=lambda key: self.where(value.line_of(key)))
        for key in required:
            if key not in value:
                self.fail(value.line, where or "plan", f"'{key}' is missing")
        return value

    def listed(self, value: Any, line: int, where: str, most: int, what: str, hint: str | None = None) -> LocatedList:
        """``value`` checked to be a list of at most ``most`` items (``what``: their name in the message)."""
        if not isinstance(value, list):
            self.fail(line, where, "expected a list")
        if len(value) > most:
            self.fail(line, where, f"{len(value)} {what} are more than {most}", hint)
        return value if isinstance(value, LocatedList) else locate(value)

    def number(self, value: Any, line: int, where: str, *, lo: float | None = None, hi: float | None = None,
               angle: bool = False, strict_lo: bool = False) -> float:
        what = "a number (or {deg: value})" if angle else "a number"
        if angle and isinstance(value, dict) and set(value) == {"deg"}:
            value = value["deg"]
            deg = self.check.number(value, self.where(line), where, what="a number of degrees", lo=-1e6, hi=1e6)
            value = math.radians(deg)
        lo, hi = _bounds(where, lo, hi)
        return self.check.number(value, self.where(line), where, lo=lo, hi=hi, strict_lo=strict_lo, what=what)

    def vector(self, value: Any, line: int, where: str, n: int, *, angle: bool = False, positive: bool = False) -> np.ndarray:
        if angle and isinstance(value, dict) and set(value) == {"deg"}:  # each in degrees, its bounds in radians (number)
            degrees = value["deg"]
            if not isinstance(degrees, list) or len(degrees) != n:
                self.fail(line, where, f"expected a list of {n} numbers of degrees, got {_kind(degrees)}")
            return np.array([self.number({"deg": v}, line, f"{where}[{i}]", angle=True, lo=0.0 if positive else None, strict_lo=positive)
                             for i, v in enumerate(degrees)])
        if not isinstance(value, list) or len(value) != n:
            self.fail(line, where, f"expected a list of {n} numbers, got {_kind(value)}")
        lo, hi = _bounds(where, 0.0 if positive else None, None)
        if all(type(v) in (int, float) and lo <= v <= hi and (not positive or v > lo) and math.isfinite(v) for v in value):
            return np.array(value, dtype=float)  # every number fits: the checks below would pass (they name the bad one)
        return np.array([self.number(v, line, f"{where}[{i}]", lo=0.0 if positive else None, strict_lo=positive)
                         for i, v in enumerate(value)])

    def string(self, value: Any, line: int, where: str, choices: tuple[str, ...] | None = None) -> str:
        return self.check.name(value, self.where(line), where, choices=choices, max_len=4096)


#: Range of every number a plan may give, by field name (the last part of its path), intersected
#: with the range the reader passes. Upper bounds keep memory and time small: a wait of 1e8 s would be
#: 10^10 samples, a velocity scale of 1e-9 an endless motion. Units: m, rad, s, kg, m/s.
FIELD_BOUNDS: dict[str, tuple[float, float]] = {
    "wait": (0.0, 3600.0),
    "xyz": (-10.0, 10.0),
    "size": (0.0, 10.0),
    "radius": (0.0, 10.0),
    "length": (0.0, 10.0),
    "mass": (0.0, 100.0),
    "rpy": (-4 * math.pi, 4 * math.pi),
    "pitch": (-4 * math.pi, 4 * math.pi),
    "roll": (-4 * math.pi, 4 * math.pi),
    "joints": (-100.0, 100.0),  # rad or m: the robot's own limits are checked when planning
    "start": (-100.0, 100.0),
    "gripper_open": (-4 * math.pi, 4 * math.pi),
    "gripper_closed": (-4 * math.pi, 4 * math.pi),
    "grasp_offset": (-0.5, 0.5),
    "grasp_width": (0.0, 10.0),
    "gripper": (-4 * math.pi, 4 * math.pi),
    "scale": (0.0, 1e6),
    "resolution": (1e-4, 1.0),
}
# the options' numbers, where they are written (limits.*, planner.*) and wherever a field of the same name is (a move's zone)
FIELD_BOUNDS |= {name: (b.lo, b.hi) for name, b in (LIMITS_BOUNDS | PLANNER_BOUNDS).items()
                 if not (b.flag or b.whole or b.choices)}
DEFAULT_BOUND = 1e6  # any other number, unless its reader gives a tighter range
MAX_TASKS = 1000  # tasks in the file, and tasks x cycles
MAX_CYCLES = 1000
MAX_ITEMS = 500  # obstacles, and objects


def _bounds(where: str, lo: float | None, hi: float | None) -> tuple[float, float]:
    flo, fhi = FIELD_BOUNDS.get(_field_name(where), (-DEFAULT_BOUND, DEFAULT_BOUND))
    return (flo if lo is None else max(lo, flo)), (fhi if hi is None else min(hi, fhi))


def _field_name(where: str) -> str:
    """The field a path names, for ``FIELD_BOUNDS``: "scene.obstacles[3].xyz[0]" -> "xyz", "task 2: wait" -> "wait"
    (its last part after a '.' or ':', index brackets left out)."""
    key = where
    while key.endswith("]"):
        key = key[:key.rfind("[")]
    key = key[key.rfind(".") + 1:]
    return key[key.rfind(":") + 1:].strip()


def _position(ctx: _Ctx, value: Any, line: int, where: str, frames: dict | None) -> np.ndarray:
    """A position: ``[x, y, z]`` in metres (world frame), or ``{FRAME: [x, y, z]}`` in a frame of
    the robot (its unit, e.g. ``{firmware: [300, 0, -100]}`` in mm). Before the robot is known
    (``frames`` None) the numbers are only checked."""
    if isinstance(value, dict) and len(value) == 1 and next(iter(value)) != "deg":
        (name, vals), = value.items()
        v = ctx.vector(vals, line, f"{where}.{name}", 3)
        if frames is None:
            return v
        if name == "world":
            return v
        if name not in frames:
            ctx.fail(line, where, f"the robot has no frame '{name}'", f"frames: {', '.join(['world', *frames])}")

        return from_frame(frames[name], v)
    return ctx.vector(value, line, where, 3)


_kind = describe_value


# ------------------------------------------------------------------ items
def _item(ctx: _Ctx, raw: Any, line: int, where: str, role: str, frames: dict | None = None) -> ItemSpec:
    known = ctx.known.get(id(raw))
    if known is not None and known.role == role:
        ctx.specs[id(raw)] = known
        return known
    spec = _item_spec(ctx, raw, line, where, role, frames)  # one item: field by field is quicker than a batch of one
    if not (isinstance(raw, dict) and isinstance(raw.get("xyz"), dict)):  # no position in a robot frame
        ctx.specs[id(raw)] = spec
    return spec


_ITEM_KEYS = ("name", "shape", "size", "radius", "length", "xyz", "rpy", "mass", "com", "inertia", "grasp_width",
              "file", "scale", "collision", "resolution")
_SHAPE_KEYS = ("size", "radius", "length", "file", "scale", "collision", "resolution")  # each shape has its own of these
_OWN_KEYS = {"box": ("size",), "cylinder": ("radius", "length"), "sphere": ("radius",), "mesh": ("file", "scale", "collision"),
             "cloud": ("file", "resolution")}
_NO_ROTATION = (0.0, 0.0, 0.0)  # rpy when an item gives none


# The keys of an obstacle or the table written as a primitive with nothing else (most of a big scene): a shape's own
_PLAIN_KEYS = {"box": frozenset(("name", "shape", "size", "xyz", "rpy")),
               "cylinder": frozenset(("name", "shape", "radius", "length", "xyz", "rpy")),
               "sphere": frozenset(("name", "shape", "radius", "xyz", "rpy"))}


_NUMBER_TYPES = frozenset((int, float))  # a plain number (bool is not one)
_ONE = 1.0  # stands for a dimension a cylinder or sphere lacks (within every bound below)
# A plain primitive's numbers in one row: xyz, rpy, then size (box) or radius, length (cylinder) or radius (sphere)
_ROW_LO = np.array([FIELD_BOUNDS["xyz"][0]] * 3 + [FIELD_BOUNDS["rpy"][0]] * 3 + [0.0] * 3)
_ROW_HI = np.array([FIELD_BOUNDS["xyz"][1]] * 3 + [FIELD_BOUNDS["rpy"][1]] * 3 + [FIELD_BOUNDS["size"][1]] * 3)
assert FIELD_BOUNDS["radius"] == FIELD_BOUNDS["length"] == FIELD_BOUNDS["size"] == (0.0, 10.0)


def _plain_primitive(ctx: _Ctx, raw: Any, where: str, role: str) -> ItemSpec | None:
    """``_plain_primitives`` of one item."""
    return _plain_primitives(ctx, [raw], role, [where])[0]


_BATCH_LEAST = 3  # obstacles that _plain_primitives reads together (its numpy pass costs about what two items read alone do)
_PLAIN_ITEM = (LocatedDict, dict)  # an item _plain_primitives reads: located, or a plan dict's own (``_locate_plan``)
_PLAIN_SEQ = (LocatedList, list, tuple)  # its xyz, rpy and size


def _plain_primitives(ctx: _Ctx, raws: list, role: str, wheres: list[str]) -> list[ItemSpec | None]:
    """The specs ``_item_spec`` makes of the obstacles (or the table) ``raws`` (``wheres``: their paths) written as a
    box, cylinder or sphere with nothing but its name, shape, size (radius, length), xyz as [x, y, z] and rpy as
    [r, p, y], every field well-formed and within its ``FIELD_BOUNDS``: the same checks on all of them at once (one
    numpy pass over their numbers: the common case of a scene of many items), the same specs. None for any other
    item (and one read before: ``ctx.known``), which ``_item_spec`` reads field by field (and names what is wrong).
    An item may be a located dict or a plan dict's own (not located: its line is 0, as locate would say)."""
    out: list[ItemSpec | None] = [None] * len(raws)
    if role == "object":
        return out
    rows, picked = [], []
    known, plain_keys, seq, no_rotation = ctx.known, _PLAIN_KEYS, _PLAIN_SEQ, _NO_ROTATION
    for i, raw in enumerate(raws):
        if type(raw) not in _PLAIN_ITEM or id(raw) in known:
            continue
        shape = raw.get("shape")
        keys = plain_keys.get(shape) if type(shape) is str else None
        if keys is None or not keys.issuperset(raw) or (role != "table" and "name" not in raw):
            continue
        xyz, rpy = raw.get("xyz"), raw.get("rpy", no_rotation)
        if type(xyz) not in seq or len(xyz) != 3 or (rpy is not no_rotation and (type(rpy) not in seq or len(rpy) != 3)):
            continue
        if shape == "box":
            dims = raw.get("size")
            if type(dims) not in seq or len(dims) != 3:
                continue
        else:
            dims = (raw.get("radius"), raw.get("length"), _ONE) if shape == "cylinder" else (raw.get("radius"), _ONE, _ONE)
        rows.append((*xyz, *rpy, *dims))
        picked.append(i)
    if not set(map(type, itertools.chain.from_iterable(rows))) <= _NUMBER_TYPES:  # a string, bool, None... somewhere
        keep = [k for k, row in enumerate(rows) if set(map(type, row)) <= _NUMBER_TYPES]
        rows, picked = [rows[k] for k in keep], [picked[k] for k in keep]
    if not rows:
        return out
    try:
        a = np.array(rows, dtype=float)
    except OverflowError:  # an integer beyond a float: the field-by-field reader names it
        return out
    ok = np.all((a >= _ROW_LO) & (a <= _ROW_HI), axis=1) & np.all(a[:, 6:] > 0.0, axis=1)  # NaN fails every test
    if not ok.all():
        a = a[ok]
        picked = [i for i, good in zip(picked, ok.tolist(), strict=True) if good]
    # poses: without rotation (rpy +0.0 everywhere, most items) the matrix ``transform`` makes, bit for bit; else its own
    poses = np.zeros((len(a), 4, 4))
    poses[:, range(4), range(4)] = 1.0
    poses[:, 2, 0] = -0.0
    poses[:, :3, 3] = a[:, :3]
    turned = np.flatnonzero(np.any((a[:, 3:6] != 0.0) | np.signbit(a[:, 3:6]), axis=1))
    for k in turned.tolist():
        raw = raws[picked[k]]
        poses[k] = transform(raw["xyz"], raw["rpy"])
    at = ctx.where(0) if ctx.is_dict else None  # a dict's items all name the dict
    for i, pose, dims in zip(picked, poses, a[:, 6:].tolist(), strict=True):
        raw = raws[i]
        shape, name = raw["shape"], str(raw.get("name", "table"))
        line = raw.line if type(raw) is LocatedDict else 0
        where = f"{at or ctx.where(line)}: {wheres[i]}"
        if shape == "box":
            out[i] = ItemSpec(name, role, shape, pose, tuple(dims), line=line, where=where)
        else:
            out[i] = ItemSpec(name, role, shape, pose, radius=dims[0], length=dims[1] if shape == "cylinder" else 0.0,
                              line=line, where=where)
    return out


def _obstacles(ctx: _Ctx, obs: LocatedList, frames: dict | None) -> list[ItemSpec]:
    """The specs of the scene's obstacles ``obs``: those read before as they were (``ctx.known``), the plain primitives
    in one batch (``_plain_primitives``), the others field by field (a plan dict's own item located first, in ``obs``,
    so that the next reading of the document finds it)."""
    specs: list[ItemSpec | None] = [None] * len(obs)
    todo = []
    for i, o in enumerate(obs):
        known = ctx.known.get(id(o))
        if known is not None and known.role == "obstacle":
            ctx.specs[id(o)] = specs[i] = known
        else:
            todo.append(i)
    if todo:
        raws = [obs[i] for i in todo]
        wheres = [f"scene.obstacles[{i}]" for i in todo]
        batch = _plain_primitives(ctx, raws, "obstacle", wheres) if len(todo) >= _BATCH_LEAST else [None] * len(todo)
        for i, o, where, spec in zip(todo, raws, wheres, batch, strict=True):
            if spec is None:  # anything but a plain primitive: field by field
                if type(o) is dict:  # a plan dict's own (``_locate_plan``)
                    o = obs[i] = locate(o)
                spec = _item(ctx, o, obs.line_of(i), where, "obstacle", frames)
            else:
                ctx.specs[id(o)] = spec
            specs[i] = spec
    return specs  # type: ignore[return-value]  # every entry set above


def _locate_plan(source: dict) -> Any:
    """``locate(source)``, except that its scene's obstacles stay the dict's own dicts (in a located list):
    ``_obstacles`` reads plain primitives as they are and locates the others (a scene of many boxes: locating them
    all was a sixth of ``api.plan``'s set-up)."""
    scene = source.get("scene")
    if type(scene) is not dict or type(scene.get("obstacles")) is not list or not scene["obstacles"]:
        return locate(source)
    obstacles = scene["obstacles"]
    raw = locate({**source, "scene": {**scene, "obstacles": []}})
    lst = LocatedList(o if type(o) is dict else locate(o) for o in obstacles)
    lst.line, lst.lines = 0, []
    raw["scene"]["obstacles"] = lst
    return raw


def _item_spec(ctx: _Ctx, raw: Any, line: int, where: str, role: str, frames: dict | None = None) -> ItemSpec:
    d = ctx.mapping(raw, line, where, _ITEM_KEYS, required=("shape", "xyz") + (("name",) if role != "table" else ()))
    shape = ctx.string(d["shape"], d.line_of("shape"), f"{where}.shape", PRIMITIVES if role == "object" else SHAPES)
    xyz = _position(ctx, d["xyz"], d.line_of("xyz"), f"{where}.xyz", frames)
    rpy = ctx.vector(d["rpy"], d.line_of("rpy"), f"{where}.rpy", 3, angle=True) if "rpy" in d else _NO_ROTATION
    spec = ItemSpec(name=str(d.get("name", "table")), role=role, shape=shape, pose=transform(xyz, rpy), line=d.line)
    spec.where = f"{ctx.where(d.line)}: {where}"
    own = _OWN_KEYS[shape]
    for key in _SHAPE_KEYS:
        if key in d and key not in own:
            ctx.fail(d.line_of(key), f"{where}.{key}", f"does not apply to a {shape}")
    if shape in ("mesh", "cloud"):
        _file_item(ctx, d, where, spec)
        return spec
    if shape == "box":
        if "size" not in d:
            ctx.fail(d.line, where, "a box needs 'size: [x, y, z]' (m)")
        spec.size = tuple(ctx.vector(d["size"], d.line_of("size"), f"{where}.size", 3, positive=True).tolist())
    else:
        if "radius" not in d:
            ctx.fail(d.line, where, f"a {shape} needs 'radius' (m)")
        spec.radius = ctx.number(d["radius"], d.line_of("radius"), f"{where}.radius", lo=0, strict_lo=True)
        if shape == "cylinder":
            if "length" not in d:
                ctx.fail(d.line, where, "a cylinder needs 'length' (m, along its local z)")
            spec.length = ctx.number(d["length"], d.line_of("length"), f"{where}.length", lo=0, strict_lo=True)
    if "mass" in d:
        if role != "object":
            ctx.fail(d.line_of("mass"), f"{where}.mass", "only objects have a mass")
        spec.mass = ctx.number(d["mass"], d.line_of("mass"), f"{where}.mass", lo=0)
    for key in ("com", "inertia"):
        if key in d and "mass" not in d:
            ctx.fail(d.line_of(key), f"{where}.{key}", "needs a 'mass' (kg) beside it")
    if "com" in d:
        spec.com = ctx.vector(d["com"], d.line_of("com"), f"{where}.com", 3)
    if "inertia" in d:  # [ixx, iyy, izz] about the COM, object axes
        spec.inertia = np.diag(ctx.vector(d["inertia"], d.line_of("inertia"), f"{where}.inertia", 3))
        if np.any(np.diag(spec.inertia) < 0):
            ctx.fail(d.line_of("inertia"), f"{where}.inertia", "moments of inertia must not be negative")
    if "grasp_width" in d:
        if role != "object":
            ctx.fail(d.line_of("grasp_width"), f"{where}.grasp_width", "only objects are grasped")
        spec.grasp_width = ctx.number(d["grasp_width"], d.line_of("grasp_width"), f"{where}.grasp_width", lo=0, strict_lo=True)
    return spec


def _file_item(ctx: _Ctx, d: LocatedDict, where: str, spec: ItemSpec) -> None:
    """A mesh's or a point cloud's keys: ``file`` (relative to the plan's folder, and inside it), a mesh's
    ``scale`` (a number or [x, y, z]) and ``collision`` (convex | exact), a cloud's ``resolution`` (m)."""
    if "file" not in d:
        ctx.fail(d.line, where, f"a {spec.shape} needs 'file: PATH' (relative to the plan's folder)")
    name = ctx.string(d["file"], d.line_of("file"), f"{where}.file")
    root = ctx.path.parent.resolve()
    path = (root / Path(name)).resolve()
    if not path.is_relative_to(root):
        ctx.fail(d.line_of("file"), f"{where}.file", f"'{name}' lies outside the plan's folder {root}",
                 "put the file in the plan's folder or a folder below it")
    spec.file = path
    if spec.shape == "mesh":
        if "scale" in d:
            v = d["scale"]
            if isinstance(v, list):
                spec.scale = tuple(ctx.vector(v, d.line_of("scale"), f"{where}.scale", 3, positive=True))
            else:
                k = ctx.number(v, d.line_of("scale"), f"{where}.scale", lo=0.0, strict_lo=True)
                spec.scale = (k, k, k)
        if "collision" in d:
            spec.exact = ctx.string(d["collision"], d.line_of("collision"), f"{where}.collision", MESH_COLLISION) == "exact"
    else:
        if "resolution" not in d:
            ctx.fail(d.line, where, "a cloud needs 'resolution' (m, the edge of its occupied cells, e.g. 0.005)")
        spec.resolution = ctx.number(d["resolution"], d.line_of("resolution"), f"{where}.resolution", lo=1e-4, hi=1.0)


# ------------------------------------------------------------------ tasks
def _task(ctx: _Ctx, raw: Any, line: int, where: str, objects: dict[str, ItemSpec], poses: list[str] | None,
          frames: dict | None = None) -> Any:
    if not isinstance(raw, LocatedDict) or len(raw) != 1:
        ctx.fail(line, where, "each task is one of 'pick: {...}', 'place: {...}', 'move: {...}', 'wait: seconds'")
    (kind, body), = raw.items()
    bline = raw.line_of(kind)
    w = f"{where}: {kind}"  # "task 2: place.xyz": tasks count from 1 in every message, as in planning errors
    if kind == "wait":
        if isinstance(body, dict):
            ctx.mapping(body, bline, w, ("seconds",), ("seconds",))
            secs = body["seconds"]
        else:
            secs = body
        return WaitTask(ctx.number(secs, bline, w, lo=0.0), line=bline)
    if kind in ("pick", "place") and isinstance(body, dict) and "zone" in body:
        what = "grasp" if kind == "pick" else "release"
        ctx.fail(body.line_of("zone") if isinstance(body, LocatedDict) else bline, f"{w}.zone",
                 f"a {kind}'s {what} is always reached (the jaws act there), so it takes no zone",
                 "leave zone out; the straight approach and retreat are joined by the planner within 1 mm of their line")
    if kind == "pick":
        d = ctx.mapping(body, bline, w, ("object", "approach_height", "pitch", "roll", "gripper_open", "gripper_closed", "grasp_offset",
                                         "squeeze"), ("object",))
        name = ctx.string(d["object"], d.line_of("object"), f"{w}.object")
        if name not in objects:
            ctx.fail(d.line_of("object"), f"{w}.object", f"no object named '{name}'",
                     f"objects: {', '.join(objects) or 'none'}")
        pick = PickTask(object=name, line=bline)
        _common_grasp(ctx, d, w, pick)
        if "gripper_closed" in d:
            pick.gripper_closed = ctx.number(d["gripper_closed"], d.line_of("gripper_closed"), f"{w}.gripper_closed", angle=True)
        if "grasp_offset" in d:
            pick.grasp_offset = ctx.number(d["grasp_offset"], d.line_of("grasp_offset"), f"{w}.grasp_offset")
        if "squeeze" in d:
            pick.squeeze = ctx.number(d["squeeze"], d.line_of("squeeze"), f"{w}.squeeze", lo=0.0, hi=0.05)
        return pick
    if kind == "place":
        d = ctx.mapping(body, bline, w, ("object", "xyz", "approach_height", "pitch", "roll", "gripper_open"), ("xyz",))
        place = PlaceTask(xyz=_position(ctx, d["xyz"], d.line_of("xyz"), f"{w}.xyz", frames), line=bline)
        if "object" in d:
            place.object = ctx.string(d["object"], d.line_of("object"), f"{w}.object")
            if place.object not in objects:
                ctx.fail(d.line_of("object"), f"{w}.object", f"no object named '{place.object}'", f"objects: {', '.join(objects) or 'none'}")
        _common_grasp(ctx, d, w, place)
        return place
    if kind == "move":
        d = ctx.mapping(body, bline, w, ("pose", "joints", "xyz", "pitch", "gripper", "zone"))
        given = [k for k in ("pose", "joints", "xyz") if k in d]
        if len(given) != 1:
            ctx.fail(bline, w, "give exactly one of 'pose' (a named pose), 'joints' (list) or 'xyz' (+ 'pitch')")
        move = MoveTask(line=bline)
        if "gripper" in d:
            g = d["gripper"]
            if isinstance(g, str):
                move.gripper = ctx.string(g, d.line_of("gripper"), f"{w}.gripper", ("open", "closed"))
            else:
                move.gripper = ctx.number(g, d.line_of("gripper"), f"{w}.gripper", angle=True)
        if "zone" in d:
            move.zone = ctx.number(d["zone"], d.line_of("zone"), f"{w}.zone")
        if "pose" in d:
            move.pose = ctx.string(d["pose"], d.line_of("pose"), f"{w}.pose", tuple(poses) if poses is not None else None)
        elif "joints" in d:
            j = d["joints"]
            deg = isinstance(j, dict) and set(j) == {"deg"}
            vals = j["deg"] if deg else j
            if not isinstance(vals, list):
                ctx.fail(d.line_of("joints"), f"{w}.joints", "expected a list of joint values (rad) or {deg: [...]}")
            move.joints = ctx.vector(j, d.line_of("joints"), f"{w}.joints", len(vals), angle=True)
        else:
            move.xyz = _position(ctx, d["xyz"], d.line_of("xyz"), f"{w}.xyz", frames)
            if "pitch" in d:
                _pitch(ctx, d, w, move)
        return move
    close = closest(str(kind), ("pick", "place", "move", "wait"))
    ctx.fail(bline, f"{where}", f"unknown task '{kind}'", f"did you mean '{close}'?" if close else "tasks: pick, place, move, wait")


def _pitch(ctx: _Ctx, d: LocatedDict, w: str, t: Any) -> None:
    """``pitch: angle``, ``pitch: auto`` (nearest valid to straight down) or ``pitch: {auto: angle}``
    (nearest valid to that angle)."""
    v, line = d["pitch"], d.line_of("pitch")
    t.pitch_set = True
    if v == "auto":
        t.pitch, t.pitch_auto = math.pi / 2, True
    elif isinstance(v, dict) and set(v) == {"auto"}:
        t.pitch = ctx.number(v["auto"], line, f"{w}.pitch.auto", angle=True, lo=-math.pi, hi=math.pi)
        t.pitch_auto = True
    else:
        if isinstance(v, str):
            ctx.fail(line, f"{w}.pitch", f"'{v}' is not an angle", "give an angle, {deg: 90}, 'auto' or {auto: {deg: 60}}")
        t.pitch = ctx.number(v, line, f"{w}.pitch", angle=True, lo=-math.pi, hi=math.pi)


def _common_grasp(ctx: _Ctx, d: LocatedDict, w: str, t: Any) -> None:
    if "approach_height" in d:
        t.approach_height = ctx.number(d["approach_height"], d.line_of("approach_height"), f"{w}.approach_height", lo=0.0, hi=0.3)
    if "pitch" in d:
        _pitch(ctx, d, w, t)
    if "roll" in d:
        t.roll = ctx.number(d["roll"], d.line_of("roll"), f"{w}.roll", angle=True, lo=-math.pi, hi=math.pi)
    if "gripper_open" in d:
        t.gripper_open = ctx.number(d["gripper_open"], d.line_of("gripper_open"), f"{w}.gripper_open", angle=True)


# ------------------------------------------------------------------ top level
TOP_KEYS = ("robot", "start", "scene", "objects", "tasks", "cycles", "limits", "planner")


def load_plan(source: str | Path | dict, named_poses: list[str] | None = None, base_dir: str | Path | None = None,
              frames: dict | None = None, parsed: Plan | None = None) -> Plan:
    """Read and validate a plan: a YAML file path, or a dict of the same form (built in code).

    ``named_poses``, when given, are the robot's pose names (for checking ``start`` and
    ``move: {pose}``); the pipeline passes them after loading the robot. For a dict, errors name
    ``<plan dict>`` instead of a file and line, and a relative ``robot`` path is taken from
    ``base_dir`` (default: the current directory). ``frames``: the robot's frames (positions written
    as ``{FRAME: [x, y, z]}`` are converted to the world frame). ``start: current`` stays the string
    ``"current"`` (the caller measures it). ``parsed``: a ``Plan`` this function returned for the same
    ``source``; its parsed document is validated again (with ``named_poses`` and ``frames``), not read again.
    """
    if parsed is not None and parsed.document is not None:
        raw, path, digest = parsed.document, parsed.path, parsed.sha256
    elif isinstance(source, dict):
        digest = _dict_digest(source)
        raw = _locate_plan(source)
        path = Path(base_dir or ".") / DICT_NAME
    else:
        path = Path(source)
        raw, digest = load_yaml(path, PlanFileError, digest=True)
    ctx = _Ctx(path)
    ctx.known = parsed.item_specs if parsed is not None and parsed.document is raw else {}
    # top-level keys starting with 'x-' are ignored: a place to define YAML anchors for '<<: *name'
    extensions = tuple(k for k in raw if isinstance(k, str) and k.startswith("x-")) if isinstance(raw, dict) else ()
    if isinstance(raw, dict) and "datagen" in raw:  # a template names the plan it varies: say which command reads it
        ctx.fail(raw.line_of("datagen") if isinstance(raw, LocatedDict) else 1, "datagen",
                 "this is a datagen template, not a plan", f"make a dataset from it: roarmctl datagen {path} -n N -o DIR")
    top = ctx.mapping(raw, getattr(raw, "line", 1), "", TOP_KEYS + extensions, required=("robot", "tasks"))
    robot = ctx.string(top["robot"], top.line_of("robot"), "robot")

    start: str | np.ndarray = "home"
    if "start" in top:
        s = top["start"]
        if isinstance(s, str):
            start = "current" if s == "current" else ctx.string(
                s, top.line_of("start"), "start", tuple(named_poses) + ("current",) if named_poses is not None else None)
        else:
            vals = s["deg"] if isinstance(s, dict) and "deg" in s else s
            if not isinstance(vals, list):
                ctx.fail(top.line_of("start"), "start", "expected a named pose or a list of joint values")
            start = ctx.vector(s, top.line_of("start"), "start", len(vals), angle=True)

    scene: list[ItemSpec] = []
    if "scene" in top:
        sc = ctx.mapping(top["scene"], top.line_of("scene"), "scene", ("table", "obstacles"))
        if "table" in sc and sc["table"] is not None:
            scene.append(_item(ctx, sc["table"], sc.line_of("table"), "scene.table", "table", frames))
        obs = ctx.listed(sc.get("obstacles") or [], sc.line_of("obstacles"), "scene.obstacles", MAX_ITEMS, "obstacles")
        scene.extend(_obstacles(ctx, obs, frames))

    objects: list[ItemSpec] = []
    objs = ctx.listed(top.get("objects") or [], top.line_of("objects"), "objects", MAX_ITEMS, "objects")
    for i, o in enumerate(objs):
        objects.append(_item(ctx, o, objs.line_of(i), f"objects[{i}]", "object", frames))
    names: dict[str, ItemSpec] = {}
    for item in scene + objects:
        if item.name in names:
            ctx.fail(item.line, "name", f"'{item.name}' is used twice", "give every obstacle and object its own name")
        names[item.name] = item
    by_object = {o.name: o for o in objects}

    tasks_raw = top["tasks"]
    if not isinstance(tasks_raw, list) or not tasks_raw:
        ctx.fail(top.line_of("tasks"), "tasks", "expected a non-empty list of tasks")
    tasks_raw = ctx.listed(tasks_raw, top.line_of("tasks"), "tasks", MAX_TASKS, "tasks", "split the plan")
    tasks = [_task(ctx, t, tasks_raw.line_of(i), f"task {i + 1}", by_object, named_poses, frames) for i, t in enumerate(tasks_raw)]

    cycles = 1
    if "cycles" in top:
        c = top["cycles"]
        if isinstance(c, bool) or not isinstance(c, int) or c < 1:
            ctx.fail(top.line_of("cycles"), "cycles", f"expected a whole number >= 1, got {_kind(c)}")
        if c > MAX_CYCLES or c * len(tasks) > MAX_TASKS:
            ctx.fail(top.line_of("cycles"), "cycles", f"{c} cycles of {len(tasks)} task(s) are more than {MAX_TASKS} tasks",
                     f"at most {min(MAX_CYCLES, MAX_TASKS // len(tasks))} cycles of this plan")
        cycles = c

    limits = _options(ctx, top, "limits", Limits, LIMITS_BOUNDS)
    planner = _options(ctx, top, "planner", PlannerConfig, PLANNER_BOUNDS)

    least = cycles * sum(_least_duration(t, limits) for t in tasks)
    if least > MAX_DURATION:
        ctx.fail(top.line_of("cycles" if cycles > 1 else "tasks"), "cycles" if cycles > 1 else "tasks",
                 f"the plan needs at least {least:.0f} s of motion ({least * 100:.0f} samples at 100 Hz), "
                 f"more than the {MAX_DURATION:.0f} s a trajectory may last", "split it, or shorten the waits")

    return Plan(path=path, sha256=digest, robot=robot, start=start, scene=scene, objects=objects, tasks=tasks,
                cycles=cycles, limits=limits, planner=planner, lines=dict(top.lines), document=raw, item_specs=ctx.specs)


def _options(ctx: _Ctx, top: LocatedDict, section: str, cls: type[_O], bounds: dict[str, Bound]) -> _O:
    """The options object of a top-level section (``limits``, ``planner``): each field written checked against the
    object's own bound (``bounds``), the error naming file, line and ``section.field``; the rest its defaults."""
    if section not in top:
        return cls()
    d = ctx.mapping(top[section], top.line_of(section), section, tuple(bounds))
    given = {key: bounds[key].check(d[key], ctx.check, ctx.where(d.line_of(key)), f"{section}.{key}")
             for key in bounds if key in d and not (bounds[key].optional and d[key] is None)}
    return cls(**given)


def _json_value(value: Any) -> Any:
    """What ``locate`` makes of a value JSON has no form for (numpy arrays and scalars: lists and numbers), else its text."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


def _dict_digest(source: dict) -> str:
    """sha256 of a plan dict: of its JSON, keys sorted, numpy values as ``locate`` makes them (the text of the located
    dict, without walking it twice). A key JSON cannot sort or write (a number beside names) makes it the dict's
    repr; the checks name such a key."""
    try:
        text = json.dumps(source, sort_keys=True, default=_json_value)
    except (TypeError, ValueError):
        text = repr(source)
    return hashlib.sha256(text.encode()).hexdigest()


def _least_duration(task: Any, limits: Limits) -> float:
    """A lower bound (s) on the motion ``task`` becomes: its wait, its gripper action, and its
    straight approach and retreat at ``max_tcp_speed``. Refusing a plan above the limit before
    planning is then never wrong."""
    if isinstance(task, WaitTask):
        return task.seconds
    if isinstance(task, (PickTask, PlaceTask)):
        approach = 2 * task.approach_height / limits.max_tcp_speed if limits.max_tcp_speed else 0.0
        return limits.gripper_time + approach
    return 0.0
