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

The checker is split by job: ``collision_world`` (the scene, carried objects, grasp target, gripper; the arm's
shapes), ``collision_tables`` (the kernel's tables and the sweep gain) and this module (the queries).
"""

from __future__ import annotations

import itertools
import math
import threading
from typing import Any

import fcl
import numpy as np

from roarmctl import _kernel
from roarmctl.errors import InputError
from roarmctl.motion.collision_tables import KernelTables
from roarmctl.motion.collision_world import _Moving
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.model import Robot
from roarmctl.robot.singularity import margin_text

_EPS = 1e-9  # rad: joint-limit tolerance (the kernel uses the same)
_NO_GRIP = np.zeros(0).data  # "every state at the set_gripper value"
_NO_IDX = np.zeros(0, dtype=np.int64)
COARSE_STRIDE = 8  # segment_valid first checks every 8th state of long segments
BUFFER_MIN = 256  # states the kernel's output buffers hold at least (CollisionChecker._buffers)


#: The kernel's output buffers (``CollisionChecker._buffers``): "n" (states they hold), arrays "valid", "near", "scene",
#: "self", "pose", "idx", "near_bytes" (under "near"), "views"/"seg_views" (memoryviews as the kernel takes them).
_Buffers = dict[str, Any]

_FCL_REQUEST = fcl.CollisionRequest()  # FCL's defaults (what fcl.collide makes when given none), made once
# One check at a time in the process: checkers share FCL objects (a check sets their poses) and the kernel's tables;
# the kernel and FCL hold the GIL while they work, so no parallelism is lost.
_LOCK = threading.RLock()


class CollisionChecker(KernelTables):
    """Validity of arm configurations (N, arm_dof) for ``robot`` in ``scene``.

    ``padding`` (m) inflates the arm against the scene (a link the description pads itself,
    ``robot.padding``, keeps its own value). ``singularity_margin`` (m/rad), when
    given, is the smallest allowed singular value of the 3 x arm_dof translational Jacobian.
    ``contact_tolerance`` (m) shrinks attached objects so resting contact is not a collision.
    The checker keeps its own copy of the scene (``self.scene``): ``detach`` moves items in it.
    """

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
            # at least twice the last size, and BUFFER_MIN: a plan's checks ask for ever longer batches (1, 110, 177,
            # 219, 245, 949 states on query b), and each new set of buffers cost ~30 us
            n = max(n, 2 * b.get("n", 0), BUFFER_MIN)
            s, m = len(self._moving_shapes), len(self._items)
            near = bytearray(n)  # also seen as bytes: segment_valid asks bytearray.find whether any state is near
            self._bufs = b = {"n": n, "valid": np.empty(n, dtype=np.uint8), "near": np.frombuffer(near, dtype=np.uint8),
                              "near_bytes": near,
                              "scene": np.empty((n * max(len(self._active) * m, 1), 3), dtype=np.int64),
                              "self": np.empty((n * max(len(self._pairs), 1), 2), dtype=np.int64),
                              "pose": np.empty((n, max(s, 1), _kernel.POSEF)), "idx": np.empty(n, dtype=np.int64)}
            # each state's and shape's rotation (3, 3) and centre (3,) as views, for FCL (_narrow, _any_hit)
            b["rot"] = b["pose"][:, :, :9].reshape(n, b["pose"].shape[1], 3, 3)
            b["pos"] = b["pose"][:, :, 9:]
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
        moving, items, rot, pos, req = self._moving_shapes, self._item_objs, b["rot"], b["pos"], _FCL_REQUEST
        res = fcl.CollisionResult()  # one for the call: fcl.collide adds a contact to it per hit, which no one reads
        first_hit = len(valid)
        skip = -1
        for i, a, k in b["scene"][:ns].tolist():
            if i == skip:
                continue
            obj = moving[a].obj_scene
            obj.setRotation(rot[i, a])
            obj.setTranslation(pos[i, a])
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
            oa.setRotation(rot[i, a])
            oa.setTranslation(pos[i, a])
            ob.setRotation(rot[i, c])
            ob.setTranslation(pos[i, c])
            if fcl.collide(oa, ob, req, res):
                valid[i] = False
                if stop_at_first:
                    break

    def _any_hit(self, b: _Buffers, ns: int, npairs: int) -> bool:
        """Whether FCL finds a collision in any of the kernel's ``ns`` scene and ``npairs`` self candidate pairs (of
        whichever states): ``_narrow``'s verdict where only "all valid or not" is asked, without its array, and
        without the self pairs once a scene pair collides."""
        moving, items, rot, pos, req = self._moving_shapes, self._item_objs, b["rot"], b["pos"], _FCL_REQUEST
        res = fcl.CollisionResult()
        for i, a, k in b["scene"][:ns].tolist():
            obj = moving[a].obj_scene
            obj.setRotation(rot[i, a])
            obj.setTranslation(pos[i, a])
            if fcl.collide(obj, items[k], req, res):
                return True
        pairs = self._pairs
        for i, pp in b["self"][:npairs].tolist():
            a, c = pairs[pp]
            oa, ob = moving[a].obj_self, moving[c].obj_self
            oa.setRotation(rot[i, a])
            oa.setTranslation(pos[i, a])
            ob.setRotation(rot[i, c])
            ob.setTranslation(pos[i, c])
            if fcl.collide(oa, ob, req, res):
                return True
        return False

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
            return not (ns or npairs) or not self._any_hit(b, ns, npairs)

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
        return not (ns or npairs) or not self._any_hit(b, ns, npairs)

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
