"""``roarmctl datagen``: a template's episodes, planned, run in physics and rendered, as a LeRobot v3.0 dataset."""

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from roarmctl.cli import common, signals
from roarmctl.errors import InputError

if TYPE_CHECKING:
    from roarmctl.export.lerobot.datagen import Summary


def register(app: typer.Typer) -> None:
    """Add ``datagen`` to the app."""
    app.command("datagen")(datagen)


def _size(text: str) -> tuple[int, int]:
    w, _, h = text.lower().partition("x")
    if not (w.isdigit() and h.isdigit()):
        raise InputError(f"--size: expected WIDTHxHEIGHT, got '{text[:40]}'", "e.g. --size 320x240")
    return int(w), int(h)


def datagen(
    template: Path = typer.Argument(..., help="Template: a plan file plus a 'datagen:' block (see the guide)."),
    episodes: int = typer.Option(..., "-n", "--episodes", help="Episodes to keep."),
    output: Path = typer.Option(..., "-o", "--output", help="Dataset folder to write (new, or a killed run's with --resume)."),
    workers: int = typer.Option(1, "--workers", "-j", help="Worker processes (or Ray tasks) at once."),
    seed: int = typer.Option(0, "--seed", help="Same seed, same dataset (whatever the worker count)."),
    size: str = typer.Option("640x480", "--size", help="Camera image size, WIDTHxHEIGHT pixels."),
    ray: str | None = typer.Option(None, "--ray", help="Run the shards as Ray tasks: 'local' (a Ray started here) or a cluster ADDRESS."),
    resume: bool = typer.Option(False, "--resume", help="Go on with a killed run in -o (its finished tries are kept)."),
    cameras: str = typer.Option("front,wrist", "--cameras", help="Cameras to render, comma-separated (front, wrist), or 'none': state and action only."),
    codec: str = typer.Option("h264", "--codec", help="Video codec: h264 (x264, fast to encode) or av1 (lerobot's default: smaller, 6x the encoding CPU)."),
    max_tries: int = typer.Option(0, "--max-tries", help="Give up (exit 3) after this many tries (default: 20 per episode, at least 50)."),
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object."),
) -> None:
    """Make a LeRobot v3.0 dataset: sample each episode's scene from TEMPLATE, plan it, run it in physics,
    keep it only if every object is placed and nothing unintended is touched, and render the front and
    wrist cameras.

    Rejected tries are counted by cause (crowded, unreachable, no path, not lifted, not placed, contact).
    """
    from roarmctl.export.lerobot.datagen import DatagenOptions, generate

    width, height = _size(size)
    try:
        options = DatagenOptions(episodes=episodes, seed=seed, workers=workers, width=width, height=height, max_tries=max_tries,
                                 ray=None if ray is None else ("" if ray == "local" else ray), resume=resume,
                                 codec=codec, cameras=() if cameras.strip() == "none" else tuple(c.strip() for c in cameras.split(",")))
    except InputError as exc:
        if exc.option in ("width", "height"):  # typed as --size WIDTHxHEIGHT: there is no --width
            raise InputError(f"{exc.option}: {exc.problem}", exc.hint, option="size") from None
        raise
    def check(s: "Summary") -> None:
        """Raise a stop whose exception Python discarded, at a shard's report; the last report (``wall`` set) comes
        once the dataset is written: the run has finished its work then."""
        if not s.wall:
            signals.check()

    err = common.console(stderr=True)
    if json_out or not err.is_terminal:
        summary = generate(template, output, options, check)
    else:
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        columns = (TextColumn("episodes"), BarColumn(), MofNCompleteColumn(), TextColumn("kept, {task.fields[tried]} tried,"),
                   TextColumn("{task.fields[rate]}"), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn())
        with Progress(*columns, console=err, transient=True) as bar:
            task = bar.add_task("datagen", total=episodes, tried=0, rate="")

            def progress(s: "Summary") -> None:
                check(s)
                rate = f"{100 * s.kept / s.tried:.0f} % kept" if s.tried else ""
                bar.update(task, completed=min(s.kept, episodes), tried=s.tried, rate=rate)

            summary = generate(template, output, options, progress)
    _render(summary, output, json_out)


def _render(s: "Summary", output: Path, json_out: bool) -> None:
    result = {"ok": True, "output": str(output), "episodes": s.kept, "tried": s.tried, "rejected": s.causes, "frames": s.frames,
              "bytes": s.bytes, "stages_s": {k: round(v, 3) for k, v in s.stages.items()}, "wall_s": round(s.wall, 3),
              "resumed_tries": s.resumed, "complete": s.complete}
    if json_out:
        common.print_json(result)
        return
    out = common.console()
    if s.complete:
        out.print(f"{output} is complete ({s.kept} episodes, {s.frames} frames): nothing to resume")
        return
    rejected = ", ".join(f"{k} {v}" for k, v in s.causes.items() if v) or "none"
    out.print(f"wrote {common.shown(output)}: {s.kept} episodes, {s.frames} frames, {s.bytes / 1e6:.1f} MB "
              f"({s.tried} tries; rejected: {rejected})" + (f"; {s.resumed} tries resumed" if s.resumed else ""))
    total = sum(s.stages.values())
    if total > 0:
        out.print("time per stage (all workers): " + ", ".join(f"{k} {v:.1f} s" for k, v in s.stages.items() if v)
                  + f"; wall {s.wall:.1f} s")
