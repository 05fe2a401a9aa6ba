"""The sidecar YAML's fields that the URDF and DH formats share: limits, gripper, named poses, wire fields,
allowed collisions, frames and the tool offset (docs/reference.md, "Robot descriptions").

Every mistake raises ``DescriptionError`` naming the file and the field.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot import validate as checks
from roarmctl.robot.frames import UNITS, Frame
from roarmctl.robot.implied import DEFAULT_JERK_PER_ACCELERATION
from roarmctl.robot.model import FixedJaw, Gripper, Joint, WireField, transform

FORMAT = "roarmctl.robot/1"


def read_sidecar(path: Path) -> dict[str, Any]:
    """A sidecar or DH YAML file as a mapping, bounded like a plan file; its ``format`` must be ours."""
    data = checks.read_yaml(path)  # bounded like a plan file: size, nesting, aliases, UTF-8
    if not isinstance(data, dict):
        raise DescriptionError(f"{path}: expected a mapping at the top level")
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        raise DescriptionError(f"{path}: format: '{fmt}' is not supported (expected '{FORMAT}')")
    checks.check_document(data, str(path))
    return data


def number(value: Any, where: str, *, angle: bool = False, deg: bool = False) -> float:
    """``value`` as a float (radians if ``angle`` and ``deg``: the file's angles are in degrees)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DescriptionError(f"{where}: expected a number, got {value!r}")
    return math.radians(value) if (angle and deg) else float(value)


def vector(value: Any, n: int, where: str) -> np.ndarray:
    """``value`` as ``n`` floats, shape (n,)."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise DescriptionError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return np.array([number(v, f"{where}[{i}]") for i, v in enumerate(value)])


def _fixed_jaw(value: Any, where: str) -> FixedJaw:
    """``{link, point: [x, y, z] m, normal: [x, y, z]}`` -> FixedJaw (normal made unit; the link is checked
    once the robot is built)."""
    if not isinstance(value, dict) or not isinstance(value.get("link"), str):
        raise DescriptionError(f"{where}: expected {{link, point: [x, y, z], normal: [x, y, z]}}")
    point = vector(value.get("point"), 3, f"{where}.point")
    normal = vector(value.get("normal"), 3, f"{where}.normal")
    norm = float(np.linalg.norm(normal))
    if not norm > 1e-9 or not np.all(np.isfinite(point)):
        raise DescriptionError(f"{where}.normal: must be a non-zero vector")
    return FixedJaw(value["link"], (float(point[0]), float(point[1]), float(point[2])),
                    (float(normal[0]) / norm, float(normal[1]) / norm, float(normal[2]) / norm))


def _per_joint(data: dict, key: str, names: list[str], default: np.ndarray, where: str) -> np.ndarray:
    """A per-joint value given as a list (in joint order) or a {joint: value} mapping."""
    value = data.get(key)
    if value is None:
        return default
    if isinstance(value, list):
        out = vector(value, len(names), f"{where}.{key}")
        for name, v in zip(names, out):
            if v <= 0:
                raise DescriptionError(f"{where}.{key}.{name}: must be positive")
        return out
    if isinstance(value, dict):
        out = default.copy()
        for name, v in value.items():
            if name not in names:
                raise DescriptionError(f"{where}.{key}: unknown joint '{name}' (joints: {', '.join(names)})")
            out[names.index(name)] = number(v, f"{where}.{key}.{name}")
            if out[names.index(name)] <= 0:
                raise DescriptionError(f"{where}.{key}.{name}: must be positive")
        return out
    raise DescriptionError(f"{where}.{key}: expected a list or a mapping joint -> value")


def common_fields(data: dict, path: Path, names: list[str], velocity: np.ndarray, acceleration: np.ndarray,
            effort: np.ndarray | None = None, defaulted: dict[str, set[str]] | None = None) -> dict:
    """Sidecar fields shared by the URDF and DH formats.

    ``defaulted``: limit kind -> joints whose value in ``velocity`` / ``acceleration`` is roarmctl's
    default (the description gave none); those the sidecar's ``limits`` sets are dropped from it, and
    jerk is defaulted wherever the sidecar gives none. Returned as ``defaults`` (kind -> joint names)."""
    where = str(path)
    limits = data.get("limits", {}) or {}
    if not isinstance(limits, dict):
        raise DescriptionError(f"{where}: limits: expected a mapping with 'velocity' and 'acceleration'")

    def given(key: str) -> set[str]:
        value = limits.get(key)
        return set(names) if isinstance(value, list) else set(value) if isinstance(value, dict) else set()

    defaults = {key: [n for n in names if n in (defaulted or {}).get(key, set()) and n not in given(key)]
                for key in ("velocity", "acceleration")}
    defaults["jerk"] = [n for n in names if n not in given("jerk")]
    defaults = {k: v for k, v in defaults.items() if v}
    vel = _per_joint(limits, "velocity", names, velocity, f"{where}: limits")
    acc = _per_joint(limits, "acceleration", names, acceleration, f"{where}: limits")
    jerk = _per_joint(limits, "jerk", names, acc * DEFAULT_JERK_PER_ACCELERATION, f"{where}: limits")
    # N m (N for prismatic joints); inf where neither the sidecar nor the URDF gives one
    eff = _per_joint(limits, "effort", names, np.full(len(names), np.inf) if effort is None else effort, f"{where}: limits")
    gripper = None
    if data.get("gripper") is not None:
        g = data["gripper"]
        if not isinstance(g, dict) or "joint" not in g:
            raise DescriptionError(f"{where}: gripper: expected {{joint, open, closed}}")
        if g["joint"] not in names:
            raise DescriptionError(f"{where}: gripper.joint: '{g['joint']}' is not an actuated joint")
        jq, jw = (), ()
        if g.get("jaw_width") is not None:
            jw_raw = g["jaw_width"]
            if not isinstance(jw_raw, dict) or not isinstance(jw_raw.get("q"), list) or not isinstance(jw_raw.get("mm"), list):
                raise DescriptionError(f"{where}: gripper.jaw_width: expected {{q: [rad, ...], mm: [opening, ...]}}")
            n = len(jw_raw["q"])
            jq = tuple(vector(jw_raw["q"], n, f"{where}: gripper.jaw_width.q"))
            jw = tuple(vector(jw_raw["mm"], n, f"{where}: gripper.jaw_width.mm") / 1000.0)
            if n < 2 or np.any(np.diff(jq) <= 0) or np.any(np.diff(jw) <= 0):
                raise DescriptionError(f"{where}: gripper.jaw_width: needs 2+ points, q and mm both increasing")
        extra = {k: number(g[k], f"{where}: gripper.{k}") for k in ("squeeze", "clearance") if g.get(k) is not None}
        jaw = None if g.get("fixed_jaw") is None else _fixed_jaw(g["fixed_jaw"], f"{where}: gripper.fixed_jaw")
        gripper = Gripper(g["joint"], number(g.get("open"), f"{where}: gripper.open"), number(g.get("closed"), f"{where}: gripper.closed"),
                          jq, jw, extra.get("squeeze", Gripper.squeeze), extra.get("clearance", Gripper.clearance), fixed_jaw=jaw)
    poses = {}
    for pname, values in (data.get("named_poses") or {}).items():
        vals = list(values) if isinstance(values, list) else values
        if isinstance(vals, list) and len(vals) == len(names) - (1 if gripper else 0) and gripper:
            vals = vals + [gripper.closed]
        poses[str(pname)] = vector(vals, len(names), f"{where}: named_poses.{pname}")
    wire = []
    for i, w in enumerate(data.get("wire") or []):
        loc = f"{where}: wire[{i}]"
        if not isinstance(w, dict) or "joint" not in w or "field" not in w:
            raise DescriptionError(f"{loc}: expected {{joint, field, sign, offset, clamp}}")
        if w["joint"] not in names:
            raise DescriptionError(f"{loc}.joint: '{w['joint']}' is not an actuated joint")
        clamp = vector(w.get("clamp", [-math.inf, math.inf]), 2, f"{loc}.clamp")
        wire.append(WireField(w["joint"], str(w["field"]), number(w.get("sign", 1), f"{loc}.sign"),
                              number(w.get("offset", 0), f"{loc}.offset"), float(clamp[0]), float(clamp[1])))
    allowed = set()
    for i, pair in enumerate(data.get("allowed_collisions") or []):
        if not isinstance(pair, list) or len(pair) != 2:
            raise DescriptionError(f"{where}: allowed_collisions[{i}]: expected a pair of link names")
        allowed.add(frozenset(str(p) for p in pair))
    return dict(velocity_limits=vel, acceleration_limits=acc, jerk_limits=jerk, effort_limits=eff, gripper=gripper, named_poses=poses, wire=wire,
                defaults=defaults,
                allowed_collisions=allowed, singularity_model=data.get("singularity_model"),
                description=str(data.get("description", "")), frames=_frames(data, where))


def _frames(data: dict, where: str) -> dict:
    """``frames: {name: {origin: [x, y, z] m, unit: m|mm, point: {link, xyz}}}`` -> Frame objects."""
    raw = data.get("frames") or {}
    if not isinstance(raw, dict):
        raise DescriptionError(f"{where}: frames: expected a mapping name -> {{origin, unit, point}}")
    out = {}
    for name, f in raw.items():
        loc = f"{where}: frames.{name}"
        if not isinstance(f, dict) or "origin" not in f:
            raise DescriptionError(f"{loc}: expected {{origin: [x, y, z], unit, point}}")
        unit = f.get("unit", "m")
        if unit not in UNITS:
            raise DescriptionError(f"{loc}.unit: must be one of {', '.join(UNITS)}")
        link, xyz = None, None
        if f.get("point") is not None:
            pt = f["point"]
            if not isinstance(pt, dict) or "link" not in pt or "xyz" not in pt:
                raise DescriptionError(f"{loc}.point: expected {{link, xyz}}")
            link, xyz = str(pt["link"]), vector(pt["xyz"], 3, f"{loc}.point.xyz")
        out[str(name)] = Frame(str(name), vector(f["origin"], 3, f"{loc}.origin"), unit, link, xyz)
    return out



def tool_joint(data: dict, where: str, parent: str, taken: set[str], lscale: float = 1.0,
                deg: bool = False) -> Joint | None:
    """The fixed joint of ``tool: {xyz, rpy}`` (the TCP offset from ``parent``; xyz in the file's length
    unit, rpy in its angle unit), to a new link named ``tool`` (``tool_1``... if taken); None without one."""
    tool = data.get("tool")
    if not tool:
        return None
    if not isinstance(tool, dict):
        raise DescriptionError(f"{where}: tool: expected {{xyz, rpy}}")
    xyz = vector(tool.get("xyz", [0, 0, 0]), 3, f"{where}: tool.xyz") * lscale
    rpy = vector(tool.get("rpy", [0, 0, 0]), 3, f"{where}: tool.rpy")
    if deg:
        rpy = np.radians(rpy)
    name, k = "tool", 0
    while name in taken:
        k += 1
        name = f"tool_{k}"
    return Joint(name, "fixed", parent, name, transform(xyz, rpy))
