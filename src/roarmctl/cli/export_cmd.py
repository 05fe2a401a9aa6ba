"""``roarmctl export``: a trajectory or an execution log as MCAP, a ROS 2 bag folder, or CSV."""

from pathlib import Path

import typer

from roarmctl.cli import common
from roarmctl.export import export


def register(app: typer.Typer) -> None:
    """Add ``export`` to the app."""
    @app.command("export")
    def export_cmd(
        source: Path = typer.Argument(..., help="Trajectory (.traj.json) or execution log (.exec.json)."),
        output: Path = typer.Option(..., "-o", "--output",
                                    help="NAME.mcap (Foxglove), NAME.csv (spreadsheet), or a folder name without extension (ROS 2 bag)."),
        trajectory: Path | None = typer.Option(None, "--trajectory", "-t",
                                                  help="With an execution log: the trajectory it ran, added as planned joint states and scene."),
        force: bool = typer.Option(False, "--force", help="Replace an existing bag folder that roarmctl did not write "
                                   "(deleting everything in it)."),
        json_out: bool = typer.Option(False, "--json", help="Print one JSON object."),
    ) -> None:
        """Export SOURCE for Foxglove, RViz (ros2 bag play) or a spreadsheet; the format follows the -o name."""
        summary = export(source, output, trajectory=trajectory, force=force)
        if json_out:
            common.print_json({"ok": True, **summary})
            return
        if "rows" in summary:
            common.console().print(f"wrote {summary['output']} (CSV, {summary['rows']} rows)")
            return
        what = "MCAP file" if summary["format"] == "mcap" else "ROS 2 bag folder"
        topics = ", ".join(f"{t} {n}" for t, n in summary["topics"].items())
        common.console().print(f"wrote {summary['output']} ({what}; messages: {topics})")
