"""Load a robot by bundled name or path: URDF plus sidecar YAML, a bare URDF, or a DH table in YAML.

The formats are read by ``urdf_loader`` (URDF, xacro, SRDF, joint_limits.yaml) and ``dh_loader`` (DH table),
the sidecar's shared fields by ``sidecar``; here a robot is found, kept, given its link roles and checked.
Every mistake in a description raises ``DescriptionError`` naming the file and the field.
"""

from __future__ import annotations

import functools
import os
from importlib import resources
from pathlib import Path

from roarmctl.errors import DescriptionError, InputError
from roarmctl.fileio import FilesRead, resolved
from roarmctl.kept import Kept
from roarmctl.robot import validate as checks
from roarmctl.robot import xacro_input
from roarmctl.robot.dh_loader import from_dh
from roarmctl.robot.ik import IK_FAMILIES, ur6_params
from roarmctl.robot.implied import adjacent_pairs, default_notes, gripper_part_pairs
from roarmctl.robot.jaw_meshes import with_jaw_meshes
from roarmctl.robot.meshes import PACKAGE_PATHS, description_roots
from roarmctl.robot.model import Robot
from roarmctl.robot.sidecar import read_sidecar
from roarmctl.robot.singularity import MODELS
from roarmctl.robot.urdf_loader import from_urdf


def bundled_dir() -> Path:
    """The folder of the bundled robot descriptions (package data)."""
    return Path(str(resources.files("roarmctl") / "robots"))


def bundled_robots() -> list[str]:
    """Names of the robots shipped with roarmctl (the package's own files: listed once per process; every plan's
    trajectory asks whether its robot is one of them)."""
    return list(_bundled_names())


@functools.cache
def _bundled_names() -> tuple[str, ...]:
    return tuple(sorted(p.stem for p in bundled_dir().glob("*.yaml")))


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


def _listed(folder: Path, most: int = 200) -> list[Path]:
    """Up to ``most`` entries of ``folder`` (a huge folder is not read whole for a message); none if unreadable."""
    try:
        with os.scandir(folder) as it:
            return [Path(e.path) for _, e in zip(range(most), it)]
    except OSError:
        return []


def _load(spec: str, trust_sidecar: bool, confine: bool) -> Robot:
    """``load_robot`` itself (not kept)."""
    path = bundled_dir() / f"{spec}.yaml"
    if "/" in spec or os.sep in spec or not _is_file(path):  # a bundled name is a plain name
        path = Path(spec).expanduser()
        if _is_dir(path):  # a description's folder (tests/data/arms/ur5e): name the files in it that could be meant
            # names found in a folder a plan, trajectory or log named are not put in a message (issue 40's rule)
            found = [] if confine else sorted(p.name for p in _listed(path) if p.suffix.lower() in (".yaml", ".yml", ".urdf", ".xacro"))
            raise InputError(f"robot '{spec[:80]}' is a folder, not a description file",
                             f"give one of its files: {', '.join(found[:5])}" if found
                             else "give the path of its .yaml sidecar or its .urdf/.xacro file")
        if not _is_file(path) and ("/" in spec or os.sep in spec or path.suffix.lower() in (".yaml", ".yml", ".urdf", ".xacro")):
            # a path, not a bundled name: 'unknown robot ... or give a path' told the user to do what they did
            raise InputError(f"no such description file '{spec[:80]}'", "check the path (relative to the plan's "
                             f"folder in a plan); bundled robots by name: {', '.join(bundled_robots())}")
        if not _is_file(path):
            raise InputError(
                f"unknown robot '{spec[:80]}'",
                f"bundled robots: {', '.join(bundled_robots())}; or give a path to a .yaml or .urdf file",
            )
    data: dict = {}
    if path.suffix.lower() in (".urdf", ".xacro"):
        robot = from_urdf(path, {"_roots": description_roots({}, path)}, path)
    else:
        data = read_sidecar(path)
        if "dh" in data:
            robot = from_dh(path, data)
        elif "urdf" in data:
            data["_roots"] = description_roots(data, path, confined=confine)
            data["_trusted"] = trust_sidecar and data.get("trust") is True
            urdf = resolved(path.parent / str(data["urdf"]), f"{path}: urdf", DescriptionError)
            if not urdf.exists():  # anything else (a FIFO, a folder) is refused by the reader
                raise DescriptionError(f"{path}: urdf: file '{data['urdf']}' not found", "the path is relative to the YAML file")
            robot = from_urdf(urdf, data, path)
        else:
            raise DescriptionError(f"{path}: needs either a 'dh' table or a 'urdf' file reference")
    jaw = robot.gripper.fixed_jaw if robot.gripper is not None else None
    if jaw is not None and jaw.link not in robot.link_names:
        raise DescriptionError(f"{path}: gripper.fixed_jaw.link: '{jaw.link}' is not a link of {robot.name}")
    for f in robot.frames.values():
        if f.point_link is not None and f.point_link not in robot.link_names:
            raise DescriptionError(f"{path}: frames.{f.name}.point.link: '{f.point_link}' is not a link of {robot.name}")
    grip = robot.gripper.joint if robot.gripper is not None else None
    mimic = [robot.joints[j].name for j in robot.kin.tcp_chain_joints if grip is not None and robot.joints[j].mimic == grip]
    if mimic:  # a mimic joint of the arm (ABB's IRB 5400 wrist) is a column of the Jacobian; one of the gripper is not
        raise DescriptionError(f"{path}: tcp_link: '{robot.tcp_link}' is moved by '{mimic[0]}', which mimics the "
                               f"gripper joint '{grip}'", "put the TCP on a link the arm joints move, e.g. the hand "
                               "between the fingers")
    robot = _link_roles(robot, data, str(path))
    robot = with_jaw_meshes(robot, data, path, data.get("_roots") or (description_roots(data, path) if data else None))
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


def _is_dir(path: Path) -> bool:
    """``is_dir`` that answers False for names the OS refuses (too long, NUL byte)."""
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


def _is_file(path: Path) -> bool:
    """``is_file`` that answers False for names the OS refuses (too long, NUL byte)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False
