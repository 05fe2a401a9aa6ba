"""A robot description carried inside a trajectory or an execution log, so that opening one never loads
a file it names.

A trajectory planned for a bundled robot names it (``"robot": "roarm_m3_pro"``). For any other
description the planner writes its ``robot_description``: the files the loader read, as data -
``robot.yaml`` (the sidecar, its file references pointing into the bundle), ``robot.urdf`` (the URDF
after xacro, checked; every collision mesh renamed ``meshes/mK.ext``, and the visual meshes too within
``VISUAL_BYTES``, their shapes read when the bundle is loaded, for pictures),
``robot.srdf`` and ``joint_limits.yaml`` when the sidecar has them, the mesh files' bytes (base64), and the
convex pieces of the gripper's jaw meshes the plan closed by (``jaw_pieces/jN.json``; the sidecar's
``jaw_meshes`` name them).
No xacro is left to evaluate and no path leads outside the bundle.

Reading one (``load_bundle``) checks the form (known file names only, sizes, base64), writes the
files into a private temporary folder, loads that with the ordinary loader (every check of a
description applies; the folder is the only root) and removes the folder. Old trajectories that name
a description by path still load it (``trajectory_robot``), as data: xacro only through the safe
evaluator, the sidecar's ``trust`` ignored.
"""

from __future__ import annotations

import base64
import binascii
import copy
import hashlib
import json
import os
import re
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from roarmctl.checks import Checker
from roarmctl.errors import DescriptionError, InputError, TrajectoryFileError
from roarmctl.fileio import FilesRead, Roots, read_bytes, read_text, resolved
from roarmctl.kept import Kept
from roarmctl.robot.jaw_meshes import jaw_triangles
from roarmctl.robot.jaw_pieces import CACHE_BYTES, cache_key, cache_text, convex_pieces, keep_jaw_pieces
from roarmctl.robot.meshes import (
    CONFINED_HINT,
    MESH_BYTES,
    MESH_TYPES,
    PACKAGE_PATHS,
    description_roots,
    package_map,
    resolve,
)
from roarmctl.robot.model import JawMesh, Robot
from roarmctl.robot.visuals import keep_visuals
from roarmctl.robot.xacro_input import expand

FORMAT = "roarmctl.robot-bundle/1"
MAX_BUNDLE_BYTES = 64 * 1024 * 1024  # all files of a bundle together, decoded
#: Files of a bundle (each is written to a temporary folder to be loaded: 100,000 empty meshes took 19 s).
MAX_BUNDLE_FILES = 1000
#: Bytes of visual mesh files a bundle carries (pictures only; a CAD export over it is left out, drawn as collision).
VISUAL_BYTES = 16 * 1024 * 1024
FILE_NAME = re.compile(r"^(robot\.yaml|robot\.urdf|robot\.srdf|joint_limits\.yaml|meshes/m\d{1,5}\.(stl|obj|dae|ply|off|glb)"
                       r"|jaw_pieces/j\d{1,2}\.json)$")
_LOADED: Kept[Robot] = Kept(64)  # robots of bundles, by their files' digests
# bundles made, by the spec (and the current folder for a relative one) and the options, with the files each read: a
# hit is handed out only while every one of them is unchanged (as loader.load_robot's robots; every plan of a
# xacro description expanded its URDF and SRDF again: a third of planning the xArm6's short plans)
_MADE: Kept[tuple[dict[str, Any], FilesRead]] = Kept(64)


def _plain(value: Any) -> Any:
    """Located YAML containers -> plain dicts and lists (for ``yaml.safe_dump``)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items() if not str(k).startswith("_")}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def make_bundle(spec: str, confine: bool = False) -> dict[str, Any] | None:
    """The ``robot_description`` of the description at path ``spec`` (None for a bundled robot's name).

    Reads exactly what loading it reads (inside its roots, bounded; ``confine`` as ``load_robot``'s, for a
    description a plan named); xacro is expanded as loading it from a plan would (the safe evaluator,
    unless the user's ``--trust-xacro``). Made once while none of the files it read changed (a fresh copy each call)."""
    from roarmctl.robot import loader, xacro_input

    if spec in loader.bundled_robots():
        return None
    here = "" if os.path.isabs(spec) else os.getcwd()
    key = (spec, here, confine, xacro_input.TRUST_ALL, tuple(sorted((k, str(v)) for k, v in PACKAGE_PATHS.items())))
    hit = _MADE.get(key)
    if hit is not None and hit[1].unchanged():
        return copy.deepcopy(hit[0])
    _MADE.pop(key, None)
    with FilesRead() as files:
        bundle = _make_bundle(spec, confine)
    return copy.deepcopy(_MADE.keep(key, (bundle, files))[0])


def _make_bundle(spec: str, confine: bool) -> dict[str, Any]:
    import yaml

    from roarmctl.robot.joint_limits import JOINT_LIMITS_BYTES, substituted
    from roarmctl.robot.sidecar import read_sidecar
    from roarmctl.robot.urdf_loader import URDF_BYTES, read_urdf

    path = Path(spec)
    files: dict[str, Any] = {}
    if path.suffix.lower() in (".urdf", ".xacro"):
        side: dict[str, Any] = {}
        urdf = path
    else:
        side = dict(read_sidecar(path))
        if "dh" in side:
            files["robot.yaml"] = yaml.safe_dump(_plain(side), sort_keys=False)
            return {"format": FORMAT, "files": files}
        urdf = resolved(path.parent / str(side["urdf"]), f"{path}: urdf", DescriptionError)
    roots = description_roots(side, path, confined=confine)
    side["_roots"] = roots
    root = read_urdf(urdf, side, path)
    packages = package_map(side.get("packages"), path, str(path))
    renamed: dict[Path, str] = {}
    visual_bytes = 0
    for link in root.findall("link"):
        for k, col in enumerate(link.findall("collision")):
            mesh = col.find("geometry/mesh")
            if mesh is None or not mesh.get("filename"):
                continue
            where = f"{urdf}: link '{link.get('name')}' collision[{k}]"
            src = resolve(str(mesh.get("filename")), urdf, packages, where, roots)
            if src not in renamed:
                data = read_bytes(src, f"{where} mesh filename", MESH_BYTES, roots=roots, error=DescriptionError)
                renamed[src] = f"meshes/m{len(renamed)}{src.suffix.lower()}"
                files[renamed[src]] = {"base64": base64.b64encode(data).decode("ascii")}
            mesh.set("filename", renamed[src])
    for link in root.findall("link"):  # the visuals, for pictures, within VISUAL_BYTES; one that does not fit is left out
        for k, visual in enumerate(link.findall("visual")):
            mesh = visual.find("geometry/mesh")
            if mesh is None or not mesh.get("filename"):
                continue
            where = f"{urdf}: link '{link.get('name')}' visual[{k}]"
            try:
                src = resolve(str(mesh.get("filename")), urdf, packages, where, roots)
                if src not in renamed:
                    size = src.stat().st_size
                    if visual_bytes + size > VISUAL_BYTES or src.suffix.lower().lstrip(".") not in MESH_TYPES:
                        raise DescriptionError(f"{where}: over the visual budget")
                    data = read_bytes(src, f"{where} mesh filename", MESH_BYTES, roots=roots, error=DescriptionError)
                    visual_bytes += len(data)
                    renamed[src] = f"meshes/m{len(renamed)}{src.suffix.lower()}"
                    files[renamed[src]] = {"base64": base64.b64encode(data).decode("ascii")}
            except (DescriptionError, OSError):  # not shipped, too large: drawn without it (said when drawn)
                link.remove(visual)
                continue
            mesh.set("filename", renamed[src])
    files["robot.urdf"] = ET.tostring(root, encoding="unicode")
    out = _plain(side)
    for key in ("xacro_args", "trust", "packages"):
        out.pop(key, None)
    out["urdf"] = "robot.urdf"
    if side.get("srdf") is not None:
        srdf = path.parent / str(side["srdf"])
        if srdf.suffix.lower() == ".xacro":
            files["robot.srdf"] = expand(srdf, side.get("xacro_args"), str(path), roots=roots)
        else:
            files["robot.srdf"] = read_text(srdf, f"{path}: srdf", URDF_BYTES, roots=roots, error=DescriptionError)
        out["srdf"] = "robot.srdf"
    if side.get("joint_limits") is not None:
        limits = path.parent / str(side["joint_limits"])  # $(var NAME) replaced: the bundle keeps no xacro_args
        files["joint_limits.yaml"] = substituted(read_text(limits, f"{path}: joint_limits", JOINT_LIMITS_BYTES, roots=roots,
                                                           error=DescriptionError), side.get("xacro_args"), str(limits))
        out["joint_limits"] = "joint_limits.yaml"
    _carry_jaw_pieces(out, files, urdf, packages, roots)
    files["robot.yaml"] = yaml.safe_dump(out, sort_keys=False)
    return {"format": FORMAT, "files": files}


def _carry_jaw_pieces(side: dict[str, Any], files: dict[str, Any], urdf: Path, packages: dict, roots: Roots) -> None:
    """The sidecar ``side``'s ``gripper.jaw_meshes`` as the convex pieces the plan closed by, carried in ``files``
    (``jaw_pieces/jN.json``, ``roarmctl.robot.jaw_pieces``' format), each entry rewritten to name them: the physics
    of a run from the trajectory alone squeezes with the planner's jaws, not the links' collision shapes, and no
    machine decomposes a mesh again. An entry whose file is not there is left out, as loading left it out."""
    gripper = side.get("gripper")
    if not isinstance(gripper, dict) or not gripper.get("jaw_meshes"):
        return
    entries = gripper["jaw_meshes"]
    carried: list[dict[str, Any]] = []
    for i, entry in enumerate(entries):
        where = f"{urdf}: gripper.jaw_meshes[{i}]"
        given = str(entry["pieces"] if "pieces" in entry else entry["file"])
        path = resolve(given, urdf, packages, where, roots)
        if not path.is_file():
            continue
        name = f"jaw_pieces/j{len(carried)}.json"
        if "pieces" in entry:
            files[name] = read_text(path, where, CACHE_BYTES, roots=roots, error=DescriptionError)
        else:
            mesh = JawMesh(str(entry["link"]), str(path), float(entry.get("scale", 1.0)), roots)
            files[name] = cache_text(cache_key(*jaw_triangles(mesh)), convex_pieces(mesh))
        carried.append({"link": entry["link"], "pieces": name})
    gripper["jaw_meshes"] = carried


def _decoded(doc: Any, where: str) -> dict[str, bytes]:
    """The files of a bundle document, checked: names, types, base64, total size."""
    check = Checker(TrajectoryFileError, json=True)
    field = "robot_description"
    check.mapping(doc, where, field)
    if doc.get("format") != FORMAT:
        check.fail(where, f"{field}.format", f"expected '{FORMAT}', got {check.kind(doc.get('format'))}")
    check.known_keys(doc, ("format", "files"), where, field)
    files = check.mapping(doc.get("files"), where, f"{field}.files")
    if len(files) > MAX_BUNDLE_FILES:
        check.fail(where, f"{field}.files", f"more than {MAX_BUNDLE_FILES} files", "a robot has one mesh file per shape")
    out: dict[str, bytes] = {}
    total = 0
    for name, value in files.items():
        at = f"{field}.files.{str(name)[:60]}"
        if not isinstance(name, str) or not FILE_NAME.match(name):
            check.fail(where, at, "not a file a robot description bundle holds",
                       "robot.yaml, robot.urdf, robot.srdf, joint_limits.yaml, meshes/mN.EXT, jaw_pieces/jN.json")
        if isinstance(value, str):
            data = value.encode("utf-8")
        elif isinstance(value, dict) and set(value) == {"base64"} and isinstance(value["base64"], str):
            try:
                data = base64.b64decode(value["base64"], validate=True)
            except (binascii.Error, ValueError):
                check.fail(where, f"{at}.base64", "not valid base64")
        else:
            check.fail(where, at, f"expected the file's text or {{base64: ...}}, got {check.kind(value)}")
        total += len(data)
        if total > MAX_BUNDLE_BYTES:
            check.fail(where, field, f"its files hold more than {MAX_BUNDLE_BYTES // 2 ** 20} MiB")
        out[name] = data
    if "robot.yaml" not in out:
        check.fail(where, f"{field}.files", "'robot.yaml' is missing")
    return out


def load_bundle(doc: Any, where: str) -> Robot:
    """The ``Robot`` of a ``robot_description`` (see the module docstring); refusals name ``where``
    (the trajectory or log file) and the field."""
    from roarmctl.robot.loader import load_robot

    files = _decoded(doc, where)
    key = hashlib.sha256(json.dumps({k: hashlib.sha256(v).hexdigest() for k, v in sorted(files.items())}).encode()).hexdigest()
    if (key,) in _LOADED:
        return _LOADED[(key,)]
    with tempfile.TemporaryDirectory(prefix="roarmctl-robot-") as tmp:
        folder = Path(tmp)
        for name, data in files.items():
            (folder / name).parent.mkdir(exist_ok=True)
            (folder / name).write_bytes(data)
        try:
            robot = load_robot(str(folder / "robot.yaml"), confine=True)
            keep_visuals(robot)  # read now: the folder goes at the end of this block
            keep_jaw_pieces(robot)
        except InputError as exc:
            message = exc.message.replace(str(folder), f"{where}: robot_description")
            raise type(exc)(message, exc.hint) from None
    return _LOADED.keep((key,), robot)


def trajectory_robot(name: str, description: Any, where: str) -> Robot:
    """The robot of a trajectory or execution log: its ``robot_description`` when it carries one, else the
    bundled robot ``name`` - or, in a file written before bundles, the description at path ``name``,
    loaded as data (xacro by the safe evaluator, a sidecar's ``trust`` ignored). When ``where`` is the
    file, that path must lie beside it (relative to its folder) or under a ``--package-path`` folder,
    and the description reads only inside its own folder (``load_robot``'s ``confine``), as a plan's."""
    from roarmctl.robot.loader import bundled_robots, load_robot

    if description is not None:
        return load_bundle(description, where)
    source = Path(where)
    if name in bundled_robots() or not source.is_file():  # a bundled name, or a trajectory made in memory
        return load_robot(name)
    candidate = source.parent / Path(name)
    if "/" not in name and os.sep not in name and not candidate.is_file():
        return load_robot(name)  # an unknown plain name: said as such
    Roots([source.parent], PACKAGE_PATHS).check(candidate, f"{where}: robot", TrajectoryFileError, CONFINED_HINT)
    return load_robot(str(candidate), confine=True)
