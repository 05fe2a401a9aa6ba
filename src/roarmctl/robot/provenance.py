"""What a loaded robot is made of and where each value came from (``roarmctl robots show ARM``).

``summary(spec)`` loads the robot (a bundled name or a path, as everywhere) and returns plain data: per
joint its type, limits with units and the source of each (``URDF``, ``DH table``, ``joint_limits.yaml``,
``sidecar``, ``roarmctl default``), the TCP link and tool offset, the gripper, the named poses, the groups
the sidecar names, the collision pairs allowed (from the SRDF or sidecar, and the adjacent links roarmctl
always allows), the meshes (collision, visual) and the loader's notes. The library returns; the CLI prints.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.implied import adjacent_pairs
from roarmctl.robot.joint_limits import read_joint_limits
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.robot.model import Robot
from roarmctl.validation import load_yaml

DEFAULT = "roarmctl default"


def _sidecar(robot: Robot, spec: str) -> tuple[dict[str, Any], Path | None]:
    """The description's YAML (bundled or named) and its path; ({}, None) for a bare URDF or xacro."""
    path = bundled_dir() / f"{spec}.yaml"
    if not path.is_file():
        path = Path(robot.spec or spec)
    if path.suffix.lower() not in (".yaml", ".yml"):
        return {}, None
    data = load_yaml(path, DescriptionError)
    return (data if isinstance(data, dict) else {}), path


def _given(side: dict[str, Any], key: str, name: str, index: int) -> bool:
    """Whether the sidecar's ``limits.KEY`` gives joint ``name`` (mapping) or every joint (list or number)."""
    value = (side.get("limits") or {}).get(key)
    if isinstance(value, dict):
        return name in value
    return value is not None


def summary(spec: str, trust_sidecar: bool = True) -> dict[str, Any]:
    """The robot ``spec`` as data with the source of every value (see the module docstring)."""
    robot = load_robot(spec, trust_sidecar=trust_sidecar)
    side, path = _sidecar(robot, spec)
    kind = "DH table" if "dh" in side else "URDF"
    jl: dict[str, dict[str, float]] = {}
    if side.get("joint_limits") and path is not None:
        jl = read_joint_limits(path.parent / str(side["joint_limits"]), set(robot.joint_names), str(path),
                               args=side.get("xacro_args"))
    moveit = "SRDF" if side.get("srdf") else None
    joints = []
    for i, name in enumerate(robot.joint_names):
        jtype = next(j.kind for j in robot.joints if j.name == name)
        lim = jl.get(name, {})

        def source(key: str, lim: dict = lim, name: str = name, i: int = i) -> str:
            if _given(side, key, name, i):
                return "sidecar"
            if name in robot.defaults.get(key, []):
                return DEFAULT
            return "joint_limits.yaml" if key in lim else kind

        effort = None if robot.effort_limits is None else float(robot.effort_limits[i])
        joints.append({
            "name": name, "type": jtype, "unit": robot.joint_unit(i),
            "lower": float(robot.lower[i]), "upper": float(robot.upper[i]),
            "position_source": "joint_limits.yaml" if "lower" in lim else kind,
            "velocity": float(robot.velocity_limits[i]), "velocity_unit": robot.joint_unit(i, 1),
            "velocity_source": source("velocity"),
            "acceleration": float(robot.acceleration_limits[i]), "acceleration_unit": robot.joint_unit(i, 2),
            "acceleration_source": source("acceleration"),
            "effort": effort if effort is not None and math.isfinite(effort) else None,
            "effort_unit": robot.joint_unit(i, kind="effort"),
            "effort_source": "sidecar" if _given(side, "effort", name, i) else (
                kind if effort is not None and math.isfinite(effort) else "none given"),
        })
    tool = side.get("tool")
    tcp_source = "sidecar" if "tcp_link" in side else moveit or DEFAULT
    gripper = None
    if robot.gripper is not None:
        gripper = {"joint": robot.gripper.joint, "open": robot.gripper.open, "closed": robot.gripper.closed,
                   "source": "sidecar" if "gripper" in side else moveit or DEFAULT}
    side_poses = set((side.get("named_poses") or {}).keys()) if isinstance(side.get("named_poses"), dict) else set()
    adjacent = adjacent_pairs(robot)
    side_pairs = {frozenset(p) for p in side.get("allowed_collisions") or [] if isinstance(p, list)}
    pairs = []
    for pair in sorted(robot.allowed_collisions, key=sorted):
        src = "sidecar" if pair in side_pairs else "adjacent (always allowed)" if pair in adjacent else moveit or kind
        pairs.append({"links": sorted(pair), "source": src})
    visuals = robot.visual_source.elements if robot.visual_source is not None else ()
    return {
        "name": robot.name, "spec": robot.spec or spec, "description": robot.description, "source": robot.source,
        "sidecar": str(path) if path is not None else None,
        "joints": joints,
        "held_joints": dict(robot.held_joints),
        "tcp": {"link": next(j.parent for j in robot.joints if j.child == robot.tcp_link) if isinstance(tool, dict)
                else robot.tcp_link, "source": tcp_source,
                "tool": ({"xyz": list(tool.get("xyz", [0, 0, 0])), "rpy": list(tool.get("rpy", [0, 0, 0]))}
                         if isinstance(tool, dict) else None)},
        "gripper": gripper,
        "named_poses": {n: {"q": np.asarray(q, dtype=float).tolist(), "source": "sidecar" if n in side_poses else
                            moveit or DEFAULT} for n, q in robot.named_poses.items()},
        "groups": {k: side[k] for k in ("arm_group", "gripper_group") if k in side},
        "allowed_collisions": pairs,
        "meshes": {"collision": sum(1 for s in robot.collision if s.kind == "mesh"),
                   "collision_shapes": len(robot.collision),
                   "visual_elements": len(visuals)},
        "notes": list(robot.notes),
    }
