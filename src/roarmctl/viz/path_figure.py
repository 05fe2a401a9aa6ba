"""Draw a trajectory on one sheet: 3D scene and TCP path, joint curves, TCP speed, manipulability.

Importing this module imports matplotlib (object-oriented API with the Agg canvas, no pyplot and no
global backend switch), so only the ``visualize-path`` command imports it. The numbers come from
``roarmctl.viz.data.path_data``; every drawn artist that carries data has a ``gid`` so tests can
find it (``tcp_path``, ``arm:<kind>:<i>``, ``event:<kind>:<axes>``, ``vlim:<joint>``, ...).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FormatStrFormatter
from mpl_toolkits.mplot3d import proj3d
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from roarmctl.fileio import atomic_write_with
from roarmctl.viz.data import GRASP_RADIUS, EventMark, PathData, path_data, robot_for
from roarmctl.viz.formats import picture_format
from roarmctl.viz.shapes import item_extent, item_faces

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.gridspec import GridSpec
    from mpl_toolkits.mplot3d import Axes3D

    from roarmctl.motion.planning.assembly import PartialPlan
    from roarmctl.motion.trajectory import Trajectory

VIEWS = {"iso": (26.0, -38.0), "top": (90.0, -90.0), "front": (0.0, 0.0), "side": (0.0, -90.0)}
ROLE_STYLE: dict[str, dict[str, Any]] = {
    "table": dict(facecolor=(0.80, 0.72, 0.60, 0.35), edgecolor=(0.55, 0.45, 0.35, 0.5), linewidth=0.4),
    "obstacle": dict(facecolor=(0.85, 0.20, 0.15, 0.22), edgecolor=(0.65, 0.10, 0.08, 0.8), linewidth=0.7),
    "object": dict(facecolor=(0.15, 0.45, 0.85, 0.55), edgecolor=(0.05, 0.25, 0.60, 0.9), linewidth=0.7),
}
RC: dict[Any, Any] = {"grid.linewidth": 0.5, "grid.color": "0.88", "axes3d.grid": True}
EVENT_COLOR = {"grasp": "#1b9e3a", "release": "#8e44ad", "failed": "#d62728"}
EVENT_MARKER = {"grasp": "v", "release": "^", "failed": "X"}
PLACED_STYLE = dict(facecolor=(0.15, 0.45, 0.85, 0.10), edgecolor=(0.05, 0.25, 0.60, 0.8), linewidth=0.8, linestyle="--")
ARM_COLOR = "0.35"
PATH_CMAP = "viridis"
LABEL_BOX = dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.75)


@dataclass
class Label:
    """A text tag for a 3D point (m); placed in 2D by ``place_labels`` so tags do not overlap."""

    anchor: np.ndarray
    text: str
    color: object
    size: float
    weight: str
    priority: int = 1


def place_labels(ax: Axes3D, labels: list[Label]) -> list[tuple[float, float]]:
    """Put each label near its projected anchor without overlapping the ones already placed.

    Works in points on the axes' 2D projection of the final view; candidate offsets go up first,
    then sideways and down; a thin leader line joins a moved label to its anchor. Returns the
    label positions (axes fraction) for tests.
    """
    fig = ax.figure
    to_pt = 72.0 / fig.dpi
    proj = ax.get_proj()
    placed: list[tuple[float, float, float, float]] = []  # x0, y0, x1, y1 in points
    out = []
    offsets = [(0, 12), (0, 26), (0, 40), (48, 12), (-48, 12), (48, 30), (-48, 30), (0, -22), (60, -10), (-60, -10), (0, 56)]
    for lab in sorted(labels, key=lambda lb: lb.priority):
        x2, y2, _ = proj3d.proj_transform(*lab.anchor, proj)
        ax_pt = np.array(ax.transData.transform((x2, y2))) * to_pt
        w, h = 0.62 * lab.size * max(len(lab.text), 1) + 4, 1.45 * lab.size + 2
        for dx, dy in offsets:
            cx, cy = ax_pt[0] + dx, ax_pt[1] + dy + h / 2
            box = (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)
            if not any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
                break
        placed.append(box)
        pos = ax.transAxes.inverted().transform((cx / to_pt, cy / to_pt))
        anchor = ax.transAxes.inverted().transform(ax_pt / to_pt)
        if (dx, dy) != offsets[0]:
            ax.plot(*np.transpose([anchor, pos]), transform=ax.transAxes, color=lab.color, lw=0.6, alpha=0.8, zorder=9)
        ax.text2D(pos[0], pos[1], lab.text, transform=ax.transAxes, fontsize=lab.size, color=lab.color,
                  fontweight=lab.weight, ha="center", va="center", zorder=10, bbox=LABEL_BOX, gid=f"label:{lab.text}")
        out.append((float(pos[0]), float(pos[1])))
    return out


MAX_CLOUD_MARKS = 20_000  # points drawn of a cloud item (every n-th cell beyond)


def _add_solid(ax: Axes3D, item: dict, index: int, zorder: int, gid: str, style: dict) -> None:
    """One scene item as translucent faces; curved sides without edges (only the cap rims are outlined)."""
    faces = item_faces(item, index)
    if item.get("shape") == "cloud":  # its occupied cells as small squares, at most MAX_CLOUD_MARKS of them
        pts = faces[0][:: max(1, -(-len(faces[0]) // MAX_CLOUD_MARKS))]
        marks = ax.scatter(pts[:, 0], pts[:, 1], pts[:, 2], s=2.0, marker="s", color=style["edgecolor"],
                           alpha=0.6, linewidths=0, depthshade=False, zorder=zorder)
        marks.set_gid(gid)
        return
    if item.get("shape") in ("box", "mesh"):
        poly = Poly3DCollection(faces, zorder=zorder, **style)
    else:
        plain = dict(style, linewidth=0.0, edgecolor="none")
        poly = Poly3DCollection(faces, zorder=zorder, **plain)
        if item.get("shape") == "cylinder":
            rims = [np.vstack([f, f[:1]]) for f in faces[-2:]]
            ax.add_collection3d(Line3DCollection(rims, colors=[style["edgecolor"]], linewidths=style["linewidth"],
                                                 linestyles=style.get("linestyle", "-"), zorder=zorder))
    poly.set_gid(gid)
    ax.add_collection3d(poly)


def _bounds(data: PathData) -> np.ndarray:
    """(2, 3) axis-aligned bounds of everything drawn in 3D, with a margin."""
    pts = [data.tcp] + [k.links for k in data.key_poses] + [e.target[None] for e in data.events]
    pts += [item_extent(item, i) for i, item in enumerate(data.scene_items + data.placed_items)]
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = 0.04 * max(float(np.max(hi - lo)), 1e-3)
    return np.stack([lo - pad, hi + pad])


def _draw_targets(ax: Axes3D, data: PathData, labels: list[Label]) -> None:
    """Each target the plan names (the trajectory's table): a cross at it, a line from it to the TCP at its closest
    sample, and its miss in mm (red when outside its zone; ``zone`` shown when it has one)."""
    for k, row in enumerate(data.targets):
        p = np.asarray(row["position"], dtype=float)
        i = int(np.clip(np.searchsorted(data.times, row["time"] - 1e-9), 0, len(data.tcp) - 1))
        color = "#2ca02c" if row["reached"] else "#d62728"
        ax.scatter(*p, s=46, marker="+", color=color, linewidth=1.4, depthshade=False, zorder=9, gid=f"miss:{k}")
        ax.plot(*np.transpose([p, data.tcp[i]]), color=color, lw=1.0, zorder=9, gid=f"missline:{k}")
        text = f"{row['distance'] * 1e3:.1f} mm" + (f" (zone {row['zone'] * 1e3:.0f})" if row["zone"] > 0 else "")
        labels.append(Label(p, text, color, 7.0, "normal", priority=2))


def _segments(points: np.ndarray) -> np.ndarray:
    return np.stack([points[:-1], points[1:]], axis=1)


def draw_scene_3d(ax: Axes3D, data: PathData, view: str) -> tuple[Normalize, Colormap]:
    """The 3D panel: scene items, arm at key moments, TCP path coloured by speed, targets; returns the speed
    colouring (norm, colormap) for the colour bar."""
    ax.computed_zorder = False  # draw in our order: scene, arm, path, markers (path stays visible)
    ax.set_proj_type("ortho")
    labels: list[Label] = []
    grasped = [e.target for e in data.events if e.kind == "grasp"]
    for i, item in enumerate(data.scene_items):
        role = item.get("role", "obstacle")
        style = ROLE_STYLE.get(role, ROLE_STYLE["obstacle"])
        _add_solid(ax, item, i, {"table": 0, "obstacle": 2, "object": 3}.get(role, 2), f"scene:{item.get('name', i)}", style)
        center = np.asarray(item.get("xyz", (0, 0, 0)), dtype=float)
        named_by_event = role == "object" and any(np.linalg.norm(center - g) <= GRASP_RADIUS for g in grasped)
        if role != "table" and not named_by_event:
            lo, hi = item_extent(item, i)
            labels.append(Label(np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2]]), str(item.get("name", "")),
                                style["edgecolor"], 7.5, "normal"))

    for i, item in enumerate(data.placed_items):  # where carried objects end up: a dashed ghost
        _add_solid(ax, item, i, 3, f"placed:{item.get('name', i)}", PLACED_STYLE)

    # Arm at key moments: links as light lines, joints as dots.
    for k, pose in enumerate(data.key_poses):
        segs = np.array([[pose.links[a], pose.links[b]] for a, b in data.arm_segments])
        alpha = 0.55 if pose.kind in ("grasp", "release") else 0.38
        coll = Line3DCollection(segs, colors=ARM_COLOR, linewidths=3.2, alpha=alpha, zorder=4, capstyle="round")
        coll.set_gid(f"arm:{pose.kind}:{k}")
        ax.add_collection3d(coll)
        joints = np.unique(segs.reshape(-1, 3), axis=0)
        ax.scatter(*joints.T, s=6, color=ARM_COLOR, alpha=alpha, depthshade=False, zorder=4)

    # TCP path: one segment per sample interval, coloured by the mean speed, thick where Cartesian.
    speed_mid = 0.5 * (data.tcp_speed[1:] + data.tcp_speed[:-1])
    vmax = max(float(data.tcp_speed.max()), data.max_tcp_speed or 0.0, 1e-6)
    norm = Normalize(0.0, vmax)
    cmap = colormaps[PATH_CMAP]
    widths = np.where(data.segment_kind == "cartesian", 4.0, 1.8)
    path = Line3DCollection(_segments(data.tcp), colors=cmap(norm(speed_mid)), linewidths=widths, zorder=6, capstyle="round")
    path.set_gid("tcp_path")
    if len(data.tcp) > 1:  # a single sample is only a start/end marker
        ax.add_collection3d(path)

    if data.blends:  # where one segment flows into the next without stopping
        at = np.clip(np.searchsorted(data.times, data.blends), 0, len(data.times) - 1)
        ax.scatter(*data.tcp[at].T, s=28, marker="D", color="#ff7f0e", edgecolor="k", linewidth=0.4, depthshade=False,
                   zorder=8, gid="blend3d")
    ax.scatter(*data.tcp[0], s=130, marker="o", color="#2ca02c", edgecolor="k", linewidth=0.6, depthshade=False, zorder=8, label="start")
    ax.scatter(*data.tcp[-1], s=40, marker="s", color="#d62728", edgecolor="k", linewidth=0.6, depthshade=False, zorder=8, label="end")
    for e in data.events:
        c = EVENT_COLOR.get(e.kind, "k")
        m = ax.scatter(*e.target, s=110, marker=EVENT_MARKER.get(e.kind, "x"), color=c, edgecolor="k", linewidth=0.6,
                       depthshade=False, zorder=8)
        m.set_gid(f"target:{e.kind}")
        labels.append(Label(e.target, e.label or e.kind, c, 8.5, "bold", priority=0))

    _draw_targets(ax, data, labels)

    lo, hi = _bounds(data)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(tuple(hi - lo), zoom=1.0)
    elev, azim = VIEWS[view]
    ax.view_init(elev=elev, azim=azim)
    ax.set_xlabel("x (m)", labelpad=6)
    ax.set_ylabel("y (m)", labelpad=6)
    ax.set_zlabel("z (m)", labelpad=4)
    ax.tick_params(labelsize=7, pad=1)
    if view == "top":
        ax.set_zticks([])
        ax.set_zlabel("")
    elif view == "front":
        ax.set_xticks([])
        ax.set_xlabel("")
    elif view == "side":
        ax.set_yticks([])
        ax.set_ylabel("")
    for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
        axis.pane.set_alpha(0.0)
    place_labels(ax, labels)
    if view == "iso":  # z ticks on the left edge, away from the time plots; the label would not follow
        ax.zaxis.set_ticks_position("lower")
        ax.set_zlabel("")
    ax.set_title("scene and TCP path (m)", fontsize=9, loc="center", pad=0)

    handles = [
        Line2D([], [], color=cmap(0.55), lw=4.0, label="Cartesian (straight) segment"),
        Line2D([], [], color=cmap(0.55), lw=1.8, label="free motion"),
        Line2D([], [], color=ARM_COLOR, lw=3.2, alpha=0.5, label="arm at start, grasp, release, end"),
        Line2D([], [], ls="", marker="o", color="#2ca02c", mec="k", label="start"),
        Line2D([], [], ls="", marker="s", color="#d62728", mec="k", label="end"),
    ]
    if data.blends:
        handles.append(Line2D([], [], ls="", marker="D", color="#ff7f0e", mec="k", ms=5, label="blended join (no stop)"))
    if data.targets:
        handles.append(Line2D([], [], ls="", marker="+", color="#2ca02c", mew=1.4, label="target: miss (mm)"))
    for kind in dict.fromkeys(e.kind for e in data.events):
        handles.append(Line2D([], [], ls="", marker=EVENT_MARKER.get(kind, "x"), color=EVENT_COLOR.get(kind, "k"),
                              mec="k", ms=8, label=f"{kind} target"))
    ax.legend(handles=handles, loc="upper left", fontsize=7.5, framealpha=0.85, bbox_to_anchor=(0.0, 1.0))
    return norm, cmap


def _event_lines(ax: Axes, data: PathData, name: str, labels: bool = False) -> None:
    for e in data.events:
        line = ax.axvline(e.time, color=EVENT_COLOR.get(e.kind, "k"), lw=1.0, ls="-.", alpha=0.9, zorder=1)
        line.set_gid(f"event:{e.kind}:{name}")
        if labels:
            ax.annotate(e.label or e.kind, (e.time, 1.0), xycoords=("data", "axes fraction"), xytext=(2, 2),
                        textcoords="offset points", fontsize=7.5, color=EVENT_COLOR.get(e.kind, "k"), va="bottom")


def _shade_cartesian(ax: Axes, data: PathData) -> None:
    kinds = data.segment_kind
    t = data.times
    i = 0
    while i < len(kinds):
        if kinds[i] == "cartesian":
            j = i
            while j + 1 < len(kinds) and kinds[j + 1] == "cartesian":
                j += 1
            ax.axvspan(t[i], t[j + 1], color="0.5", alpha=0.10, lw=0, zorder=0)
            i = j + 1
        else:
            i += 1


def _blend_lines(ax: Axes, data: PathData, name: str) -> None:
    for tb in data.blends:
        ax.axvline(tb, color="#ff7f0e", lw=0.9, ls=":", alpha=0.9, zorder=1, gid=f"blend:{name}")


def _axis_for(ax: Axes, data: PathData, j: int, twins: dict, label: str) -> Axes:
    """The axes joint ``j`` is drawn on: ``ax`` for a revolute joint, a twin axis on the right (made once,
    labelled ``label``) for a prismatic one (metres and radians do not share a scale)."""
    if data.prismatic is None or not data.prismatic[j]:
        return ax
    if ax not in twins:
        tw = ax.twinx()
        tw.set_ylabel(label, fontsize=8)
        tw.tick_params(labelsize=7)
        twins[ax] = tw
    return twins[ax]


def torque_shares(data: PathData) -> np.ndarray | None:
    """(N, dof) each joint's torque (force for a prismatic joint) as a share of its own limit, in %; NaN for a joint
    without a finite limit; None without inertial data. One scale for joints whose limits differ (an xArm6's 50 and
    20 N m): a joint at 18 of 50 N m reads 36 %, never 90 % beside another joint's line."""
    if data.torque is None:
        return None
    lim = np.full(data.torque.shape[1], np.inf) if data.torque_limit is None else np.asarray(data.torque_limit, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = 100.0 * data.torque / np.where(np.isfinite(lim) & (lim > 0), lim, np.nan)
    return share


def _draw_torque(ax: Axes, data: PathData) -> None:
    """Joint torques by RNEA (held objects included), each as a share of its own limit (%, the limit dashed at
    +-100 %); a joint without a limit in N m (N when prismatic) on a twin axis, dash-dotted."""
    colors = colormaps["tab10"]
    share = torque_shares(data)
    if data.torque is None or share is None:
        ax.set_ylabel("torque\n(N m)")
        ax.text(0.5, 0.5, "no inertial data in the robot description", transform=ax.transAxes, ha="center", va="center",
                fontsize=8, color="0.4")
        return
    limited = [j for j in range(len(data.joint_names)) if np.all(np.isfinite(share[:, j]))]
    if limited:
        ax.set_ylabel("torque\n(% of limit)")
        top = max(float(np.max(np.abs(share[:, limited]))), 100.0)
        for sign in (1, -1):
            ax.axhline(sign * 100.0, color="0.3", lw=0.9, ls="--", alpha=0.75, gid="taulim")
        ax.set_ylim(-top * 1.08, top * 1.08)
    else:
        ax.set_ylabel("torque\n(N m)")
    twin = None
    for j, name in enumerate(data.joint_names):
        c = colors(j % 10)
        if j in limited:
            ax.plot(data.times, share[:, j], color=c, lw=1.1, gid=f"tau:{name}")
            continue
        target = ax
        if limited or (data.prismatic is not None and data.prismatic[j]):
            if twin is None:
                twin = ax.twinx()
                twin.set_ylabel("no limit:\nN m (N prismatic)", fontsize=8)
                twin.tick_params(labelsize=7)
            target = twin
        target.plot(data.times, data.torque[:, j], color=c, lw=1.1, ls="-." if target is twin else "-", gid=f"tau:{name}")
    title = "each joint's torque as a share of its own limit (dashed)" if limited else "joint torque (no limits given)"
    ax.set_title(title + "; dotted orange: blended joins", fontsize=8, loc="right", pad=2)


def draw_time_plots(axes: Sequence[Axes], data: PathData) -> None:
    """Joint position/velocity/acceleration, joint torque, TCP speed, manipulability against time (shared x)."""
    ax_q, ax_v, ax_a, ax_t, ax_s, ax_m = axes
    colors = colormaps["tab10"]
    t = data.times
    twins: dict = {}  # prismatic joints (m, m/s, m/s^2) on a twin axis of each panel, drawn dash-dotted
    for j, name in enumerate(data.joint_names):
        c = colors(j % 10)
        ls = "-." if data.prismatic is not None and data.prismatic[j] else "-"
        aq = _axis_for(ax_q, data, j, twins, "position (m),\nprismatic")
        av = _axis_for(ax_v, data, j, twins, "velocity (m/s),\nprismatic")
        aa = _axis_for(ax_a, data, j, twins, "acceleration\n(m/s²), prismatic")
        aq.plot(t, data.positions[:, j], color=c, lw=1.3, ls=ls, label=name if aq is ax_q else f"{name} (m, right axis)",
                gid=f"q:{name}")
        av.plot(t, data.velocities[:, j], color=c, lw=1.3, ls=ls, gid=f"v:{name}")
        aa.plot(t, data.accelerations[:, j], color=c, lw=1.1, ls=ls, gid=f"a:{name}")
        for ax, lim, tag in ((av, data.velocity_limit[j], "vlim"), (aa, data.acceleration_limit[j], "alim")):
            for sign in (1, -1):
                ax.axhline(sign * lim, color=c, lw=0.9, ls="--", alpha=0.75, gid=f"{tag}:{name}")
    src = "" if data.limits_source == "trajectory" else " (robot's limits: the file has none)"
    ax_q.set_ylabel("position\n(rad)")
    ax_v.set_ylabel("velocity\n(rad/s)")
    ax_a.set_ylabel("acceleration\n(rad/s²)")
    ax_v.set_title(f"dashed: velocity limit × {data.velocity_scale:g}{src}", fontsize=8, loc="right", pad=2)
    ax_a.set_title(f"dashed: acceleration limit × {data.acceleration_scale:g}", fontsize=8, loc="right", pad=2)

    handles, _ = ax_q.get_legend_handles_labels()
    if ax_q in twins:
        handles += twins[ax_q].get_legend_handles_labels()[0]
    handles.append(Patch(color="0.5", alpha=0.2, label="Cartesian segment (band)"))
    ax_q.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.13), ncol=4, fontsize=7.5, frameon=False,
                handlelength=1.5, columnspacing=1.0, borderaxespad=0.0)

    _draw_torque(ax_t, data)
    ax_s.plot(t, data.tcp_speed, color="k", lw=1.3, gid="tcp_speed")
    ax_s.set_ylabel("TCP speed\n(m/s)")
    if data.max_tcp_speed is not None:
        ax_s.axhline(data.max_tcp_speed, color="#d62728", lw=1.0, ls="--", gid="max_tcp_speed")
        ax_s.set_title(f"dashed: max TCP speed {data.max_tcp_speed:g} m/s", fontsize=8, loc="right", pad=2)
    ax_s.set_ylim(bottom=0.0)

    ax_m.plot(t, data.sigma_min, color="#1f77b4", lw=1.4, gid="sigma_min", label="σ_min (left axis)")
    ax_m.set_ylabel("σ_min of J_v\n(m/rad)", color="#1f77b4")
    ax_m.set_ylim(bottom=0.0)
    if data.min_singular_value is not None:
        ax_m.axhline(data.min_singular_value, color="#d62728", lw=1.0, ls="--", gid="singularity_margin")
        ax_m.axhspan(0.0, data.min_singular_value, color="#d62728", alpha=0.08, lw=0)
        ax_m.set_title(f"dashed: singularity margin σ_min ≥ {data.min_singular_value:g} m/rad", fontsize=8, loc="right", pad=2)
        ax_m.set_ylim(0.0, max(float(data.sigma_min.max()), data.min_singular_value) * 1.1)
    tw = ax_m.twinx()
    tw.plot(t, data.w, color="0.45", lw=1.0, ls=":", gid="w")
    tw.set_ylabel("w = Πσ (m³)", color="0.4", fontsize=8)
    tw.tick_params(labelsize=7, colors="0.4")
    tw.set_ylim(bottom=0.0)

    tw.yaxis.set_major_formatter(FormatStrFormatter("%.3g"))
    ax_m.set_xlabel("time (s)")

    for k, (ax, name) in enumerate(zip(axes, ("q", "v", "a", "torque", "speed", "manip"))):
        _shade_cartesian(ax, data)
        _event_lines(ax, data, name, labels=(k == 0))
        _blend_lines(ax, data, name)
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.tick_params(labelsize=7.5)
        ax.yaxis.label.set_fontsize(8.5)
        ax.set_xlim(t[0], t[-1] if t[-1] > t[0] else t[0] + 1.0)
        if k < len(axes) - 1:
            ax.tick_params(labelbottom=False)


def render_path(data: PathData, *, view: str = "iso", size: tuple[float, float] = (16.0, 10.0),
                title: str = "", subtitle: str = "") -> Figure:
    """The whole sheet as a matplotlib ``Figure`` (not yet saved); ``size`` in inches."""
    with matplotlib.rc_context(RC):
        fig = Figure(figsize=size)
        FigureCanvasAgg(fig)
        gs = fig.add_gridspec(1, 2, width_ratios=[1.2, 1.0], left=0.0, right=0.94, top=0.88, bottom=0.06, wspace=0.16)
        ax3 = fig.add_subplot(gs[0, 0], projection="3d")
        ax3.set_position((0.02, 0.08, 0.49, 0.84))
        norm, cmap = draw_scene_3d(ax3, data, view)
        _draw_right(fig, gs, data, norm, cmap, title, subtitle)
    return fig


def _draw_right(fig: Figure, gs: GridSpec, data: PathData, norm: Normalize, cmap: Colormap, title: str,
                subtitle: str) -> None:
    """Time plots in the right column, the speed colour bar, title and subtitle."""
    right = gs[0, 1].subgridspec(6, 1, hspace=0.36)
    axes = [fig.add_subplot(right[0, 0])]
    axes += [fig.add_subplot(right[i, 0], sharex=axes[0]) for i in range(1, 6)]
    draw_time_plots(axes, data)
    cax = fig.add_axes((0.06, 0.055, 0.42, 0.014))

    cb = fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), cax=cax, orientation="horizontal")
    cb.set_label("TCP speed (m/s)", fontsize=8.5)
    cb.ax.tick_params(labelsize=7.5)
    if data.max_tcp_speed is not None and norm.vmax is not None and data.max_tcp_speed <= norm.vmax:
        cb.ax.axvline(data.max_tcp_speed, color="#d62728", lw=1.2, ls="--")
    if title:
        fig.suptitle(title, x=0.02, y=0.985, ha="left", fontsize=13, fontweight="bold")
    if subtitle:
        fig.text(0.02, 0.945, subtitle, ha="left", va="top", fontsize=9, color="0.25")


def save_png(fig: Figure, path: str | Path, dpi: float) -> Path:
    """Write ``fig`` atomically (temporary file, then rename) as PNG, SVG or PDF, by ``path``'s extension."""
    fmt = picture_format(path)
    return atomic_write_with(path, lambda f: fig.savefig(f, format=fmt, dpi=dpi))


def describe(data: PathData, name: str) -> tuple[str, str]:
    """Title and subtitle lines of the sheet."""
    n_grasp = sum(e.kind == "grasp" for e in data.events)
    n_release = sum(e.kind == "release" for e in data.events)
    title = f"{name} — {data.robot_name}"
    bits = [f"{data.times[-1]:.2f} s", f"{len(data.times)} samples", f"{n_grasp} grasp, {n_release} release",
            f"peak TCP speed {data.tcp_speed.max():.3f} m/s", f"lowest σ_min {data.sigma_min.min():.4f} m/rad"]
    return title, " · ".join(bits)


def visualize_trajectory(traj: Trajectory, out: str | Path, *, view: str = "iso", dpi: float = 100.0,
                         size: tuple[float, float] = (16.0, 10.0), name: str | None = None,
                         failure: PartialPlan | None = None) -> Path:
    """Render ``traj`` (a ``Trajectory``) to ``out`` (.png, .svg or .pdf); returns the path written.

    ``failure``: a ``motion.pipeline.PartialPlan`` when planning failed: ``traj`` is what was planned
    before the failing task, whose target is marked with a red X and named in the title.
    """
    data = path_data(traj, robot_for(traj))
    title, subtitle = describe(data, name or "trajectory")
    if failure is not None:
        if failure.target is not None:
            data.events.append(EventMark(float(traj.duration), "failed", f"failed: {failure.label}",
                                         np.asarray(failure.target, dtype=float), True))
        title += f" — PLANNING FAILED at {failure.label}"
    fig = render_path(data, view=view, size=size, title=title, subtitle=subtitle)
    return save_png(fig, out, dpi)
