"""Draw the reachable workspace: a side (r-z) and a top (x-y) map of sampled TCP positions.

Each map bins the samples on a grid and colours a cell by the best (largest) manipulability measure
found there, so a dark cell means "reachable only close to a singularity" and a blank one "not reached
by any sample". Imports matplotlib: only the ``workspace`` command imports this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from roarmctl.errors import InputError
from roarmctl.viz.data import WorkspaceData, workspace_data

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

MEASURES = {"sigma": ("σ_min of J_v (m/rad)", "smallest singular value"), "w": ("w = Πσ of J_v", "Yoshikawa manipulability")}


@dataclass
class BinnedMap:
    """Best value per grid cell: ``values`` (ny, nx) with NaN where no sample fell; ``extent`` (x0, x1, y0, y1) m."""

    values: np.ndarray
    extent: tuple[float, float, float, float]
    count: int


def bin_max(u: np.ndarray, v: np.ndarray, value: np.ndarray, cell: float, pad: float = 0.0) -> BinnedMap:
    """Grid the points (u, v) with square cells of ``cell`` m; keep the largest ``value`` per cell."""
    if len(u) == 0:
        return BinnedMap(np.full((1, 1), np.nan), (-cell, cell, -cell, cell), 0)
    u0, v0 = u.min() - pad, v.min() - pad
    nx = max(int(np.ceil((u.max() + pad - u0) / cell)), 1)
    ny = max(int(np.ceil((v.max() + pad - v0) / cell)), 1)
    ix = np.clip(((u - u0) / cell).astype(int), 0, nx - 1)
    iy = np.clip(((v - v0) / cell).astype(int), 0, ny - 1)
    grid = np.full(nx * ny, -np.inf)
    np.maximum.at(grid, iy * nx + ix, value)
    grid[np.isinf(grid)] = np.nan
    return BinnedMap(grid.reshape(ny, nx), (u0, u0 + nx * cell, v0, v0 + ny * cell), len(u))


def workspace_maps(data: WorkspaceData, measure: str = "sigma", height: float | None = None,
                   band: float | None = None, cells: int = 70) -> tuple[BinnedMap, BinnedMap, float]:
    """Side map (r = sqrt(x^2 + y^2), z) and top map (x, y); returns (side, top, cell size m).

    With ``height`` the top map is a section: only samples with |z - height| <= ``band`` (default
    one side-map cell) on a grid twice as coarse. Without it the top map is the footprint over all heights.
    """
    value = data.sigma_min if measure == "sigma" else data.w
    p = data.points
    r = np.hypot(p[:, 0], p[:, 1])
    span = max(float(np.ptp(p[:, 0])), float(np.ptp(p[:, 1])), float(np.ptp(p[:, 2])), 1e-3)
    cell = span / cells
    side = bin_max(r, p[:, 2], value, cell)
    sel = np.ones(len(p), dtype=bool)
    if height is not None:  # NaN, inf or a height out of reach drew an empty top map, exit 0
        if not np.isfinite(height):
            raise InputError(f"expected a finite height (m), got {height:g}", "e.g. 0.05", option="height")
        sel = np.abs(p[:, 2] - height) <= (band if band is not None else cell)
        if not sel.any():
            raise InputError(f"no reachable sample at z = {height:g} m (the samples span z {p[:, 2].min():.3f} to "
                             f"{p[:, 2].max():.3f} m)", "give a height within that span", option="height")
    # A thin section holds few samples: coarser cells keep it from looking like noise.
    top = bin_max(p[sel, 0], p[sel, 1], value[sel], cell if height is None else 2 * cell)
    return side, top, cell


def flat_axis(points: np.ndarray) -> int | None:
    """Index (0 x, 1 y, 2 z) of the coordinate that never changes (a planar arm), else None."""
    ptp = np.ptp(points, axis=0) if len(points) else np.zeros(3)
    span = max(float(ptp.max()), 1e-9)
    flat = [i for i in range(3) if ptp[i] < 1e-6 * span]
    return flat[0] if flat else None


def render_workspace(data: WorkspaceData, *, measure: str = "sigma", height: float | None = None,
                     size: tuple[float, float] = (13.0, 6.0)) -> Figure:
    """The workspace sheet as a ``Figure`` (not yet saved).

    Two maps (side r-z, top x-y); a planar arm (one coordinate constant) gets one map of its plane.
    """
    value = data.sigma_min if measure == "sigma" else data.w
    vmax = float(np.nanmax(value)) if len(value) else 1.0
    cmap = colormaps["magma"].with_extremes(bad="white")
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    names = ("x (m)", "y (m)", "z (m)")
    flat = flat_axis(data.points)
    links = data.home_links
    if flat is None:
        side, top, cell = workspace_maps(data, measure, height)
        axs = fig.subplots(1, 2, gridspec_kw=dict(left=0.06, right=0.88, bottom=0.11, top=0.83, wspace=0.22))
        panels = [(axs[0], side, "r = √(x² + y²) (m)", "z (m)"), (axs[1], top, "x (m)", "y (m)")]
        side_xy = lambda p: (np.hypot(p[0], p[1]), p[2])  # noqa: E731
        top_xy = lambda p: (p[0], p[1])  # noqa: E731
        arms = [(axs[0], side_xy), (axs[1], top_xy)]
    else:
        u, v = [i for i in range(3) if i != flat]
        span = max(float(np.ptp(data.points[:, u])), float(np.ptp(data.points[:, v])), 1e-3)
        cell = span / 90
        m = bin_max(data.points[:, u], data.points[:, v], value, cell)
        ax = fig.subplots(1, 1, gridspec_kw=dict(left=0.06, right=0.88, bottom=0.11, top=0.83))
        axs = [ax]
        panels = [(ax, m, names[u], names[v])]
        arms = [(ax, lambda p: (p[u], p[v]))]
    ims = []
    for ax, m, xl, yl in panels:
        im = ax.imshow(np.ma.masked_invalid(m.values), origin="lower", extent=m.extent, cmap=cmap, vmin=0.0, vmax=vmax,
                       interpolation="nearest", aspect="equal")
        ims.append(im)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(True, lw=0.4, alpha=0.4)
        ax.tick_params(labelsize=8)
    # The robot at its home pose, for scale.
    for k, (ax, proj) in enumerate(arms):
        for a, b in data.arm_segments:
            (xa, ya), (xb, yb) = proj(links[a]), proj(links[b])
            ax.plot([xa, xb], [ya, yb], color="#1f9bd7", lw=2.2, alpha=0.9, solid_capstyle="round", gid=f"home:{k}")
        ax.plot(*proj(np.zeros(3)), marker="+", color="0.2", ms=10)
    axs[0].plot([], [], color="#1f9bd7", lw=2.2, label="arm at home pose")
    axs[0].legend(loc="upper right", fontsize=8, framealpha=0.85)
    if flat is None:
        axs[0].axhline(0.0, color="0.4", lw=0.8, ls=":")
        axs[0].set_title("side section (all base angles folded onto r)", fontsize=10)
        if height is None:
            axs[1].set_title("top view (footprint over all heights)", fontsize=10)
        else:
            axs[1].set_title(f"top section at z = {height:.3f} ± {cell:.3f} m ({top.count} samples)", fontsize=10)
    else:
        axs[0].set_title(f"the arm's plane ({names[flat][0]} = {data.points[0, flat] + 0.0:.3f} m everywhere)", fontsize=10)
    cax = fig.add_axes((0.905, 0.11, 0.015, 0.72))
    label, long = MEASURES[measure]
    cb = fig.colorbar(ims[0], cax=cax)
    cb.set_label(f"best {label} in the cell", fontsize=9)
    cb.ax.tick_params(labelsize=8)
    fig.suptitle(f"{data.robot_name}: reachable workspace", x=0.06, ha="left", y=0.97, fontsize=13, fontweight="bold")
    fig.text(0.06, 0.905, f"{len(data.points)} uniform random configurations within the joint limits (seed {data.seed}); "
             f"colour: {long} of the translational Jacobian, darker = closer to a singularity; blank = not reached",
             fontsize=8.5, color="0.3", ha="left")
    return fig


def visualize_workspace(robot: Robot, out: str | Path, *, samples: int = 80000, seed: int = 0, measure: str = "sigma",
                        height: float | None = None, dpi: float = 100.0,
                        size: tuple[float, float] = (13.0, 6.0)) -> Path:
    """Sample ``robot``'s workspace and write the PNG ``out``; returns the path written."""
    from roarmctl.viz.path_figure import save_png

    fig = render_workspace(workspace_data(robot, samples, seed), measure=measure, height=height, size=size)
    return save_png(fig, out, dpi)
