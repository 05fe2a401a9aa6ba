"""The plan writer: a plan file as YAML text that ``roarmctl.plan.schema.load_plan`` reads back.

``plan_text`` writes the sections in the order the reader documents them (``robot``, ``start``, the carried
``scene`` and ``objects``, ``tasks``, ``limits``, ``planner``), with a comment above a task where its writer
has something to say (``roarmctl teach`` flags a waypoint the planner would refuse). The task makers write one
task each in the reader's words: joint angles in rad, positions in m, pitch in degrees.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import yaml


@dataclass(frozen=True)
class TaskText:
    """One task of a written plan: its YAML flow mapping (``move: {...}``), the comment lines above it and a
    short note after it on the same line."""

    text: str
    comments: Sequence[str] = field(default_factory=tuple)
    note: str | None = None


def plain(value: Any) -> Any:
    """Located YAML containers (dict/list subclasses) -> plain ones that ``yaml.safe_dump`` writes."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [plain(v) for v in value]
    return value


def section(key: str, value: Any) -> str:
    """One top-level section as YAML (no trailing newline)."""
    return yaml.safe_dump({key: plain(value)}, sort_keys=False, default_flow_style=None, width=110).rstrip()


def numbers(values: Iterable[float]) -> str:
    """A flow list of numbers to 1e-6 (rad or m)."""
    return "[" + ", ".join(f"{float(v):.6f}" for v in values) + "]"


def move_task(joints: Iterable[float], gripper: float | None = None) -> str:
    """``move: {joints: [...] (rad), gripper: rad}``; no gripper keeps it as it is."""
    body = f"joints: {numbers(joints)}"
    if gripper is not None:
        body += f", gripper: {gripper:.6f}"
    return f"move: {{{body}}}"


def pick_task(name: str, pitch_deg: float, grasp_offset: float, gripper_closed: float) -> str:
    """``pick`` of object ``name`` at a tool pitch (deg), the TCP ``grasp_offset`` m above its centre, the
    gripper closed to ``gripper_closed`` rad."""
    return (f"pick: {{object: {name}, pitch: {{deg: {pitch_deg:.2f}}}, grasp_offset: {grasp_offset:.4f}, "
            f"gripper_closed: {gripper_closed:.6f}}}")


def place_task(xyz: Iterable[float], pitch_deg: float, gripper_open: float) -> str:
    """``place`` of the held object with its centre at ``xyz`` (m), at a tool pitch (deg), the gripper
    opened to ``gripper_open`` rad."""
    return f"place: {{xyz: {numbers(xyz)}, pitch: {{deg: {pitch_deg:.2f}}}, gripper_open: {gripper_open:.6f}}}"


def plan_text(robot: str, tasks: Sequence[TaskText], *, header: Sequence[str] = (), start: str = "current",
              carried: dict[str, Any] | None = None, limits: dict[str, Any] | None = None,
              limits_note: str | None = None, planner: dict[str, Any] | None = None) -> str:
    """A plan file's text. ``header``: comment lines at the top (each starting with '#'); ``carried``: sections
    copied from another plan (``scene``, ``objects``), written in that order when present; ``limits_note``: a
    comment line above ``limits``."""
    lines = [*header, f"robot: {robot}", f"start: {start}", ""]
    for key in ("scene", "objects"):
        if carried and key in carried:
            lines.append(section(key, carried[key]))
    lines.append("tasks:")
    for task in tasks:
        lines.extend(f"  # {c}" for c in task.comments)
        lines.append(f"  - {task.text}" + (f"   # {task.note}" if task.note else ""))
    if limits is not None:
        if limits_note:
            lines.append(f"# {limits_note}")
        lines.append(section("limits", limits))
    if planner is not None:
        lines.append(section("planner", planner))
    return "\n".join(lines) + "\n"
