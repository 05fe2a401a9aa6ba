"""The plan's tasks: pick, place, move and wait, each read into its task type; and the least time each takes,
for refusing a plan longer than a trajectory may last before planning it.
"""

from __future__ import annotations

import math
from typing import Any

from roarmctl.checks import closest
from roarmctl.motion.options import Limits
from roarmctl.plan.fields import ReadContext, position
from roarmctl.plan.types import ItemSpec, MoveTask, PickTask, PlaceTask, WaitTask
from roarmctl.validation import LocatedDict


def read_task(ctx: ReadContext, raw: Any, line: int, where: str, objects: dict[str, ItemSpec], poses: list[str] | None,
              frames: dict | None = None) -> Any:
    """One task of the list (``where``: "task N"): a ``PickTask``, ``PlaceTask``, ``MoveTask`` or ``WaitTask``, its
    object checked against ``objects`` and a named pose against ``poses`` (None: not known yet)."""
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
        place = PlaceTask(xyz=position(ctx, d["xyz"], d.line_of("xyz"), f"{w}.xyz", frames), line=bline)
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
            move.xyz = position(ctx, d["xyz"], d.line_of("xyz"), f"{w}.xyz", frames)
            if "pitch" in d:
                _pitch(ctx, d, w, move)
        return move
    close = closest(str(kind), ("pick", "place", "move", "wait"))
    ctx.fail(bline, f"{where}", f"unknown task '{kind}'", f"did you mean '{close}'?" if close else "tasks: pick, place, move, wait")


def _pitch(ctx: ReadContext, d: LocatedDict, w: str, t: Any) -> None:
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


def _common_grasp(ctx: ReadContext, d: LocatedDict, w: str, t: Any) -> None:
    if "approach_height" in d:
        t.approach_height = ctx.number(d["approach_height"], d.line_of("approach_height"), f"{w}.approach_height", lo=0.0, hi=0.3)
    if "pitch" in d:
        _pitch(ctx, d, w, t)
    if "roll" in d:
        t.roll = ctx.number(d["roll"], d.line_of("roll"), f"{w}.roll", angle=True, lo=-math.pi, hi=math.pi)
    if "gripper_open" in d:
        t.gripper_open = ctx.number(d["gripper_open"], d.line_of("gripper_open"), f"{w}.gripper_open", angle=True)


def least_duration(task: Any, limits: Limits) -> float:
    """A lower bound (s) on the motion ``task`` becomes: its wait, its gripper action, and its
    straight approach and retreat at ``max_tcp_speed``. Refusing a plan above the limit before
    planning is then never wrong."""
    if isinstance(task, WaitTask):
        return task.seconds
    if isinstance(task, (PickTask, PlaceTask)):
        approach = 2 * task.approach_height / limits.max_tcp_speed if limits.max_tcp_speed else 0.0
        return limits.gripper_time + approach
    return 0.0
