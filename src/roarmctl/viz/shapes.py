"""Scene items (box, cylinder, sphere, mesh) and robot collision shapes as polygon meshes, for 3D drawing; a
point cloud's occupied cells as points (their centres, ``cell_centres``).

Only numpy: each function returns a list of faces, each face an (k, 3) array of vertices in m (convex
polygons; their winding is not consistent, so draw them two-sided); ``triangles`` fans them into triangles for the
browser view. The PNG (``path_figure``) and the browser view (``viz.web``) draw from these same faces.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import TrajectoryFileError
from roarmctl.formats import SHAPES
from roarmctl.robot.model import transform

if TYPE_CHECKING:
    from roarmctl.robot.model import CollisionShape



def _place(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return points @ pose[:3, :3].T + pose[:3, 3]


def box_faces(size: Iterable[float], pose: np.ndarray) -> list[np.ndarray]:
    """Six quads of a box of ``size`` (x, y, z) m centred at ``pose`` (4x4)."""
    hx, hy, hz = (0.5 * float(s) for s in size)
    c = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    c = _place(c, pose)
    quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [c[list(q)] for q in quads]


def cylinder_faces(radius: float, length: float, pose: np.ndarray, n: int = 24) -> list[np.ndarray]:
    """Side quads and two caps of a cylinder along its local z, centred at ``pose``."""
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    lo = _place(np.column_stack([ring, np.full(n + 1, -0.5 * length)]), pose)
    hi = _place(np.column_stack([ring, np.full(n + 1, 0.5 * length)]), pose)
    sides = [np.array([lo[i], lo[i + 1], hi[i + 1], hi[i]]) for i in range(n)]
    return sides + [lo[:-1], hi[:-1]]


def sphere_faces(radius: float, pose: np.ndarray, n: int = 12) -> list[np.ndarray]:
    """Latitude-longitude quads of a sphere centred at ``pose``."""
    th = np.linspace(0.0, np.pi, n + 1)
    ph = np.linspace(0.0, 2 * np.pi, 2 * n + 1)
    pts = radius * np.stack([np.outer(np.sin(th), np.cos(ph)), np.outer(np.sin(th), np.sin(ph)),
                             np.outer(np.cos(th), np.ones_like(ph))], axis=-1)
    pts = _place(pts.reshape(-1, 3), pose).reshape(n + 1, 2 * n + 1, 3)
    return [np.array([pts[i, j], pts[i, j + 1], pts[i + 1, j + 1], pts[i + 1, j]]) for i in range(n) for j in range(2 * n)]


def capsule_faces(radius: float, length: float, pose: np.ndarray, n: int = 16) -> list[np.ndarray]:
    """A capsule along its local z: a cylinder of ``length`` (m, without the caps) and two half spheres."""
    sides = cylinder_faces(radius, length, pose, n)[:-2]
    half = n // 2
    th = np.linspace(0.0, 0.5 * np.pi, half + 1)
    ph = np.linspace(0.0, 2 * np.pi, n + 1)
    out = sides
    for sign in (1.0, -1.0):
        pts = np.stack([radius * np.outer(np.sin(th), np.cos(ph)), radius * np.outer(np.sin(th), np.sin(ph)),
                        np.outer(sign * (radius * np.cos(th)) + sign * 0.5 * length, np.ones_like(ph))], axis=-1)
        pts = _place(pts.reshape(-1, 3), pose).reshape(half + 1, n + 1, 3)
        for i in range(half):
            for j in range(n):
                out.append(np.array([pts[i, j], pts[i, j + 1], pts[i + 1, j + 1], pts[i + 1, j]]))
    return out


def robot_shape_faces(shape: CollisionShape) -> list[np.ndarray]:
    """Faces of one robot collision shape (``robot.model.CollisionShape``) in its link's frame, as the checker
    sees it: box, cylinder, sphere, capsule, or the mesh the checker uses (its convex hull, or the triangles)."""
    pose = np.asarray(shape.origin, dtype=float)
    if shape.kind == "box":
        return box_faces(shape.size, pose)
    if shape.kind == "cylinder":
        return cylinder_faces(shape.radius, shape.length, pose)
    if shape.kind == "sphere":
        return sphere_faces(shape.radius, pose)
    if shape.kind == "capsule":
        return capsule_faces(shape.radius, shape.length, pose)
    if shape.kind == "mesh":
        assert shape.mesh is not None  # a mesh shape carries its MeshGeometry
        v = _place(np.asarray(shape.mesh.vertices, dtype=float), pose)
        return list(v[np.asarray(shape.mesh.faces)])
    raise ValueError(f"collision shape kind '{shape.kind}' cannot be drawn")


def triangles(faces: list[np.ndarray]) -> np.ndarray:
    """Convex polygons -> triangles (T, 3, 3) m, each polygon fanned from its first vertex; degenerate triangles (zero area, e.g. at a sphere's poles) dropped."""
    tris = [np.stack([f[0], f[k], f[k + 1]]) for f in faces for k in range(1, len(f) - 1)]
    if not tris:
        return np.zeros((0, 3, 3))
    t = np.asarray(tris, dtype=float)
    area = np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    return t[area > 1e-14]


def item_pose(item: dict, where: str) -> np.ndarray:
    """A scene item's 4x4 pose from its ``xyz`` (m) and ``rpy`` (rad); ``where`` names it in errors."""
    try:
        xyz = [float(v) for v in item.get("xyz", (0, 0, 0))]
        rpy = [float(v) for v in item.get("rpy", (0, 0, 0))]
    except (TypeError, ValueError):
        raise TrajectoryFileError(f"{where}: xyz/rpy must be lists of numbers") from None
    if len(xyz) != 3 or len(rpy) != 3:
        raise TrajectoryFileError(f"{where}: xyz and rpy need 3 numbers each")
    return transform(xyz, rpy)


def item_faces(item: dict, index: int = 0, local: bool = False) -> list[np.ndarray]:
    """Faces of one scene item (``{"shape", "size" | "radius" [, "length"], "xyz", "rpy"}``), in the world
    frame, or in the item's own frame when ``local`` (to be placed by ``item_pose``)."""
    if not isinstance(item, dict):
        raise TrajectoryFileError(f"scene.items[{index}]: expected an object")
    where = f"scene.items[{index}] ('{item.get('name', '?')}')"
    pose = item_pose(item, where)
    if local:
        pose = np.eye(4)
    shape = item.get("shape")
    try:
        if shape == "box":
            size = [float(v) for v in item["size"]]
            if len(size) != 3:
                raise ValueError
            return box_faces(size, pose)
        if shape == "cylinder":
            return cylinder_faces(float(item["radius"]), float(item["length"]), pose)
        if shape == "sphere":
            return sphere_faces(float(item["radius"]), pose)
        if shape == "mesh":
            out: list[np.ndarray] = []
            for piece in item["pieces"]:
                v = _place(np.asarray(piece["vertices"], dtype=float).reshape(-1, 3), pose)
                out.extend(v[np.asarray(piece["faces"], dtype=np.int64).reshape(-1, 3)])
            return out
        if shape == "cloud":
            return [cell_centres(item, index, local)]
    except (KeyError, TypeError, ValueError, IndexError):
        raise TrajectoryFileError(f"{where}: '{shape}' needs size [x, y, z] (box), radius and length (cylinder) or radius (sphere)") from None
    raise TrajectoryFileError(f"{where}: shape: expected one of {', '.join(SHAPES)}, got {shape!r}")


def cell_centres(item: dict, index: int = 0, local: bool = False) -> np.ndarray:
    """World centres (K, 3) m of a cloud item's occupied cells (``resolution``, ``cells`` [[i, j, k], ...]), or in
    the item's own frame when ``local``."""
    where = f"scene.items[{index}] ('{item.get('name', '?')}')"
    try:
        r = float(item["resolution"])
        cells = np.asarray(item["cells"], dtype=float).reshape(-1, 3)
    except (KeyError, TypeError, ValueError):
        raise TrajectoryFileError(f"{where}: a cloud needs resolution and cells [[i, j, k], ...]") from None
    return _place((cells + 0.5) * r, np.eye(4) if local else item_pose(item, where))


def item_extent(item: dict, index: int = 0) -> np.ndarray:
    """(2, 3) lower and upper corners of the item's axis-aligned bounding box, m (a cloud's: of its cell centres,
    grown by half a cell)."""
    pts = np.vstack(item_faces(item, index))
    if item.get("shape") == "cloud":
        half = 0.5 * float(item["resolution"])
        return np.stack([pts.min(axis=0) - half, pts.max(axis=0) + half])
    return np.stack([pts.min(axis=0), pts.max(axis=0)])


def outward(tris: np.ndarray, inside: np.ndarray | None = None) -> np.ndarray:
    """Triangles (T, 3, 3) of a convex solid, each wound counter-clockwise seen from outside (its normal points away
    from ``inside``, a point within the solid; default the origin), so a renderer that skips back faces fills only
    the near side. Only for convex shapes (the primitives): a non-convex mesh has no such point."""
    t = np.array(tris, dtype=float, copy=True)
    if not len(t):
        return t
    centre = np.zeros(3) if inside is None else np.asarray(inside, dtype=float)
    normal = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    flip = np.einsum("ij,ij->i", normal, t.mean(axis=1) - centre) < 0
    t[flip] = t[flip][:, ::-1]
    return t
