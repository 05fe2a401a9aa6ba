"""State-validity checking: joint limits, singularity margin, arm vs scene and arm vs itself (FCL).

How a batch of states (N, arm_dof) is checked, in one call of the compiled kernel
(``src/roarmctl/_kernel.c``, a small C extension built at install time) per batch:

1. joint limits, the library's one FK (the kernel's ``fk`` on ``robot.kin``'s tables, which
   ``Kinematics.frames4`` also calls) and, when a margin is set, the smallest singular value of the
   translational Jacobian (the kernel's Jacobian columns, as ``Kinematics.pose_jacobian``);
2. every collision shape's world pose;
3. conservative pre-filters that only clear pairs that are certainly apart: a shape's bounding
   sphere vs the item's axis-aligned box (and shape spheres against each other), the world boxes,
   then the separating-axis test of the two oriented bounding boxes (each shape lies inside its
   box, so an axis that separates the boxes separates the shapes); a pair with a cylinder item also
   meets the separating-axis test against a second box of the cylinder (``_second_box``), which
   clears most pairs near the first box's corners;
4. python-fcl answers the pairs that no filter cleared, exactly (boxes, cylinders, spheres, meshes),
   in state order, skipping the rest of a state after its first collision (and every later state
   in ``first_invalid``). For two boxes the kernel only leaves pairs that overlap, so FCL is called
   about once per colliding state.

Motion segments (``segment_valid``) are checked as one batch at ``resolution``; steps between
two states where a shape's box grown by the distance any arm point can travel in half a step
(``sweep_gain``) is not apart from an item's box (or a shape's sphere so grown comes near another
shape's) are re-checked at a finer resolution, so that a finer
re-check of the segment (the pipeline's, or a test's) agrees with it.

Rules: arm shapes are inflated by ``padding`` against the scene; self-collision uses the
description's boxes as they are and skips ``robot.allowed_collisions``. The description's
``base_links`` (the links that sit on the table) are never checked against items of role "table".
A grasp target may touch the description's ``jaw_links``. An attached object moves with the TCP;
it is checked against the scene and against every arm link except the jaw links, shrunk by
``contact_tolerance`` so that resting on the table or touching a neighbour is not a collision.
Static items are never checked against each other.
"""

from __future__ import annotations

import itertools
import math
import threading
from dataclasses import dataclass
from typing import Any

import fcl
import numpy as np

from roarmctl import _kernel
from roarmctl.errors import InputError
from roarmctl.motion.geometry import Part, item_parts
from roarmctl.motion.geometry import fcl_geometry as _geometry
from roarmctl.motion.geometry import half_extents as _half_extents
from roarmctl.motion.scene import Scene, SceneItem, settled
from roarmctl.robot.meshes import MeshGeometry
from roarmctl.robot.model import Joint, Kinematics, Robot
from roarmctl.robot.singularity import margin_text

_EPS = 1e-9  # rad: joint-limit tolerance (the kernel uses the same)
_NO_GRIP = np.zeros(0).data  # "every state at the set_gripper value"
_NO_IDX = np.zeros(0, dtype=np.int64)
COARSE_STRIDE = 8  # segment_valid first checks every 8th state of long segments
_STATE_CACHE = 64  # collision states whose tables are kept (for every checker of the process: _rebuild), least recently used out
# What _build_tables sets: the kept tables of one collision state.
_TABLES = ("_parts", "_items", "_item_objs", "_item_lo", "_item_hi", "_item_c", "_item_h", "_moving_shapes", "_mv_link", "_mv_rot",
           "_mv_pos", "_mv_half", "_mv_half_self", "_mv_radius", "_scene_mask", "_active", "_active_mask", "_active_r2",
           "_pairs", "_pair_r2", "_ki", "_kf", "_q_template", "_kfm", "_kim")


#: The kernel's output buffers (``CollisionChecker._buffers``): "n" (states they hold), arrays "valid", "near", "scene",
#: "self", "pose", "idx", "near_bytes" (under "near"), "views"/"seg_views" (memoryviews as the kernel takes them).
_Buffers = dict[str, Any]

_FCL_REQUEST = fcl.CollisionRequest()  # FCL's defaults (what fcl.collide makes when given none), made once
_SWEEP_GAINS: dict[tuple, tuple[Robot, float]] = {}  # see CollisionChecker._cached_sweep_gain
# Set-up shared by the checkers of a process (every plan, api.plan call or query makes one, mostly for the same robot
# and scene): the arm's shapes per robot and padding, the tables of the last _STATE_CACHE collision states (with the
# robot each was made for: ids are compared only while it lives).
_ARM_SHAPES: dict[tuple, tuple[Robot, list[_Moving]]] = {}
_STATE_TABLES: dict[tuple, tuple[Robot, dict[str, Any]]] = {}
# One check at a time in the process: checkers share FCL objects (a check sets their poses) and the kernel's tables;
# the kernel and FCL hold the GIL while they work, so no parallelism is lost.
_LOCK = threading.RLock()


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


class CollisionChecker:
    """Validity of arm configurations (N, arm_dof) for ``robot`` in ``scene``.

    ``padding`` (m) inflates the arm against the scene (a link the description pads itself,
    ``robot.padding``, keeps its own value). ``singularity_margin`` (m/rad), when
    given, is the smallest allowed singular value of the 3 x arm_dof translational Jacobian.
    ``contact_tolerance`` (m) shrinks attached objects so resting contact is not a collision.
    The checker keeps its own copy of the scene (``self.scene``): ``detach`` moves items in it.
    """

    _parts: list[Part]  # the scene's collision parts (_build_tables); _items: the item of each part
    _items: list[SceneItem]
    _kf: np.ndarray  # the kernel's float table (_pack); this checker's own copy

    def __init__(self, robot: Robot, scene: Scene, *, padding: float = 0.005,
                 singularity_margin: float | None = None, contact_tolerance: float = 0.001) -> None:
        if padding < 0:
            raise InputError(f"collision padding must be >= 0 m, got {padding}")
        self.robot = robot
        self.scene = scene.copy()
        self.padding = float(padding)
        self.singularity_margin = singularity_margin
        self.contact_tolerance = float(contact_tolerance)
        self.check_count = 0
        self._fk = robot.kin  # the library's one FK
        self._arm = np.asarray(robot.arm_indices)
        self._lower = robot.lower[self._arm]
        self._upper = robot.upper[self._arm]
        self._q_template = robot.full_q(np.zeros(robot.arm_dof))  # a view into the kernel's table after _rebuild
        self._bufs: _Buffers = {}
        # One check at a time: the kernel's output buffers and the FCL objects' poses are shared (OMPL's PRM
        # calls back from two threads; checkers share their shapes: _LOCK).
        self._lock = _LOCK
        self._gripper_index = robot.joint_index(robot.gripper.joint) if robot.gripper else None
        kin = robot.kin
        self._link_index = kin.link_index
        self._tcp = kin.tcp_index
        self._chain = [(kin._parent[j], robot.joints[j]) for j in kin.tcp_chain_joints if robot.joints[j].kind != "fixed"]
        self._grasp_target: str | None = None
        self._jaw_strict = False  # set_grasp_target(..., moving_jaw_clear=True)
        self._attached: dict[str, tuple[SceneItem, np.ndarray]] = {}  # name -> (item, pose in TCP frame)
        with self._lock:  # the shapes and tables kept for every checker of the process
            self._arm_shapes = self._shared_arm_shapes()
            self._rebuild()

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

    # ------------------------------------------------------------------ configuration
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

    def _rebuild(self) -> None:
        """Recompute the static tables (items, moving shapes, pair masks) after a scene change.

        The last few collision states' tables are kept for every checker of the process (``_STATE_TABLES``): a plan
        switches between a handful (grasp target, moving-jaw check, attached object), plans of one scene start from
        the same one, and a build costs ~0.5 ms (5 ms with 200 boxes). A kept state gets a copy of its float table with
        this checker's joint template (the gripper value); the rest is only read. Under the lock: they are shared."""
        with self._lock:
            self._rebuild_locked()

    def _rebuild_locked(self) -> None:
        key = (id(self.robot), *self._state_key())
        hit = _STATE_TABLES.pop(key, None)  # put back below as the most recently used (a big scene's key hashes slowly)
        if hit is None or hit[0] is not self.robot:
            self._build_tables()
            if len(_STATE_TABLES) >= _STATE_CACHE:
                _STATE_TABLES.pop(next(iter(_STATE_TABLES)))
            _STATE_TABLES[key] = (self.robot, {name: getattr(self, name) for name in _TABLES})
        else:
            _STATE_TABLES[key] = hit
            template = self._q_template.copy()
            for name, value in hit[1].items():
                setattr(self, name, value)
            self._kf = self._kf.copy()  # this checker's own: set_gripper writes the template in it
            self._kfm = self._kf.data
            self._q_template = self._template_view()
            self._q_template[:] = template
            by_name = {it.name: it for it in self.scene.items}
            self._items = [by_name[it.name] for it in self._items]  # the scene's own item objects, one per part
            self._bufs = {}
        key = tuple((name, rel.tobytes()) for name, (_, rel) in self._attached.items())  # moving shapes only
        if getattr(self, "_sweep_key", None) != key:
            self.sweep_gain = self._cached_sweep_gain()
            self._sweep_key = key

    def _build_tables(self) -> None:
        parts = [part for it in self.scene.items for part in item_parts(it)]
        self._parts = parts
        self._items = [part.item for part in parts]  # one entry per part: the item it belongs to
        self._item_objs = [part.obj for part in parts]
        m = len(parts)
        lo, hi = np.zeros((m, 3)), np.zeros((m, 3))
        for k, part in enumerate(parts):
            if part.kind in ("box", "cylinder", "sphere"):  # the item's own (a cylinder's is tighter than its box's)
                lo[k], hi[k] = part.item.aabb()
            else:
                h = np.abs(part.rot) @ part.half
                lo[k], hi[k] = part.centre - h, part.centre + h
        self._item_lo, self._item_hi = lo, hi
        self._item_c, self._item_h = (lo + hi) / 2, (hi - lo) / 2

        moving = list(self._arm_shapes)
        tol = self.contact_tolerance
        for name, (item, rel) in self._attached.items():
            moving.append(self._moving(name, self._tcp, rel, item.shape, item.size, item.radius, item.length,
                                       -tol, -tol, attached=True))
        self._moving_shapes = moving
        s = len(moving)
        self._mv_link = np.array([mv.link for mv in moving], dtype=int)  # int even when empty (a DH robot has no shapes)
        self._mv_rot = np.array([mv.rot for mv in moving]).reshape(s, 3, 3)
        self._mv_pos = np.array([mv.pos for mv in moving]).reshape(s, 3)
        self._mv_half = np.array([mv.half for mv in moving]).reshape(s, 3)
        self._mv_half_self = np.array([mv.half_self for mv in moving]).reshape(s, 3)
        self._mv_radius = np.array([mv.radius for mv in moving])
        link_names = self._fk.robot.kin.link_names
        jaw_links, base_links = set(self.robot.jaw_links), set(self.robot.base_links)
        moving_jaw = set(self.moving_jaw_links) if self._jaw_strict else set()
        touching = jaw_links - moving_jaw  # may touch the grasp target

        # Shape vs item mask: which pairs are checked at all.
        mask = np.ones((s, m), dtype=bool)
        is_table = np.array([it.role == "table" for it in self._items], dtype=bool)
        is_target = np.array([it.name == self._grasp_target for it in self._items], dtype=bool)
        for a, mv in enumerate(moving):
            lname = link_names[mv.link] if not mv.attached else None
            if lname in base_links:
                mask[a] &= ~is_table
            if lname in touching:
                mask[a] &= ~is_target
            if moving_jaw and lname not in moving_jaw:  # moving_jaw_clear: only the moving jaw is checked
                mask[a] = False
        self._scene_mask = mask
        # Shapes that are checked against at least one item take part in the scene pre-filter.
        self._active = np.flatnonzero(mask.any(axis=1)) if m else np.zeros(0, dtype=int)
        self._active_mask = mask[self._active]
        self._active_r2 = (self._mv_radius[self._active] ** 2)[:, None]

        # Moving-vs-moving pairs (self-collision and attached objects vs the arm).
        allowed = self.robot.allowed_collisions
        pairs = []
        for a in range(s):
            for b in range(a + 1, s):
                ma, mb = moving[a], moving[b]
                if ma.attached or mb.attached:
                    other = mb if ma.attached else ma
                    if other.attached or link_names[other.link] in jaw_links:
                        continue
                    pairs.append((a, b))
                    continue
                la, lb = link_names[ma.link], link_names[mb.link]
                if la == lb or frozenset((la, lb)) in allowed:
                    continue
                if moving_jaw and la not in moving_jaw and lb not in moving_jaw:
                    continue
                pairs.append((a, b))
        self._pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        self._pair_r2 = (self._mv_radius[self._pairs[:, 0]] + self._mv_radius[self._pairs[:, 1]]) ** 2 if len(pairs) else np.zeros(0)
        # Self checks use unpadded geometry: the pre-filter radii above are padded, hence conservative.
        self._pack()

    def _pack(self) -> None:
        """The kernel's tables: one int64 and one float64 array (layout: parse_model in src/roarmctl/_kernel.c), the
        robot's kinematic tables (``Kinematics._pack``) inside."""
        kin = self._fk
        for what, count, most in (("joints", len(self._q_template), 64), ("links", kin.n_links, 256),
                                  ("collision shapes (with attached objects)", len(self._moving_shapes), 512)):
            if count > most:  # the kernel's fixed-size work arrays (_kernel.c: MAXDOF, MAXLINKS, MAXSHAPES)
                raise InputError(f"{self.robot.name} has {count} {what}; the collision checker handles at most {most}",
                                 "merge collision shapes, or split the description")
        s, m = len(self._moving_shapes), len(self._items)
        shapes = np.hstack([self._mv_rot.reshape(s, 9), self._mv_pos, self._mv_half, self._mv_half_self,
                            self._mv_radius[:, None]]) if s else np.zeros((0, 19))
        items = np.zeros((m, 37))
        if m:
            parts = self._parts
            items[:, :3], items[:, 3:6] = self._item_c, self._item_h
            items[:, 6:15] = np.array([p.rot for p in parts]).reshape(m, 9)
            items[:, 15:18] = np.array([p.centre for p in parts])
            items[:, 18:21] = np.array([p.half for p in parts])
            for k, part in enumerate(parts):
                if part.box2 is not None:
                    items[k, 24], items[k, 25:34], items[k, 34:37] = 1.0, part.box2[0], part.box2[1]
        # Sphere centres (link, centre in the link frame), each listed once: the kernel makes each world centre once
        # per state, for every group and link pair that has it (a link's group and link-pair spheres are the same
        # sphere when all its shapes take part in the scene test).
        sph_index: dict[tuple[int, bytes], int] = {}
        sph_link: list[int] = []
        sph_c: list[np.ndarray] = []

        def sph(link: int, c: np.ndarray) -> int:
            key = (int(link), np.asarray(c, dtype=float).tobytes())
            if key not in sph_index:
                sph_index[key] = len(sph_link)
                sph_link.append(int(link))
                sph_c.append(c)
            return sph_index[key]

        # Groups for the kernel's first scene test: the active shapes of one link, in one sphere about their
        # mean centre (link frame) that holds each shape's sphere, plus 1e-9 m against rounding.
        links = self._mv_link[self._active]
        g_links = sorted(set(links.tolist()))
        g_order: list[int] = []
        g_start, g_sph, g_r, g_mask = [0], [], [], []
        for link in g_links:
            members = np.flatnonzero(links == link)
            centres = self._mv_pos[self._active[members]]
            c = centres.mean(axis=0)
            g_order += members.tolist()
            g_start.append(len(g_order))
            g_sph.append(sph(link, c))
            g_r.append(float(np.max(np.linalg.norm(centres - c, axis=1) + self._mv_radius[self._active[members]])) + 1e-9)
            g_mask.append(self._active_mask[members].any(axis=0))
        # Link pairs for the kernel's first self test: every link's sphere holds the spheres of all its shapes.
        sphere = {}
        for link in sorted(set(self._mv_link.tolist())):
            members = np.flatnonzero(self._mv_link == link)
            c = self._mv_pos[members].mean(axis=0)
            sphere[link] = (c, float(np.max(np.linalg.norm(self._mv_pos[members] - c, axis=1) + self._mv_radius[members])) + 1e-9)
        by_links: dict[tuple[int, int], list[int]] = {}
        for p, (a, b) in enumerate(self._pairs.tolist()):
            by_links.setdefault((int(self._mv_link[a]), int(self._mv_link[b])), []).append(p)
        lp_order: list[int] = []
        lp_sph, lp_start, lp_r = [], [0], []
        for (la, lb), in_pair in by_links.items():
            lp_sph += [sph(la, sphere[la][0]), sph(lb, sphere[lb][0])]
            lp_order += in_pair
            lp_start.append(len(lp_order))
            lp_r += [sphere[la][1], sphere[lb][1]]
        margin = self.singularity_margin
        ints = [len(self._arm), s, m, len(self._active), len(self._pairs),
                -1 if self._gripper_index is None else self._gripper_index, int(margin is not None), len(g_links),
                len(by_links), len(kin._ki), len(kin._kf), len(sph_link)]
        ints += list(kin._ki) + list(self._arm) + list(self._mv_link) + list(self._active)
        ints += list(self._active_mask.astype(np.int64).ravel()) + list(self._pairs.ravel())
        ints += g_sph + g_start + g_order + list(np.array(g_mask, dtype=np.int64).ravel())
        ints += lp_sph + lp_start + lp_order + sph_link
        self._ki = np.array(ints, dtype=np.int64)
        floats = [kin._kf, self._lower, self._upper, self._q_template, [0.0 if margin is None else float(margin)],
                  shapes.ravel(), items.ravel(),
                  self._active_r2.ravel(), self._pair_r2, np.sqrt(self._active_r2.ravel()), np.sqrt(self._pair_r2),
                  g_r, lp_r, np.array(sph_c, dtype=float).ravel()]
        self._kf = np.concatenate([np.asarray(f, dtype=float).ravel() for f in floats])
        self._q_template = self._template_view()  # set_gripper writes the kernel's table
        self._kfm, self._kim = self._kf.data, self._ki.data  # cheaper to pass than the arrays
        self._bufs = {}

    def _template_view(self) -> np.ndarray:
        """The joint template (dof,) inside the kernel's float table ``self._kf`` (after the kinematic tables and the
        arm's lower and upper limits: parse_model in src/roarmctl/_kernel.c)."""
        off = len(self._fk._kf) + 2 * len(self._arm)
        return self._kf[off:off + self.robot.dof]

    def _cached_sweep_gain(self) -> float:
        """``_sweep_gain()``, computed once per process for the same robot, shapes and joint template (a plan and every
        query of a scene build checkers for the same arm again and again; 512 FK samples cost a few ms)."""
        key = (id(self.robot), self._q_template.tobytes(), self._mv_link.tobytes(), self._mv_pos.tobytes(),
               self._mv_radius.tobytes(), self._lower.tobytes(), self._upper.tobytes())
        hit = _SWEEP_GAINS.get(key)
        if hit is not None and hit[0] is self.robot:
            return hit[1]
        gain = self._sweep_gain()
        if len(_SWEEP_GAINS) >= 64:
            _SWEEP_GAINS.pop(next(iter(_SWEEP_GAINS)))
        _SWEEP_GAINS[key] = (self.robot, gain)
        return gain

    def _sweep_gain(self) -> float:
        """Bound (m per rad) on how far any point of a moving shape moves for a joint step of
        Euclidean norm 1: sqrt(sum_i rho_i^2), rho_i = the largest distance from arm joint i's axis
        point to a point of a shape it moves, taken over 512 sampled configurations plus 10 %."""
        rng = np.random.default_rng(0)
        q = rng.uniform(self._lower, self._upper, (512, len(self._arm)))
        rot, pos = self._fk.frames(self._full(q))
        centres = pos[:, self._mv_link] + np.einsum("nsij,sj->nsi", rot[:, self._mv_link], self._mv_pos)
        kin = self.robot.kin
        rho = []
        for parent, joint in self._chain:
            origin = pos[:, parent] + rot[:, parent] @ joint.origin[:3, 3]
            distal = [a for a, mv in enumerate(self._moving_shapes)
                      if self._moves_with(kin, mv.link, joint)]
            if not distal:
                rho.append(0.0)
                continue
            d = np.linalg.norm(centres[:, distal] - origin[:, None, :], axis=2) + self._mv_radius[distal]
            rho.append(float(d.max()))
        return 1.1 * float(np.sqrt(np.sum(np.square(rho))))

    @staticmethod
    def _moves_with(kin: Kinematics, link: int, joint: Joint) -> bool:
        """True when ``link`` is ``joint``'s child or a descendant of it."""
        child = kin.link_index[joint.child]
        while link != 0:
            if link == child:
                return True
            link = kin._parent[kin._child.index(link)]
        return False

    # ------------------------------------------------------------------ checks
    def _full(self, q: np.ndarray) -> np.ndarray:
        full = np.broadcast_to(self._q_template, (q.shape[0], self._q_template.size)).copy()
        full[:, self._arm] = q
        return full

    def margin_measure(self, Q: np.typing.ArrayLike, gripper: float | np.typing.ArrayLike | None = None) -> np.ndarray:
        """Smallest singular value (N,) of the translational Jacobian (3 x arm_dof), m/rad, at arm
        configurations ``Q`` (N, arm_dof): the quantity the singularity margin bounds."""
        Q = np.ascontiguousarray(np.atleast_2d(Q), dtype=float)
        out = np.empty(Q.shape[0])
        _kernel.sigma(self._kf, self._ki, Q, self._grip_arg(gripper, Q.shape[0]), out)
        return out

    def _grip_arg(self, gripper: float | np.typing.ArrayLike | None, n: int) -> np.ndarray | memoryview:
        if gripper is None:
            return _NO_GRIP
        if self._gripper_index is None:
            raise InputError(f"{self.robot.name} has no gripper")
        return np.ascontiguousarray(np.broadcast_to(np.asarray(gripper, dtype=float), (n,)))

    def _buffers(self, n: int) -> _Buffers:
        """Output buffers of the kernel for batches of up to ``n`` states (reused between calls)."""
        b = self._bufs
        if b.get("n", 0) < n:
            s, m = len(self._moving_shapes), len(self._items)
            near = bytearray(n)  # also seen as bytes: segment_valid asks bytearray.find whether any state is near
            self._bufs = b = {"n": n, "valid": np.empty(n, dtype=np.uint8), "near": np.frombuffer(near, dtype=np.uint8),
                              "near_bytes": near,
                              "scene": np.empty((n * max(len(self._active) * m, 1), 3), dtype=np.int64),
                              "self": np.empty((n * max(len(self._pairs), 1), 2), dtype=np.int64),
                              "pose": np.empty((n, max(s, 1), 12)), "idx": np.empty(n, dtype=np.int64)}
            b["views"] = tuple(b[k].data for k in ("valid", "near", "scene", "self", "pose"))
            b["seg_views"] = b["views"] + (b["idx"].data,)  # _kernel.segment's
        return b

    def _evaluate(self, q: np.ndarray, stop_at_first: bool, sweep: float = 0.0,
                  gripper: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Validity (N,) of arm states ``q`` (N, arm_dof); with ``stop_at_first`` states after the first
        invalid one are left marked valid and not checked. Also returns, when ``sweep`` > 0 (m), which
        states are "near" (N,): some shape's box grown by ``sweep`` is not apart from an item's box (nor from
        a cylinder's second box), or its bounding sphere so grown touches another shape's; else None."""
        q = np.ascontiguousarray(q, dtype=float)
        n = q.shape[0]
        self.check_count += n
        b = self._buffers(n)
        ns, npairs, _ = _kernel.check(self._kfm, self._kim, q, self._grip_arg(gripper, n), *b["views"], float(sweep),
                                      stop_at_first)
        valid = b["valid"][:n].astype(bool)
        near = b["near"][:n].astype(bool) if sweep > 0 else None
        if ns or npairs:
            self._narrow(valid, b, ns, npairs, stop_at_first)
        return valid, near

    def _narrow(self, valid: np.ndarray, b: _Buffers, ns: int, npairs: int, stop_at_first: bool) -> None:
        """FCL on the kernel's candidate pairs, in state order; marks colliding states invalid in ``valid``."""
        moving, items, pose, req = self._moving_shapes, self._item_objs, b["pose"], _FCL_REQUEST
        res = fcl.CollisionResult()  # one for the call: fcl.collide adds a contact to it per hit, which no one reads
        first_hit = len(valid)
        skip = -1
        for i, a, k in b["scene"][:ns].tolist():
            if i == skip:
                continue
            p = pose[i, a]
            obj = moving[a].obj_scene
            obj.setRotation(p[:9].reshape(3, 3))
            obj.setTranslation(p[9:])
            if fcl.collide(obj, items[k], req, res):
                valid[i] = False
                skip = i
                if stop_at_first:
                    first_hit = i
                    break
        pairs = self._pairs
        for i, pp in b["self"][:npairs].tolist():
            if i >= first_hit:
                break
            if not valid[i]:
                continue
            a, c = pairs[pp]
            oa, ob = moving[a].obj_self, moving[c].obj_self
            pa, pc = pose[i, a], pose[i, c]
            oa.setRotation(pa[:9].reshape(3, 3))
            oa.setTranslation(pa[9:])
            ob.setRotation(pc[:9].reshape(3, 3))
            ob.setTranslation(pc[9:])
            if fcl.collide(oa, ob, req, res):
                valid[i] = False
                if stop_at_first:
                    break

    def validity_batch(self, Q: np.typing.ArrayLike, gripper: float | np.typing.ArrayLike | None = None) -> np.ndarray:
        """Validity (N,) bool of arm configurations ``Q`` (N, arm_dof), rad; ``gripper`` (N,) as in ``first_invalid``."""
        with self._lock:
            Q = np.atleast_2d(np.asarray(Q, dtype=float))
            if Q.shape[0] == 0:
                return np.zeros(0, dtype=bool)
            if gripper is not None and self._gripper_index is None:
                raise InputError(f"{self.robot.name} has no gripper")
            return self._evaluate(Q, stop_at_first=False, gripper=None if gripper is None else np.asarray(gripper, dtype=float))[0]

    def is_valid(self, q_arm: np.typing.ArrayLike) -> bool:
        """True when arm configuration ``q_arm`` (arm_dof,) is within limits, margin and collision-free."""
        with self._lock:
            q = np.ascontiguousarray(q_arm, dtype=float)
            if q.size != self._lower.size:
                raise InputError(f"an arm configuration has {self._lower.size} values, got {q.size}")
            self.check_count += 1
            b = self._bufs or self._buffers(1)
            ns, npairs, limit = _kernel.check(self._kfm, self._kim, q, _NO_GRIP, *b["views"], 0.0, True)
            if limit == 0:  # limits or margin
                return False
            if not (ns or npairs):
                return True
            valid = np.ones(1, dtype=bool)
            self._narrow(valid, b, ns, npairs, True)
            return bool(valid[0])

    def first_invalid(self, Q: np.typing.ArrayLike, gripper: float | np.typing.ArrayLike | None = None) -> int | None:
        """Index of the first invalid row of ``Q`` (N, arm_dof), or None when all are valid; ``gripper`` (N,)
        gives each row its own gripper value (rad; default: the value of ``set_gripper``)."""
        with self._lock:
            Q = np.atleast_2d(np.asarray(Q, dtype=float))
            if Q.shape[0] == 0:
                return None
            if gripper is not None and self._gripper_index is None:
                raise InputError(f"{self.robot.name} has no gripper")
            valid = self._evaluate(Q, stop_at_first=True, gripper=None if gripper is None else np.asarray(gripper, dtype=float))[0]
            return None if valid.all() else int(np.argmin(valid))

    def segment_valid(self, q0: np.typing.ArrayLike, q1: np.typing.ArrayLike, resolution: float = 0.01, refine: int = 4) -> bool:
        """True when the straight joint-space segment q0 -> q1 (arm_dof,) is valid.

        States are checked at steps of at most ``resolution`` rad (Euclidean norm over the arm
        joints), both ends included. A step between two states is proven clear when at both ends no
        shape's box, grown by how far any point of the arm can move in half a step (``sweep_gain``),
        comes near an item's box, nor its bounding sphere so grown near another shape's; the other steps are re-checked at ``refine`` times finer resolution,
        so that a finer re-check of the segment does not find what the coarse one missed.
        """
        with self._lock:
            # The states of interpolate(q0, q1, resolution), made by the kernel itself (same numbers), every pass in one
            # kernel call until one leaves candidates for FCL; once FCL cleared them, the next call goes on from there.
            q0 = np.ascontiguousarray(q0, dtype=float).ravel()
            q1 = np.ascontiguousarray(q1, dtype=float).ravel()
            b = self._bufs or self._buffers(1)
            first = 0
            while True:
                status, done, ns, npairs, limit, n, count, steps, sweep = _kernel.segment(
                    self._kfm, self._kim, q0, q1, resolution, self.sweep_gain, refine, COARSE_STRIDE, first, *b["seg_views"])
                self.check_count += count
                if status < 2:  # 0: a limit or the margin; 1: every pass clear
                    return status == 1
                if status > 2:
                    break
                if not self._all_clear(b, n, ns, npairs, limit):  # pass `done` left candidates: FCL decides them
                    return False
                first = done + 1
                if first > 2:
                    return True
            if status == 4:  # not for the kernel alone (an arm of 16 joints or more, bad input): numpy's numbers
                d = q1 - q0
                steps = max(1, math.ceil(math.sqrt(d.dot(d)) / resolution))  # the same numbers as np.sqrt / np.ceil
                e = (q0 + d * (1.0 / steps)) - q0  # the first step, as interpolate's q[1] - q[0]
                sweep = 0.5 * math.sqrt(e.dot(e)) * self.sweep_gain
            return self._passes(q0, q1 - q0, steps, sweep, refine, done)  # 3: buffers too small for pass `done`

    def _passes(self, q0: np.ndarray, d: np.ndarray, steps: int, sweep: float, refine: int, first: int) -> bool:
        """segment_valid's passes ``first`` (0: every COARSE_STRIDE-th state, 1: the others, 2: the refinement, 3:
        none) to the last over the segment q0 -> q0 + d (arm_dof,) of ``steps`` steps; True when all are clear."""
        if first > 2:
            return True
        b = self._bufs if self._bufs.get("n", 0) > steps else self._buffers(steps + 1)
        coarse = steps + 1 > 4 * COARSE_STRIDE
        if first == 0 and coarse and not self._line_ok(b, q0, d, steps, COARSE_STRIDE, COARSE_STRIDE, sweep):
            return False  # most invalid motions are caught by every 8th state, at an eighth of the cost
        # the full pass skips the states the coarse pass checked (their near flags stay in b)
        if first <= 1 and not self._line_ok(b, q0, d, steps, 0, 1, sweep, skip=COARSE_STRIDE if coarse else 0):
            return False
        if refine <= 1 or sweep <= 0:
            return True
        if b["near_bytes"].find(1, 0, steps + 1) < 0:  # no state of the call just made is near anything
            return True
        near = b["near"][:steps + 1].view(bool)
        idx = np.flatnonzero(near[:-1] | near[1:])
        n = len(idx) * (refine - 1)
        return self._line_ok(b if b["n"] >= n else self._buffers(n), q0, d, steps, 0, 1, 0.0, idx, refine)

    def _line_ok(self, b: _Buffers, q0: np.ndarray, d: np.ndarray, steps: int, start: int, stride: int,
                 sweep: float = 0.0, idx: np.ndarray = _NO_IDX, refine: int = 1, skip: int = 0) -> bool:
        """True when the states of the segment q0 -> q0 + d that ``_kernel.check_line`` makes (see there) are
        all valid; stops at the first invalid one. ``b``: output buffers (``_buffers``) large enough for them; with
        ``sweep`` > 0 the "near" flags stay in ``b``. ``idx``: int64 step indices (refinement), as the kernel takes.
        ``skip`` > 0: the states skip, 2 skip, ... were checked (and passed) by the call just made with
        start = stride = skip and this sweep; they are not checked again."""
        n = len(idx) * (refine - 1) if len(idx) else (steps - start) // stride + 1 if start <= steps else 0
        self.check_count += n - (steps // skip if skip else 0)
        ns, npairs, limit, _ = _kernel.check_line(self._kfm, self._kim, q0, d, steps, start, stride, idx, refine,
                                                  *b["views"], sweep, True, skip)
        if limit < n:  # limits or margin
            return False
        return not (ns or npairs) or self._all_clear(b, n, ns, npairs, limit)

    def _all_clear(self, b: _Buffers, n: int, ns: int, npairs: int, limit: int) -> bool:
        """The verdict on ``n`` states the kernel checked with stop-at-first: False at a limit or margin
        failure (``limit`` < n), else FCL decides the ``ns`` scene and ``npairs`` self candidates it left."""
        if limit < n:  # limits or margin
            return False
        if ns or npairs:
            valid = np.ones(n, dtype=bool)
            self._narrow(valid, b, ns, npairs, True)
            return bool(valid.all())
        return True

    def _all_valid(self, q: np.ndarray, sweep: float = 0.0) -> bool:
        """True when every state of ``q`` (N, arm_dof) is valid; stops at the first invalid one. With ``sweep``
        > 0 the kernel also leaves the "near" flags (see ``_evaluate``) in ``self._bufs["near"]``."""
        q = np.ascontiguousarray(q, dtype=float)
        n = q.shape[0]
        self.check_count += n
        b = self._buffers(n)
        ns, npairs, limit = _kernel.check(self._kfm, self._kim, q, _NO_GRIP, *b["views"], float(sweep), True)
        return self._all_clear(b, n, ns, npairs, limit)

    def explain(self, q_arm: np.typing.ArrayLike) -> str:
        """Why ``q_arm`` (arm_dof,) is invalid, in words; "valid" when it is not."""
        with self._lock:
            q = np.asarray(q_arm, dtype=float).reshape(1, -1)
            names = self.robot.joint_names
            for j, idx in enumerate(self._arm):
                if not (self._lower[j] - _EPS <= q[0, j] <= self._upper[j] + _EPS):
                    return (f"joint limit: {names[idx]} = {q[0, j]:.4f} rad is outside "
                            f"[{self._lower[j]:.4f}, {self._upper[j]:.4f}]")
            q_full = self._full(q)
            rot, pos = self._fk.frames(q_full)
            if self.singularity_margin is not None:
                sig = float(self.margin_measure(q)[0])
                if sig < self.singularity_margin:
                    return margin_text(self.robot, q[0], sig, self.singularity_margin)
            # Exhaustive FCL pass without the pre-filter, so explain() never depends on it.
            rl = rot[:, self._mv_link]
            srot, scen = rl @ self._mv_rot, pos[:, self._mv_link] + np.einsum("nsij,sj->nsi", rl, self._mv_pos)
            link_names = self.robot.kin.link_names
            moving = self._moving_shapes

            def label(mv: _Moving) -> str:
                return f"attached object '{mv.name}'" if mv.attached else link_names[mv.link]

            for a, mv in enumerate(moving):
                mv.obj_scene.setRotation(srot[0, a])
                mv.obj_scene.setTranslation(scen[0, a])
                for k, it in enumerate(self._items):
                    if self._scene_mask[a, k] and fcl.collide(mv.obj_scene, self._item_objs[k]):
                        return f"{label(mv)} hits {it.role} '{it.name}'"
            for a, b in self._pairs:
                oa, ob = moving[a].obj_self, moving[b].obj_self
                oa.setRotation(srot[0, a])
                oa.setTranslation(scen[0, a])
                ob.setRotation(srot[0, b])
                ob.setTranslation(scen[0, b])
                if fcl.collide(oa, ob):
                    if moving[a].attached or moving[b].attached:
                        return f"{label(moving[a])} hits {label(moving[b])}"
                    return f"self-collision: {label(moving[a])} hits {label(moving[b])}"
            return "valid"


def interpolate(q0: np.typing.ArrayLike, q1: np.typing.ArrayLike, resolution: float) -> np.ndarray:
    """States (K, n) on the straight segment q0 -> q1, both ends included, at most ``resolution``
    apart (Euclidean norm, rad); K >= 2."""
    q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
    d = q1 - q0
    steps = max(1, int(np.ceil(np.sqrt(d.dot(d)) / resolution)))  # = np.linalg.norm(d), without its overhead
    t = _T_GRIDS.get(steps)
    if t is None:
        t = np.linspace(0.0, 1.0, steps + 1)[:, None]
        if len(_T_GRIDS) < 4096:
            _T_GRIDS[steps] = t
    return q0 + d * t


_T_GRIDS: dict[int, np.ndarray] = {}  # steps -> np.linspace(0, 1, steps + 1)[:, None] (read-only use)


def densify(path: np.ndarray, max_step: float | None) -> np.ndarray:
    """Insert states on each straight piece of ``path`` (K, n) so no two consecutive rows are
    more than ``max_step`` apart (rad, Euclidean); ``None`` returns the path as it is."""
    if max_step is None or len(path) < 2:
        return path
    out = [path[:1]]
    for a, b in itertools.pairwise(path):
        out.append(interpolate(a, b, max_step)[1:])
    return np.vstack(out)
