"""The world the arm moves in: a table (or floor), obstacles and graspable objects.

Every item has a pose in the world frame (the robot's root frame; for the RoArm z = 0 is the desk surface
under the base) and a shape: a primitive (box, cylinder, sphere), a triangle mesh (``mesh``: convex pieces or
the exact triangles, from an STL, OBJ, PLY or DAE file or from arrays) or the occupied cells of a point cloud
(``cloud``: cubic cells of a stated resolution, from a PLY, PCD or .npy file or an array; FCL checks them as an
octree). Units: metres and radians.

``Scene.to_dict()`` is the form that goes into the trajectory file (the visualizer reads it):
``{"items": [{"name", "role", "shape", "size" | "radius" (+ "length"), "xyz", "rpy"}]}``; a mesh adds
``"pieces": [{"vertices": [[x, y, z], ...], "faces": [[i, j, k], ...]}]`` (item frame, m), ``"collision"``
(convex | exact) and ``"source"``; a cloud adds ``"resolution"`` (m), ``"cells": [[i, j, k], ...]`` (cell i
spans [i r, (i + 1) r) along x in the item frame, and so on) and ``"source"``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.formats import ROLES, SHAPES, Role, Shape
from roarmctl.motion.scenefiles import CloudData, MeshData, cloud_data, mesh_data, read_cloud_item, read_mesh_item
from roarmctl.robot.model import rpy_from_matrix, transform


@dataclass
class SceneItem:
    """One shape in the world.

    ``pose`` (4, 4) places the shape's centre (a mesh's or a cloud's own frame) in the world frame. Box:
    ``size`` = full edge lengths (x, y, z) in m. Cylinder: ``radius`` and ``length`` (m) along the local z axis.
    Sphere: ``radius``. Mesh: ``mesh`` (``MeshData``). Cloud: ``cloud`` (``CloudData``). Only primitives can be
    objects (grasped and carried).
    """

    name: str
    role: Role
    shape: Shape
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    mesh: MeshData | None = None
    cloud: CloudData | None = None

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise InputError(f"scene item '{self.name}': role '{self.role}' is not one of {', '.join(ROLES)}")
        if self.shape not in SHAPES:
            raise InputError(f"scene item '{self.name}': shape '{self.shape}' is not one of {', '.join(SHAPES)}")
        self.pose = np.array(self.pose, dtype=float)
        if self.pose.shape != (4, 4):
            raise InputError(f"scene item '{self.name}': pose must be a 4x4 transform")
        self.size = tuple(float(v) for v in self.size)  # type: ignore[assignment]
        self.radius, self.length = float(self.radius), float(self.length)
        if self.shape in ("mesh", "cloud"):
            data = self.mesh if self.shape == "mesh" else self.cloud
            if data is None or len(data.pieces if isinstance(data, MeshData) else data.cells) == 0:
                raise InputError(f"scene item '{self.name}': a {self.shape} item needs its "
                                 f"{'triangles' if self.shape == 'mesh' else 'occupied cells'}")
            if self.role == "object":
                raise InputError(f"scene item '{self.name}': a {self.shape} cannot be an object (grasped)",
                                 "objects are boxes, cylinders or spheres; make it an obstacle")
            return
        dims = {"box": self.size, "cylinder": (self.radius, self.length), "sphere": (self.radius,)}[self.shape]
        if len(dims) != (3 if self.shape == "box" else len(dims)) or min(dims) <= 0:
            raise InputError(f"scene item '{self.name}': {self.shape} dimensions must be positive, got {dims}")

    @classmethod
    def checked_primitive(cls, name: str, role: Role, shape: Shape, pose: np.ndarray, size: tuple[float, float, float],
                          radius: float, length: float) -> SceneItem:
        """A box, cylinder or sphere whose fields a reader has checked already (a plan's: ``roarmctl.plan.schema``):
        the item ``cls(...)`` makes of them (``pose`` copied, numbers as floats) without checking them again."""
        item = object.__new__(cls)
        item.__dict__.update(name=name, role=role, shape=shape, pose=np.array(pose, dtype=float),
                             size=(float(size[0]), float(size[1]), float(size[2])), radius=float(radius),
                             length=float(length), mesh=None, cloud=None)
        return item

    @classmethod
    def box(cls, name: str, size: Iterable[float], xyz: Iterable[float], rpy: Iterable[float] = (0.0, 0.0, 0.0),
            role: Role = "obstacle") -> SceneItem:
        """A box of full edge lengths ``size`` (m) centred at ``xyz`` (m) with URDF ``rpy`` (rad)."""
        three = cast("tuple[float, float, float]", tuple(size))  # __post_init__ refuses another length
        return cls(name, role, "box", transform(xyz, rpy), size=three)

    @classmethod
    def cylinder(cls, name: str, radius: float, length: float, xyz: Iterable[float],
                 rpy: Iterable[float] = (0.0, 0.0, 0.0), role: Role = "obstacle") -> SceneItem:
        """A cylinder of ``radius`` and ``length`` (m) along its local z, centred at ``xyz`` (m), turned by ``rpy`` (rad)."""
        return cls(name, role, "cylinder", transform(xyz, rpy), radius=radius, length=length)

    @classmethod
    def sphere(cls, name: str, radius: float, xyz: Iterable[float], role: Role = "obstacle") -> SceneItem:
        """A sphere of ``radius`` (m) centred at ``xyz`` (m)."""
        return cls(name, role, "sphere", transform(xyz), radius=radius)

    @classmethod
    def from_mesh(cls, name: str, vertices: npt.ArrayLike, faces: npt.ArrayLike, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                  rpy: Iterable[float] = (0.0, 0.0, 0.0), *, exact: bool = False, role: Role = "obstacle",
                  source: str = "") -> SceneItem:
        """A mesh from triangles: ``vertices`` (V, 3) m in the item frame, ``faces`` (F, 3) vertex indices; placed at
        ``xyz`` (m) with URDF ``rpy`` (rad). ``exact`` False: the convex hulls of its connected parts (what FCL
        checks fastest); True: the triangles as they are (a BVH: hollows and holes stay open)."""
        return cls(name, role, "mesh", transform(xyz, rpy), mesh=mesh_data(vertices, faces, exact, source, f"scene item '{name}'"))

    @classmethod
    def mesh_file(cls, name: str, path: str | Path, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                  rpy: Iterable[float] = (0.0, 0.0, 0.0), *, scale: npt.ArrayLike = 1.0, exact: bool = False,
                  role: Role = "obstacle") -> SceneItem:
        """A mesh read from an STL, OBJ, PLY or DAE file (its units times ``scale``, a number or (3,)); see ``from_mesh``."""
        return cls(name, role, "mesh", transform(xyz, rpy), mesh=read_mesh_item(path, scale, exact, f"scene item '{name}'"))

    @classmethod
    def from_points(cls, name: str, points: npt.ArrayLike, resolution: float, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                    rpy: Iterable[float] = (0.0, 0.0, 0.0), *, role: Role = "obstacle", source: str = "") -> SceneItem:
        """A point cloud: ``points`` (N, 3) m in the item frame (e.g. a camera's), each occupying the cubic cell of
        edge ``resolution`` (m) it falls in; placed at ``xyz`` (m) with URDF ``rpy`` (rad). Role "table" keeps it
        from being checked against the robot's base links (a scan of the desk under the arm)."""
        return cls(name, role, "cloud", transform(xyz, rpy), cloud=cloud_data(points, resolution, source, f"scene item '{name}'"))

    @classmethod
    def cloud_file(cls, name: str, path: str | Path, resolution: float, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                   rpy: Iterable[float] = (0.0, 0.0, 0.0), *, role: Role = "obstacle") -> SceneItem:
        """A point cloud read from a PLY, PCD or .npy file (m); see ``from_points``."""
        return cls(name, role, "cloud", transform(xyz, rpy), cloud=read_cloud_item(path, resolution, f"scene item '{name}'"))

    @property
    def xyz(self) -> np.ndarray:
        """The item's centre (3,) m, world frame."""
        return self.pose[:3, 3].copy()

    def half_extents_world(self) -> np.ndarray:
        """Half edge lengths (3,) of the item's world-axis-aligned bounding box (m)."""
        rot = self.pose[:3, :3]
        data = self.mesh if self.shape == "mesh" else self.cloud if self.shape == "cloud" else None
        if data is not None:
            return np.abs(rot) @ data.local_box()[1]
        if self.shape == "box":
            return np.abs(rot) @ (np.asarray(self.size) / 2)
        if self.shape == "sphere":
            return np.full(3, self.radius)
        axis = rot[:, 2]
        return self.radius * np.sqrt(np.clip(1.0 - axis**2, 0.0, None)) + 0.5 * self.length * np.abs(axis)

    def aabb(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) corners (3,) of the world-axis-aligned bounding box (m)."""
        h = self.half_extents_world()
        c = self.pose[:3, 3]
        data = self.mesh if self.shape == "mesh" else self.cloud if self.shape == "cloud" else None
        if data is not None:
            c = c + self.pose[:3, :3] @ data.local_box()[0]
        return c - h, c + h

    def to_dict(self, xyz: list[float] | None = None, rpy: list[float] | None = None) -> dict:
        """The item as the trajectory file's ``scene`` entry (name, role, shape, sizes, xyz, rpy). ``xyz`` (m) and
        ``rpy`` (rad): the pose's, when the caller read them already (``Scene.to_dict``, for all items at once)."""
        d: dict = {"name": self.name, "role": self.role, "shape": self.shape}
        if self.mesh is not None:
            d["collision"] = "exact" if self.mesh.exact else "convex"
            d["source"] = self.mesh.source
            d["pieces"] = self.mesh.as_lists
        elif self.cloud is not None:
            d["resolution"] = self.cloud.resolution
            d["source"] = self.cloud.source
            d["cells"] = self.cloud.as_lists
        elif self.shape == "box":
            d["size"] = [float(v) for v in self.size]
        else:
            d["radius"] = float(self.radius)
            if self.shape == "cylinder":
                d["length"] = float(self.length)
        d["xyz"] = [float(v) for v in self.pose[:3, 3]] if xyz is None else xyz
        d["rpy"] = [float(v) for v in rpy_from_matrix(self.pose[:3, :3])] if rpy is None else rpy
        return d

    @classmethod
    def from_dict(cls, d: dict) -> SceneItem:
        """An item from its ``to_dict`` form; a bad entry raises InputError."""
        try:
            pose = transform(d.get("xyz", (0, 0, 0)), d.get("rpy", (0, 0, 0)))
            if d.get("shape") == "mesh":
                pieces = tuple((np.asarray(p["vertices"], dtype=float).reshape(-1, 3), np.asarray(p["faces"], dtype=np.int64).reshape(-1, 3))
                               for p in d["pieces"])
                mesh = MeshData(pieces, d.get("collision") == "exact", str(d.get("source", "")))
                return cls(str(d["name"]), d["role"], "mesh", pose, mesh=mesh)
            if d.get("shape") == "cloud":
                cells = np.asarray(d["cells"], dtype=np.int64).reshape(-1, 3)
                cloud = CloudData(cells, float(d["resolution"]), 0, str(d.get("source", "")))
                return cls(str(d["name"]), d["role"], "cloud", pose, cloud=cloud)
            return cls(str(d["name"]), d["role"], d["shape"], pose, size=tuple(d.get("size", (0.0, 0.0, 0.0))),
                       radius=float(d.get("radius", 0.0)), length=float(d.get("length", 0.0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"scene item {d!r}: {exc}") from None


@dataclass
class Scene:
    """A list of scene items with unique names."""

    items: list[SceneItem] = field(default_factory=list)

    def __post_init__(self) -> None:
        dup = sorted(name for name, n in Counter(i.name for i in self.items).items() if n > 1)
        if dup:
            raise InputError(f"scene: duplicate item name(s) {', '.join(dup)}")

    def __getitem__(self, name: str) -> SceneItem:
        for item in self.items:
            if item.name == name:
                return item
        raise InputError(f"scene has no item '{name}' (items: {', '.join(i.name for i in self.items) or 'none'})")

    def __contains__(self, name: str) -> bool:
        return any(i.name == name for i in self.items)

    def names(self) -> list[str]:
        """The items' names, in order."""
        return [i.name for i in self.items]

    def copy(self) -> Scene:
        """A copy whose items can be moved (poses copied); mesh and cloud data (read-only) are shared."""
        items = []
        for item in self.items:
            twin = object.__new__(SceneItem)  # copy.copy's result, without its generic protocol (5x the time)
            twin.__dict__.update(item.__dict__)
            twin.pose = item.pose.copy()
            items.append(twin)
        out = object.__new__(Scene)  # its names are this scene's: unique, no need to check them again
        out.items = items
        return out

    def to_dict(self) -> dict:
        """``{"items": [...]}`` of the items' ``to_dict`` forms (the same dicts, bit for bit), the primitives' positions
        and rotations read in one numpy pass over the scene rather than item by item (a trajectory records the
        scene: 200 boxes took about 5 ms item by item)."""
        items = self.items
        poses = np.array([it.pose for it in items]).reshape(len(items), 4, 4)
        xyz = poses[:, :3, 3].tolist()
        rpy = _rpy_all(poses[:, :3, :3])
        # meshes and clouds read their own pose: their dicts are the item's alone, as before
        out = [it.to_dict() if it.mesh is not None or it.cloud is not None else it.to_dict(p, r)
               for it, p, r in zip(items, xyz, rpy, strict=True)]
        return {"items": out}

    @classmethod
    def from_dict(cls, d: dict) -> Scene:
        """A scene from its ``to_dict`` form; a bad one raises InputError."""
        if not isinstance(d, dict) or not isinstance(d.get("items", []), list):
            raise InputError("scene: expected {'items': [...]}")
        return cls([SceneItem.from_dict(i) for i in d.get("items", [])])


_EYE3 = np.eye(3)


def _rpy_all(rot: np.ndarray) -> list[list[float]]:
    """``rpy_from_matrix`` of each rotation of ``rot`` (N, 3, 3), as lists of floats: a rotation that is the identity
    by value (either sign of its zeros: most scene items) gives its zeros back as the arctangents do (atan2(+-0, 1)
    is +-0, hypot(1, +-0) is 1), so only the turned ones are computed one by one."""
    plain = np.all(rot == _EYE3, axis=(1, 2)).tolist()
    zeros = np.stack([rot[:, 2, 1], -rot[:, 2, 0], rot[:, 1, 0]], axis=1).tolist()  # roll, pitch, yaw of a plain one
    return [z if flat else [float(v) for v in rpy_from_matrix(r)] for z, flat, r in zip(zeros, plain, rot, strict=True)]


def settled(pose: np.ndarray, step: float) -> np.ndarray:
    """``pose`` (4, 4) with its position (m) and roll-pitch-yaw (rad) rounded to multiples of ``step`` (> 0), and no
    negative zeros: the same for poses that differ by less than ``step`` (unless they straddle a rounding boundary).

    The planner records where an object is put down this way (``roarmctl.motion.planning.grasp``): where the jaws
    leave it differs between repeats of one placement by rounding (1e-16 m) and by the fixed jaw's iteration (about
    1e-9 rad a time); rounded to a micrometre and a microradian, far below any arm's repeatability, repeated cycles of
    a plan meet bit for bit the same world and reuse what they computed (timings keyed by exact waypoints)."""
    xyz = np.round(pose[:3, 3] / step) * step + 0.0
    rpy = np.round(rpy_from_matrix(pose[:3, :3]) / step) * step + 0.0
    return transform(xyz, rpy)


def example_scene() -> Scene:
    """The RoArm example used by tests and benchmarks: table, a cube, a wall between pick and place.

    Table top at z = 0 (0.8 x 0.6 x 0.02 m box), a 40 mm cube at (0.25, -0.15), a 30 mm cylinder at
    the place area's side, and a 0.04 x 0.10 x 0.15 m obstacle at (0.28, 0, 0.075).
    """
    return Scene([
        SceneItem.box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table"),
        SceneItem.box("wall", (0.04, 0.10, 0.15), (0.28, 0.0, 0.075)),
        SceneItem.box("cube", (0.04, 0.04, 0.04), (0.25, -0.15, 0.02), role="object"),
        SceneItem.cylinder("can", 0.015, 0.05, (0.18, 0.22, 0.025), role="object"),
    ])
