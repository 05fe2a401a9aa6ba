"""The numbers of the browser view: one JSON-able dict that the page's script reads (``roarmctl.view/1``).

Per sample (N after thinning to at most ``MAX_SAMPLES``): time, joint values, the world pose of every link
that carries geometry (from the library's one FK), the TCP position, TCP speed and its colour, the smallest
singular value of the translational Jacobian, the clearance to the nearest scene item (FCL, without the
padding) and the segment kind; the pose of every object while it is carried; and, for a run, the measured
arm (the "ghost"). Geometry (the checker's collision shapes per link, the scene items) is triangles in the
link's or the item's own frame. Large arrays are base64 of little-endian float32 (``_f32``), so a bundled
plan's page stays well under a megabyte of data.

Only numpy and the library here (matplotlib only for the speed colour map, the same as the PNG's).
"""

from __future__ import annotations

import base64
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.export.streams import item_tracks
from roarmctl.formats import PRIMITIVES
from roarmctl.motion.scene import SceneItem
from roarmctl.robot.visuals import visual_shapes
from roarmctl.viz.data import PathData, path_data, robot_for
from roarmctl.viz.shapes import item_extent, item_faces, item_pose, outward, robot_shape_faces, triangles

if TYPE_CHECKING:
    from roarmctl.motion.planning.assembly import PartialPlan
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

FORMAT = "roarmctl.view/1"
MAX_SAMPLES = 4000  # per page; a longer motion is thinned evenly (events, blends and the ends are kept)
COLOR_STOPS = 11  # of the speed colour bar
CONVEX_KINDS = ("box", "cylinder", "sphere", "capsule")  # a robot's collision shapes wound outward (not its meshes)


@dataclass
class Ghost:
    """A second arm drawn beside the commanded one (e.g. the measured joints of a run).

    ``times`` (K,) s on the view's clock, increasing; ``positions`` (K, dof) rad in the robot's joint order.
    """

    label: str
    times: np.ndarray
    positions: np.ndarray
    #: name -> (times (K,) s, positions (K, 3) m, quaternions (K, 4) w-x-y-z): where the run had the scene's
    #: objects (a physics run tracks them), drawn as outlines of the items of those names.
    objects: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: (times (M,) s, TCP errors (M,) m) measured against the plan by the run itself, shown instead of the distance
    #: to the commanded arm (a log viewed without its trajectory: its commands carry the sag offset, not the plan).
    error: tuple[np.ndarray, np.ndarray] | None = None


def _f32(a: np.ndarray) -> str:
    """base64 of the array as little-endian float32, row-major."""
    return base64.b64encode(np.ascontiguousarray(a, dtype="<f4").tobytes()).decode("ascii")


def _pose12(m: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (..., 12): the top three rows, row-major."""
    return np.asarray(m)[..., :3, :4].reshape(*np.shape(m)[:-2], 12)


def _thin(times: np.ndarray, keep: list[int], max_samples: int) -> np.ndarray:
    """Sample indices: every k-th sample so that at most about ``max_samples`` remain, plus ``keep`` and both ends."""
    n = len(times)
    stride = max(1, -(-n // max(max_samples, 2)))
    idx = set(range(0, n, stride)) | {n - 1} | {int(k) for k in keep if 0 <= k < n}
    return np.array(sorted(idx), dtype=int)


def hex_color(rgba: Sequence[float]) -> str:
    """'#rrggbb' of an RGB(A) colour with components in [0, 1] (alpha dropped)."""
    r, g, b = (int(round(255 * float(c))) for c in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def _speed_colors(speed: np.ndarray, vmax: float) -> tuple[np.ndarray, list[str]]:
    """(N, 3) uint8 colours of ``speed`` on the PNG's colour map over [0, vmax], and the colour bar's stops."""
    from matplotlib import colormaps

    from roarmctl.viz.path_figure import PATH_CMAP

    cmap = colormaps[PATH_CMAP]
    rgb = (np.asarray(cmap(np.clip(speed / vmax, 0.0, 1.0)))[:, :3] * 255).round().astype(np.uint8)
    stops = [cmap(x) for x in np.linspace(0.0, 1.0, COLOR_STOPS)]
    return rgb, [hex_color(s) for s in stops]


def _links(robot: Robot) -> tuple[list[int], list[dict[str, Any]], list[str]]:
    """Links that carry geometry: their kinematic indices; per link its collision shapes' triangles (as the
    checker sees them) and its visual shapes' triangles and colours (``robot.visuals``), in the link frame; and
    notes on visuals left out or decimated, first of all that the robot is drawn without visuals when it is."""
    collision: dict[int, list[np.ndarray]] = {}
    names: dict[int, list[str]] = {}
    closed: dict[int, bool] = {}  # every shape of the link convex and wound outward (drawn without back faces)
    for shape in robot.collision:
        k = robot.kin.link_index[shape.link]
        tris = triangles(robot_shape_faces(shape))
        convex = shape.kind in CONVEX_KINDS
        collision.setdefault(k, []).append(outward(tris, np.asarray(shape.origin)[:3, 3]) if convex else tris)
        closed[k] = closed.get(k, True) and convex
        names.setdefault(k, []).append(shape.name or shape.link)
    visuals, notes = visual_shapes(robot)
    if not visuals:  # the page draws what the checker sees: said, so that nobody takes it for the arm's looks
        why = "its description has no visual meshes" if not notes else "none of its visual meshes could be read"
        notes = [f"drawn from its collision shapes: {why}" if robot.collision else
                 f"drawn as lines from joint to joint: {why} and no collision shapes"] + notes
    visual: dict[int, list[dict[str, Any]]] = {}
    for v in visuals:
        k = robot.kin.link_index[v.shape.link]
        visual.setdefault(k, []).append({"triangles": _f32(triangles(robot_shape_faces(v.shape))),
                                         "color": hex_color(v.rgba) if v.rgba is not None else None})
    order = sorted(set(collision) | set(visual))
    links = [{"name": robot.kin.link_names[k], "shapes": names.get(k, []),
              "collision": _f32(np.concatenate(collision[k])) if k in collision else None,
              "closed": closed.get(k, False),
              "visual": visual.get(k, [])} for k in order]
    return order, links, notes


def _item_tracks(traj: Trajectory, robot: Robot, times: np.ndarray) -> tuple[list[dict], np.ndarray, np.ndarray]:
    """The scene items' tracks (``export.streams.item_tracks``: a carried object follows the TCP) at ``times``:
    the items, their poses (N, M, 4, 4) and whether each is carried at each time (N, M)."""
    tracks = item_tracks(traj, robot)
    n = len(times)
    poses = np.zeros((n, len(tracks), 4, 4))
    carried = np.zeros((n, len(tracks)), dtype=bool)
    for k, tr in enumerate(tracks):
        j = np.clip(np.searchsorted(tr.times, times + 1e-9, side="right") - 1, 0, len(tr.times) - 1)
        poses[:, k] = tr.poses[j]
        for a, b in tr.held:
            carried[:, k] |= (times > a + 1e-9) & (times <= b + 1e-9)
    return [tr.item for tr in tracks], poses, carried


def _bounds(data: PathData, link_origins: np.ndarray, items: list[dict], extra: list[np.ndarray]) -> np.ndarray:
    """(2, 3) corners (m) of everything drawn: TCP path, link origins, items, marked targets."""
    pts = [data.tcp, link_origins.reshape(-1, 3)] + [p.reshape(-1, 3) for p in extra]
    pts += [item_extent(it, i) for i, it in enumerate(items) if it.get("role") != "table"]
    allp = np.vstack(pts)
    return np.stack([allp.min(axis=0), allp.max(axis=0)])


def view_document(traj: Trajectory, robot: Robot | None = None, *, name: str = "trajectory",
                  failure: PartialPlan | None = None,
                  ghost: Ghost | None = None, max_samples: int = MAX_SAMPLES, notes: list[str] | None = None) -> dict[str, Any]:
    """Everything the page shows of ``traj`` (see the module doc).

    ``failure``: a ``motion.pipeline.PartialPlan`` (``traj`` is what was planned before it): its target is
    marked and its label named. ``ghost``: a second arm (e.g. measured), interpolated to the samples.
    ``notes``: lines shown under the title (e.g. what a run's log says).
    """
    from roarmctl.motion.clearance import clearance
    from roarmctl.viz.path_figure import EVENT_COLOR, ROLE_STYLE, VIEWS, describe, torque_shares

    robot = robot if robot is not None else robot_for(traj)
    data = path_data(traj, robot)
    times_all = data.times

    def index_at(t: float) -> int:
        return int(np.clip(np.searchsorted(times_all, t - 1e-9), 0, len(times_all) - 1))

    keep = [index_at(e.time) for e in data.events] + [index_at(b) for b in data.blends]
    idx = _thin(times_all, keep, max_samples)
    times = times_all[idx]
    q = data.positions[idx]
    n = len(idx)

    link_ids, links, visual_notes = _links(robot)
    frames = robot.kin.link_frames(q)  # (n, L, 4, 4)
    bone_links = sorted({k for pair in data.arm_segments for k in pair})  # the PNG's stick arm: joint to joint
    bones = [[bone_links.index(a), bone_links.index(b)] for a, b in data.arm_segments]
    items, item_poses, carried = _item_tracks(traj, robot, times)
    scene_items = [SceneItem.from_dict(it) for it in items]
    clear = clearance(robot, scene_items, q, item_poses, carried, per_item=True)
    assert clear.item_distance is not None and clear.item_part is not None and clear.item_points is not None
    intended = intended_contact(traj, times, carried, clear.item_part, len(robot.collision))

    speed = data.tcp_speed[idx]
    vmax = max(float(data.tcp_speed.max()) if len(data.tcp_speed) else 0.0, data.max_tcp_speed or 0.0, 1e-6)
    colors, stops = _speed_colors(speed, vmax)
    seg = np.append(data.segment_kind, data.segment_kind[-1:] if len(data.segment_kind) else [""])[idx]
    seg_kinds = sorted({str(s) for s in seg})

    def sample_of(t: float) -> int:  # index in the thinned samples of the sample nearest at or after t
        return int(np.clip(np.searchsorted(idx, index_at(t)), 0, n - 1))

    events = [{"time": float(e.time), "kind": e.kind, "label": e.label or e.kind, "index": sample_of(e.time),
               "target": [float(v) for v in e.target], "color": EVENT_COLOR.get(e.kind, "#333333")} for e in data.events]
    fail = None
    if failure is not None:
        fail = {"label": str(failure.label), "color": EVENT_COLOR["failed"],
                "target": None if failure.target is None else [float(v) for v in np.asarray(failure.target, dtype=float)]}
    doc_items = []
    for k, it in enumerate(items):
        cloud = it.get("shape") == "cloud"  # occupied cells: drawn as points a cell wide
        faces = item_faces(it, k, local=True)
        moves = bool(carried[:, k].any()) or not np.allclose(item_poses[:, k], item_poses[:1, k])
        style = ROLE_STYLE.get(str(it.get("role")), ROLE_STYLE["obstacle"])
        primitive = it.get("shape") in PRIMITIVES  # convex about its own origin: wound outward, no back faces drawn
        doc_items.append({"name": str(it.get("name", f"item {k}")), "role": str(it.get("role", "obstacle")),
                          "color": hex_color(style["facecolor"]),
                          "triangles": None if cloud else _f32(outward(triangles(faces)) if primitive else triangles(faces)),
                          "closed": primitive,
                          "points": _f32(faces[0]) if cloud else None,
                          "point_size": float(it["resolution"]) if cloud else None,
                          "pose": _pose12(item_pose(it, f"scene.items[{k}]")).tolist(),
                          "track": _f32(_pose12(item_poses[:, k])) if moves else None})

    ghost_doc = None
    extra = [np.array([e["target"] for e in events]).reshape(-1, 3)]
    if fail is not None and fail["target"] is not None:
        extra.append(np.array(fail["target"]))
    if ghost is not None:
        gq = np.column_stack([np.interp(times, ghost.times, ghost.positions[:, j]) for j in range(robot.dof)])
        gframes = robot.kin.link_frames(gq)
        gtcp = gframes[:, robot.kin.tcp_index, :3, 3]
        ghost_doc = {"label": ghost.label, "poses": _f32(_pose12(gframes[:, link_ids])), "q": _f32(gq), "tcp": _f32(gtcp),
                     "error": _f32(np.linalg.norm(gtcp - data.tcp[idx], axis=1) if ghost.error is None
                                   else np.interp(times, *ghost.error)),
                     "error_source": "run" if ghost.error is not None else "plan" if traj.events or traj.scene else "commanded",
                     "span": [float(ghost.times[0]), float(ghost.times[-1])],
                     "items": _ghost_items(ghost, items, times)}
        extra.append(gtcp)
    lo, hi = _bounds(data, frames[:, link_ids + bone_links][..., :3, 3], items, extra)

    title, subtitle = describe(data, name)
    if failure is not None:
        title += f" — PLANNING FAILED at {failure.label}"
    nearest = np.where(np.isfinite(clear.distance), clear.distance, -1.0)
    shares = torque_shares(data)
    return {
        "format": FORMAT,
        "title": title,
        "subtitle": subtitle,
        "notes": list(notes or []) + visual_notes[:3] + ([f"... and {len(visual_notes) - 3} more visuals left out"]
                                                          if len(visual_notes) > 3 else []),
        "robot": robot.name,
        "joint_names": list(traj.joint_names),
        "joint_units": ["m" if robot.joints[_joint_of(robot, j)].kind == "prismatic" else "rad" for j in traj.joint_names],
        "n": n,
        "duration": float(times[-1]) if n else 0.0,
        "times": _f32(times),
        "q": _f32(q),
        "tcp": _f32(data.tcp[idx]),
        "speed": _f32(speed),
        "speed_max": vmax,
        "colors": base64.b64encode(colors.tobytes()).decode("ascii"),
        "color_stops": stops,
        "sigma_min": _f32(data.sigma_min[idx]),
        # (n, dof) N m (N prismatic) by RNEA and as % of each joint's own limit (NaN: no limit), as the PNG draws them
        "torque": None if data.torque is None else _f32(data.torque[idx]),
        "torque_share": None if shares is None else _f32(shares[idx]),
        "clearance": _f32(nearest),
        # (n, M) each item's own distance (m, -1: not measured), its nearest moving part, whether it is intended
        # contact (uint8), each item's closest-point pair (n, M, 6) m, on the moving part first; the plan's padding (m)
        "item_clearance": _f32(np.where(np.isfinite(clear.item_distance), clear.item_distance, -1.0)),
        "item_part": _f32(clear.item_part),
        "intended": base64.b64encode(intended.astype(np.uint8).tobytes()).decode("ascii"),
        "item_points": _f32(clear.item_points.reshape(n, len(items) * 6)),  # NaN: none, or touching
        "padding": _padding(traj),
        "nearest_item": [int(v) for v in clear.item],
        "nearest_part": [int(v) for v in clear.part],
        "parts": clear.parts,
        "segment": [seg_kinds.index(str(s)) for s in seg],
        "segment_kinds": seg_kinds,
        "links": links,
        "poses": _f32(_pose12(frames[:, link_ids])),
        "bones": bones,
        "bone_points": _f32(frames[:, bone_links][..., :3, 3]),
        "tcp_link": robot.tcp_link,
        "items": doc_items,
        "events": events,
        "blends": [{"time": float(b), "index": sample_of(b)} for b in data.blends],
        "failure": fail,
        "limits": {"max_tcp_speed": data.max_tcp_speed, "min_singular_value": data.min_singular_value},
        "ghost": ghost_doc,
        "bounds": [lo.tolist(), hi.tolist()],
        "views": {k: list(v) for k, v in VIEWS.items()},  # the PNG's views: elevation, azimuth (deg)
        # each target the plan names (the trajectory's table) with its miss: where the TCP came closest, when
        "targets": [{"name": str(t.get("name", "")), "kind": str(t.get("kind", "")),
                     "position": [float(v) for v in t["position"]], "distance": float(t["distance"]),
                     "zone": float(t.get("zone", 0.0)), "reached": bool(t.get("reached", True)),
                     "time": float(t["time"]), "index": sample_of(float(t["time"])),
                     "closest": [float(v) for v in data.tcp[index_at(float(t["time"]))]]} for t in data.targets],
    }


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (K, 3, 3) of unit quaternions (K, 4) in w, x, y, z order."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)


def _ghost_items(ghost: Ghost, items: list[dict], times: np.ndarray) -> list[dict[str, Any]]:
    """The run's objects at ``times``: for each tracked name that is a scene item, its index and poses (N, 12);
    positions interpolated, the orientation of the last track sample at or before each time."""
    out = []
    names = [str(it.get("name")) for it in items]
    for name, (t, xyz, quat) in ghost.objects.items():
        if name not in names or len(t) == 0:
            continue
        pose = np.zeros((len(times), 3, 4))
        pose[:, :, 3] = np.column_stack([np.interp(times, t, xyz[:, k]) for k in range(3)])
        j = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 1)
        pose[:, :, :3] = _quat_matrix(quat)[j]
        out.append({"item": names.index(name), "track": _f32(pose.reshape(len(times), 12))})
    return out


def _padding(traj: Trajectory) -> float | None:
    """The padding (m) the plan kept from the scene, when the trajectory records it."""
    pad = (traj.plan or {}).get("padding")
    return float(pad) if isinstance(pad, (int, float)) and np.isfinite(pad) and pad >= 0 else None


def intended_contact(traj: Trajectory, times: np.ndarray, carried: np.ndarray, item_part: np.ndarray,
                     n_shapes: int) -> np.ndarray:
    """(N, M) bool: where an item's distance is contact the plan means, not a near miss. Around each grasp and
    release (the run of non-free segments that holds it: descent, gripper, lift), the object it takes or leaves
    (the item carried just after a grasp or just before a release) against the arm, and whatever the carried
    object rests on (an item whose nearest moving part is that object). ``times`` (N,) s of the samples,
    ``carried`` (N, M), ``item_part`` (N, M) from ``motion.clearance`` (parts from ``n_shapes`` on are carried items)."""
    n, m = carried.shape
    out = np.zeros((n, m), dtype=bool)
    spans = sorted((float(sg.start), float(sg.end), sg.kind) for sg in traj.segments)
    for e in traj.events:
        if e.kind not in ("grasp", "release"):
            continue
        lo = hi = float(e.time)
        grown = True
        while grown:  # widen over the non-free segments that touch the window, until none does
            grown = False
            for start, end, kind in spans:
                if kind != "free" and start <= hi + 1e-6 and end >= lo - 1e-6 and (start < lo or end > hi):
                    lo, hi, grown = min(lo, start), max(hi, end), True
        inside = (times >= lo - 1e-9) & (times <= hi + 1e-9)
        k_at = int(np.clip(np.searchsorted(times, e.time + (1e-6 if e.kind == "grasp" else -1e-6)), 0, n - 1))
        held = np.flatnonzero(carried[min(k_at + 1, n - 1)] if e.kind == "grasp" else carried[max(k_at, 0)])
        for k in held:
            out[inside, k] = True
            # the carried object's own parts follow the robot's shapes: what it rests on is intended too
            on_it = item_part[inside] >= n_shapes
            out[np.flatnonzero(inside)[:, None].repeat(m, 1)[on_it], np.nonzero(on_it)[1]] = True
    return out


def _joint_of(robot: Robot, name: str) -> int:
    """Index in ``robot.joints`` of the actuated joint ``name``."""
    return next(i for i, j in enumerate(robot.joints) if j.name == name)
