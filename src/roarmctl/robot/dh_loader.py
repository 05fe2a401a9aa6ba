"""A robot from a Denavit-Hartenberg table in YAML (standard or modified convention, m or mm, rad or deg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.implied import DEFAULT_ACCELERATION, DEFAULT_VELOCITY
from roarmctl.robot.model import Inertial, Joint, Robot, transform
from roarmctl.robot.sidecar import common_fields, number, tool_joint, vector


def from_dh(path: Path, data: dict) -> Robot:
    """The robot of the DH table ``data`` (read from ``path``): one joint per row, link1..linkN, the tool offset last."""
    where = str(path)
    convention = data.get("convention")
    if convention not in ("standard", "modified"):
        raise DescriptionError(f"{where}: convention: must be 'standard' or 'modified' (Craig), got {convention!r}")
    lscale = {"m": 1.0, "mm": 1e-3}.get(data.get("length_unit", "m"))
    if lscale is None:
        raise DescriptionError(f"{where}: length_unit: must be 'm' or 'mm'")
    deg = {"rad": False, "deg": True}.get(data.get("angle_unit", "rad"))
    if deg is None:
        raise DescriptionError(f"{where}: angle_unit: must be 'rad' or 'deg'")
    rows = data["dh"]
    if not isinstance(rows, list) or not rows:
        raise DescriptionError(f"{where}: dh: expected a non-empty list of rows")
    joints: list[Joint] = []
    names: list[str] = []
    root = "base"
    if data.get("base"):  # optional mounting transform: world -> DH frame 0
        base = data["base"]
        if not isinstance(base, dict):
            raise DescriptionError(f"{where}: base: expected {{xyz, rpy}}")
        xyz = vector(base.get("xyz", [0, 0, 0]), 3, f"{where}: base.xyz") * lscale
        rpy = vector(base.get("rpy", [0, 0, 0]), 3, f"{where}: base.rpy")
        joints.append(Joint("world_to_base", "fixed", "world", "base", transform(xyz, np.radians(rpy) if deg else rpy)))
        root = "world"
    prev = "base"
    dh_rows: list[dict] = []
    for i, row in enumerate(rows):
        loc = f"{where}: dh[{i}]"
        if not isinstance(row, dict):
            raise DescriptionError(f"{loc}: expected a mapping with a, alpha, d, theta")
        unknown = set(row) - {"name", "type", "a", "alpha", "d", "theta", "offset", "lower", "upper"}
        if unknown:
            raise DescriptionError(f"{loc}: unknown field(s) {sorted(unknown)}")
        for key in ("a", "alpha", "d"):
            if key not in row:
                raise DescriptionError(f"{loc}.{key}: missing")
        kind = row.get("type", "revolute")
        if kind not in ("revolute", "prismatic"):
            raise DescriptionError(f"{loc}.type: must be 'revolute' or 'prismatic'")
        a = number(row["a"], f"{loc}.a") * lscale
        alpha = number(row["alpha"], f"{loc}.alpha", angle=True, deg=deg)
        d = number(row["d"], f"{loc}.d") * lscale
        theta = number(row.get("theta", 0.0), f"{loc}.theta", angle=True, deg=deg)
        offset = number(row.get("offset", 0.0), f"{loc}.offset", angle=(kind == "revolute"), deg=deg)
        if kind == "prismatic":
            offset *= lscale
        name = str(row.get("name", f"joint{i + 1}"))
        for key in ("lower", "upper"):
            if key not in row:
                raise DescriptionError(f"{loc}.{key}: missing (joint limits are required)")
        lo = number(row["lower"], f"{loc}.lower", angle=kind == "revolute", deg=deg)
        hi = number(row["upper"], f"{loc}.upper", angle=kind == "revolute", deg=deg)
        if kind == "prismatic":
            lo, hi = lo * lscale, hi * lscale
        if lo >= hi:
            raise DescriptionError(f"{loc}: lower must be below upper")
        child = f"link{i + 1}"
        rx, tx, tz, rz = transform(rpy=(alpha, 0, 0)), transform((a, 0, 0)), transform((0, 0, d)), transform(rpy=(0, 0, theta))
        if convention == "modified":  # T = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)
            origin, post = (rx @ tx @ tz, np.eye(4)) if kind == "revolute" else (rx @ tx @ rz, np.eye(4))
        else:  # standard: T = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
            origin, post = (np.eye(4), tz @ tx @ rx) if kind == "revolute" else (rz, tx @ rx)
        total_offset = offset + (theta if kind == "revolute" else d)
        joints.append(Joint(name, kind, prev, child, origin, np.array([0.0, 0.0, 1.0]), post, lo, hi, total_offset))
        names.append(name)
        dh_rows.append({"kind": kind, "a": a, "alpha": alpha, "d": d, "offset": total_offset})
        prev = child
    tcp = "link" + str(len(rows))
    tool = tool_joint(data, where, prev, {j.child for j in joints} | {j.name for j in joints} | {"base", "world"},
                       lscale, deg)
    if tool is not None:
        joints.append(tool)
        tcp = tool.child
    inertials = {}
    for i, item in enumerate(data.get("inertials") or []):
        loc = f"{where}: inertials[{i}]"
        if not isinstance(item, dict) or "mass" not in item:
            raise DescriptionError(f"{loc}: expected {{link, mass, com, inertia}}")
        link = str(item.get("link", f"link{i + 1}"))
        if link not in [j.child for j in joints if j.kind != "fixed"]:
            raise DescriptionError(f"{loc}.link: '{link}' is not a moving link (links: link1 .. link{len(rows)})")
        if number(item["mass"], f"{loc}.mass") < 0:
            raise DescriptionError(f"{loc}.mass: must not be negative")
        inertia = item.get("inertia", [[0, 0, 0], [0, 0, 0], [0, 0, 0]])
        if isinstance(inertia, list) and len(inertia) == 3 and not isinstance(inertia[0], list):
            inertia = np.diag(vector(inertia, 3, f"{loc}.inertia"))
        else:
            inertia = np.array([vector(r, 3, f"{loc}.inertia") for r in inertia])
        inertials[link] = Inertial(number(item["mass"], f"{loc}.mass"), vector(item.get("com", [0, 0, 0]), 3, f"{loc}.com") * lscale, inertia)
    vel_default = np.full(len(names), DEFAULT_VELOCITY)
    common = common_fields(data, path, names, vel_default, np.full(len(names), DEFAULT_ACCELERATION),
                     defaulted={"velocity": set(names), "acceleration": set(names)})
    if deg:
        for key in ("velocity_limits", "acceleration_limits", "jerk_limits"):
            if (data.get("limits") or {}).get(key.split("_")[0]) is not None:
                common[key] = np.radians(common[key])
        common["named_poses"] = {k: np.radians(v) for k, v in common["named_poses"].items()}
    return Robot(
        name=str(data.get("name", path.stem)),
        source=str(data.get("source", f"DH table ({convention})")),
        root=root,
        joints=joints,
        joint_names=names,
        tcp_link=tcp,
        lower=np.array([j.lower for j in joints if j.kind != "fixed"]),
        upper=np.array([j.upper for j in joints if j.kind != "fixed"]),
        inertials=inertials,
        dh=(convention, dh_rows),
        **common,
    )
