"""The collision checker's tables for the compiled kernel (``src/roarmctl/_kernel.c``): the scene's parts and the
arm's moving shapes as flat int64 and float64 arrays (layout: ``parse_model`` in the kernel, record sizes from its
module constants ``_kernel.SHAPEF``, ``ITEMF``, ``MAXDOF``, ... so both languages read one source), the pair masks,
the pre-filter spheres, and the sweep gain of ``segment_valid``. Tables of recent collision states are kept for
every checker of the process (``_STATE_TABLES``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from roarmctl import _kernel
from roarmctl.errors import InputError
from roarmctl.motion.collision_world import CheckerWorld, _Moving
from roarmctl.motion.geometry import Part, item_parts
from roarmctl.motion.scene import SceneItem
from roarmctl.robot.model import Robot

_STATE_CACHE = 64  # collision states whose tables are kept (for every checker of the process: _rebuild), least recently used out
# What _build_tables sets: the kept tables of one collision state.
_TABLES = ("_parts", "_items", "_item_objs", "_item_lo", "_item_hi", "_item_c", "_item_h", "_moving_shapes", "_mv_link", "_mv_rot",
           "_mv_pos", "_mv_half", "_mv_half_self", "_mv_radius", "_scene_mask", "_active", "_active_mask", "_active_r2",
           "_pairs", "_pair_r2", "_ki", "_kf", "_q_template", "_kfm", "_kim")
_SWEEP_GAINS: dict[tuple, tuple[Robot, float]] = {}  # see KernelTables._cached_sweep_gain
# the tables of the last _STATE_CACHE collision states, with the robot each was made for (ids are compared only while it lives)
_STATE_TABLES: dict[tuple, tuple[Robot, dict[str, Any]]] = {}


class KernelTables(CheckerWorld):
    """Builds and keeps the kernel's tables of a ``CollisionChecker`` (see the module's docstring)."""

    _parts: list[Part]  # the scene's collision parts (_build_tables); _items: the item of each part
    _items: list[SceneItem]
    _item_objs: list[Any]
    _moving_shapes: list[_Moving]
    _arm_shapes: list[_Moving]
    _mv_link: np.ndarray
    _mv_rot: np.ndarray
    _mv_pos: np.ndarray
    _mv_radius: np.ndarray
    _scene_mask: np.ndarray
    _active: np.ndarray
    _pairs: np.ndarray
    _kf: np.ndarray  # the kernel's float table (_pack); this checker's own copy
    _ki: np.ndarray
    _kfm: memoryview
    _kim: memoryview
    sweep_gain: float

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
        for what, count, most in (("joints", len(self._q_template), _kernel.MAXDOF), ("links", kin.n_links, _kernel.MAXLINKS),
                                  ("collision shapes (with attached objects)", len(self._moving_shapes), _kernel.MAXSHAPES)):
            if count > most:  # the kernel's fixed-size work arrays
                raise InputError(f"{self.robot.name} has {count} {what}; the collision checker handles at most {most}",
                                 "merge collision shapes, or split the description")
        s, m = len(self._moving_shapes), len(self._items)
        shapes = np.hstack([self._mv_rot.reshape(s, 9), self._mv_pos, self._mv_half, self._mv_half_self,
                            self._mv_radius[:, None]]) if s else np.zeros((0, _kernel.SHAPEF))
        items = np.zeros((m, _kernel.ITEMF))
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
        point to a point of a shape it moves, taken over 512 sampled configurations plus 10 %. A mimic joint of
        the chain moves |multiplier| times as far as its leader: its rho, so scaled, adds to its leader's."""
        rng = np.random.default_rng(0)
        q = rng.uniform(self._lower, self._upper, (512, len(self._arm)))
        rot, pos = self._fk.frames(self._full(q))
        centres = pos[:, self._mv_link] + np.einsum("nsij,sj->nsi", rot[:, self._mv_link], self._mv_pos)
        kin = self.robot.kin
        rho: dict[str, float] = {}
        for parent, joint in self._chain:
            origin = pos[:, parent] + rot[:, parent] @ joint.origin[:3, 3]
            distal = [a for a, mv in enumerate(self._moving_shapes)
                      if self._moves_with(kin, mv.link, joint)]
            d = np.linalg.norm(centres[:, distal] - origin[:, None, :], axis=2) + self._mv_radius[distal] if distal else None
            column = joint.mimic or joint.name
            rho[column] = rho.get(column, 0.0) + (abs(joint.multiplier) * float(d.max()) if d is not None else 0.0)
        return 1.1 * float(np.sqrt(np.sum(np.square(list(rho.values())))))
