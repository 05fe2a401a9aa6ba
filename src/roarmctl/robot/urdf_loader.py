"""A robot from a URDF (or a xacro file expanded safely) with its sidecar, SRDF and joint_limits.yaml.

Read as urdfdom reads it where a value is optional or out of range (a limit below 0 means "not given", a
continuous joint has no bounds); every mistake raises ``DescriptionError`` naming the file and the element.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.fileio import read_text, resolved
from roarmctl.robot import validate as checks
from roarmctl.robot import visuals
from roarmctl.robot.implied import DEFAULT_ACCELERATION, DEFAULT_VELOCITY, held_fixed, mimic_bounds, rest_value
from roarmctl.robot.joint_limits import read_joint_limits
from roarmctl.robot.meshes import description_roots, load_mesh, mesh_modes, package_map, resolve, unit_notes
from roarmctl.robot.model import CollisionShape, Inertial, Joint, JointKind, Robot
from roarmctl.robot.padding import sidecar_padding
from roarmctl.robot.sidecar import common_fields, tool_joint
from roarmctl.robot.srdf import parse_srdf, read_srdf
from roarmctl.robot.urdf_values import fattr as _fattr
from roarmctl.robot.urdf_values import floats as _floats
from roarmctl.robot.urdf_values import origin as _origin
from roarmctl.robot.xacro_input import expand
from roarmctl.validation import check_markup

MESH_SCALE = (1e-5, 1e5)  # a mesh's scale factors (a mesh in mm has 0.001); beyond, a link's shape vanishes or explodes
URDF_BYTES = 16 * 1024 * 1024  # a URDF (or the text xacro makes) may have; published arms have < 1 MiB


def read_urdf(urdf: Path, side: dict, sidecar: Path) -> ET.Element:
    """The URDF's XML root; a ``.xacro`` file is expanded first (``xacro_args`` in the sidecar)."""
    roots = side.get("_roots") or description_roots(side, sidecar)
    if urdf.suffix.lower() == ".xacro":
        text = expand(urdf, side.get("xacro_args"), str(sidecar), roots=roots, trusted=bool(side.get("_trusted")))
        try:
            return ET.fromstring(text)
        except ET.ParseError as exc:
            raise DescriptionError(f"{urdf}: xacro output is not valid XML ({exc})") from None
    text = check_markup(read_text(urdf, None, URDF_BYTES, roots=roots, error=DescriptionError), str(urdf), DescriptionError)
    try:
        return ET.fromstring(text)
    except ET.ParseError as exc:
        raise DescriptionError(f"{urdf}: not valid XML ({exc})") from None


def _moveit(side: dict, sidecar: Path, ordered: list[Joint], links: dict, actuated: list[str]) -> tuple[dict, dict]:
    """Merge the SRDF's fields into a copy of the sidecar (the sidecar wins); read joint_limits.yaml.

    The copy's ``_driven`` holds the joints to drive when the sidecar lists none (the SRDF's arm and
    gripper groups' joints, passive joints left out), ``_notes`` what was left out."""
    side = dict(side)
    side["_driven"], side["_notes"], side["_srdf_poses"] = list(actuated), [], []
    jl: dict = {}
    if side.get("joint_limits") is not None:
        jl = read_joint_limits(sidecar.parent / str(side["joint_limits"]), {j.name for j in ordered if j.kind != "fixed"},
                               str(sidecar), roots=side.get("_roots"), args=side.get("xacro_args"), notes=side["_notes"])
    if side.get("srdf") is None:
        return side, jl
    jinfo = {j.name: (j.kind, j.child, j.mimic, j.parent) for j in ordered}
    root, src = parse_srdf(resolved(sidecar.parent / str(side["srdf"]), f"{sidecar}: srdf", DescriptionError), side, sidecar,
                           str(sidecar))
    got = read_srdf(root, src, jinfo, set(links), side, str(sidecar))
    side["_notes"] += list(got["notes"])
    driven = [a for a in actuated if a not in got["passive_joints"]]
    if got.get("planned_joints"):
        driven = [a for a in driven if a in got["planned_joints"]]
    side["allowed_collisions"] = list(got["allowed_collisions"]) + list(side.get("allowed_collisions") or [])
    if "tcp_link" in got:
        side.setdefault("tcp_link", got["tcp_link"])
    if "gripper" in got:
        side.setdefault("gripper", got["gripper"])
    grip = (side.get("gripper") or {}).get("joint") if isinstance(side.get("gripper"), dict) else got.get("gripper_joint")
    if "joints" not in side and grip in driven:  # gripper last
        side["joints"] = [j for j in driven if j != grip] + [grip]
    names = list(side.get("joints", driven))
    arm = [n for n in names if n != grip]
    poses = dict(side.get("named_poses") or {})
    for pname, values in got["named_poses_by_joint"].items():
        missing = [n for n in arm if n not in values]
        if missing:  # MoveIt keeps a partial state; a named pose of roarmctl gives every arm joint
            side["_notes"].append(f"{side['srdf']}: group_state '{pname}' left out: no value for {', '.join(missing)} "
                                  "(give every arm joint a value, or define the pose in the sidecar's named_poses)")
            continue
        grip_value = [values[grip]] if grip is not None and grip in values and grip in names else []
        if pname not in poses:
            poses[pname] = [values[n] for n in arm] + grip_value
            side["_srdf_poses"].append(pname)
    side["named_poses"] = poses
    side["_driven"] = driven
    return side, jl

def _mimic(elem: ET.Element, where: str) -> tuple[str, float, float]:
    """URDF ``<mimic joint= multiplier= offset=>``: value = multiplier * q[joint] + offset. Returns the
    joint followed, the multiplier (default 1) and the offset (default 0; rad or m)."""
    master = elem.get("joint")
    if not master:
        raise DescriptionError(f"{where}: <mimic> needs joint=...")
    mult = _fattr(elem, "multiplier", 1.0, f"{where} mimic")
    offset = _fattr(elem, "offset", 0.0, f"{where} mimic")
    if mult == 0 or not math.isfinite(mult) or not math.isfinite(offset):
        raise DescriptionError(f"{where}: mimic multiplier {mult:g} / offset {offset:g}: the multiplier must be a "
                               "finite non-zero number and the offset finite",
                               "make the joint fixed in a copy of the URDF if it does not move")
    return master, mult, offset



# URDF joint types -> roarmctl's kinds: a continuous joint is a revolute one without limits (+-2 pi)
_URDF_KINDS: dict[str, JointKind] = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic",
                                     "fixed": "fixed"}


def _link_of(joint: ET.Element, tag: str) -> str:
    """The link a URDF joint's ``<parent>`` or ``<child>`` (``tag``) names; "" when absent (check_urdf refuses that)."""
    end = joint.find(tag)
    return "" if end is None else end.get("link", "")


def from_urdf(urdf: Path, side: dict, sidecar: Path) -> Robot:
    """The robot of a URDF or xacro file ``urdf`` with its sidecar's fields ``side`` (read from ``sidecar``)."""
    root = read_urdf(urdf, side, sidecar)
    checks.check_urdf(root, str(urdf))  # a tree with finite numbers before it is walked
    links = {el.get("name", ""): el for el in root.findall("link")}  # check_urdf: every link and joint has a name
    joints_xml = root.findall("joint")
    for j in joints_xml:
        for tag in ("parent", "child"):
            if _link_of(j, tag) not in links:
                raise DescriptionError(f"{urdf}: joint '{j.get('name')}': <{tag} link=...> missing or names no link")
    children = {_link_of(j, "child") for j in joints_xml}
    roots = [name for name in links if name not in children]
    if len(roots) != 1:
        raise DescriptionError(f"{urdf}: expected one root link, found {roots}")
    by_parent: dict[str, list[ET.Element]] = {}
    for j in joints_xml:
        by_parent.setdefault(_link_of(j, "parent"), []).append(j)
    ordered: list[Joint] = []
    bounded: set[str] = set()  # joints whose <limit> gives lower and upper
    stack = [roots[0]]
    while stack:  # depth-first so parents precede children
        link = stack.pop(0)
        for j in by_parent.get(link, []):
            name = j.get("name", "")
            where = f"{urdf}: joint '{name}'"
            kind = _URDF_KINDS.get(j.get("type", ""))
            if kind is None:
                raise DescriptionError(f"{where}: type '{j.get('type')}' is not supported (revolute, continuous, prismatic, fixed)")
            axis_el = j.find("axis")
            axis = _floats("1 0 0" if axis_el is None else axis_el.get("xyz"), 3, f"{where} axis")
            if np.linalg.norm(axis) == 0 and kind != "fixed":
                raise DescriptionError(f"{where}: axis is zero")
            lim = j.find("limit")
            # a bound not written is 0, as urdfdom reads it (a fixed joint's <limit> means nothing)
            j_lower = _fattr(lim, "lower", 0.0 if lim is not None else -math.pi, f"{where} limit")
            j_upper = _fattr(lim, "upper", 0.0 if lim is not None else math.pi, f"{where} limit")
            if j.get("type") == "continuous":
                j_lower, j_upper = -2 * math.pi, 2 * math.pi
            elif lim is not None and lim.get("lower") is not None and lim.get("upper") is not None:
                bounded.add(name)
            axis = axis / (np.linalg.norm(axis) or 1.0)
            master: str | None = None
            mult, offset = 1.0, 0.0
            mimic_el = j.find("mimic")
            if mimic_el is not None and kind != "fixed":
                master, mult, offset = _mimic(mimic_el, where)
            ordered.append(Joint(name, kind, link, _link_of(j, "child"), _origin(j.find("origin"), where),
                                 axis, lower=j_lower, upper=j_upper, offset=offset, mimic=master, multiplier=mult))
            stack.append(_link_of(j, "child"))
    actuated = [j.name for j in ordered if j.kind != "fixed" and j.mimic is None]
    for jt in ordered:
        if jt.mimic is not None and jt.mimic not in actuated:
            raise DescriptionError(f"{urdf}: joint '{jt.name}' mimic joint: '{jt.mimic}' is not a movable, non-mimic joint")
    side, jl = _moveit(side, sidecar, ordered, links, actuated)
    notes: list[str] = list(side.pop("_notes"))
    driven = side.pop("_driven")
    names = list(side.get("joints", driven))
    for n in names:
        if n not in actuated:
            mimics = next((j.mimic for j in ordered if j.name == n and j.mimic), None)
            raise DescriptionError(f"{sidecar}: joints: '{n}' is not a movable joint of {urdf.name}"
                                   + (f" (it mimics '{mimics}')" if mimics else ""))
    held = [a for a in actuated if a not in names]
    held_values = {j.name: rest_value(j) for j in ordered if j.name in held}
    if held:  # a movable joint that nothing drives (not in joints:, or SRDF-passive) stays where it rests
        rest = held_values
        notes.append("joint(s) not driven, held still: " + ", ".join(
            f"{n} at {rest[n]:g} {'m' if next(j for j in ordered if j.name == n).kind == 'prismatic' else 'rad'}"
            for n in held) + " (list them in the sidecar's joints: to drive them)")
        ordered = held_fixed(ordered, held)
    urdf_vel, urdf_eff, vel_default, negative = [], [], set(), []
    for n in names:
        lim = next(j for j in joints_xml if j.get("name") == n).find("limit")
        v = _fattr(lim, "velocity", 0.0, f"{urdf}: joint '{n}' limit")
        if "velocity" not in jl.get(n, {}) and not v > 0:
            vel_default.add(n)
        urdf_vel.append(jl.get(n, {}).get("velocity", v if v > 0 else DEFAULT_VELOCITY))
        e = _fattr(lim, "effort", 0.0, f"{urdf}: joint '{n}' limit")
        urdf_eff.append(e if e > 0 else np.inf)  # URDF effort 0 means unset
        negative += [f"{n} {key} {value:g}" for key, value in (("velocity", v), ("effort", e)) if value < 0]
    if negative:  # urdfdom reads any number here; a vendor's -1 means "not given" (Annin's AR4 writes effort="-1")
        notes.append(f"URDF limit(s) below 0 taken as not given: {', '.join(negative)} (no effort bound; "
                     "roarmctl's default velocity unless joint_limits.yaml gives one)")
    by_name = {j.name: j for j in ordered}

    meshes = {"urdf": urdf, "packages": package_map(side.get("packages"), sidecar, str(sidecar)),
              "modes": mesh_modes(side.get("mesh_collision"), list(links), str(sidecar)), "roots": side.get("_roots")}
    inertials, shapes, massless = {}, [], []
    for lname, el in links.items():
        inn = el.find("inertial")
        if inn is not None and inn.find("mass") is not None:
            o = _origin(inn.find("origin"), f"{urdf}: link '{lname}' inertial")
            i = inn.find("inertia")
            g = {k: _fattr(i, k, 0.0, f"{urdf}: link '{lname}' inertia") for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
            tensor = np.array([[g.get("ixx", 0), g.get("ixy", 0), g.get("ixz", 0)],
                               [g.get("ixy", 0), g.get("iyy", 0), g.get("iyz", 0)],
                               [g.get("ixz", 0), g.get("iyz", 0), g.get("izz", 0)]])
            r = o[:3, :3]
            inertials[lname] = Inertial(_fattr(inn.find("mass"), "value", 0.0, f"{urdf}: link '{lname}' mass"), o[:3, 3], r @ tensor @ r.T)
        else:
            # URDF: a link without <inertial> has no mass. Said when the link has a body (collision geometry):
            # a frame link without one is massless by design
            inertials[lname] = Inertial(0.0, np.zeros(3), np.zeros((3, 3)))
            if el.find("collision") is not None:
                massless.append(lname)
        for k, c in enumerate(el.findall("collision")):
            shapes.extend(urdf_shape(lname, c, f"{urdf}: link '{lname}' collision[{k}]", k, meshes))
    if massless:
        notes.append(f"link(s) with collision geometry but no <inertial>, taken as massless: {', '.join(massless)}")
    notes += unit_notes(shapes, ordered)
    tcp = side.get("tcp_link", next((j.child for j in reversed(ordered) if j.mimic is None), ordered[-1].child))
    if tcp not in links:
        raise DescriptionError(f"{sidecar}: tcp_link: '{tcp}' is not a link of {urdf.name}")
    tool = tool_joint(side, str(sidecar), tcp, set(links) | {j.name for j in ordered})
    if tool is not None:
        ordered.append(tool)
        tcp = tool.child
    lower = np.array([jl.get(n, {}).get("lower", by_name[n].lower) for n in names])
    upper = np.array([jl.get(n, {}).get("upper", by_name[n].upper) for n in names])
    mimic_bounds(ordered, names, bounded, lower, upper, notes)
    acc = np.array([jl.get(n, {}).get("acceleration", DEFAULT_ACCELERATION) for n in names])
    acc_default = {n for n in names if "acceleration" not in jl.get(n, {})}
    common = common_fields(side, sidecar, names, np.array(urdf_vel), acc, np.array(urdf_eff),
                     {"velocity": vel_default, "acceleration": acc_default})
    for pname in side.get("_srdf_poses", []):  # MoveIt loads a state outside the limits; a named pose lies within
        pose = common["named_poses"].get(pname)
        off = np.zeros(0, dtype=int) if pose is None else np.flatnonzero((pose < lower - 1e-6) | (pose > upper + 1e-6))
        if pose is not None and len(off):
            k = int(off[0])
            del common["named_poses"][pname]
            notes.append(f"{side['srdf']}: group_state '{pname}' left out: {names[k]} = {pose[k]:g} is outside its limits "
                         f"[{lower[k]:g}, {upper[k]:g}] (MoveIt loads such a state; roarmctl's named poses lie within)")
    return Robot(
        name=str(side.get("name", root.get("name", urdf.stem))),
        source=str(side.get("source", urdf.name)),
        root=roots[0],
        joints=ordered,
        joint_names=names,
        tcp_link=tcp,
        lower=lower,
        upper=upper,
        inertials=inertials,
        collision=shapes,
        visual_source=visuals.source_of(((n, k, v) for n, e in links.items() for k, v in enumerate(e.findall("visual"))),
                                        meshes, root, urdf_shape),
        notes=notes,
        padding=sidecar_padding(side, str(sidecar), set(links)),
        held_joints=held_values,
        **common,
    )


def urdf_shape(link: str, c: ET.Element, where: str, k: int, meshes: dict) -> list[CollisionShape]:
    """One ``<collision>`` element -> shapes. ``meshes``: {"urdf", "packages", "modes"} for mesh files."""
    origin = _origin(c.find("origin"), where)
    geom = c.find("geometry")
    name = c.get("name", f"{link}_{k}")
    if geom is None or len(geom) == 0:
        raise DescriptionError(f"{where}: missing <geometry>")
    if len(geom) > 1:
        raise DescriptionError(f"{where}: <geometry> holds {len(geom)} shapes; URDF allows one per <collision>")
    g = geom[0]

    def req(key: str) -> float:
        if g.get(key) is None:
            raise DescriptionError(f"{where} {g.tag}: missing attribute '{key}'")
        v = _fattr(g, key, 0.0, f"{where} {g.tag}")
        if not v > 0 or not math.isfinite(v):
            raise DescriptionError(f"{where} {g.tag} {key}: must be a positive number, got '{g.get(key)}'")
        return v

    if g.tag == "box":
        size = _floats(g.get("size"), 3, f"{where} box size") if g.get("size") is not None else None
        if size is None or not np.all(size > 0):
            raise DescriptionError(f"{where} box size: expected 3 positive numbers, got {g.get('size')!r}")
        return [CollisionShape(link, "box", origin, size=tuple(size), name=name)]
    if g.tag == "cylinder":
        return [CollisionShape(link, "cylinder", origin, radius=req("radius"), length=req("length"), name=name)]
    if g.tag == "sphere":
        return [CollisionShape(link, "sphere", origin, radius=req("radius"), name=name)]
    if g.tag == "capsule":  # not URDF 1.0, but common (Gazebo/SDF extension)
        return [CollisionShape(link, "capsule", origin, radius=req("radius"), length=req("length"), name=name)]
    if g.tag == "mesh":
        filename, scale_text = g.get("filename"), g.get("scale")
        if not filename:
            raise DescriptionError(f"{where} mesh: missing attribute 'filename'")
        scale = np.ones(3)
        if scale_text is not None:
            scale = _floats(scale_text, 3, f"{where} mesh scale")
            if not np.all((scale >= MESH_SCALE[0]) & (scale <= MESH_SCALE[1])):
                raise DescriptionError(f"{where} mesh scale: '{scale_text[:40]}': each factor must be between "
                                       f"{MESH_SCALE[0]:g} and {MESH_SCALE[1]:g}", "mm to m is 0.001")
        path = resolve(filename, meshes["urdf"], meshes["packages"], where, meshes.get("roots"))
        mesh, centre = load_mesh(path, scale, meshes["modes"].get(link, "convex") == "exact", where, meshes.get("roots"))
        placed = origin.copy()
        placed[:3, 3] = origin[:3, 3] + origin[:3, :3] @ centre
        return [CollisionShape(link, "mesh", placed, name=name, mesh=mesh)]
    raise DescriptionError(f"{where}: geometry <{g.tag}> is not supported (box, cylinder, sphere, capsule, mesh)")
