"""What ``roarmctl teach`` saves: a plan file that ``roarmctl plan`` reads (checked and timed like any other).

The plan starts where the arm stands (``start: current``), carries the scene of the plan given with
``--plan`` (its ``scene``, ``objects`` and ``planner``), and moves through the recorded joint waypoints
in order, one ``move: {joints: [...]}`` task each. A grasp or release is a move to its waypoint that
sets the gripper to the value measured there (``gripper: rad``, as the gripper was when ``g`` was
pressed), so the replay closes and opens the gripper where the hand did (a grasp at one of ``--plan``'s
objects is a ``pick`` of it and its release a ``place``: see ``_picks``); the first waypoint, and any
whose gripper moved by more than ``GRIPPER_MOVED``, set it too (a move sets the gripper after the arm arrives). ``limits.blend`` is false and ``limits.zone`` 0 (written
out): the replay reaches every waypoint and stops there instead of rounding it. Waypoints the planner would refuse (inside
the singularity margin, in collision, beyond a limit) or that lie within the warning band are flagged
in a comment above their task.
"""

from __future__ import annotations

import math
import os
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.teach import NEAR_FACTOR, Waypoint, gripper_index
from roarmctl.fileio import atomic_write_text
from roarmctl.motion.geometry import half_extents
from roarmctl.motion.planning.context import scene_item
from roarmctl.plan.writer import TaskText, move_task, pick_task, place_task, plain
from roarmctl.plan.writer import plan_text as write_plan_text
from roarmctl.robot.ik.pitch import tool_pitch

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

GRASP_REACH = 0.015  # m: a grasp with the TCP this close to an object's box picks that object
GRIPPER_MOVED = 0.02  # rad: a waypoint sets the gripper when it moved more than this since the last one that did
FORMAT_NOTE = "# Taught by hand with 'roarmctl teach': replay with 'roarmctl plan FILE --port PORT' (or --sim)."


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
    header = [FORMAT_NOTE,
              f"# {len(waypoints)} waypoint(s), {len(actions)} gripper action(s) ({', '.join(actions) or 'none'}); "
              f"{flagged} flagged. Judged against singularity margin {margin:.4f} m/rad (warning below {NEAR_FACTOR:g}x)"
              + (f" and the scene of {source.path.name}." if source is not None else ".")]
    tasks = []
    last_grip: float | None = None
    picks = _picks(robot, waypoints, source)
    for k, w in enumerate(waypoints, 1):
        head = f"waypoint {k} at {w.t:.1f} s: sigma {w.measures.sigma:.4f} m/rad"
        if w.measures.clearance is not None:
            head += f", clearance {w.measures.clearance * 1e3:.1f} mm" + (f" ({w.measures.nearest})" if w.measures.nearest else "")
        comments = [head, *(f"FLAGGED: {flag}" for flag in w.flags)]
        grip = float(w.q[gi])
        if k - 1 in picks:
            text, note = picks[k - 1]
            tasks.append(TaskText(text, comments, note))
            last_grip = grip
            continue
        gripper = None
        if w.action is not None or last_grip is None or abs(grip - last_grip) > GRIPPER_MOVED:
            gripper = last_grip = grip
        tasks.append(TaskText(move_task(np.asarray(w.q)[arm], gripper), comments, w.action))
    limits = dict(plain(doc.get("limits") or {}))
    limits["blend"] = False
    limits["zone"] = 0.0
    planner = dict(plain(doc.get("planner") or {}))
    planner.setdefault("singularity_margin", float(margin))
    return write_plan_text(robot.name, tasks, header=header, carried=doc, limits=limits, planner=planner,
                           limits_note="zone: 0, blend: false - every taught waypoint is reached (the arm stops at "
                                       "each; a taught grasp closes after it arrives); give a move a zone and set "
                                       "blend: true to let the replay flow past it")


def _picks(robot: Robot, waypoints: list[Waypoint], source: Any) -> dict[int, tuple[str, str]]:
    """Grasps with the TCP at one of ``source``'s objects (inside its box grown by ``GRASP_REACH``) as
    ``pick`` tasks, and their releases as ``place`` tasks: {waypoint index: (task text, note)}.

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
    out: dict[int, tuple[str, str]] = {}
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
            out[k] = (pick_task(name, pitch, offset, float(w.q[gi])), f"grasp, taught at waypoint {k + 1}")
            held = (name, rel)
            del items[name]
        elif w.action == "release" and held is not None:
            name, rel = held
            xyz = (t_tcp @ np.append(rel, 1.0))[:3]
            out[k] = (place_task(xyz, pitch, float(w.q[gi])), f"release '{name}', taught at waypoint {k + 1}")
            held = None
    return out


def save_plan(path: str | os.PathLike[str], robot: Robot, waypoints: list[Waypoint], margin: float,
              source: Any = None) -> None:
    """Write :func:`plan_text` to ``path`` atomically."""
    atomic_write_text(path, plan_text(robot, waypoints, margin, source))
