"""Load a robot by bundled name or path: URDF plus sidecar YAML, a bare URDF, or a DH table in YAML.

Every mistake in a description raises ``DescriptionError`` naming the file and the field.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.errors import DescriptionError, InputError
from roarmctl.fileio import FilesRead, read_text, resolved
from roarmctl.kept import Kept
from roarmctl.robot import validate as checks
from roarmctl.robot import visuals, xacro_input
from roarmctl.robot.frames import UNITS, Frame
from roarmctl.robot.ik import IK_FAMILIES, ur6_params
from roarmctl.robot.implied import (
    DEFAULT_ACCELERATION,
    DEFAULT_JERK_PER_ACCELERATION,
    DEFAULT_VELOCITY,
    adjacent_pairs,
    default_notes,
    gripper_part_pairs,
    held_fixed,
    mimic_bounds,
    rest_value,
)
from roarmctl.robot.meshes import (
    PACKAGE_PATHS,
    description_roots,
    load_mesh,
    mesh_modes,
    package_map,
    resolve,
    unit_notes,
)
from roarmctl.robot.model import (
    CollisionShape,
    FixedJaw,
    Gripper,
    Inertial,
    Joint,
    JointKind,
    Robot,
    WireField,
    transform,
)
from roarmctl.robot.padding import sidecar_padding
from roarmctl.robot.singularity import MODELS
from roarmctl.robot.srdf import parse_srdf, read_joint_limits, read_srdf
from roarmctl.robot.urdf_values import fattr as _fattr
from roarmctl.robot.urdf_values import floats as _floats
from roarmctl.robot.urdf_values import origin as _origin
from roarmctl.robot.xacro_input import expand
from roarmctl.validation import check_markup

FORMAT = "roarmctl.robot/1"
MESH_SCALE = (1e-5, 1e5)  # a mesh's scale factors (a mesh in mm has 0.001); beyond, a link's shape vanishes or explodes
URDF_BYTES = 16 * 1024 * 1024  # a URDF (or the text xacro makes) may have; published arms have < 1 MiB


def bundled_dir() -> Path:
    """The folder of the bundled robot descriptions (package data)."""
    return Path(str(resources.files("roarmctl") / "robots"))


def bundled_robots() -> list[str]:
    """Names of the robots shipped with roarmctl."""
    return sorted(p.stem for p in bundled_dir().glob("*.yaml"))


# loaded robots, by the spec (and the current folder for a relative one) and the options, with the files each
# load read: a hit is handed out only while every one of them is unchanged
_CACHE: Kept[tuple[Robot, FilesRead]] = Kept(64)


def load_robot(spec: str, trust_sidecar: bool = False, confine: bool = False) -> Robot:
    """A bundled robot name (``roarm_m3_pro``) or a path to a ``.yaml``, ``.urdf`` or ``.xacro`` file.

    A description reads only inside its roots (``meshes.description_roots``: its folder and its
    packages). ``trust_sidecar``: a sidecar's ``trust: true`` lets xacro evaluate its expressions
    itself - True only where the user named the file (``kin``, ``api.load_robot``), never where a plan,
    trajectory or log did (then only the user's ``--trust-xacro`` counts, see ``robot.xacro_safe``).
    ``confine``: a plan, trajectory or log named it: it reads only inside its own folder and the
    ``--package-path`` folders (``meshes.description_roots``), whatever its sidecar names.
    """
    here = "" if os.path.isabs(spec) else os.getcwd()
    key = (spec, here, trust_sidecar, confine, xacro_input.TRUST_ALL, tuple(sorted((k, str(v)) for k, v in PACKAGE_PATHS.items())))
    hit = _CACHE.get(key)
    if hit is not None and hit[1].unchanged():  # the URDF, an include, the SRDF, a mesh edited: loaded again
        return hit[0]
    _CACHE.pop(key, None)
    with FilesRead() as files:
        robot = _load(spec, trust_sidecar, confine)
    return _CACHE.keep(key, (robot, files))[0]


def _load(spec: str, trust_sidecar: bool, confine: bool) -> Robot:
    """``load_robot`` itself (not kept)."""
    path = bundled_dir() / f"{spec}.yaml"
    if "/" in spec or os.sep in spec or not _is_file(path):  # a bundled name is a plain name
        path = Path(spec).expanduser()
        if not _is_file(path):
            raise InputError(
                f"unknown robot '{spec[:80]}'",
                f"bundled robots: {', '.join(bundled_robots())}; or give a path to a .yaml or .urdf file",
            )
    data: dict = {}
    if path.suffix.lower() in (".urdf", ".xacro"):
        robot = _from_urdf(path, {"_roots": description_roots({}, path)}, path)
    else:
        data = _read_yaml(path)
        if "dh" in data:
            robot = _from_dh(path, data)
        elif "urdf" in data:
            data["_roots"] = description_roots(data, path, confined=confine)
            data["_trusted"] = trust_sidecar and data.get("trust") is True
            urdf = resolved(path.parent / str(data["urdf"]), f"{path}: urdf", DescriptionError)
            if not urdf.exists():  # anything else (a FIFO, a folder) is refused by the reader
                raise DescriptionError(f"{path}: urdf: file '{data['urdf']}' not found", "the path is relative to the YAML file")
            robot = _from_urdf(urdf, data, path)
        else:
            raise DescriptionError(f"{path}: needs either a 'dh' table or a 'urdf' file reference")
    jaw = robot.gripper.fixed_jaw if robot.gripper is not None else None
    if jaw is not None and jaw.link not in robot.link_names:
        raise DescriptionError(f"{path}: gripper.fixed_jaw.link: '{jaw.link}' is not a link of {robot.name}")
    for f in robot.frames.values():
        if f.point_link is not None and f.point_link not in robot.link_names:
            raise DescriptionError(f"{path}: frames.{f.name}.point.link: '{f.point_link}' is not a link of {robot.name}")
    mimic = [robot.joints[j].name for j in robot.kin.tcp_chain_joints if robot.joints[j].mimic]
    if mimic:
        raise DescriptionError(f"{path}: tcp_link: '{robot.tcp_link}' is moved by the mimic joint '{mimic[0]}'",
                               "put the TCP on a link the arm joints move, e.g. the hand between the fingers")
    robot = _link_roles(robot, data, str(path))
    robot.notes = [f"{robot.name}: {n}" for n in robot.notes] + default_notes(robot)
    robot.spec = spec if path == bundled_dir() / f"{spec}.yaml" else str(path.resolve())
    robot.allowed_collisions |= adjacent_pairs(robot)
    checks.check_robot(robot, str(path))
    return robot


def _link_roles(robot: Robot, data: dict, where: str) -> Robot:
    """Fill ``jaw_links`` and ``base_links`` from the sidecar, or derive them from the tree.

    Defaults: base links are the root and every link fixed to it; jaw links are the gripper joint's
    child and parent and the children of joints that mimic it (else the last moving link of the TCP
    chain), each with the links fixed to it.
    """
    links = set(robot.link_names)

    def fixed_group(start: str) -> list[str]:
        out, todo = [start], [start]
        while todo:
            cur = todo.pop()
            for j in robot.joints:
                if j.kind == "fixed" and cur in (j.parent, j.child):
                    other = j.child if j.parent == cur else j.parent
                    if other not in out:
                        out.append(other)
                        todo.append(other)
        return out

    def listed(key: str) -> tuple[str, ...] | None:
        value = data.get(key)
        if value is None:
            return None
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise DescriptionError(f"{where}: {key}: expected a list of link names")
        for v in value:
            if v not in links:
                raise DescriptionError(f"{where}: {key}: '{v}' is not a link (links: {', '.join(robot.link_names)})")
        return tuple(value)

    base = listed("base_links")
    robot.base_links = base if base is not None else tuple(fixed_group(robot.root))
    jaws = listed("jaw_links")
    if jaws is None:
        if robot.gripper is not None:
            moved = robot.joints_moved_by(robot.gripper.joint)  # a mimicking finger is a jaw too
            seeds = [j.child for j in moved] + [moved[0].parent]
        else:
            moving = [robot.joints[j] for j in robot.kin.tcp_chain_joints if robot.joints[j].kind != "fixed"]
            seeds = [moving[-1].child] if moving else [robot.tcp_link]
        jaws = tuple(dict.fromkeys(link for s in seeds for link in fixed_group(s)))
    robot.jaw_links = jaws
    robot.allowed_collisions |= gripper_part_pairs(robot)

    sm = robot.singularity_model
    if sm is not None and sm not in MODELS:
        raise DescriptionError(f"{where}: singularity_model: unknown model '{sm}' (known: {', '.join(MODELS)})",
                               "leave it out to classify by the Jacobian's smallest singular value")
    ik = data.get("ik", sm if sm in IK_FAMILIES else None)
    if ik is not None and ik not in IK_FAMILIES:
        raise DescriptionError(f"{where}: ik: unknown IK family {ik!r} (known: {', '.join(IK_FAMILIES)})",
                               "leave it out for the numerical (damped least squares) IK")
    robot.ik = ik
    if "ur6" in (sm, ik):
        robot.derived["ur6_params"] = ur6_params(robot)  # refuses a table the ur6 model cannot serve
    return robot


# --------------------------------------------------------------------------- helpers
def _is_file(path: Path) -> bool:
    """``is_file`` that answers False for names the OS refuses (too long, NUL byte)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _read_yaml(path: Path) -> dict[str, Any]:
    data = checks.read_yaml(path)  # bounded like a plan file: size, nesting, aliases, UTF-8
    if not isinstance(data, dict):
        raise DescriptionError(f"{path}: expected a mapping at the top level")
    fmt = data.get("format", FORMAT)
    if fmt != FORMAT:
        raise DescriptionError(f"{path}: format: '{fmt}' is not supported (expected '{FORMAT}')")
    checks.check_document(data, str(path))
    return data


def _num(value: Any, where: str, *, angle: bool = False, deg: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DescriptionError(f"{where}: expected a number, got {value!r}")
    return math.radians(value) if (angle and deg) else float(value)


def _vec(value: Any, n: int, where: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise DescriptionError(f"{where}: expected a list of {n} numbers, got {value!r}")
    return np.array([_num(v, f"{where}[{i}]") for i, v in enumerate(value)])


def _fixed_jaw(value: Any, where: str) -> FixedJaw:
    """``{link, point: [x, y, z] m, normal: [x, y, z]}`` -> FixedJaw (normal made unit; the link is checked
    once the robot is built)."""
    if not isinstance(value, dict) or not isinstance(value.get("link"), str):
        raise DescriptionError(f"{where}: expected {{link, point: [x, y, z], normal: [x, y, z]}}")
    point = _vec(value.get("point"), 3, f"{where}.point")
    normal = _vec(value.get("normal"), 3, f"{where}.normal")
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
        out = _vec(value, len(names), f"{where}.{key}")
        for name, v in zip(names, out):
            if v <= 0:
                raise DescriptionError(f"{where}.{key}.{name}: must be positive")
        return out
    if isinstance(value, dict):
        out = default.copy()
        for name, v in value.items():
            if name not in names:
                raise DescriptionError(f"{where}.{key}: unknown joint '{name}' (joints: {', '.join(names)})")
            out[names.index(name)] = _num(v, f"{where}.{key}.{name}")
            if out[names.index(name)] <= 0:
                raise DescriptionError(f"{where}.{key}.{name}: must be positive")
        return out
    raise DescriptionError(f"{where}.{key}: expected a list or a mapping joint -> value")


def _common(data: dict, path: Path, names: list[str], velocity: np.ndarray, acceleration: np.ndarray,
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
            jq = tuple(_vec(jw_raw["q"], n, f"{where}: gripper.jaw_width.q"))
            jw = tuple(_vec(jw_raw["mm"], n, f"{where}: gripper.jaw_width.mm") / 1000.0)
            if n < 2 or np.any(np.diff(jq) <= 0) or np.any(np.diff(jw) <= 0):
                raise DescriptionError(f"{where}: gripper.jaw_width: needs 2+ points, q and mm both increasing")
        extra = {k: _num(g[k], f"{where}: gripper.{k}") for k in ("squeeze", "clearance") if g.get(k) is not None}
        jaw = None if g.get("fixed_jaw") is None else _fixed_jaw(g["fixed_jaw"], f"{where}: gripper.fixed_jaw")
        gripper = Gripper(g["joint"], _num(g.get("open"), f"{where}: gripper.open"), _num(g.get("closed"), f"{where}: gripper.closed"),
                          jq, jw, fixed_jaw=jaw, **extra)
    poses = {}
    for pname, values in (data.get("named_poses") or {}).items():
        vals = list(values) if isinstance(values, list) else values
        if isinstance(vals, list) and len(vals) == len(names) - (1 if gripper else 0) and gripper:
            vals = vals + [gripper.closed]
        poses[str(pname)] = _vec(vals, len(names), f"{where}: named_poses.{pname}")
    wire = []
    for i, w in enumerate(data.get("wire") or []):
        loc = f"{where}: wire[{i}]"
        if not isinstance(w, dict) or "joint" not in w or "field" not in w:
            raise DescriptionError(f"{loc}: expected {{joint, field, sign, offset, clamp}}")
        if w["joint"] not in names:
            raise DescriptionError(f"{loc}.joint: '{w['joint']}' is not an actuated joint")
        clamp = _vec(w.get("clamp", [-math.inf, math.inf]), 2, f"{loc}.clamp")
        wire.append(WireField(w["joint"], str(w["field"]), _num(w.get("sign", 1), f"{loc}.sign"),
                              _num(w.get("offset", 0), f"{loc}.offset"), float(clamp[0]), float(clamp[1])))
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
            link, xyz = str(pt["link"]), _vec(pt["xyz"], 3, f"{loc}.point.xyz")
        out[str(name)] = Frame(str(name), _vec(f["origin"], 3, f"{loc}.origin"), unit, link, xyz)
    return out


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


def _tool_joint(data: dict, where: str, parent: str, taken: set[str], lscale: float = 1.0,
                deg: bool = False) -> Joint | None:
    """The fixed joint of ``tool: {xyz, rpy}`` (the TCP offset from ``parent``; xyz in the file's length
    unit, rpy in its angle unit), to a new link named ``tool`` (``tool_1``... if taken); None without one."""
    tool = data.get("tool")
    if not tool:
        return None
    if not isinstance(tool, dict):
        raise DescriptionError(f"{where}: tool: expected {{xyz, rpy}}")
    xyz = _vec(tool.get("xyz", [0, 0, 0]), 3, f"{where}: tool.xyz") * lscale
    rpy = _vec(tool.get("rpy", [0, 0, 0]), 3, f"{where}: tool.rpy")
    if deg:
        rpy = np.radians(rpy)
    name, k = "tool", 0
    while name in taken:
        k += 1
        name = f"tool_{k}"
    return Joint(name, "fixed", parent, name, transform(xyz, rpy))


# --------------------------------------------------------------------------- URDF
def _read_urdf(urdf: Path, side: dict, sidecar: Path) -> ET.Element:
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
    side["_driven"], side["_notes"] = list(actuated), []
    jl: dict = {}
    if side.get("joint_limits") is not None:
        jl = read_joint_limits(sidecar.parent / str(side["joint_limits"]), {j.name for j in ordered if j.kind != "fixed"},
                               str(sidecar), roots=side.get("_roots"))
    if side.get("srdf") is None:
        return side, jl
    jinfo = {j.name: (j.kind, j.child, j.mimic, j.parent) for j in ordered}
    root, src = parse_srdf(resolved(sidecar.parent / str(side["srdf"]), f"{sidecar}: srdf", DescriptionError), side, sidecar,
                           str(sidecar))
    got = read_srdf(root, src, jinfo, set(links), side, str(sidecar))
    side["_notes"] = list(got["notes"])
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
        if missing:
            raise DescriptionError(f"{side['srdf']}: group_state '{pname}': no value for {', '.join(missing)}",
                                   "give every arm joint a value, or define the pose in the sidecar's named_poses")
        grip_value = [values[grip]] if grip is not None and grip in values and grip in names else []
        poses.setdefault(pname, [values[n] for n in arm] + grip_value)
    side["named_poses"] = poses
    side["_driven"] = driven
    return side, jl


# URDF joint types -> roarmctl's kinds: a continuous joint is a revolute one without limits (+-2 pi)
_URDF_KINDS: dict[str, JointKind] = {"revolute": "revolute", "continuous": "revolute", "prismatic": "prismatic",
                                     "fixed": "fixed"}


def _link_of(joint: ET.Element, tag: str) -> str:
    """The link a URDF joint's ``<parent>`` or ``<child>`` (``tag``) names; "" when absent (check_urdf refuses that)."""
    end = joint.find(tag)
    return "" if end is None else end.get("link", "")


def _from_urdf(urdf: Path, side: dict, sidecar: Path) -> Robot:
    root = _read_urdf(urdf, side, sidecar)
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
            j_lower = _fattr(lim, "lower", -math.pi, f"{where} limit")
            j_upper = _fattr(lim, "upper", math.pi, f"{where} limit")
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
            shapes.extend(_urdf_shape(lname, c, f"{urdf}: link '{lname}' collision[{k}]", k, meshes))
    if massless:
        notes.append(f"link(s) with collision geometry but no <inertial>, taken as massless: {', '.join(massless)}")
    notes += unit_notes(shapes, ordered)
    tcp = side.get("tcp_link", next((j.child for j in reversed(ordered) if j.mimic is None), ordered[-1].child))
    if tcp not in links:
        raise DescriptionError(f"{sidecar}: tcp_link: '{tcp}' is not a link of {urdf.name}")
    tool = _tool_joint(side, str(sidecar), tcp, set(links) | {j.name for j in ordered})
    if tool is not None:
        ordered.append(tool)
        tcp = tool.child
    lower = np.array([jl.get(n, {}).get("lower", by_name[n].lower) for n in names])
    upper = np.array([jl.get(n, {}).get("upper", by_name[n].upper) for n in names])
    mimic_bounds(ordered, names, bounded, lower, upper, notes)
    acc = np.array([jl.get(n, {}).get("acceleration", DEFAULT_ACCELERATION) for n in names])
    acc_default = {n for n in names if "acceleration" not in jl.get(n, {})}
    common = _common(side, sidecar, names, np.array(urdf_vel), acc, np.array(urdf_eff),
                     {"velocity": vel_default, "acceleration": acc_default})
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
                                        meshes, root, _urdf_shape),
        notes=notes,
        padding=sidecar_padding(side, str(sidecar), set(links)),
        held_joints=held_values,
        **common,
    )


def _urdf_shape(link: str, c: ET.Element, where: str, k: int, meshes: dict) -> list[CollisionShape]:
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


# --------------------------------------------------------------------------- DH
def _from_dh(path: Path, data: dict) -> Robot:
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
        xyz = _vec(base.get("xyz", [0, 0, 0]), 3, f"{where}: base.xyz") * lscale
        rpy = _vec(base.get("rpy", [0, 0, 0]), 3, f"{where}: base.rpy")
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
        a = _num(row["a"], f"{loc}.a") * lscale
        alpha = _num(row["alpha"], f"{loc}.alpha", angle=True, deg=deg)
        d = _num(row["d"], f"{loc}.d") * lscale
        theta = _num(row.get("theta", 0.0), f"{loc}.theta", angle=True, deg=deg)
        offset = _num(row.get("offset", 0.0), f"{loc}.offset", angle=(kind == "revolute"), deg=deg)
        if kind == "prismatic":
            offset *= lscale
        name = str(row.get("name", f"joint{i + 1}"))
        for key in ("lower", "upper"):
            if key not in row:
                raise DescriptionError(f"{loc}.{key}: missing (joint limits are required)")
        lo = _num(row["lower"], f"{loc}.lower", angle=kind == "revolute", deg=deg)
        hi = _num(row["upper"], f"{loc}.upper", angle=kind == "revolute", deg=deg)
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
    tool = _tool_joint(data, where, prev, {j.child for j in joints} | {j.name for j in joints} | {"base", "world"},
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
        if _num(item["mass"], f"{loc}.mass") < 0:
            raise DescriptionError(f"{loc}.mass: must not be negative")
        inertia = item.get("inertia", [[0, 0, 0], [0, 0, 0], [0, 0, 0]])
        if isinstance(inertia, list) and len(inertia) == 3 and not isinstance(inertia[0], list):
            inertia = np.diag(_vec(inertia, 3, f"{loc}.inertia"))
        else:
            inertia = np.array([_vec(r, 3, f"{loc}.inertia") for r in inertia])
        inertials[link] = Inertial(_num(item["mass"], f"{loc}.mass"), _vec(item.get("com", [0, 0, 0]), 3, f"{loc}.com") * lscale, inertia)
    vel_default = np.full(len(names), DEFAULT_VELOCITY)
    common = _common(data, path, names, vel_default, np.full(len(names), DEFAULT_ACCELERATION),
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
