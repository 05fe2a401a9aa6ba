"""``roarmctl visualize-path`` and ``roarmctl workspace``: PNG pictures of a plan and of a robot's reach.

matplotlib is imported inside the commands (through ``roarmctl.viz.*_figure``), never at import of
``roarmctl.cli``, so ``roarmctl --help`` stays fast.
"""

from pathlib import Path

import typer

from roarmctl.cli import common
from roarmctl.errors import InfeasibleError, InputError
from roarmctl.viz.formats import picture_format

VIEW_NAMES = ("iso", "top", "front", "side")
MAX_PIXELS = 12000  # per side; beyond this a PNG is a mistake, not a picture


def register(app: typer.Typer) -> None:
    """Add ``visualize-path`` and ``workspace`` to ``app``."""
    app.command("visualize-path")(visualize_path)
    app.command("workspace")(workspace)


def parse_size(text: str, dpi: float) -> tuple[float, float]:
    """``WxH`` in inches (e.g. ``16x10``) -> (w, h); the PNG is w*dpi x h*dpi pixels."""
    parts = text.lower().replace("×", "x").split("x")
    try:
        w, h = (float(p) for p in parts)
    except ValueError:
        raise InputError(f"--size: '{text}' is not WxH in inches", "for example --size 16x10") from None
    if not (1.0 <= w <= 100.0 and 1.0 <= h <= 100.0):
        raise InputError(f"--size: {text} is out of range", "each side between 1 and 100 inches")
    if max(w, h) * dpi > MAX_PIXELS:
        raise InputError(f"--size {text} at --dpi {dpi:g} gives more than {MAX_PIXELS} pixels per side", "lower --dpi or --size")
    return w, h


def _check_dpi(dpi: float) -> None:
    if not (10 <= dpi <= 1200):
        raise InputError(f"--dpi: {dpi:g} is out of range", "use 10 to 1200 (100 gives 1600x1000 px at the default size)")


def default_output(source: Path, suffix: str = ".png") -> Path:
    """``dir/name.traj.json`` or ``dir/name.yaml`` -> ``dir/name.png``."""
    name = source.name
    for ext in (".traj.json", ".json", ".yaml", ".yml"):
        if name.lower().endswith(ext):
            name = name[: -len(ext)]
            break
    return source.with_name((name or source.name) + suffix)


def visualize_path(
    source: Path = typer.Argument(..., help="Trajectory file (*.traj.json), or a plan file (.yaml) to plan first; "
                                  "with -o NAME.html also an execution log (*.exec.json).", show_default=False),
    output: Path | None = typer.Option(None, "-o", "--output",
                                       help="Picture to write: .png, .svg or .pdf, or .html for the interactive 3D page (default: next to SOURCE, same name, .png)."),
    view: str = typer.Option("iso", "--view", help="3D view: iso, top, front or side."),
    dpi: float = typer.Option(100.0, "--dpi", help="Pixels per inch of the PNG."),
    size: str = typer.Option("16x10", "--size", help="Sheet size WxH in inches (pixels = size x dpi)."),
    trajectory: Path | None = typer.Option(None, "--trajectory", "-t",
                                        help="With an execution log and -o NAME.html: the trajectory it ran (its scene, marks and commanded arm), for a log that carries none (an older roarmctl's)."),
) -> None:
    """Draw a planned trajectory (PNG, SVG or PDF): 3D scene and TCP path, joint curves, TCP speed, manipulability.
    With -o NAME.html: the interactive 3D view as one self-contained page (no server, no network), also of an
    execution log (what the arm was told and what it reported)."""
    out = output if output is not None else default_output(source)
    if out.suffix.lower() == ".html":
        _write_html(source, out, trajectory)
        return
    if trajectory is not None:
        raise InputError("--trajectory goes with an execution log drawn as the 3D page", "write it with -o NAME.html")
    if view not in VIEW_NAMES:
        raise InputError(f"--view: '{view}' is not one of {', '.join(VIEW_NAMES)}")
    _check_dpi(dpi)
    figsize = parse_size(size, dpi)

    try:
        picture_format(out)  # before any work: the extension decides png / svg / pdf
    except InputError as exc:
        exc.hint = f"{exc.hint}, or in .html for the 3D page"
        raise
    from roarmctl.viz.path_figure import visualize_trajectory
    from roarmctl.viz.web.sources import trajectory_or_plan

    try:
        traj = trajectory_or_plan(source)
    except InfeasibleError as exc:
        partial = getattr(exc, "partial", None)
        if partial is None:
            raise
        # draw what was planned and mark the failing target, then fail with the planner's exit code
        written = visualize_trajectory(partial.trajectory, out, view=view, dpi=dpi, size=figsize, name=source.name, failure=partial)
        exc.hint = (f"{exc.hint}; " if exc.hint else "") + f"drawn up to the failure in {written}"
        raise
    except InputError:
        if _is_log(source):  # the trajectory reader's "format: expected ..." would not say what to do
            raise InputError(f"{source}: an execution log is drawn only as the 3D page",
                             f"use -o {default_output(source, '.html').name}, or roarmctl view {source.name}") from None
        raise
    written = visualize_trajectory(traj, out, view=view, dpi=dpi, size=figsize, name=source.name)
    w, h = round(figsize[0] * dpi), round(figsize[1] * dpi)
    common.console().print(f"wrote {common.shown(written)} ({w} x {h} px)")


def _is_log(source: Path) -> bool:
    """Whether ``source`` is an execution log (read again only on this error path)."""
    from roarmctl.device.execlog import is_log
    from roarmctl.formats import read_document

    try:
        data = read_document(source)
    except InputError:
        return False
    return is_log(data)


def _write_html(source: Path, out: Path, trajectory: Path | None = None) -> None:
    """``visualize-path SOURCE -o out.html``: the browser view as one file; a failing plan is drawn up to the
    failure, then reported (exit 3) as for a picture."""
    from roarmctl.viz.web.page import write_page
    from roarmctl.viz.web.sources import load_view_source, source_document

    src = load_view_source(source, trajectory)
    written = write_page(source_document(src), out)
    if src.error is not None:
        exc = src.error
        exc.hint = (f"{exc.hint}; " if exc.hint else "") + f"drawn up to the failure in {written}"
        raise exc
    common.console().print(f"wrote {common.shown(written)} ({written.stat().st_size / 1e6:.2f} MB; open it in a web browser)", soft_wrap=True)


def workspace(
    robot: str = typer.Argument(..., help="Bundled robot name or path to a description."),
    output: Path | None = typer.Option(None, "-o", "--output", help="Picture to write: .png, .svg or .pdf (default: ROBOT_workspace.png here)."),
    samples: int = typer.Option(80000, "--samples", help="Random configurations to sample."),
    seed: int = typer.Option(0, "--seed", help="Random seed (the same seed draws the same picture)."),
    height: float | None = typer.Option(None, "--height", help="Top map as a section at this z (m) instead of the footprint."),
    measure: str = typer.Option("sigma", "--measure", help="Colour by 'sigma' (smallest singular value) or 'w' (product)."),
    dpi: float = typer.Option(100.0, "--dpi", help="Pixels per inch of the PNG."),
    size: str = typer.Option("13x6", "--size", help="Sheet size WxH in inches."),
) -> None:
    """Draw the reachable workspace (side and top maps of sampled TCP positions, coloured by manipulability)."""

    if measure not in ("sigma", "w"):
        raise InputError(f"--measure: '{measure}' is not 'sigma' or 'w'")
    if not (1 <= samples <= 2_000_000):
        raise InputError(f"--samples: {samples} is out of range", "use 1 to 2000000")
    _check_dpi(dpi)
    figsize = parse_size(size, dpi)
    r = common.load_robot(robot)
    out = output if output is not None else Path(f"{r.name}_workspace.png")

    picture_format(out)
    from roarmctl.viz.workspace_figure import visualize_workspace

    written = visualize_workspace(r, out, samples=samples, seed=seed, measure=measure, height=height, dpi=dpi, size=figsize)
    common.console().print(f"wrote {common.shown(written)} ({round(figsize[0] * dpi)} x {round(figsize[1] * dpi)} px)")
