"""The plan's items: the table, the scene's obstacles and the objects, each read into an ``ItemSpec`` (its shape,
pose, size or file, and for an object its mass and grasp); a scene of many plain boxes, cylinders and spheres in
one numpy pass, with the same checks and messages as field by field.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.formats import PRIMITIVES, SHAPES
from roarmctl.plan.fields import FIELD_BOUNDS, ReadContext, position
from roarmctl.plan.types import ItemSpec
from roarmctl.robot.model import transform
from roarmctl.validation import LocatedDict, LocatedList, locate

MESH_COLLISION = ("convex", "exact")


def read_item(ctx: ReadContext, raw: Any, line: int, where: str, role: str, frames: dict | None = None) -> ItemSpec:
    """The ``ItemSpec`` of one item (the table, an obstacle or an object, by ``role``): as read before when the same
    item was (``ctx.known``), else field by field."""
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


def _plain_primitive(ctx: ReadContext, raw: Any, where: str, role: str) -> ItemSpec | None:
    """``_plain_primitives`` of one item."""
    return _plain_primitives(ctx, [raw], role, [where])[0]


_BATCH_LEAST = 3  # obstacles that _plain_primitives reads together (its numpy pass costs about what two items read alone do)
_PLAIN_ITEM = (LocatedDict, dict)  # an item _plain_primitives reads: located, or a plan dict's own (``locate_plan``)
_PLAIN_SEQ = (LocatedList, list, tuple)  # its xyz, rpy and size


def _plain_primitives(ctx: ReadContext, raws: list, role: str, wheres: list[str]) -> list[ItemSpec | None]:
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


def read_obstacles(ctx: ReadContext, obs: LocatedList, frames: dict | None) -> list[ItemSpec]:
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
                if type(o) is dict:  # a plan dict's own (``locate_plan``)
                    o = obs[i] = locate(o)
                spec = read_item(ctx, o, obs.line_of(i), where, "obstacle", frames)
            else:
                ctx.specs[id(o)] = spec
            specs[i] = spec
    return specs  # type: ignore[return-value]  # every entry set above


def locate_plan(source: dict) -> Any:
    """``locate(source)``, except that its scene's obstacles stay the dict's own dicts (in a located list):
    ``read_obstacles`` reads plain primitives as they are and locates the others (a scene of many boxes: locating them
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


def _item_spec(ctx: ReadContext, raw: Any, line: int, where: str, role: str, frames: dict | None = None) -> ItemSpec:
    d = ctx.mapping(raw, line, where, _ITEM_KEYS, required=("shape", "xyz") + (("name",) if role != "table" else ()))
    shape = ctx.string(d["shape"], d.line_of("shape"), f"{where}.shape", PRIMITIVES if role == "object" else SHAPES)
    xyz = position(ctx, d["xyz"], d.line_of("xyz"), f"{where}.xyz", frames)
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


def _file_item(ctx: ReadContext, d: LocatedDict, where: str, spec: ItemSpec) -> None:
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
