"""MoveIt's joint_limits.yaml, turned into per-joint limits (``joint_limits: file.yaml`` in the sidecar).

Per joint ``has_velocity_limits`` / ``max_velocity``, ``has_acceleration_limits`` / ``max_acceleration``,
``has_deceleration_limits`` / ``max_deceleration`` (MoveIt 2; roarmctl's timing brakes as it speeds up, so the
smaller of the two magnitudes is the acceleration limit), ``has_position_limits`` / ``min_position`` /
``max_position``; a limit whose ``has_*`` is false is not used (the URDF's or the sidecar's applies).
``default_velocity_scaling_factor`` / ``default_acceleration_scaling_factor`` are MoveIt's per-request defaults:
read and checked, not limits (the plan file's ``velocity_scale`` plays that role); ``cartesian_limits`` (Pilz's) are
read, not used, with a note. Jerk limits are refused when switched on. Entries for joints that roarmctl does not
drive (mimic fingers) are read and checked but not used.

Two layouts: MoveIt 1's (``joint_limits:`` at the top) and a ROS 2 parameter file's, which MoveIt 2's launch files
load (``NODE: {ros__parameters: {robot_description_planning: {joint_limits: ...}}}``). A launch file loads the
latter with substitutions (``ParameterFile(..., allow_substs=True)``): ``$(var NAME)`` is replaced by the launch
argument NAME before the YAML is read; roarmctl takes its value from the sidecar's ``xacro_args`` (those launch
files pass the same arguments to xacro), and refuses any other substitution.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from roarmctl.errors import DescriptionError, describe_value
from roarmctl.fileio import Roots, read_text
from roarmctl.validation import parse_yaml

JOINT_LIMITS_BYTES = 1024 * 1024  # a joint_limits.yaml may have (published ones: < 10 KiB)
_SUBSTITUTION = re.compile(r"\$\(([^()]*)\)")
_KEYS = {"has_velocity_limits", "max_velocity", "has_acceleration_limits", "max_acceleration",
         "has_deceleration_limits", "max_deceleration", "has_position_limits", "min_position", "max_position",
         "has_jerk_limits", "max_jerk", "has_effort_limits", "max_effort", "angle_wraparound"}
_TOP = {"joint_limits", "default_velocity_scaling_factor", "default_acceleration_scaling_factor", "cartesian_limits"}


def substituted(text: str, args: Mapping[str, Any] | None, where: str) -> str:
    """``text`` with each ``$(var NAME)`` replaced by ``args[NAME]`` (a launch file's substitution, done on the text
    before YAML reads it, as ``launch_ros`` does); any other ``$(...)``, or a NAME not in ``args``, is refused."""
    def one(m: re.Match[str]) -> str:
        words = m.group(1).split()
        if len(words) != 2 or words[0] != "var":
            raise DescriptionError(f"{where}: '{m.group(0)[:40]}': only $(var NAME) is read in a joint_limits file",
                                   "write the value itself")
        if args is None or words[1] not in args:
            raise DescriptionError(f"{where}: '$(var {words[1][:40]})' has no value",
                                   f"give it in the sidecar's xacro_args (e.g. xacro_args: {{{words[1][:40]}: ''}})")
        return str(args[words[1]])

    values = [one(m) for m in _SUBSTITUTION.finditer(text)]
    if len(text) + sum(map(len, values)) > 4 * JOINT_LIMITS_BYTES:  # counted before the text is made
        raise DescriptionError(f"{where}: the $(var ...) substitutions make more than {4 * JOINT_LIMITS_BYTES:,} characters")
    it = iter(values)
    return _SUBSTITUTION.sub(lambda m: next(it), text)


def _unwrapped(data: Any, src: str) -> dict:
    """The limits mapping of either layout (a ROS 2 parameter file's ``NODE.ros__parameters.robot_description_planning``)."""
    if not isinstance(data, dict):
        raise DescriptionError(f"{src}: expected a mapping at the top level")
    if len(data) == 1:
        node, inner = next(iter(data.items()))
        if isinstance(inner, dict) and "ros__parameters" in inner:
            params = inner["ros__parameters"]
            planning = params.get("robot_description_planning") if isinstance(params, dict) else None
            if not isinstance(planning, dict):
                raise DescriptionError(f"{src}: {node}.ros__parameters: no robot_description_planning mapping "
                                       "(where MoveIt 2 reads joint limits)")
            return planning
    return data


def read_joint_limits(path: Path, joints: set[str], where: str, roots: Roots | None = None,
                      args: Mapping[str, Any] | None = None,
                      notes: list[str] | None = None) -> dict[str, dict[str, float]]:
    """MoveIt joint_limits.yaml -> {joint: {velocity, acceleration, lower, upper}} (only the limits in force; rad or
    m, per s, per s²). Read inside ``roots``, bounded (size, nesting, UTF-8); ``args``: the values of ``$(var NAME)``;
    what is read but not used is appended to ``notes``."""
    src = str(path)
    text = read_text(path, f"{where}: joint_limits", JOINT_LIMITS_BYTES, roots=roots, error=DescriptionError)
    data = _unwrapped(parse_yaml(substituted(text, args, src), src, DescriptionError) or {}, src)
    for key in ("default_velocity_scaling_factor", "default_acceleration_scaling_factor"):
        v = data.get(key, 1.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= 1:
            raise DescriptionError(f"{src}: {key}: expected a number in (0, 1], got {v!r}")
    unknown = set(data) - _TOP
    if unknown:
        raise DescriptionError(f"{src}: unknown key(s) {sorted(unknown)}")
    if data.get("cartesian_limits") is not None and notes is not None:
        notes.append(f"{src}: cartesian_limits not used (Pilz's; roarmctl's plans give max_tcp_speed)")
    out: dict[str, dict[str, float]] = {}
    limits = data.get("joint_limits") or {}
    if not isinstance(limits, dict):
        raise DescriptionError(f"{src}: joint_limits: expected a mapping joint -> limits, got {describe_value(limits)}")
    for jname, spec in limits.items():
        loc = f"{src}: joint_limits.{jname}"
        if jname not in joints:
            raise DescriptionError(f"{loc}: not a joint of the URDF")
        if not isinstance(spec, dict):
            raise DescriptionError(f"{loc}: expected a mapping")
        bad = set(spec) - _KEYS
        if bad:
            raise DescriptionError(f"{loc}: unknown key(s) {sorted(bad)}")

        def num(key: str, spec: dict = spec, loc: str = loc) -> float:
            v = spec.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise DescriptionError(f"{loc}.{key}: expected a number, got {v!r}")
            return float(v)

        got: dict[str, float] = {}
        for flag, key, name in (("has_velocity_limits", "max_velocity", "velocity"),
                                ("has_acceleration_limits", "max_acceleration", "acceleration")):
            if spec.get(flag) is True:
                v = num(key)
                if v <= 0:
                    raise DescriptionError(f"{loc}.{key}: must be positive when {flag} is true")
                got[name] = v
        if spec.get("has_deceleration_limits") is True:
            v = num("max_deceleration")
            if v == 0:
                raise DescriptionError(f"{loc}.max_deceleration: must not be 0 when has_deceleration_limits is true")
            if abs(v) < got.get("acceleration", math.inf):
                if "acceleration" in got and notes is not None:
                    notes.append(f"{loc}: max_deceleration {v:g} is smaller than max_acceleration "
                                 f"{got['acceleration']:g}: the acceleration limit is {abs(v):g} (roarmctl's timing "
                                 "brakes as it speeds up)")
                got["acceleration"] = abs(v)
        if spec.get("has_position_limits") is True:
            got["lower"], got["upper"] = num("min_position"), num("max_position")
            if got["lower"] >= got["upper"]:
                raise DescriptionError(f"{loc}: min_position must be below max_position")
        if spec.get("has_jerk_limits") is True:
            raise DescriptionError(f"{loc}.has_jerk_limits: jerk limits are not supported by roarmctl's timing",
                                   "set has_jerk_limits: false")
        out[jname] = got
    return out
