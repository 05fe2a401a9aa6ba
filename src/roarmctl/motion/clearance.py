"""How far the arm is from the scene: the smallest distance between the arm (and what it carries) and the
scene items, at each sample of a motion, by FCL's distance query on the checker's own geometry.

The geometry is the collision checker's: the description's boxes, cylinders, spheres, capsules and mesh hulls
(``geometry.fcl_geometry``) and each scene item's collision parts (``geometry.item_parts``: a primitive, a
mesh's convex pieces or triangles, a point cloud's octree blocks), *without* the checker's padding: the number
is the true gap, from which the padding was kept. As in the checker, links listed in the description's
``base_links`` are not measured against items of role "table" (they stand on it). An object carried at a
sample is a moving part at that sample (measured against the other items), not an item.

Cost: per sample, pairs are visited in the order of a cheap lower bound (centre distance minus both
bounding-sphere radii) and the FCL calls stop once that bound exceeds the best distance found, so a
sample costs a few FCL calls, not one per pair.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import fcl
import numpy as np

from roarmctl.motion.geometry import fcl_geometry, half_extents, item_parts
from roarmctl.motion.scene import SceneItem
from roarmctl.robot.model import Robot

if TYPE_CHECKING:
    from roarmctl.robot.model import CollisionShape


@dataclass
class Clearance:
    """Per sample (N,): ``distance`` m (0 where touching or overlapping, ``inf`` where nothing is measured),
    ``item`` index into the items (-1: none), ``part`` index into ``parts`` (-1: none). ``parts``: the
    names of the moving parts, the robot's collision shapes first (``shape.name`` or its link), then the
    items carried at some sample (their item names)."""

    distance: np.ndarray
    item: np.ndarray
    part: np.ndarray
    parts: list[str]
    #: with ``per_item``: (N, M) m each item's own smallest distance (``inf``: not measured at that sample), the
    #: moving part nearest each item (N, M) (-1: none), each item's closest-point pair (N, M, 2, 3) m in the world,
    #: on the moving part first, and the nearest item's pair (N, 2, 3) (NaN where nothing is measured or the pair
    #: touches: FCL's points are no pair of closest points then)
    item_distance: np.ndarray | None = None
    item_part: np.ndarray | None = None
    points: np.ndarray | None = None
    item_points: np.ndarray | None = None


@dataclass
class _Solid:
    """One FCL object of an item or a robot shape: ``rel`` (4, 4) its pose in the item's (link's) frame, ``centre``
    (3,) the centre of its bounding sphere in that frame, ``radius`` m, ``owner`` the item index (or moving part)."""

    obj: fcl.CollisionObject
    rel: np.ndarray
    centre: np.ndarray
    radius: float
    owner: int


def _pose(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot, pos
    return m


def _item_solids(item: SceneItem, owner: int) -> list[_Solid]:
    """An item's collision parts, each placed relative to the item's own pose."""
    inv = np.linalg.inv(item.pose)
    out = []
    for p in item_parts(item):
        rel = inv @ _pose(p.obj.getRotation(), p.obj.getTranslation())
        out.append(_Solid(p.obj, rel, (inv @ np.append(p.centre, 1.0))[:3], float(np.linalg.norm(p.half)), owner))
    return out


def _shape_radius(shape: CollisionShape) -> float:
    """Radius (m) of a sphere about the shape's origin that holds the shape."""
    if shape.mesh is not None:
        return float(np.max(np.linalg.norm(shape.mesh.vertices, axis=1)))
    return float(np.linalg.norm(half_extents(shape.kind, shape.size, shape.radius, shape.length)))


def clearance(robot: Robot, items: list[SceneItem], q: np.ndarray, item_poses: np.ndarray | None = None,
              carried: np.ndarray | None = None, per_item: bool = False) -> Clearance:
    """The arm's clearance from ``items`` along the configurations ``q`` (N, dof), see ``Clearance``.

    ``item_poses`` (N, M, 4, 4): each item's world pose at each sample (default: ``item.pose`` throughout);
    ``carried`` (N, M) bool: the item moves with the hand at that sample (default: none is carried).
    ``per_item``: also every item's own distance and the nearest pair's closest points (more FCL calls: the
    search stops per item, not at the first item).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, m = len(q), len(items)
    if item_poses is None:
        item_poses = np.broadcast_to(np.array([it.pose for it in items]).reshape(1, m, 4, 4), (n, m, 4, 4))
    if carried is None:
        carried = np.zeros((n, m), dtype=bool)
    kin = robot.kin
    shapes = list(robot.collision)
    frames = kin.link_frames(q)  # (N, L, 4, 4): the library's one FK
    carried_idx = [k for k in range(m) if carried[:, k].any()]
    parts = [sh.name or sh.link for sh in shapes] + [items[k].name for k in carried_idx]

    # moving solids: a robot shape rides its link; a carried item's parts ride the item's pose
    moving = [_Solid(fcl.CollisionObject(fcl_geometry(sh.kind, sh.size, sh.radius, sh.length, 0.0, sh.mesh)),
                     np.asarray(sh.origin, dtype=float), np.asarray(sh.origin, dtype=float)[:3, 3], _shape_radius(sh), a)
              for a, sh in enumerate(shapes)]
    moving_frame = [kin.link_index[sh.link] for sh in shapes]  # -1 - k: carried item k
    for j, k in enumerate(carried_idx):
        for solid in _item_solids(items[k], len(shapes) + j):  # objects of their own, apart from the fixed ones
            moving.append(solid)
            moving_frame.append(-1 - k)
    fixed = [s for k, it in enumerate(items) for s in _item_solids(it, k)]

    dist = np.full(n, np.inf)
    best_item = np.full(n, -1, dtype=int)
    best_part = np.full(n, -1, dtype=int)
    each = np.full((n, m), np.inf) if per_item else None
    each_part = np.full((n, m), -1, dtype=int) if per_item else None
    points = np.full((n, 2, 3), np.nan) if per_item else None
    each_points = np.full((n, m, 2, 3), np.nan) if per_item else None
    if not moving or not fixed:
        return Clearance(dist, best_item, best_part, parts, each, each_part, points, each_points)
    base = set(robot.base_links)
    owner_m = np.array([s.owner for s in moving])
    owner_f = np.array([s.owner for s in fixed])
    skip = np.zeros((len(moving), len(fixed)), dtype=bool)  # pairs never measured
    for a, s in enumerate(moving):
        if s.owner < len(shapes):
            skip[a] = [shapes[s.owner].link in base and items[k].role == "table" for k in owner_f]
        else:
            skip[a] = owner_f == carried_idx[s.owner - len(shapes)]

    # world poses of every solid at every sample, and the lower bounds of every pair
    mframe = np.stack([frames[:, f] if f >= 0 else item_poses[:, -1 - f] for f in moving_frame], axis=1)  # (N, A, 4, 4)
    mpose = mframe @ np.array([s.rel for s in moving])
    mcentre = np.einsum("naij,aj->nai", mframe[..., :3, :], np.array([np.append(s.centre, 1.0) for s in moving]))
    fpose = item_poses[:, owner_f] @ np.array([s.rel for s in fixed])
    fcentre = np.einsum("nbij,bj->nbi", item_poses[:, owner_f, :3, :], np.array([np.append(s.centre, 1.0) for s in fixed]))
    gap = (np.linalg.norm(mcentre[:, :, None] - fcentre[:, None], axis=-1)
           - np.array([s.radius for s in moving])[None, :, None] - np.array([s.radius for s in fixed])[None, None, :])
    nf = len(fixed)
    request = fcl.DistanceRequest(enable_nearest_points=per_item)
    for i in range(n):
        active = ~skip & ~carried[i][owner_f][None, :]
        for a in range(len(moving)):  # a carried item's parts are moving parts only while it is carried
            if owner_m[a] >= len(shapes) and not carried[i, carried_idx[owner_m[a] - len(shapes)]]:
                active[a] = False
        cand = np.flatnonzero(active.ravel())
        if not len(cand):
            continue
        order = cand[np.argsort(gap[i].ravel()[cand], kind="stable")]
        if per_item:
            assert each is not None and each_part is not None and points is not None and each_points is not None
            _per_item_sample(i, order, nf, gap, moving, fixed, mpose, fpose, owner_m, owner_f, request, each[i],
                             each_part[i], each_points[i])
            k = int(np.argmin(each[i]))
            if np.isfinite(each[i, k]):
                dist[i], best_part[i], best_item[i] = each[i, k], each_part[i, k], k
                points[i] = each_points[i, k]
            continue
        best, ba, bk = np.inf, -1, -1
        for flat in order:
            a, b = divmod(int(flat), nf)
            if gap[i, a, b] >= best:
                break
            moving[a].obj.setTransform(fcl.Transform(mpose[i, a, :3, :3], mpose[i, a, :3, 3]))
            fixed[b].obj.setTransform(fcl.Transform(fpose[i, b, :3, :3], fpose[i, b, :3, 3]))
            d = max(float(fcl.distance(moving[a].obj, fixed[b].obj, request, fcl.DistanceResult())), 0.0)
            if d < best:
                best, ba, bk = d, int(owner_m[a]), int(owner_f[b])
            if best == 0.0:
                break
        dist[i], best_part[i], best_item[i] = best, ba, bk
    return Clearance(dist, best_item, best_part, parts, each, each_part, points, each_points)


def _per_item_sample(i: int, order: np.ndarray, nf: int, gap: np.ndarray, moving: list[_Solid], fixed: list[_Solid],
                     mpose: np.ndarray, fpose: np.ndarray, owner_m: np.ndarray, owner_f: np.ndarray,
                     request: fcl.DistanceRequest, each: np.ndarray, each_part: np.ndarray, points: np.ndarray) -> None:
    """Sample ``i``'s smallest distance per item into ``each`` (M,) and ``each_part`` (M,), and each item's closest
    points into ``points`` (M, 2, 3): per item its pairs in ``order`` (by their lower bound), stopping once the bound
    reaches that item's best (a point cloud's thousands of blocks cost a few FCL calls, not a Python step each)."""
    bounds = gap[i].ravel()[order]
    owners = owner_f[order % nf]
    for k in np.unique(owners):
        mine = owners == k
        for flat, bound in zip(order[mine], bounds[mine]):
            if bound >= each[k]:
                break
            a, b = divmod(int(flat), nf)
            moving[a].obj.setTransform(fcl.Transform(mpose[i, a, :3, :3], mpose[i, a, :3, 3]))
            fixed[b].obj.setTransform(fcl.Transform(fpose[i, b, :3, :3], fpose[i, b, :3, 3]))
            result = fcl.DistanceResult()
            d = max(float(fcl.distance(moving[a].obj, fixed[b].obj, request, result)), 0.0)
            if d < each[k]:  # touching or overlapping: FCL's points are not a pair of closest points then
                each[k], each_part[k] = d, int(owner_m[a])
                points[k] = np.asarray(result.nearest_points, dtype=float) if d > 0 else np.nan
            if d == 0.0:
                break
