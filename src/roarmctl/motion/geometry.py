"""The FCL side of shapes: a primitive's or mesh's FCL geometry, its bounding box, and the collision parts of a
scene item (what the checker hands to its compiled pre-filter and to FCL).

A scene item becomes one or more parts, each an FCL object placed in the world and an oriented box that holds
it (the pre-filter's test; ``src/roarmctl/_kernel.c`` clears a pair only where the boxes are apart, so every part
must lie inside its box): a primitive is one part (a cylinder also has a second box, ``second_box``); a mesh
one part per convex piece (FCL's convex polytope) or one for its exact triangles (a BVH); a point cloud one
FCL octree per occupied block of ``octree.BLOCK_CELLS``^3 cells, boxed tightly by its cells. The parts'
geometry (meshes' polytopes and BVHs, clouds' octrees) is built once per item data and shared.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import fcl
import numpy as np

from roarmctl.errors import InputError
from roarmctl.motion.octree import blocks, fcl_octree
from roarmctl.motion.scene import SceneItem
from roarmctl.motion.scenefiles import CloudData, MeshData
from roarmctl.robot.meshes import centred

if TYPE_CHECKING:
    from roarmctl.robot.meshes import MeshGeometry


def fcl_geometry(kind: str, size: Sequence[float] = (0, 0, 0), radius: float = 0.0, length: float = 0.0,
                 grow: float = 0.0, mesh: MeshGeometry | None = None) -> fcl.CollisionGeometry:
    """An FCL geometry, every surface moved outwards by ``grow`` (m; negative shrinks).

    A mesh (``MeshGeometry``) becomes an FCL convex polytope (its hull), or a BVH of its triangles
    when ``mesh.exact``; ``grow`` > 0 pads it (``MeshGeometry.grown``).
    """
    if kind == "mesh":
        assert mesh is not None  # a mesh shape carries its MeshGeometry
        v, f = mesh.grown(max(grow, 0.0))
        if mesh.exact:
            bvh = fcl.BVHModel()
            bvh.beginModel(len(v), len(f))
            bvh.addSubModel(v, f)
            bvh.endModel()
            return bvh
        return fcl.Convex(v, len(f), np.hstack([np.full((len(f), 1), 3), f]).ravel())
    if kind == "box":
        return fcl.Box(*[max(float(s) + 2 * grow, 1e-6) for s in size])
    if kind == "cylinder":
        return fcl.Cylinder(max(radius + grow, 1e-6), max(length + 2 * grow, 1e-6))
    if kind == "sphere":
        return fcl.Sphere(max(radius + grow, 1e-6))
    if kind == "capsule":
        return fcl.Capsule(max(radius + grow, 1e-6), max(length, 1e-6))
    raise InputError(f"collision shape kind '{kind}' is not supported")


def half_extents(kind: str, size: Sequence[float] = (0, 0, 0), radius: float = 0.0, length: float = 0.0,
                 grow: float = 0.0, mesh: MeshGeometry | None = None) -> np.ndarray:
    """Half extents (3,) of the shape's local bounding box, grown by ``grow``."""
    if kind == "mesh":
        assert mesh is not None  # a mesh shape carries its MeshGeometry
        h = np.max(np.abs(mesh.grown(max(grow, 0.0))[0]), axis=0)
        return np.maximum(h, 1e-6)
    if kind == "box":
        h = np.asarray(size, dtype=float) / 2
    elif kind == "cylinder":
        h = np.array([radius, radius, length / 2])
    elif kind == "sphere":
        h = np.full(3, radius)
    else:  # capsule
        h = np.array([radius, radius, length / 2 + radius])
    return np.maximum(h + grow, 1e-6)


_BOX2_GROW = 1e-5  # m: the second box of a cylinder stands off it, far beyond FCL's own tolerances


def second_box(item: SceneItem) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """For a cylinder item: a second box that holds it, its own box turned 45 degrees about the axis and grown by
    ``_BOX2_GROW`` (rotation (9,) row-major, centre (3,), half extents (3,), as ``_kernel.apart`` takes them).
    The two boxes meet in an octagonal prism around the cylinder, so a shape whose box is apart from this one is
    apart from the cylinder even where it overlaps the first box (near its corners); None for other items."""
    if item.shape != "cylinder":
        return None
    c = s = np.sqrt(0.5)
    turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    half = np.array([item.radius, item.radius, item.length / 2]) + _BOX2_GROW
    return (np.ascontiguousarray((item.pose[:3, :3] @ turn).ravel()), np.ascontiguousarray(item.pose[:3, 3], dtype=float),
            np.ascontiguousarray(half))


@dataclass
class Part:
    """One collision part of a scene item: ``obj`` placed in the world; ``rot`` (3, 3), ``centre`` (3,) and ``half``
    (3,) an oriented box that holds it (m); ``box2`` a second such box (rotation (9,), half (3,), same centre) or
    None; ``kind`` the FCL shape kind ("box", "cylinder", "sphere", "mesh", "octree")."""

    item: SceneItem
    obj: fcl.CollisionObject
    rot: np.ndarray
    centre: np.ndarray
    half: np.ndarray
    box2: tuple[np.ndarray, np.ndarray] | None
    kind: str


_SLACK = 1e-9  # m: a mesh piece's or a cloud block's box stands off it by this, against rounding

_PRIMITIVES: dict[tuple, tuple[object, np.ndarray]] = {}  # (shape, size, radius, length) -> (FCL shape, half extents)
_GEOMETRY: dict[int, tuple[object, list]] = {}  # id(data) -> (data, [(local centre (3,), half (3,), geometry)])


def _local_geometry(data: MeshData | CloudData) -> list:
    """[(centre (3,), half extents (3,), FCL geometry placed at that centre or None for an octree)] in the item
    frame, made once per data object (kept while the data lives: the entry holds it)."""
    hit = _GEOMETRY.get(id(data))
    if hit is not None and hit[0] is data:
        return hit[1]
    out = []
    if isinstance(data, MeshData):
        for v, f in data.pieces:
            mesh, centre = centred(v, f, data.exact, data.source)
            out.append((centre, mesh.half_extents + _SLACK, fcl_geometry("mesh", mesh=mesh)))
    else:
        r = data.resolution
        for idx in blocks(data.cells):
            cells = data.cells[idx]
            lo, hi = cells.min(axis=0) * r, (cells.max(axis=0) + 1) * r
            out.append(((lo + hi) / 2, (hi - lo) / 2 + _SLACK, fcl_octree(cells, r)))
    if len(_GEOMETRY) > 256:
        _GEOMETRY.clear()
    _GEOMETRY[id(data)] = (data, out)
    return out


def item_parts(item: SceneItem) -> list[Part]:
    """The collision parts of ``item`` at its current pose (see the module doc)."""
    rot, pos = item.pose[:3, :3], item.pose[:3, 3]
    if item.shape in ("box", "cylinder", "sphere"):
        key = (item.shape, item.size, item.radius, item.length)
        shared = _PRIMITIVES.get(key)
        if shared is None:  # FCL's shapes are immutable: one per distinct shape and size, shared by every item
            shared = _PRIMITIVES[key] = (fcl_geometry(*key), half_extents(*key))
            if len(_PRIMITIVES) > 4096:
                _PRIMITIVES.clear()
        geom, half = shared
        box2 = second_box(item) if item.shape == "cylinder" else None
        return [Part(item, fcl.CollisionObject(geom, fcl.Transform(rot, pos)), rot, pos, half,
                     None if box2 is None else (box2[0], box2[2]), item.shape)]
    data = item.mesh if item.shape == "mesh" else item.cloud
    parts = []
    for centre, half, geom in _local_geometry(data):  # type: ignore[arg-type]
        world = pos + rot @ centre
        if item.shape == "mesh":  # the piece's geometry is centred on its box
            obj = fcl.CollisionObject(geom, fcl.Transform(rot, world))
        else:  # an octree's cells stay in the cloud's frame
            obj = fcl.CollisionObject(geom, fcl.Transform(rot, pos))
        parts.append(Part(item, obj, rot, world, half, None, "mesh" if item.shape == "mesh" else "octree"))
    return parts
