"""A description's visual geometry (URDF ``<visual>``), for pictures only: read when asked, never when planning.

The loader keeps each link's ``<visual>`` elements and what it needs to read their files (``VisualSource``);
``visual_shapes`` turns them into shapes with the collision parser the loader hands over (``urdf_loader.urdf_shape``:
the same geometry rules, file resolution inside the description's roots and bounded mesh reading), each mesh
as its triangles (not a hull), with the element's colour (``<material><color rgba>``, or a named material of
the robot). A visual that cannot be read (a mesh file the package does not ship, say) is left out and said,
not an error: the collision geometry, which planning uses, was read already.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.meshes import MeshGeometry
from roarmctl.robot.model import CollisionShape, Robot

#: Triangles of all the visual meshes of one robot that a picture takes (a page holds 36 bytes of each, 48 as base64:
#: 200,000 make 9.6 MB): beyond it the large meshes are decimated to fit (``decimated``, said), so a high-resolution CAD export
#: cannot make a page of hundreds of MB; what still does not fit is left out (said).
MAX_TRIANGLES = 200_000
#: Meshes with fewer triangles are never decimated (a few hundred already draw a part coarsely).
DECIMATE_ABOVE = 2_000


@dataclass(frozen=True)
class VisualSource:
    """What the loader keeps for ``visual_shapes``: ``elements`` (link, index, ``<visual>`` element), the mesh
    context of the description (``urdf``, ``packages``, ``roots``: as for collision meshes), the loader's
    geometry parser (``parse(link, element, where, index, meshes) -> [CollisionShape]``) and the robot's named
    materials (name -> rgba)."""

    elements: tuple[tuple[str, int, ET.Element], ...]
    meshes: dict[str, Any]
    parse: Callable[..., list[CollisionShape]]
    materials: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class Visual:
    """One visual shape: its geometry in the link frame (a mesh keeps its triangles) and its colour (rgba in
    [0, 1], or None where the description gives none)."""

    shape: CollisionShape
    rgba: tuple[float, float, float, float] | None


def _rgba(text: str | None) -> tuple[float, float, float, float] | None:
    try:
        v = [float(x) for x in (text or "").split()]
    except ValueError:
        return None
    if len(v) != 4 or not all(np.isfinite(v)):
        return None
    r, g, b, a = (min(max(x, 0.0), 1.0) for x in v)
    return (r, g, b, a)


def named_materials(root: ET.Element) -> dict[str, tuple[float, float, float, float]]:
    """The robot-level ``<material name><color rgba/></material>`` definitions of a URDF."""
    out = {}
    for m in root.findall("material"):
        color = m.find("color")
        rgba = _rgba(color.get("rgba") if color is not None else None)
        if m.get("name") and rgba is not None:
            out[str(m.get("name"))] = rgba
    return out


def source_of(elements: Iterable[tuple[str, int, ET.Element]], meshes: dict[str, Any], root: ET.Element,
              parse: Callable[..., list[CollisionShape]]) -> VisualSource | None:
    """The loader's hook: a ``VisualSource`` of a URDF's visual elements (None when it has none)."""
    kept = tuple(elements)
    return VisualSource(kept, dict(meshes), parse, named_materials(root)) if kept else None


def keep_visuals(robot: Robot) -> None:
    """Read the robot's visual shapes now and keep them (a robot loaded from files about to be removed)."""
    robot.derived["visuals"] = visual_shapes(robot)


def visual_shapes(robot: Robot) -> tuple[list[Visual], list[str]]:
    """The robot's visual shapes (empty without a ``visual_source``) and notes on those left out."""
    kept = robot.derived.get("visuals")
    if kept is not None:
        return kept
    src: VisualSource | None = getattr(robot, "visual_source", None)
    if src is None:
        return [], []
    out: list[Visual] = []
    notes: list[str] = []
    read: list[tuple[str, CollisionShape, Any]] = []
    budget = MAX_TRIANGLES
    for link, k, el in src.elements:
        where = f"link '{link}' visual[{k}]"
        ctx = dict(src.meshes, modes={link: "exact"})
        try:
            shapes = src.parse(link, el, where, k, ctx)
        except DescriptionError as exc:
            notes.append(f"{exc.message}: left out")
            continue
        mat = el.find("material")
        rgba = None
        if mat is not None:
            color = mat.find("color")
            rgba = _rgba(color.get("rgba")) if color is not None else src.materials.get(str(mat.get("name")))
        read.extend((where, shape, rgba) for shape in shapes)
    read, said = decimated(read, MAX_TRIANGLES)
    notes += said
    for where, shape, rgba in read:
        n = _faces(shape)
        if n > budget:
            notes.append(f"{where} left out: its {n} triangles pass the {MAX_TRIANGLES:,} of all visual meshes")
            continue
        budget -= n
        out.append(Visual(shape, rgba))
    return out, notes


def _faces(shape: CollisionShape) -> int:
    return len(shape.mesh.faces) if isinstance(shape.mesh, MeshGeometry) else 0


def decimated(read: list[tuple[str, CollisionShape, Any]], budget: int) -> tuple[list[tuple[str, CollisionShape, Any]], list[str]]:
    """The visual shapes ``read`` (where, shape, colour) with their meshes of more than ``DECIMATE_ABOVE`` triangles
    decimated, each by the same factor, so that all of them hold at most ``budget`` triangles; unchanged when they
    fit. Quadric decimation (fast-simplification, through trimesh): the same input gives the same triangles. Returns
    the shapes and a note naming the triangles before and after."""
    total = sum(_faces(s) for _, s, _ in read)
    large = sum(_faces(s) for _, s, _ in read if _faces(s) > DECIMATE_ABOVE)
    room = budget - (total - large)  # what the large meshes may keep
    if total <= budget or large == 0 or room <= 0:
        return read, []
    import trimesh

    factor = room / large
    out = []
    for where, shape, rgba in read:
        n = _faces(shape)
        if n > DECIMATE_ABOVE and isinstance(shape.mesh, MeshGeometry):
            mesh = trimesh.Trimesh(shape.mesh.vertices, shape.mesh.faces, process=False)
            mesh.merge_vertices()  # an STL repeats each corner per triangle: decimated apart, the surface tears
            fewer = mesh.simplify_quadric_decimation(face_count=max(int(n * factor), 4))
            geometry = MeshGeometry(np.asarray(fewer.vertices, dtype=float), np.asarray(fewer.faces, dtype=np.int64),
                                    shape.mesh.exact, shape.mesh.source)
            shape = replace(shape, mesh=geometry)
        out.append((where, shape, rgba))
    after = sum(_faces(s) for _, s, _ in out)
    return out, [f"visual meshes decimated from {total:,} to {after:,} triangles (pictures take at most {budget:,})"]
