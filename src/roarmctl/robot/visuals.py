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
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from roarmctl.errors import DescriptionError
from roarmctl.robot.meshes import MeshGeometry
from roarmctl.robot.model import CollisionShape, Robot

#: Triangles of all the visual meshes of one robot that a picture takes; beyond it the rest are left out
#: (said), so a high-resolution CAD export cannot make a page of hundreds of MB.
MAX_TRIANGLES = 300_000


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
        for shape in shapes:
            n = len(shape.mesh.faces) if isinstance(shape.mesh, MeshGeometry) else 0
            if n > budget:
                notes.append(f"{where} left out: its {n} triangles pass the {MAX_TRIANGLES} of all visual meshes")
                continue
            budget -= n
            out.append(Visual(shape, rgba))
    return out, notes
