"""The collision checker's world: what it checks against (its copy of the scene, the objects the TCP carries, the
grasp target the jaws may touch, the gripper's value) and the arm's shapes (``_Moving``: each moving collision shape
with its FCL objects, padded against the scene and unpadded against the arm). ``CheckerWorld`` is the part of
``roarmctl.motion.collision.CollisionChecker`` that changes this state; every change rebuilds the kernel's tables
(``roarmctl.motion.collision_tables``)."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

import fcl
import numpy as np

from roarmctl.errors import InputError
from roarmctl.motion.geometry import fcl_geometry as _geometry
from roarmctl.motion.geometry import half_extents as _half_extents
from roarmctl.motion.scene import Scene, SceneItem, settled
from roarmctl.robot.meshes import MeshGeometry
from roarmctl.robot.model import Joint, Kinematics, Robot

# Set-up shared by the checkers of a process (every plan, api.plan call or query makes one, mostly for the same robot
# and scene): the arm's shapes per robot and padding, the tables of the last _STATE_CACHE collision states (with the
# robot each was made for: ids are compared only while it lives).
_ARM_SHAPES: dict[tuple, tuple[Robot, list[_Moving]]] = {}


@dataclass
class _Moving:
    """A shape that moves with a link: arm collision boxes and attached objects."""

    name: str  # link name, or the object's name for attached objects
    link: int  # index in the kinematic link list
    rot: np.ndarray  # (3, 3) shape origin in the link frame
    pos: np.ndarray  # (3,)
    half: np.ndarray  # (3,) local half extents (padded for the scene test)
    half_self: np.ndarray  # (3,) local half extents of the self-collision geometry
    radius: float  # bounding-sphere radius (padded)
    obj_scene: fcl.CollisionObject  # geometry used against the scene (padded / shrunk)
    obj_self: fcl.CollisionObject  # geometry used against other moving shapes
    attached: bool = False


class CheckerWorld:
    """The state a ``CollisionChecker`` checks against and the calls that change it (see the module's docstring).
    The attributes are set by ``CollisionChecker.__init__``."""

    robot: Robot
    scene: Scene
    padding: float
    singularity_margin: float | None
    contact_tolerance: float
    _fk: Kinematics
    _arm: np.ndarray
    _lower: np.ndarray
    _upper: np.ndarray
    _q_template: np.ndarray
    _gripper_index: int | None
    _tcp: int
    _chain: list[tuple[int, Joint]]
    _grasp_target: str | None
    _jaw_strict: bool
    _attached: dict[str, tuple[SceneItem, np.ndarray]]
    _lock: threading.RLock
    _bufs: dict[str, Any]

    def _rebuild(self) -> None:
        """The kernel's tables for the world as it is now (``roarmctl.motion.collision_tables.KernelTables``)."""
        raise NotImplementedError

    def _shared_arm_shapes(self) -> list[_Moving]:
        """The arm's collision shapes (padded), made once per process for the same robot and padding (``_ARM_SHAPES``)."""
        robot, kin = self.robot, self.robot.kin
        key = (id(robot), self.padding)
        hit = _ARM_SHAPES.get(key)
        if hit is not None and hit[0] is robot:
            return hit[1]
        shapes = [self._moving(shape.name or shape.link, kin.link_index[shape.link], shape.origin, shape.kind, shape.size,
                               shape.radius, shape.length, robot.padding.get(shape.link, self.padding), 0.0, mesh=shape.mesh)
                  for shape in robot.collision]
        if len(_ARM_SHAPES) >= 64:
            _ARM_SHAPES.pop(next(iter(_ARM_SHAPES)))
        _ARM_SHAPES[key] = (robot, shapes)
        return shapes

    def _moving(self, name: str, link: int, origin: np.ndarray, kind: str, size: tuple[float, ...], radius: float,
                length: float, grow_scene: float, grow_self: float, attached: bool = False, mesh: MeshGeometry | None = None) -> _Moving:
        half = _half_extents(kind, size, radius, length, grow_scene, mesh)
        radius_bound = float(np.linalg.norm(half))
        if mesh is not None:  # the farthest vertex bounds the mesh more tightly than the box corner
            radius_bound = float(np.max(np.linalg.norm(mesh.grown(max(grow_scene, 0.0))[0], axis=1)))
        return _Moving(name, link, origin[:3, :3].copy(), origin[:3, 3].copy(), half,
                       _half_extents(kind, size, radius, length, grow_self, mesh),
                       radius_bound,
                       fcl.CollisionObject(_geometry(kind, size, radius, length, grow_scene, mesh)),
                       fcl.CollisionObject(_geometry(kind, size, radius, length, grow_self, mesh)), attached)

    def set_gripper(self, value: float) -> None:
        """Gripper joint value (rad) used for the jaw pose in every later check."""
        if self._gripper_index is None:
            raise InputError(f"{self.robot.name} has no gripper")
        self._q_template[self._gripper_index] = float(value)

    def set_grasp_target(self, name: str | None, moving_jaw_clear: bool = False) -> None:
        """Let scene object ``name`` touch the jaws (``robot.jaw_links``); None clears it.

        With ``moving_jaw_clear`` the checks cover only the links the gripper joint moves
        (``moving_jaw_links``: their shapes against the scene and against the other links), and these
        must stay clear of ``name`` by the padding like of any other item. This is for a gripper action
        overlapped with an arm motion whose samples were checked already with the jaws elsewhere: the
        other links are where they were, and only the moving jaw must be checked again, now without
        contact allowance, so that it closes on (or leaves) the object only while the arm is at rest.
        """
        if name is not None and name not in self.scene:
            raise InputError(f"grasp target '{name}' is not in the scene (items: {', '.join(self.scene.names())})")
        if (name, moving_jaw_clear) == (self._grasp_target, self._jaw_strict):  # every scene change rebuilds on its own; nothing to redo (3-4 ms)
            return
        self._grasp_target, self._jaw_strict = name, bool(moving_jaw_clear)
        self._rebuild()

    @property
    def moving_jaw_links(self) -> tuple[str, ...]:
        """The links the gripper joint moves (its child and that link's descendants); () without a gripper."""
        if self.robot.gripper is None:
            return ()
        kin = self.robot.kin
        joints = self.robot.joints_moved_by(self.robot.gripper.joint)  # with the fingers that mimic it
        return tuple(name for name in kin.link_names if any(self._moves_with(kin, kin.link_index[name], j) for j in joints))

    def tcp_pose(self, q_arm: np.typing.ArrayLike) -> np.ndarray:
        """TCP pose (4, 4) at arm configuration ``q_arm`` (arm_dof,) with the current gripper value."""
        rot, pos = self._fk.frames(self._full(np.atleast_2d(np.asarray(q_arm, dtype=float))))
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = rot[0, self._tcp], pos[0, self._tcp]
        return t

    def attach(self, name: str, q_arm: np.typing.ArrayLike) -> None:
        """Attach scene object ``name`` rigidly to the TCP at its current relative pose at ``q_arm``."""
        item = self.scene[name]
        if item.role == "table":
            raise InputError(f"cannot attach '{name}': it is the table")
        rel = np.linalg.inv(self.tcp_pose(q_arm)) @ item.pose
        self.scene.items.remove(item)
        self._attached[name] = (item, rel)
        self._rebuild()

    def detach(self, name: str, q_arm: np.typing.ArrayLike, step: float = 0.0) -> SceneItem:
        """Put attached object ``name`` back into the scene at its pose for ``q_arm`` (``scene.settled`` to ``step``, m and rad, if > 0); returns the item."""
        if name not in self._attached:
            raise InputError(f"'{name}' is not attached (attached: {', '.join(self._attached) or 'none'})")
        item, rel = self._attached.pop(name)
        item.pose = self.tcp_pose(q_arm) @ rel if step <= 0.0 else settled(self.tcp_pose(q_arm) @ rel, step)
        self.scene.items.append(item)
        self._rebuild()
        return item

    def add_item(self, item: SceneItem) -> None:
        """Add ``item`` to the checker's scene (names must stay unique)."""
        if item.name in self.scene or item.name in self._attached:
            raise InputError(f"scene already has an item named '{item.name}'")
        self.scene.items.append(item)
        self._rebuild()

    def remove_item(self, name: str) -> SceneItem:
        """Remove item ``name`` from the checker's scene and return it."""
        item = self.scene[name]
        self.scene.items.remove(item)
        if self._grasp_target == name:
            self._grasp_target = None
        self._rebuild()
        return item

    @property
    def attached(self) -> list[str]:
        """Names of the items attached to the arm (carried), in attach order."""
        return list(self._attached)

    def _state_key(self) -> tuple:
        """What the tables of ``_build_tables`` are made from, besides the robot (fixed per checker)."""
        items = tuple((it.name, it.role, it.shape, it.size, it.radius, it.length, id(it.mesh or it.cloud), it.pose.tobytes())
                      for it in self.scene.items)
        attached = tuple((name, item.shape, item.size, item.radius, item.length, rel.tobytes())
                         for name, (item, rel) in self._attached.items())
        return (self._grasp_target, self._jaw_strict, self.padding, self.singularity_margin, self.contact_tolerance,
                items, attached)

    @staticmethod
    def _moves_with(kin: Kinematics, link: int, joint: Joint) -> bool:
        """True when ``link`` is ``joint``'s child or a descendant of it."""
        child = kin.link_index[joint.child]
        while link != 0:
            if link == child:
                return True
            link = kin._parent[kin._child.index(link)]
        return False

    def _full(self, q: np.ndarray) -> np.ndarray:
        full = np.broadcast_to(self._q_template, (q.shape[0], self._q_template.size)).copy()
        full[:, self._arm] = q
        return full
