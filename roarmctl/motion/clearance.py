"""How far the arm is from the scene: the smallest distance between the arm (and what it carries) and the
scene items, at each sample of a motion, by FCL's distance query on the checker's own geometry.

The geometry is the collision checker's (``collision._geometry``: the description's boxes, cylinders,
spheres, capsules and mesh hulls, and the scene items' primitives), *without* the checker's padding: the
number is the true gap, from which the padding was kept. As in the checker, links listed in the
description's ``base_links`` are not measured against items of role "table" (they stand on it). An object
carried at a sample is a moving part at that sample (measured against the other items), not an item.

Cost: per sample, pairs are visited in the order of a cheap lower bound (centre distance minus both
bounding-sphere radii) and the FCL calls stop once that bound exceeds the best distance found, so a
sample costs a few FCL calls, not one per pair.
"""

from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np

from roarmctl.motion.collision import _geometry, _half_extents
from roarmctl.motion.scene import SceneItem
from roarmctl.robot.model import Robot


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


def _radius(kind: str, size=(0.0, 0.0, 0.0), radius: float = 0.0, length: float = 0.0, mesh=None) -> float:
    """Radius (m) of a sphere about the shape's origin that holds the shape."""
    if mesh is not None:
        return float(np.max(np.linalg.norm(mesh.vertices, axis=1)))
    return float(np.linalg.norm(_half_extents(kind, size, radius, length)))


def clearance(robot: Robot, items: list[SceneItem], q: np.ndarray, item_poses: np.ndarray | None = None,
              carried: np.ndarray | None = None) -> Clearance:
    """The arm's clearance from ``items`` along the configurations ``q`` (N, dof), see ``Clearance``.

    ``item_poses`` (N, M, 4, 4): each item's world pose at each sample (default: ``item.pose`` throughout);
    ``carried`` (N, M) bool: the item moves with the hand at that sample (default: none is carried).
    """
    q = np.atleast_2d(np.asarray(q, dtype=float))
    n, m = len(q), len(items)
    if item_poses is None:
        item_poses = np.broadcast_to(np.array([it.pose for it in items]).reshape(1, m, 4, 4), (n, m, 4, 4))
    if carried is None:
        carried = np.zeros((n, m), dtype=bool)
    kin = robot.kin
    shapes = list(robot.collision)
    s = len(shapes)
    frames = kin.link_frames(q)  # (N, L, 4, 4): the library's one FK
    link_of = np.array([kin.link_index[sh.link] for sh in shapes], dtype=int)
    origins = np.array([sh.origin for sh in shapes]).reshape(s, 4, 4)
    shape_pose = frames[:, link_of] @ origins  # (N, S, 4, 4)
    carried_idx = [k for k in range(m) if carried[:, k].any()]
    parts = [sh.name or sh.link for sh in shapes] + [items[k].name for k in carried_idx]

    part_obj = [fcl.CollisionObject(_geometry(sh.kind, sh.size, sh.radius, sh.length, 0.0, sh.mesh)) for sh in shapes]
    item_obj = [fcl.CollisionObject(_geometry(it.shape, it.size, it.radius, it.length)) for it in items]
    part_obj += [fcl.CollisionObject(_geometry(items[k].shape, items[k].size, items[k].radius, items[k].length))
                 for k in carried_idx]
    part_r = np.array([_radius(sh.kind, sh.size, sh.radius, sh.length, sh.mesh) for sh in shapes]
                      + [_radius(items[k].shape, items[k].size, items[k].radius, items[k].length) for k in carried_idx])
    item_r = np.array([_radius(it.shape, it.size, it.radius, it.length) for it in items])
    part_pose = np.concatenate([shape_pose, item_poses[:, carried_idx]], axis=1) if carried_idx else shape_pose

    base = set(robot.base_links)
    skip = np.zeros((len(parts), m), dtype=bool)  # pairs never measured
    for a, sh in enumerate(shapes):
        for k, it in enumerate(items):
            skip[a, k] = it.role == "table" and sh.link in base
    for j, k in enumerate(carried_idx):
        skip[s + j, k] = True

    dist = np.full(n, np.inf)
    best_item = np.full(n, -1, dtype=int)
    best_part = np.full(n, -1, dtype=int)
    if not parts or not m:
        return Clearance(dist, best_item, best_part, parts)
    gap = (np.linalg.norm(part_pose[:, :, None, :3, 3] - item_poses[:, None, :, :3, 3], axis=-1)
           - part_r[None, :, None] - item_r[None, None, :])  # (N, P, M) lower bounds
    request = fcl.DistanceRequest()
    for i in range(n):
        active = ~skip & ~carried[i][None, :]
        if carried_idx:
            active[s:] &= carried[i, carried_idx][:, None]  # a carried part only while it is carried
        cand = np.flatnonzero(active.ravel())
        if not len(cand):
            continue
        order = cand[np.argsort(gap[i].ravel()[cand], kind="stable")]
        best, ba, bk = np.inf, -1, -1
        for k in range(m):
            item_obj[k].setTransform(fcl.Transform(item_poses[i, k, :3, :3], item_poses[i, k, :3, 3]))
        for flat in order:
            a, k = divmod(int(flat), m)
            if gap[i, a, k] >= best:
                break
            part_obj[a].setTransform(fcl.Transform(part_pose[i, a, :3, :3], part_pose[i, a, :3, 3]))
            d = fcl.distance(part_obj[a], item_obj[k], request, fcl.DistanceResult())
            d = max(float(d), 0.0)
            if d < best:
                best, ba, bk = d, a, k
            if best == 0.0:
                break
        dist[i], best_part[i], best_item[i] = best, ba, bk
    return Clearance(dist, best_item, best_part, parts)
