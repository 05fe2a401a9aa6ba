"""The pick/place plan file's reader: the top level (robot, start, scene, objects, tasks, cycles, limits, planner)
into the ``Plan`` of ``roarmctl.plan.types``; the items are read by ``roarmctl.plan.items``, the tasks by
``roarmctl.plan.tasks``, each field checked through ``roarmctl.plan.fields``.

Every mistake of form (unknown key, wrong type, impossible value, missing reference) raises
``PlanFileError`` naming the file, the line and the field. docs/reference.md documents every field.
Lengths are metres; angles radians, or degrees when written as ``{deg: value}`` / ``{deg: [..]}``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from roarmctl.checks import Bound
from roarmctl.errors import PlanFileError, describe_value
from roarmctl.formats import MAX_DURATION
from roarmctl.motion.options import LIMITS_BOUNDS, PLANNER_BOUNDS, Limits, PlannerConfig
from roarmctl.plan.fields import DICT_NAME, ReadContext
from roarmctl.plan.items import locate_plan, read_item, read_obstacles
from roarmctl.plan.tasks import least_duration, read_task
from roarmctl.plan.types import ItemSpec, Plan
from roarmctl.validation import LocatedDict, load_yaml

_O = TypeVar("_O", Limits, PlannerConfig)
MAX_TASKS = 1000  # tasks in the file, and tasks x cycles
MAX_CYCLES = 1000
MAX_ITEMS = 500  # obstacles, and objects

TOP_KEYS = ("robot", "start", "scene", "objects", "tasks", "cycles", "limits", "planner")


@dataclass(frozen=True)
class PlanDocument:
    """A plan file read but not yet checked against its robot: the parsed ``document`` (located values), its
    ``path`` (``<plan dict>`` under ``base_dir`` for a dict), ``sha256`` and the ``robot`` it names (a string, at
    line ``robot_line``). ``load_plan(..., parsed=doc)`` checks every field from it without reading it again."""

    path: Path
    sha256: str
    robot: str
    robot_line: int
    document: Any
    item_specs: dict = field(default_factory=dict, repr=False)  # none yet: the items are checked once, by load_plan


def _read(source: str | Path | dict, base_dir: str | Path | None) -> tuple[Any, Path, str]:
    """The parsed document, path and sha256 of a plan file or dict."""
    if isinstance(source, dict):
        return locate_plan(source), Path(base_dir or ".") / DICT_NAME, _dict_digest(source)
    path = Path(source)
    raw, digest = load_yaml(path, PlanFileError, digest=True)
    return raw, path, digest


def _top(ctx: ReadContext, raw: Any, path: Path) -> LocatedDict:
    """The plan's top-level mapping, its keys checked (a datagen template named as such)."""
    # top-level keys starting with 'x-' are ignored: a place to define YAML anchors for '<<: *name'
    extensions = tuple(k for k in raw if isinstance(k, str) and k.startswith("x-")) if isinstance(raw, dict) else ()
    if isinstance(raw, dict) and "datagen" in raw:  # a template names the plan it varies: say which command reads it
        ctx.fail(raw.line_of("datagen") if isinstance(raw, LocatedDict) else 1, "datagen",
                 "this is a datagen template, not a plan", f"make a dataset from it: roarmctl datagen {path} -n N -o DIR")
    return ctx.mapping(raw, getattr(raw, "line", 1), "", TOP_KEYS + extensions, required=("robot", "tasks"))


def read_plan_document(source: str | Path | dict, base_dir: str | Path | None = None) -> PlanDocument:
    """Read a plan (a YAML file path or a dict) once, and check what finding its robot needs: the top level's keys
    and ``robot``. The rest is checked by ``load_plan(source, named_poses, frames=..., parsed=doc)`` once the
    robot (its poses and frames) is known."""
    raw, path, digest = _read(source, base_dir)
    ctx = ReadContext(path)
    top = _top(ctx, raw, path)
    robot = ctx.string(top["robot"], top.line_of("robot"), "robot")
    return PlanDocument(path, digest, robot, top.line_of("robot"), raw)


def load_plan(source: str | Path | dict, named_poses: list[str] | None = None, base_dir: str | Path | None = None,
              frames: dict | None = None, parsed: Plan | PlanDocument | None = None) -> Plan:
    """Read and validate a plan: a YAML file path, or a dict of the same form (built in code).

    ``named_poses``, when given, are the robot's pose names (for checking ``start`` and
    ``move: {pose}``); the pipeline passes them after loading the robot. For a dict, errors name
    ``<plan dict>`` instead of a file and line, and a relative ``robot`` path is taken from
    ``base_dir`` (default: the current directory). ``frames``: the robot's frames (positions written
    as ``{FRAME: [x, y, z]}`` are converted to the world frame). ``start: current`` stays the string
    ``"current"`` (the caller measures it). ``parsed``: the ``PlanDocument`` of ``read_plan_document`` (the file
    read once, its robot found first), or a ``Plan`` this function returned for the same ``source``: its parsed
    document is checked (with ``named_poses`` and ``frames``), not read again.
    """
    if parsed is not None and parsed.document is not None:
        raw, path, digest = parsed.document, parsed.path, parsed.sha256
    else:
        raw, path, digest = _read(source, base_dir)
    ctx = ReadContext(path)
    ctx.known = parsed.item_specs if parsed is not None and parsed.document is raw else {}
    top = _top(ctx, raw, path)
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
            scene.append(read_item(ctx, sc["table"], sc.line_of("table"), "scene.table", "table", frames))
        obs = ctx.listed(sc.get("obstacles") or [], sc.line_of("obstacles"), "scene.obstacles", MAX_ITEMS, "obstacles")
        scene.extend(read_obstacles(ctx, obs, frames))

    objects: list[ItemSpec] = []
    objs = ctx.listed(top.get("objects") or [], top.line_of("objects"), "objects", MAX_ITEMS, "objects")
    for i, o in enumerate(objs):
        objects.append(read_item(ctx, o, objs.line_of(i), f"objects[{i}]", "object", frames))
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
    tasks = [read_task(ctx, t, tasks_raw.line_of(i), f"task {i + 1}", by_object, named_poses, frames) for i, t in enumerate(tasks_raw)]

    cycles = 1
    if "cycles" in top:
        c = top["cycles"]
        if isinstance(c, bool) or not isinstance(c, int) or c < 1:
            ctx.fail(top.line_of("cycles"), "cycles", f"expected a whole number >= 1, got {describe_value(c)}")
        if c > MAX_CYCLES or c * len(tasks) > MAX_TASKS:
            ctx.fail(top.line_of("cycles"), "cycles", f"{c} cycles of {len(tasks)} task(s) are more than {MAX_TASKS} tasks",
                     f"at most {min(MAX_CYCLES, MAX_TASKS // len(tasks))} cycles of this plan")
        cycles = c

    limits = _options(ctx, top, "limits", Limits, LIMITS_BOUNDS)
    planner = _options(ctx, top, "planner", PlannerConfig, PLANNER_BOUNDS)

    least = cycles * sum(least_duration(t, limits) for t in tasks)
    if least > MAX_DURATION:
        ctx.fail(top.line_of("cycles" if cycles > 1 else "tasks"), "cycles" if cycles > 1 else "tasks",
                 f"the plan needs at least {least:.0f} s of motion ({least * 100:.0f} samples at 100 Hz), "
                 f"more than the {MAX_DURATION:.0f} s a trajectory may last", "split it, or shorten the waits")

    return Plan(path=path, sha256=digest, robot=robot, start=start, scene=scene, objects=objects, tasks=tasks,
                cycles=cycles, limits=limits, planner=planner, lines=dict(top.lines), document=raw, item_specs=ctx.specs)


def _options(ctx: ReadContext, top: LocatedDict, section: str, cls: type[_O], bounds: dict[str, Bound]) -> _O:
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
