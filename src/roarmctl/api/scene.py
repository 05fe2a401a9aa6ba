"""``Scene``: the world a ``Planner`` checks against, built one call at a time.

    scene = Scene()
    scene.add_box("table", size=(0.8, 0.6, 0.02), xyz=(0.15, 0, -0.01), role="table")
    scene.add_box("wall", size=(0.04, 0.10, 0.15), xyz=(0.28, 0, 0.075))
    scene.add_cylinder("can", radius=0.015, length=0.05, xyz=(0.18, 0.22, 0.025), role="object")
    scene.add_mesh("bracket", "bracket.stl", xyz=(0.2, -0.2, 0), scale=0.001)   # an STL in mm
    scene.add_point_cloud("desk", "scan.ply", resolution=0.01)                  # a scan, 1 cm cells
    scene.remove("can")
    scene.attach("cube", q)   # the TCP carries it from configuration q on
    scene.detach("cube", q2)  # put down where the TCP has carried it at q2

Items are ``roarmctl.motion.scene.SceneItem``s (the plan file's shapes), poses in the robot's root frame,
metres and radians. Roles: ``table`` (the arm's base links may touch it), ``obstacle``, ``object`` (may be
grasped and carried). A carried item moves rigidly with the TCP; the checker tests it like a part of the
arm. Every change bumps ``version`` so a ``Planner`` using the scene rebuilds its collision checker once.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.formats import Role
from roarmctl.motion.scene import Scene as _WorldScene
from roarmctl.motion.scene import SceneItem

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot


class Scene:
    """A mutable set of named scene items and the items the arm carries.

    ``robot`` (set by the ``Planner`` that uses the scene, or given here) is needed by ``attach`` and
    ``detach``, which place a carried item with the robot's FK.
    """

    def __init__(self, items: list[SceneItem] | None = None, *, robot: Robot | None = None) -> None:
        self.robot = robot
        self._items: dict[str, SceneItem] = {}
        self._carried: dict[str, tuple[SceneItem, np.ndarray]] = {}  # name -> (item, pose in the TCP frame)
        self.version = 0
        for item in items or []:
            self.add(item)

    # ------------------------------------------------------------------ adding and removing
    def add(self, item: SceneItem) -> SceneItem:
        """Add a ``SceneItem``; its name must be new to the scene."""
        if item.name in self:
            raise InputError(f"scene: an item named '{item.name}' is already there", "remove it first, or use another name")
        self._items[item.name] = item
        self.version += 1
        return item

    def add_box(self, name: str, size: Iterable[float], xyz: Iterable[float] = (0.0, 0.0, 0.0),
                rpy: Iterable[float] = (0.0, 0.0, 0.0), *, role: Role = "obstacle") -> SceneItem:
        """A box of full edge lengths ``size`` (3,) m, centred at ``xyz`` (m), turned by URDF ``rpy`` (rad)."""
        return self.add(SceneItem.box(name, size, xyz, rpy, role=role))

    def add_cylinder(self, name: str, radius: float, length: float, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                     rpy: Iterable[float] = (0.0, 0.0, 0.0), *, role: Role = "obstacle") -> SceneItem:
        """A cylinder of ``radius`` and ``length`` (m) along its local z, centred at ``xyz`` (3,) m, turned by URDF
        ``rpy`` (3,) rad."""
        return self.add(SceneItem.cylinder(name, radius, length, xyz, rpy, role=role))

    def add_sphere(self, name: str, radius: float, xyz: Iterable[float] = (0.0, 0.0, 0.0), *,
                   role: Role = "obstacle") -> SceneItem:
        """A sphere of ``radius`` (m) centred at ``xyz`` (3,) m."""
        return self.add(SceneItem.sphere(name, radius, xyz, role=role))

    def add_mesh(self, name: str, mesh: str | Path | npt.ArrayLike, xyz: Iterable[float] = (0.0, 0.0, 0.0),
                 rpy: Iterable[float] = (0.0, 0.0, 0.0), *, faces: npt.ArrayLike | None = None,
                 scale: npt.ArrayLike = 1.0, exact: bool = False, role: Role = "obstacle") -> SceneItem:
        """A mesh: ``mesh`` a file (STL, OBJ, PLY, DAE; its units times ``scale``) or, with ``faces`` (F, 3), the
        vertices (V, 3) m in the item frame; placed at ``xyz`` (m) with URDF ``rpy`` (rad). Checked as the convex
        hulls of its connected parts, or its triangles with ``exact`` (``SceneItem.mesh_file`` / ``from_mesh``)."""
        if isinstance(mesh, (str, Path)):
            if faces is not None:
                raise InputError(f"scene: mesh '{name}': a mesh file has its own faces", "leave faces out")
            return self.add(SceneItem.mesh_file(name, mesh, xyz, rpy, scale=scale, exact=exact, role=role))
        if faces is None:
            raise InputError(f"scene: mesh '{name}': vertices (V, 3) need their faces (F, 3)", "give faces=")
        return self.add(SceneItem.from_mesh(name, mesh, faces, xyz, rpy, exact=exact, role=role))

    def add_point_cloud(self, name: str, points: str | Path | npt.ArrayLike, resolution: float,
                        xyz: Iterable[float] = (0.0, 0.0, 0.0), rpy: Iterable[float] = (0.0, 0.0, 0.0), *,
                        role: Role = "obstacle") -> SceneItem:
        """A point cloud: ``points`` a file (PLY, PCD, .npy; m) or an (N, 3) array (m, item frame), each point
        occupying its cubic cell of side ``resolution`` (m); placed at ``xyz`` with ``rpy``
        (``SceneItem.cloud_file`` / ``from_points``)."""
        if isinstance(points, (str, Path)):
            return self.add(SceneItem.cloud_file(name, points, resolution, xyz, rpy, role=role))
        return self.add(SceneItem.from_points(name, points, resolution, xyz, rpy, role=role))

    def remove(self, name: str) -> SceneItem:
        """Take item ``name`` out of the scene (a carried one too); returns it."""
        if name in self._carried:
            item = self._carried.pop(name)[0]
        elif name in self._items:
            item = self._items.pop(name)
        else:
            raise InputError(f"scene has no item '{name}' (items: {', '.join(self.names()) or 'none'})")
        self.version += 1
        return item

    # ------------------------------------------------------------------ carrying
    def _tcp(self, q: npt.ArrayLike) -> np.ndarray:
        if self.robot is None:
            raise InputError("scene: attach/detach place the item with the robot's FK, and this scene has no robot",
                             "pass the scene to Planner(robot, scene) first, or build it with Scene(robot=robot)")
        return self.robot.kin.fk(self.robot.full_q(np.asarray(q, dtype=float)))

    def attach(self, name: str, q: npt.ArrayLike) -> None:
        """The TCP carries item ``name`` from configuration ``q`` (rad/m, dof or arm joints) on: the item keeps
        its pose relative to the TCP as it is at ``q``."""
        if name in self._carried:
            raise InputError(f"scene: '{name}' is already carried")
        item = self[name]
        if item.role == "table":
            raise InputError(f"scene: cannot attach '{name}': it is the table")
        rel = np.linalg.inv(self._tcp(q)) @ item.pose
        del self._items[name]
        self._carried[name] = (item, rel)
        self.version += 1

    def detach(self, name: str, q: npt.ArrayLike) -> SceneItem:
        """Put carried item ``name`` down where the TCP has carried it at configuration ``q`` (rad/m, dof or arm
        joints); returns it (its new pose in ``.pose``, (4, 4))."""
        if name not in self._carried:
            raise InputError(f"scene: '{name}' is not carried (carried: {', '.join(self._carried) or 'none'})")
        item, rel = self._carried.pop(name)
        item.pose = self._tcp(q) @ rel
        self._items[name] = item
        self.version += 1
        return item

    # ------------------------------------------------------------------ reading
    def __getitem__(self, name: str) -> SceneItem:
        if name in self._items:
            return self._items[name]
        if name in self._carried:
            return self._carried[name][0]
        raise InputError(f"scene has no item '{name}' (items: {', '.join(self.names()) or 'none'})")

    def __contains__(self, name: str) -> bool:
        return name in self._items or name in self._carried

    def names(self) -> list[str]:
        """Every item's name: those in the world, then the carried ones."""
        return list(self._items) + list(self._carried)

    @property
    def items(self) -> list[SceneItem]:
        """The items in the world (not the carried ones)."""
        return list(self._items.values())

    @property
    def carried(self) -> dict[str, npt.NDArray[np.float64]]:
        """Carried item name -> its pose (4, 4) in the TCP frame."""
        return {name: rel.copy() for name, (_, rel) in self._carried.items()}

    def world(self, q: npt.ArrayLike | None = None) -> _WorldScene:
        """The items as a ``roarmctl.motion.scene.Scene`` (what the checker and the trajectory file take); with
        ``q`` (rad/m, dof or arm joints), the carried items too, where the TCP holds them at ``q``."""
        items = [replace(i, pose=i.pose.copy()) for i in self._items.values()]
        if q is not None and self._carried:
            tcp = self._tcp(q)
            items += [replace(i, pose=tcp @ rel) for i, rel in self._carried.values()]
        return _WorldScene(items)

    def to_dict(self) -> dict:
        """The world items in the trajectory file's form: ``{"items": [{name, role, shape, size|radius, xyz, rpy}]}``."""
        return self.world().to_dict()
