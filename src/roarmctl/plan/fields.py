"""The plan reader's context and field checks: where in the file a value is (for messages), the range of every
number a plan may give (``FIELD_BOUNDS``), and positions in a robot frame. ``roarmctl.plan.schema`` reads the file
with them; ``roarmctl.plan.items`` and ``roarmctl.plan.tasks`` read its sections.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from roarmctl.checks import Checker
from roarmctl.errors import PlanFileError, describe_value
from roarmctl.motion.options import LIMITS_BOUNDS, PLANNER_BOUNDS
from roarmctl.robot.frames import from_frame
from roarmctl.validation import LocatedDict, LocatedList, locate

DICT_NAME = "<plan dict>"  # stands for the file name in errors about a plan given as a dict


class ReadContext:
    """Where we are in the file, for error messages; the field checks are ``roarmctl.checks``'s."""

    check = Checker(PlanFileError)

    def __init__(self, path: Path) -> None:
        self.path = path
        self.is_dict = path.name == DICT_NAME  # a dict's messages name no file and line
        self._file = str(path)
        self.known: dict = {}  # id(raw item) -> ItemSpec validated before (a frame-free item is the same again)
        self.specs: dict = {}  # what this reading validated, for the next

    def where(self, line: int) -> str:
        """The place ``line`` names in messages: "FILE:LINE", or ``DICT_NAME`` for a plan dict."""
        return DICT_NAME if self.is_dict else f"{self._file}:{line}"

    def fail(self, line: int, field_path: str, message: str, hint: str | None = None) -> NoReturn:
        """Raise PlanFileError naming the file, ``line`` and ``field_path`` (the whole plan when empty)."""
        self.check.fail(self.where(line), field_path or "plan", message, hint)

    def mapping(self, value: Any, line: int, where: str, allowed: tuple[str, ...], required: tuple[str, ...] = ()) -> LocatedDict:
        """``value`` checked to be a mapping with only ``allowed`` keys (an unknown one named, with the closest) and every
        ``required`` one."""
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
        """A number within ``lo``..``hi`` and its field's ``FIELD_BOUNDS``; with ``angle``, ``{deg: value}`` too (radians out)."""
        what = "a number (or {deg: value})" if angle else "a number"
        if angle and isinstance(value, dict) and set(value) == {"deg"}:
            value = value["deg"]
            deg = self.check.number(value, self.where(line), where, what="a number of degrees", lo=-1e6, hi=1e6)
            value = math.radians(deg)
        lo, hi = _bounds(where, lo, hi)
        return self.check.number(value, self.where(line), where, lo=lo, hi=hi, strict_lo=strict_lo, what=what)

    def vector(self, value: Any, line: int, where: str, n: int, *, angle: bool = False, positive: bool = False) -> np.ndarray:
        """A list of ``n`` numbers (n,) within their field's bounds (``positive``: each > 0); with ``angle``, ``{deg: [..]}`` too."""
        if angle and isinstance(value, dict) and set(value) == {"deg"}:  # each in degrees, its bounds in radians (number)
            degrees = value["deg"]
            if not isinstance(degrees, list) or len(degrees) != n:
                self.fail(line, where, f"expected a list of {n} numbers of degrees, got {describe_value(degrees)}")
            return np.array([self.number({"deg": v}, line, f"{where}[{i}]", angle=True, lo=0.0 if positive else None, strict_lo=positive)
                             for i, v in enumerate(degrees)])
        if not isinstance(value, list) or len(value) != n:
            self.fail(line, where, f"expected a list of {n} numbers, got {describe_value(value)}")
        lo, hi = _bounds(where, 0.0 if positive else None, None)
        if all(type(v) in (int, float) and lo <= v <= hi and (not positive or v > lo) and math.isfinite(v) for v in value):
            return np.array(value, dtype=float)  # every number fits: the checks below would pass (they name the bad one)
        return np.array([self.number(v, line, f"{where}[{i}]", lo=0.0 if positive else None, strict_lo=positive)
                         for i, v in enumerate(value)])

    def string(self, value: Any, line: int, where: str, choices: tuple[str, ...] | None = None) -> str:
        """A name (at most 4096 characters), one of ``choices`` when given."""
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


def position(ctx: ReadContext, value: Any, line: int, where: str, frames: dict | None) -> np.ndarray:
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
