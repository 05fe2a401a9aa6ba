"""What ``roarmctl teach`` saves: a plan file that ``roarmctl plan`` reads (checked and timed like any other).

The plan starts where the arm stands (``start: current``), carries the scene of the plan given with
``--plan`` (its ``scene``, ``objects`` and ``planner``), and moves through the recorded joint waypoints
in order, one ``move: {joints: [...]}`` task each. A grasp or release is a move to its waypoint that
sets the gripper to the value measured there (``gripper: rad``, as the gripper was when ``g`` was
pressed), so the replay closes and opens the gripper where the hand did (a grasp at one of ``--plan``'s
objects is a ``pick`` of it and its release a ``place``: see ``_picks``); the first waypoint, and any
whose gripper moved by more than ``GRIPPER_MOVED``, set it too (a move sets the gripper after the arm arrives). ``limits.blend`` is false:
the replay stops at every waypoint instead of rounding it. Waypoints the planner would refuse (inside
the singularity margin, in collision, beyond a limit) or that lie within the warning band are flagged
in a comment above their task.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from roarmctl.device.teach import NEAR_FACTOR, Waypoint, gripper_index
from roarmctl.fileio import atomic_write_text
from roarmctl.motion.geometry import half_extents
from roarmctl.motion.planning.context import scene_item
from roarmctl.robot.ik.pitch import tool_pitch

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

GRASP_REACH = 0.015  # m: a grasp with the TCP this close to an object's box picks that object
GRIPPER_MOVED = 0.02  # rad: a waypoint sets the gripper when it moved more than this since the last one that did
FORMAT_NOTE = "# Taught by hand with 'roarmctl teach': replay with 'roarmctl plan FILE --port PORT' (or --sim)."


def _plain(value: Any) -> Any:
    """Located YAML containers (dict/list subclasses) -> plain ones that ``yaml.safe_dump`` writes."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def _dump(key: str, value: Any) -> str:
    return yaml.safe_dump({key: _plain(value)}, sort_keys=False, default_flow_style=None, width=110)


def _numbers(values: Iterable[float]) -> str:
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def plan_text(robot: Robot, waypoints: list[Waypoint], margin: float, source: Any = None) -> str:
    """The taught plan as YAML text. ``robot``: the taught ``Robot``; ``margin`` m/rad: the singularity
    margin the waypoints were judged against; ``source``: the ``Plan`` given with ``--plan`` (its parsed
    document supplies scene, objects, limits and planner), or None."""
    if not waypoints:
        raise ValueError("no waypoints to save")
    doc = source.document if source is not None and source.document is not None else {}
    arm = list(robot.arm_indices)
    gi = gripper_index(robot)
    flagged = sum(1 for w in waypoints if w.flags)
    actions = [w.action for w in waypoints if w.action]
    lines = [FORMAT_NOTE,
             f"# {len(waypoints)} waypoint(s), {len(actions)} gripper action(s) ({', '.join(actions) or 'none'}); "
             f"{flagged} flagged. Judged against singularity margin {margin:.4f} m/rad (warning below {NEAR_FACTOR:g}x)"
             + (f" and the scene of {source.path.name}." if source is not None else "."),
             f"robot: {robot.name}", "start: current", ""]
    for key in ("scene", "objects"):
        if key in doc:
            lines.append(_dump(key, doc[key]).rstrip())
    lines.append("tasks:")
    last_grip: float | None = None
    picks = _picks(robot, waypoints, source)
    for k, w in enumerate(waypoints, 1):
        head = f"  # waypoint {k} at {w.t:.1f} s: sigma {w.measures.sigma:.4f} m/rad"
        if w.measures.clearance is not None:
            head += f", clearance {w.measures.clearance * 1e3:.1f} mm" + (f" ({w.measures.nearest})" if w.measures.nearest else "")
        lines.append(head)
        for flag in w.flags:
            lines.append(f"  # FLAGGED: {flag}")
        grip = float(w.q[gi])
        if k - 1 in picks:
            lines.append(f"  - {picks[k - 1]}")
            last_grip = grip
            continue
        body = f"joints: {_numbers(np.asarray(w.q)[arm])}"
        if w.action is not None or last_grip is None or abs(grip - last_grip) > GRIPPER_MOVED:
            body += f", gripper: {grip:.6f}"
            last_grip = grip
        lines.append(f"  - move: {{{body}}}" + (f"   # {w.action}" if w.action else ""))
    limits = dict(_plain(doc.get("limits") or {}))
    limits["blend"] = False
    lines.append("# blend: false - stop at every taught waypoint rather than round it")
    lines.append(_dump("limits", limits).rstrip())
    planner = dict(_plain(doc.get("planner") or {}))
    planner.setdefault("singularity_margin", float(margin))
    lines.append(_dump("planner", planner).rstrip())
    return "\n".join(lines) + "\n"


def _picks(robot: Robot, waypoints: list[Waypoint], source: Any) -> dict[int, str]:
    """Grasps with the TCP at one of ``source``'s objects (inside its box grown by ``GRASP_REACH``) as
    ``pick`` tasks, and their releases as ``place`` tasks: {waypoint index: task text}.

    The pick grasps the object at the taught pitch, ``grasp_offset`` the TCP's height above the object's
    centre, closing the gripper to the taught value; the place puts the object's centre where the taught
    release carried it (the object held rigidly from the taught grasp), at the taught pitch. So the plan
    carries the object (collision-checked as held) and the planner times the grasp and release; the pick's
    and place's own IK choose the arm's configuration there (the taught TCP, less any sideways offset from
    the object's centre at the grasp)."""
    if source is None or not source.objects:
        return {}
    items = {spec.name: scene_item(spec) for spec in source.objects}
    gi = gripper_index(robot)
    out: dict[int, str] = {}
    held: tuple[str, np.ndarray] | None = None  # object name, its centre in the TCP frame
    for k, w in enumerate(waypoints):
        t_tcp = robot.kin.fk(robot.full_q(w.q))
        pitch = math.degrees(tool_pitch(robot, w.q))
        if w.action == "grasp" and held is None:
            p = t_tcp[:3, 3]
            best = None
            for name, item in items.items():
                local = np.linalg.solve(item.pose, np.append(p, 1.0))[:3]
                h = half_extents(item.shape, item.size, item.radius, item.length) + GRASP_REACH
                if np.all(np.abs(local) <= h) and (best is None or np.linalg.norm(local) < best[1]):
                    best = (name, float(np.linalg.norm(local)))
            if best is None:
                continue
            name = best[0]
            centre = items[name].pose[:3, 3]
            rel = np.linalg.solve(t_tcp, np.append(centre, 1.0))[:3]
            offset = float(p[2] - centre[2])
            out[k] = (f"pick: {{object: {name}, pitch: {{deg: {pitch:.2f}}}, grasp_offset: {offset:.4f}, "
                      f"gripper_closed: {float(w.q[gi]):.6f}}}   # grasp, taught at waypoint {k + 1}")
            held = (name, rel)
            del items[name]
        elif w.action == "release" and held is not None:
            name, rel = held
            xyz = (t_tcp @ np.append(rel, 1.0))[:3]
            out[k] = (f"place: {{xyz: {_numbers(xyz)}, pitch: {{deg: {pitch:.2f}}}, gripper_open: {float(w.q[gi]):.6f}}}"
                      f"   # release '{name}', taught at waypoint {k + 1}")
            held = None
    return out


def save_plan(path: str | os.PathLike[str], robot: Robot, waypoints: list[Waypoint], margin: float,
              source: Any = None) -> None:
    """Write :func:`plan_text` to ``path`` atomically."""
    atomic_write_text(path, plan_text(robot, waypoints, margin, source))
