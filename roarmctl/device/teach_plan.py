"""What ``roarmctl teach`` saves: a plan file that ``roarmctl plan`` reads (checked and timed like any other).

The plan starts where the arm stands (``start: current``), carries the scene of the plan given with
``--plan`` (its ``scene``, ``objects`` and ``planner``), and moves through the recorded joint waypoints
in order, one ``move: {joints: [...]}`` task each. A grasp or release is a move to its waypoint that
sets the gripper to the value measured there (``gripper: rad``, as the gripper was when ``g`` was
pressed), so the replay closes and opens the gripper where the hand did; the first waypoint, and any
whose gripper moved by more than ``GRIPPER_MOVED``, set it too (a move sets the gripper after the arm arrives). ``limits.blend`` is false:
the replay stops at every waypoint instead of rounding it. Waypoints the planner would refuse (inside
the singularity margin, in collision, beyond a limit) or that lie within the warning band are flagged
in a comment above their task.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import yaml

from roarmctl.device.teach import NEAR_FACTOR, Waypoint, gripper_index
from roarmctl.fileio import atomic_write_text

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


def _numbers(values) -> str:
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def plan_text(robot, waypoints: list[Waypoint], margin: float, source: Any = None) -> str:
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
    for k, w in enumerate(waypoints, 1):
        head = f"  # waypoint {k} at {w.t:.1f} s: sigma {w.measures.sigma:.4f} m/rad"
        if w.measures.clearance is not None:
            head += f", clearance {w.measures.clearance * 1e3:.1f} mm" + (f" ({w.measures.nearest})" if w.measures.nearest else "")
        lines.append(head)
        for flag in w.flags:
            lines.append(f"  # FLAGGED: {flag}")
        body = f"joints: {_numbers(np.asarray(w.q)[arm])}"
        grip = float(w.q[gi])
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


def save_plan(path, robot, waypoints: list[Waypoint], margin: float, source: Any = None) -> None:
    """Write :func:`plan_text` to ``path`` atomically."""
    atomic_write_text(path, plan_text(robot, waypoints, margin, source))
