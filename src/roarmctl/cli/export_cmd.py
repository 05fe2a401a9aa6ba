"""``roarmctl export``: a trajectory or an execution log as MCAP, a ROS 2 bag folder, or CSV."""

from pathlib import Path

import typer

from roarmctl.cli import common
from roarmctl.errors import InputError
from roarmctl.export import ExportOptions, export


def register(app: typer.Typer) -> None:
    """Add ``export`` to the app."""
    @app.command("export")
    def export_cmd(
        source: Path = typer.Argument(..., help="Trajectory (.traj.json) or execution log (.exec.json)."),
        output: Path | None = typer.Option(None, "-o", "--output",
                                           help="NAME.mcap (Foxglove), NAME.csv (spreadsheet), or a folder name without extension (ROS 2 bag)."),
        lerobot: Path | None = typer.Option(None, "--lerobot", help="Append an execution log to this LeRobot v3.0 dataset "
                                            "folder (made if missing) as one episode: measured joints as state, sent goals as action."),
        task: str | None = typer.Option(None, "--task", help="With --lerobot: the episode's instruction (default: the dataset's first task)."),
        fps: int | None = typer.Option(None, "--fps", help="With --lerobot: frames per second of a new dataset (default 30)."),
        trajectory: Path | None = typer.Option(None, "--trajectory", "-t",
                                                  help="With an execution log: the trajectory it ran, added as planned joint states and scene (a log carries its own; this is for an older roarmctl's log, which does not)."),
        force: bool = typer.Option(False, "--force", help="Replace an existing bag folder that roarmctl did not write "
                                   "(deleting everything in it)."),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ) -> None:
        """Export SOURCE for Foxglove, RViz (ros2 bag play) or a spreadsheet (the format follows the -o name),
        or append an execution log to a LeRobot dataset (--lerobot)."""
        if (output is None) == (lerobot is None):
            raise InputError("give one of -o OUTPUT and --lerobot DATASET", "e.g. -o run.mcap, or --lerobot my_dataset/")
        if lerobot is not None:
            if trajectory is not None:
                raise InputError("--trajectory does not go with --lerobot", "the episode holds the run's joints only")
            from roarmctl.export.lerobot.run import export_run

            done = export_run(source, lerobot, task=task, fps=fps)
            if json_out:
                common.print_json({"ok": True, **done})
            else:
                common.console().print(f"appended episode {done['episode_index']} ({done['frames']} frames at {done['fps']} fps) "
                                       f"to {common.shown(done['output'])}")
            return
        if task is not None or fps is not None:
            raise InputError("--task and --fps go with --lerobot")
        assert output is not None  # one of the two (checked above)
        summary = export(source, output, trajectory=trajectory, options=ExportOptions(force=force))
        if json_out:
            common.print_json({"ok": True, **summary})
            return
        if "rows" in summary:
            common.console().print(f"wrote {common.shown(summary['output'])} (CSV, {summary['rows']} rows)")
            return
        what = "MCAP file" if summary["format"] == "mcap" else "ROS 2 bag folder"
        topics = ", ".join(f"{t} {n}" for t, n in summary["topics"].items())
        common.console().print(f"wrote {common.shown(summary['output'])} ({what}; messages: {topics})")
