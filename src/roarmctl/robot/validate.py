"""Checks of a robot description, called by the loader (``roarmctl.robot.loader``) in three places:

* ``read_yaml(path)``: the sidecar / DH YAML read with the plan reader's limits (size, nesting,
  alias expansion, UTF-8), so a description cannot hang or exhaust memory either;
* ``check_document(data, where)``: the YAML's field types, before the loader reads them, so a wrong
  type is exit 2 naming the field (``named_poses: [0]``, ``wire: 5``, ``length_unit: [mm]``);
* ``check_urdf(root, where)``: the URDF's structure before the loader walks it: ``<robot>`` root,
  unique link and joint names, parents and children that exist, one parent per link, no cycles
  (a cycle made ``kin fk`` hang), numbers finite, geometry complete;
* ``check_robot(robot, where)``: the loaded ``Robot``: finite origins, unit axes, ordered limits,
  positive speed limits, positive masses and sizes, gripper and named poses within the limits, and a
  wire map that names real protocol fields, every actuated joint once, sign +-1, ordered clamps.

Every failure raises ``DescriptionError`` (exit 2) with the file and the field.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.checks import Checker
from roarmctl.errors import DescriptionError
from roarmctl.fileio import Roots
from roarmctl.robot.model import WIRE_FIELDS, Robot
from roarmctl.validation import load_yaml

AXIS_TOL = 1e-3  # |axis| must be 1 within this (URDF axes are unit vectors)
MAX_VALUE = 1e6  # any length (m), angle (rad), limit or mass in a description


CHECK = Checker(DescriptionError, bound=MAX_VALUE, number_word="a finite number", max_name=4096)


# --------------------------------------------------------------------------- YAML
def read_yaml(path: Path, what: str | None = None, roots: Roots | None = None) -> Any:
    """A description YAML within the shared limits (``roarmctl.validation.load_yaml``)."""
    return load_yaml(path, DescriptionError, what=what, roots=roots)


def _xyz_rpy(v: Any, where: str, field: str) -> None:
    CHECK.mapping(v, where, field)
    for k in ("xyz", "rpy"):
        if k in v:
            CHECK.numbers(v[k], 3, where, f"{field}.{k}")


#: Jaw meshes one gripper may name (``gripper.jaw_meshes``): a gripper has a few jaws, each one mesh.
MAX_JAW_MESHES = 8

# Every field a description may have. A key outside these is refused rather than ignored: a typo such
# as ``allowed_colisions`` would otherwise silently drop a safety-relevant setting.
COMMON_KEYS = ("format", "name", "source", "description", "limits", "gripper", "named_poses", "wire",
               "allowed_collisions", "singularity_model", "ik", "base_links", "jaw_links", "frames")
URDF_KEYS = ("urdf", "srdf", "joint_limits", "packages", "xacro_args", "mesh_collision", "joints", "tcp_link",
             "arm_group", "gripper_group", "tool", "trust", "padding")
DH_KEYS = ("dh", "convention", "length_unit", "angle_unit", "base", "tool", "inertials")
NESTED_KEYS = {
    "limits": ("velocity", "acceleration", "jerk", "effort"),
    "gripper": ("joint", "open", "closed", "jaw_width", "squeeze", "clearance", "fixed_jaw", "jaw_meshes"),
    "gripper.jaw_width": ("q", "mm"),
    "gripper.fixed_jaw": ("link", "point", "normal"),
    "tool": ("xyz", "rpy"),
    "base": ("xyz", "rpy"),
}


def check_keys(data: dict, where: str) -> None:
    """Refuse unknown fields of a sidecar (URDF) or DH description, at the top level and one level down."""
    if "dh" in data:
        CHECK.known_keys(data, COMMON_KEYS + DH_KEYS, where, None)
    elif "urdf" in data:
        CHECK.known_keys(data, COMMON_KEYS + URDF_KEYS, where, None)
    # neither: the loader says that it needs one of them
    for field, allowed in NESTED_KEYS.items():
        head, _, tail = field.partition(".")
        value = data.get(head)
        if tail and isinstance(value, dict):
            value = value.get(tail)
        if isinstance(value, dict):
            CHECK.known_keys(value, allowed, where, field)
    for i, w in enumerate(data.get("wire") or []):
        if isinstance(w, dict):
            CHECK.known_keys(w, ("joint", "field", "sign", "offset", "clamp"), where, f"wire[{i}]")
    for i, it in enumerate(data.get("inertials") or []):
        if isinstance(it, dict):
            CHECK.known_keys(it, ("link", "mass", "com", "inertia"), where, f"inertials[{i}]")
    frames = data.get("frames")
    for name, f in (frames.items() if isinstance(frames, dict) else ()):
        if isinstance(f, dict):
            CHECK.known_keys(f, ("origin", "unit", "point"), where, f"frames.{name}")
            if isinstance(f.get("point"), dict):
                CHECK.known_keys(f["point"], ("link", "xyz"), where, f"frames.{name}.point")


def check_document(data: Any, where: str) -> None:
    """Types of every field the loader reads from a sidecar or DH YAML (``where`` names the file)."""
    if not isinstance(data, dict):
        raise DescriptionError(f"{where}: expected a mapping at the top level, got {CHECK.kind(data)}")
    if data.get("trust") is not None and not isinstance(data["trust"], bool):
        CHECK.fail(where, "trust", f"expected true or false, got {CHECK.kind(data['trust'])}")
    for key in ("name", "source", "description", "urdf", "tcp_link", "singularity_model", "format"):
        if data.get(key) is not None:
            CHECK.name(data[key], where, key)
    if data.get("name") is not None and len(data["name"]) > 255:
        CHECK.fail(where, "name", "longer than 255 characters")
    for key, choices in (("length_unit", ("m", "mm")), ("angle_unit", ("rad", "deg")), ("convention", ("standard", "modified"))):
        if data.get(key) is not None:
            CHECK.name(data[key], where, key, choices=choices)
    if data.get("joints") is not None:
        j = data["joints"]
        if not isinstance(j, list) or not j:
            CHECK.fail(where, "joints", f"expected a list of joint names, got {CHECK.kind(j)}")
        for i, n in enumerate(j):
            CHECK.name(n, where, f"joints[{i}]")
        if len(set(j)) != len(j):
            CHECK.fail(where, "joints", "a joint is listed twice")
    limits = data.get("limits")
    if limits is not None:
        CHECK.mapping(limits, where, "limits")
        for key, v in limits.items():
            if isinstance(v, list):
                CHECK.numbers(v, None, where, f"limits.{key}")
            elif isinstance(v, dict):
                for name, x in v.items():
                    CHECK.name(name, where, f"limits.{key}")
                    CHECK.number(x, where, f"limits.{key}.{name}")
            elif v is not None:
                CHECK.fail(where, f"limits.{key}", f"expected a list or a mapping joint -> value, got {CHECK.kind(v)}")
    g = data.get("gripper")
    if g is not None:
        CHECK.mapping(g, where, "gripper")
        CHECK.name(g.get("joint"), where, "gripper.joint")
        CHECK.number(g.get("open"), where, "gripper.open")
        CHECK.number(g.get("closed"), where, "gripper.closed")
        meshes = g.get("jaw_meshes")
        if meshes is not None:
            if not isinstance(meshes, list) or len(meshes) > MAX_JAW_MESHES:
                CHECK.fail(where, "gripper.jaw_meshes", f"expected a list of at most {MAX_JAW_MESHES} {{link, file, scale}} "
                           f"or {{link, pieces}}, got {len(meshes) if isinstance(meshes, list) else CHECK.kind(meshes)}")
            for i, m in enumerate(meshes):
                CHECK.mapping(m, where, f"gripper.jaw_meshes[{i}]")
                CHECK.known_keys(m, ("link", "file", "scale", "pieces"), where, f"gripper.jaw_meshes[{i}]")
                CHECK.name(m.get("link"), where, f"gripper.jaw_meshes[{i}].link")
                if ("file" in m) == ("pieces" in m):
                    CHECK.fail(where, f"gripper.jaw_meshes[{i}]", "give exactly one of file (a mesh) and pieces (its "
                               "convex pieces, made by roarmctl)")
                CHECK.name(m.get("file", m.get("pieces")), where, f"gripper.jaw_meshes[{i}].{'file' if 'file' in m else 'pieces'}")
                if "pieces" in m and m.get("scale") is not None:
                    CHECK.fail(where, f"gripper.jaw_meshes[{i}].scale", "a pieces file is in metres: no scale")
                if m.get("scale") is not None:
                    CHECK.number(m["scale"], where, f"gripper.jaw_meshes[{i}].scale", lo=0.0, strict_lo=True)
    poses = data.get("named_poses")
    if poses is not None:
        CHECK.mapping(poses, where, "named_poses")
        for name, vals in poses.items():
            CHECK.name(name, where, "named_poses")
            CHECK.numbers(vals, None, where, f"named_poses.{name}")
    wire = data.get("wire")
    if wire is not None:
        if not isinstance(wire, list):
            CHECK.fail(where, "wire", f"expected a list of {{joint, field, sign, offset, clamp}}, got {CHECK.kind(wire)}")
        for i, w in enumerate(wire):
            CHECK.mapping(w, where, f"wire[{i}]")
            CHECK.name(w.get("joint"), where, f"wire[{i}].joint")
            CHECK.name(w.get("field"), where, f"wire[{i}].field")
            for k in ("sign", "offset"):
                if k in w:
                    CHECK.number(w[k], where, f"wire[{i}].{k}")
            if "clamp" in w:
                CHECK.numbers(w["clamp"], 2, where, f"wire[{i}].clamp")
    pairs = data.get("allowed_collisions")
    if pairs is not None:
        if not isinstance(pairs, list):
            CHECK.fail(where, "allowed_collisions", f"expected a list of link pairs, got {CHECK.kind(pairs)}")
        for i, p in enumerate(pairs):
            if not isinstance(p, list) or len(p) != 2:
                CHECK.fail(where, f"allowed_collisions[{i}]", f"expected a pair of link names, got {CHECK.kind(p)}")
            for j, link in enumerate(p):
                CHECK.name(link, where, f"allowed_collisions[{i}][{j}]")
    for key in ("base", "tool"):
        if data.get(key) is not None:
            _xyz_rpy(data[key], where, key)
    if "dh" in data:
        rows = data["dh"]
        if not isinstance(rows, list) or not rows or len(rows) > 64:
            CHECK.fail(where, "dh", f"expected a list of 1 to 64 rows, got {CHECK.kind(rows)}")
        for i, row in enumerate(rows):
            CHECK.mapping(row, where, f"dh[{i}]")
            for k in ("a", "alpha", "d", "theta", "offset", "lower", "upper"):
                if k in row:
                    CHECK.number(row[k], where, f"dh[{i}].{k}")
            if "name" in row:
                CHECK.name(row["name"], where, f"dh[{i}].name")
            if "type" in row:
                CHECK.name(row["type"], where, f"dh[{i}].type", choices=("revolute", "prismatic"))
    items = data.get("inertials")
    if items is not None:
        if not isinstance(items, list):
            CHECK.fail(where, "inertials", f"expected a list, got {CHECK.kind(items)}")
        for i, it in enumerate(items):
            CHECK.mapping(it, where, f"inertials[{i}]")
            if "link" in it:
                CHECK.name(it["link"], where, f"inertials[{i}].link")
            CHECK.number(it.get("mass"), where, f"inertials[{i}].mass")
            if it["mass"] < 0:
                CHECK.fail(where, f"inertials[{i}].mass", f"{it['mass']} must not be negative")
            if "com" in it:
                CHECK.numbers(it["com"], 3, where, f"inertials[{i}].com")
            inertia = it.get("inertia")
            if inertia is not None:
                if isinstance(inertia, list) and len(inertia) == 3 and all(isinstance(r, list) for r in inertia):
                    for r, row in enumerate(inertia):
                        CHECK.numbers(row, 3, where, f"inertials[{i}].inertia[{r}]")
                else:
                    CHECK.numbers(inertia, 3, where, f"inertials[{i}].inertia")
    check_keys(data, where)


# --------------------------------------------------------------------------- URDF
def _attr_floats(elem: ET.Element, key: str, n: int, where: str, field: str,
                 required: bool = False) -> list[float] | None:
    """The ``n`` finite numbers of attribute ``key`` of ``elem`` (None when it is absent and not ``required``)."""
    text = elem.get(key)
    if text is None:
        if required:
            CHECK.fail(where, field, f"'{key}' is missing")
        return None
    try:
        vals = [float(t) for t in text.split()]
    except ValueError:
        CHECK.fail(where, field, f"'{text[:40]}' is not {n} number(s)")
    if len(vals) != n or not all(math.isfinite(v) and abs(v) <= MAX_VALUE for v in vals):
        CHECK.fail(where, field, f"'{text[:40]}' is not {n} finite number(s)")
    return vals


def _unique_name(element: ET.Element, kind: str, k: int, seen: dict[str, Any], where: str) -> str:
    """The ``name`` of the k-th URDF <link> or <joint>, required and not already in ``seen``."""
    name = element.get("name")
    if not name:
        CHECK.fail(where, f"{kind}[{k}]", "has no name")
    if name in seen:
        CHECK.fail(where, f"{kind} '{name}'", "the name is used twice")
    return name


#: Links (and joints) a URDF may have: published arms have tens (the corpus's most: 19); what a
#: description implies is computed over pairs of links.
MAX_LINKS = 300


def check_urdf(root: ET.Element, where: str) -> None:
    """The URDF's structure and numbers (``root`` is the parsed XML root element)."""
    if root.tag != "robot":
        CHECK.fail(where, "root element", f"<{root.tag}> is not <robot>")
    for tag in ("link", "joint"):
        if len(root.findall(tag)) > MAX_LINKS:
            CHECK.fail(where, f"<{tag}>", f"more than {MAX_LINKS} of them", "is this the right file?")
    links: dict[str, Any] = {}
    for k, link in enumerate(root.findall("link")):
        name = _unique_name(link, "link", k, links, where)
        links[name] = link
        inn = link.find("inertial")
        if inn is not None:
            mass = inn.find("mass")
            if mass is not None:
                value = _attr_floats(mass, "value", 1, where, f"link '{name}' mass value", required=True)
                # 0 is a massless frame link (Franka's panda_link8, many tool frames); only negative is wrong
                if value is not None and value[0] < 0:
                    CHECK.fail(where, f"link '{name}' mass value", f"{mass.get('value')} must not be negative")
            for tag, keys in (("origin", ("xyz", "rpy")), ("inertia", ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"))):
                e = inn.find(tag)
                if e is not None:
                    for key in keys:
                        _attr_floats(e, key, 3 if tag == "origin" else 1, where, f"link '{name}' inertial {tag} {key}")
            e = inn.find("inertia")
            if e is not None and any(float(e.get(k, "0")) < 0 for k in ("ixx", "iyy", "izz")):
                CHECK.fail(where, f"link '{name}' inertia", "principal moments ixx, iyy, izz must not be negative")
        for c, col in enumerate(link.findall("collision")):
            _check_geometry(col, where, f"link '{name}' collision[{c}]")
    joints: dict[str, Any] = {}
    parent_of: dict[str, str] = {}
    for k, j in enumerate(root.findall("joint")):
        name = _unique_name(j, "joint", k, joints, where)
        joints[name] = j
        ends: dict[str, str] = {}
        for tag in ("parent", "child"):
            e = j.find(tag)
            end = e.get("link") if e is not None else None
            if end is None or end not in links:
                CHECK.fail(where, f"joint '{name}' {tag}", f"<{tag} link=...> is missing or names no link")
            ends[tag] = end
        if ends["parent"] == ends["child"]:
            CHECK.fail(where, f"joint '{name}'", f"link '{ends['parent']}' is its own parent")
        if ends["child"] in parent_of:
            CHECK.fail(where, f"joint '{name}' child", f"link '{ends['child']}' already has a parent joint (a URDF is a tree)")
        parent_of[ends["child"]] = ends["parent"]
        o = j.find("origin")
        if o is not None:
            for key in ("xyz", "rpy"):
                _attr_floats(o, key, 3, where, f"joint '{name}' origin {key}")
        a = j.find("axis")
        if a is not None:
            axis = _attr_floats(a, "xyz", 3, where, f"joint '{name}' axis")
            if j.get("type") != "fixed" and axis is not None:
                n = float(np.linalg.norm(axis))
                if abs(n - 1.0) > AXIS_TOL:
                    CHECK.fail(where, f"joint '{name}' axis", f"'{a.get('xyz')}' has length {n:g}, not 1", "give a unit vector")
        lim = j.find("limit")
        if lim is None and j.get("type") in ("revolute", "prismatic"):
            # urdfdom (urdf_parser/src/joint.cpp, parseJoint) refuses the model: ROS, MoveIt and Pinocchio never load it
            CHECK.fail(where, f"joint '{name}'", f"a {j.get('type')} joint needs a <limit> (urdfdom refuses one without)",
                       "add <limit lower=... upper=... effort=... velocity=...>, or make it type=\"continuous\"")
        if lim is not None:
            for key in ("lower", "upper", "velocity", "effort"):
                _attr_floats(lim, key, 1, where, f"joint '{name}' limit {key}")
            for key in ("effort", "velocity"):  # urdfdom's parseJointLimits: required on every <limit>, any joint type
                if lim.get(key) is None:
                    CHECK.fail(where, f"joint '{name}' limit", f"no '{key}' attribute (urdfdom refuses a <limit> without "
                               "effort and velocity)", f"write {key}=\"0\" if it is not known (0 means not given)")
            # URDF reads <limit> on revolute and prismatic joints only: a fixed joint's (Kinova writes
            # lower="0" upper="0" on its fixed end_effector joint) and a continuous one's bounds mean nothing
            # a bound not written is 0, as urdfdom reads it
            lower, upper = lim.get("lower", "0"), lim.get("upper", "0")
            if j.get("type") in ("revolute", "prismatic") and not float(lower) < float(upper):
                unwritten = [k for k in ("lower", "upper") if lim.get(k) is None]
                CHECK.fail(where, f"joint '{name}' limit", f"lower {lower} must be below upper {upper}"
                           + (f" ({' and '.join(unwritten)} not written: urdfdom reads a missing bound as 0)" if unwritten else ""))
            # a negative velocity or effort is read as urdfdom reads it (any number, urdf_parser/src/joint.cpp):
            # vendors write -1 for "not given"; the loader takes it so, with a note
    for start in parent_of:  # walking up from every link must reach the root: no cycles
        seen, up = {start}, start
        while up in parent_of:
            up = parent_of[up]
            if up in seen:
                CHECK.fail(where, f"link '{start}'", "the joints form a cycle (a URDF is a tree)")
            seen.add(up)


def _check_geometry(col: ET.Element, where: str, field: str) -> None:
    o = col.find("origin")
    if o is not None:
        for key in ("xyz", "rpy"):
            _attr_floats(o, key, 3, where, f"{field} origin {key}")
    geom = col.find("geometry")
    if geom is None or len(geom) == 0:
        CHECK.fail(where, field, "missing <geometry>")
    g = geom[0]
    need = {"box": (("size", 3),), "cylinder": (("radius", 1), ("length", 1)), "sphere": (("radius", 1),),
            "capsule": (("radius", 1), ("length", 1))}.get(g.tag, ())
    for key, n in need:
        values = _attr_floats(g, key, n, where, f"{field} {g.tag} {key}", required=True)
        if values is not None and any(v <= 0 for v in values):
            CHECK.fail(where, f"{field} {g.tag} {key}", f"'{g.get(key)}' must be positive")


# --------------------------------------------------------------------------- the loaded robot
def check_robot(robot: Robot, where: str) -> None:
    """Semantic checks of a loaded ``Robot`` (see the module docstring)."""
    names = list(robot.joint_names)
    if len(set(names)) != len(names):
        CHECK.fail(where, "joints", "a joint is named twice")
    jn = [j.name for j in robot.joints]
    if len(set(jn)) != len(jn):
        CHECK.fail(where, "joints", f"joint '{next(n for n in jn if jn.count(n) > 1)}' is defined twice")
    links = robot.link_names
    if len(set(links)) != len(links):
        CHECK.fail(where, "links", f"link '{next(n for n in links if links.count(n) > 1)}' appears twice")
    for j in robot.joints:
        if not (np.all(np.isfinite(j.origin)) and np.all(np.isfinite(j.post))):
            CHECK.fail(where, f"joint '{j.name}' origin", "must be finite numbers")
        if j.kind != "fixed":
            n = float(np.linalg.norm(j.axis))
            if not math.isfinite(n) or abs(n - 1.0) > AXIS_TOL:
                CHECK.fail(where, f"joint '{j.name}' axis", f"length {n:g}, must be a unit vector")
            if not (math.isfinite(j.lower) and math.isfinite(j.upper) and j.lower < j.upper):
                CHECK.fail(where, f"joint '{j.name}' limits", f"lower {j.lower:g} must be below upper {j.upper:g}, both finite")
            if not math.isfinite(j.offset):
                CHECK.fail(where, f"joint '{j.name}' offset", "must be finite")
    for key in ("velocity_limits", "acceleration_limits", "jerk_limits"):
        arr = getattr(robot, key, None)
        if arr is None:
            continue
        arr = np.asarray(arr, dtype=float)
        bad = np.flatnonzero(~np.isfinite(arr) | (arr <= 0))
        if len(bad):
            CHECK.fail(where, f"limits.{key.split('_')[0]}.{names[int(bad[0])]}", f"{arr[bad[0]]:g} must be a positive finite number")
    eff = getattr(robot, "effort_limits", None)
    if eff is not None:
        eff = np.asarray(eff, dtype=float)
        bad = np.flatnonzero(np.isnan(eff) | (eff <= 0))
        if len(bad):
            CHECK.fail(where, f"limits.effort.{names[int(bad[0])]}", f"{eff[bad[0]]:g} must be positive")
    for link, inn in robot.inertials.items():
        if not (math.isfinite(inn.mass) and inn.mass >= 0):
            CHECK.fail(where, f"link '{link}' mass", f"{inn.mass:g} must be a finite number, not negative")
        if not (np.all(np.isfinite(inn.com)) and np.all(np.isfinite(inn.inertia))):
            CHECK.fail(where, f"link '{link}' inertial", "centre of mass and inertia must be finite")
    for k, s in enumerate(robot.collision):
        f = f"link '{s.link}' collision '{s.name or k}'"
        if not np.all(np.isfinite(s.origin)):
            CHECK.fail(where, f"{f} origin", "must be finite")
        if s.kind == "mesh":  # its largest extent (an exact mesh may be flat); the mesh reader checked the rest
            assert s.mesh is not None  # a mesh shape carries its MeshGeometry
            dims = [float(np.max(2 * s.mesh.half_extents))]
        else:
            dims = {"box": list(s.size), "sphere": [s.radius], "cylinder": [s.radius, s.length], "capsule": [s.radius]}[s.kind]
        if not all(math.isfinite(d) and 0 < d <= MAX_VALUE for d in dims):
            CHECK.fail(where, f, f"sizes {dims} must be positive finite numbers")
        if s.kind == "capsule" and not (math.isfinite(s.length) and s.length >= 0):
            CHECK.fail(where, f, "a capsule's length must be finite and not negative")
    known = set(links)
    for pair in sorted(robot.allowed_collisions, key=sorted):
        unknown = sorted(set(pair) - known)
        if unknown:
            CHECK.fail(where, "allowed_collisions", f"pair ({', '.join(sorted(pair))}): '{unknown[0]}' is not a link of "
                       f"{robot.name}", "name two links of the URDF")
    lo, hi = np.asarray(robot.lower, dtype=float), np.asarray(robot.upper, dtype=float)
    if robot.gripper is not None:
        gi = robot.joint_index(robot.gripper.joint)
        for key in ("open", "closed"):
            v = getattr(robot.gripper, key)
            if not (lo[gi] - 1e-9 <= v <= hi[gi] + 1e-9):
                CHECK.fail(where, f"gripper.{key}", f"{v:g} is outside the joint's limits [{lo[gi]:g}, {hi[gi]:g}]")
    for pname, q in robot.named_poses.items():
        q = np.asarray(q, dtype=float)
        bad = np.flatnonzero((q < lo - 1e-6) | (q > hi + 1e-6))
        if len(bad):
            i = int(bad[0])
            CHECK.fail(where, f"named_poses.{pname}", f"{names[i]} = {q[i]:g} is outside its limits [{lo[i]:g}, {hi[i]:g}]")
    if robot.wire:
        _check_wire(robot, where, set(WIRE_FIELDS))


def _check_wire(robot: Robot, where: str, fields: set[str]) -> None:
    seen_f: set[str] = set()
    seen_j: set[str] = set()
    for i, w in enumerate(robot.wire):
        f = f"wire[{i}]"
        if w.field not in fields:
            CHECK.fail(where, f"{f}.field", f"'{w.field}' is not a field of the device protocol", f"fields: {', '.join(sorted(fields))}")
        if w.field in seen_f:
            CHECK.fail(where, f"{f}.field", f"'{w.field}' is mapped twice")
        if w.joint in seen_j:
            CHECK.fail(where, f"{f}.joint", f"'{w.joint}' is mapped twice")
        seen_f.add(w.field)
        seen_j.add(w.joint)
        if w.sign not in (1.0, -1.0):
            CHECK.fail(where, f"{f}.sign", f"{w.sign:g} must be 1 or -1")
        if not math.isfinite(w.offset):
            CHECK.fail(where, f"{f}.offset", "must be finite")
        if math.isnan(w.lower) or math.isnan(w.upper) or not w.lower < w.upper:
            CHECK.fail(where, f"{f}.clamp", f"[{w.lower:g}, {w.upper:g}] must be ordered: lower below upper")
    missing = [n for n in robot.joint_names if n not in seen_j]
    if missing:
        CHECK.fail(where, "wire", f"no entry for joint(s) {', '.join(missing)}", "map every actuated joint to a device field once")
