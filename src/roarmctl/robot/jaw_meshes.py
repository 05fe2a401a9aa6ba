"""A gripper's jaw meshes (``gripper.jaw_meshes`` of a sidecar): the files its jaw table was measured on.

    gripper: {..., jaw_meshes: [{link: link5, file: meshes/link5.stl, scale: 0.001}, ...]}
    gripper: {..., jaw_meshes: [{link: link5, pieces: jaw_pieces/roarm_m3_link5.json}, ...]}

Each entry names a link of the robot and a mesh file in that link's frame (relative to the URDF, as its own
meshes are, or to the sidecar of a DH description; absolute, ``file://`` or ``package://``; inside the description's roots: checked when the description loads, read only
when asked, like a collision mesh: bounded in size and triangles, once per process); ``scale`` multiplies the
vertices (default 1: metres). Or, instead of the mesh, ``pieces``: a file of its convex pieces that roarmctl made
(``roarmctl.robot.jaw_pieces``' format, metres; the bundled descriptions ship these, not the vendor's meshes).
Picks close by their convex pieces (``roarmctl.robot.jaw_pieces``,
``roarmctl.motion.planning.jaw_reach``) and the physics' jaws are those pieces: the planner and the physics squeeze
with one geometry.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.fileio import Roots, resolved
from roarmctl.robot.meshes import PACKAGE_PATHS, package_map, read_triangles, resolve
from roarmctl.robot.model import JawMesh, Robot


def with_jaw_meshes(robot: Robot, data: dict, sidecar: Path, roots: Roots | None) -> Robot:
    """``robot`` with its gripper's ``jaw_meshes`` read from the sidecar ``data`` (checked by
    ``validate.check_document``); unchanged when the sidecar names none. A file that is not there is left out with a
    note (a description copied without them still loads). Raises DescriptionError naming the entry for a link the
    robot lacks or a file outside ``roots``."""
    g = data.get("gripper")
    entries = g.get("jaw_meshes") if isinstance(g, dict) else None
    if not entries or robot.gripper is None:
        return robot
    packages = {**PACKAGE_PATHS, **package_map(data.get("packages"), sidecar, str(sidecar))}
    base = resolved(sidecar.parent / str(data["urdf"]), f"{sidecar}: urdf", DescriptionError) if "urdf" in data else sidecar
    meshes: list[JawMesh] = []
    for i, entry in enumerate(entries):
        where = f"{sidecar}: gripper.jaw_meshes[{i}]"
        link = str(entry["link"])
        if link not in robot.link_names:
            raise DescriptionError(f"{where}.link: '{link}' is not a link of {robot.name}")
        given = str(entry["pieces"] if "pieces" in entry else entry["file"])
        path = resolve(given, base, packages, where, roots)
        if not path.is_file():  # a description copied without its jaw meshes still loads, as without visuals
            robot.notes.append(f"gripper.jaw_meshes[{i}]: '{given}' not found (relative to the "
                               f"{'URDF' if 'urdf' in data else 'sidecar'}): {link} meets objects with its collision "
                               f"shapes and picks close by the jaw table")
            continue
        if "pieces" in entry:
            meshes.append(JawMesh(link, "", 1.0, roots, pieces=str(path)))
        else:
            meshes.append(JawMesh(link, str(path), float(entry.get("scale", 1.0)), roots))
    robot.gripper = replace(robot.gripper, jaw_meshes=tuple(meshes))
    return robot


def jaw_triangles(mesh: JawMesh) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) m in the jaw link's frame, faces (F, 3) int64) of a jaw mesh, read through the one bounded
    mesh reader (``meshes.read_triangles``) inside the description's roots. Raises DescriptionError for an entry
    that gives its pieces, not its mesh."""
    if not mesh.file:
        raise DescriptionError(f"gripper.jaw_meshes ({mesh.link}): given as convex pieces ('{mesh.pieces}'), not a mesh")
    return read_triangles(Path(mesh.file), mesh.scale, f"gripper.jaw_meshes ({mesh.link})", roots=mesh.roots)

