"""Export a trajectory or an execution log for other tools: MCAP, a ROS 2 bag folder, or CSV.

``export(source, path)`` picks the format from ``path``: ``*.mcap`` -> one MCAP file of ROS 2
messages (Foxglove opens it directly); ``*.csv`` -> a spreadsheet table; a name without an
extension (or ending in ``/``) -> a ROS 2 bag folder (``metadata.yaml`` + sqlite3 ``.db3``).
Anything else is an input error (exit 2).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

from roarmctl.checks import Bound, check_options
from roarmctl.errors import InputError, TrajectoryFileError
from roarmctl.fileio import atomic_write_text, check_output_folder, note_output_folder

if TYPE_CHECKING:
    from roarmctl.export.streams import Streams
    from roarmctl.robot.model import Robot

FORMATS = ("mcap", "bag", "csv")

EXPORT_BOUNDS: dict[str, Bound] = {
    "format": Bound(choices=FORMATS, optional=True),  # None: from the output's name
    "force": Bound(flag=True),  # replace a bag folder roarmctl did not write
}


@dataclass(frozen=True)
class ExportOptions:
    """How ``export`` writes: ``format`` ('mcap', 'bag', 'csv'; None: from the output's name, ``format_for``) and
    ``force`` (replace an existing bag folder roarmctl did not write). Checks its own fields when made
    (``EXPORT_BOUNDS``): an unknown format or a flag that is not true or false raise ``OptionError`` naming the
    field. The CLI and ``roarmctl.api.export`` build one."""

    format: str | None = None
    force: bool = False

    def __post_init__(self) -> None:
        check_options(self, EXPORT_BOUNDS)


def format_for(path: str | os.PathLike) -> str:
    """'mcap', 'csv' or 'bag' from the output path; an unknown extension raises InputError."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".mcap":
        return "mcap"
    if suffix == ".csv":
        return "csv"
    try:
        folder = p.is_dir()
    except (OSError, ValueError):  # a name the OS refuses (too long, NUL byte)
        folder = False
    if suffix == "" or str(path).endswith(os.sep) or folder or p.name in ("", ".", ".."):
        return "bag"
    raise InputError(f"{path}: unknown export format '{suffix}'",
                     "use NAME.mcap (Foxglove), NAME.csv (spreadsheet) or a folder name without an extension (ROS 2 bag)",
                     option="output")


def load_source(path: str | os.PathLike | Any) -> tuple[str, Any]:
    """Read a ``*.traj.json`` (-> ('trajectory', Trajectory), checked by the one trajectory validator)
    or an execution log (-> ('log', dict))."""
    from roarmctl.device.execlog import FORMAT as LOG_FORMAT
    from roarmctl.device.execlog import parse_log
    from roarmctl.formats import read_document
    from roarmctl.motion.trajectory import FORMAT, Trajectory
    from roarmctl.motion.validate import validate_trajectory

    if isinstance(path, Trajectory):  # in memory (the Python API)
        return "trajectory", validate_trajectory(path)
    p = Path(path)
    data = read_document(p)
    kind = data.get("format") if isinstance(data, dict) else None
    if kind == LOG_FORMAT:
        return "log", parse_log(data, str(p))
    if kind == FORMAT:
        return "trajectory", validate_trajectory(data, where=str(p))
    raise TrajectoryFileError(f"{p}: format {kind!r} is neither '{FORMAT}' nor '{LOG_FORMAT}'",
                              "give a file written by 'roarmctl plan' or 'roarmctl execute'")


def streams_for(source: str | os.PathLike | Any, trajectory: str | os.PathLike | Any | None = None) -> Streams:
    """The ``Streams`` of a trajectory or execution-log file (robot loaded by the name in the file).
    ``trajectory`` (logs only): the executed trajectory, exported beside the run as ``planned``."""
    from roarmctl.export.streams import log_streams, trajectory_streams
    from roarmctl.motion.validate import robot_of

    kind, data = load_source(source)
    if kind == "trajectory":
        if trajectory is not None:
            raise InputError("goes with an execution log, not with a trajectory",
                             "export the trajectory by itself, or give the .exec.json it produced", option="trajectory")
        return trajectory_streams(data, robot_of(data, str(source)))
    traj, robot = run_trajectory(data, str(source), trajectory)
    return log_streams(data, robot, traj)


def run_trajectory(log: dict[str, Any], where: str, trajectory: str | os.PathLike | Any | None = None
                   ) -> tuple[Any, Robot]:
    """The trajectory a logged run executed and the run's robot: ``trajectory`` (a file or a ``Trajectory``) when
    given, else the one the log carries (``device.execlog.carried_trajectory``, checked against the log's robot as
    a trajectory file is), else None (a log of teach, or of a roarmctl before logs carried it)."""
    from roarmctl.device.execlog import carried_trajectory
    from roarmctl.motion.validate import check_against_robot

    if trajectory is not None:
        tkind, traj = load_source(trajectory)
        if tkind != "trajectory":
            raise InputError(f"{trajectory} is not a trajectory file", "give the .traj.json that was executed",
                             option="trajectory")
        return traj, log_robot(log, where, traj, str(trajectory))
    traj = carried_trajectory(log, where)
    robot = log_robot(log, where)
    if traj is not None:
        check_against_robot(traj, robot, f"{where}: trajectory")
    return traj, robot


def log_robot(log: dict[str, Any], where: str, traj: Any = None, traj_where: str = "trajectory") -> Robot:
    """The ``Robot`` of an execution log: the description it carries, else the one of the trajectory it ran
    (``traj``) when that carries one, else the bundled robot the log names."""
    from roarmctl.motion.validate import robot_of

    if log.get("robot_description") is None and traj is not None and traj.robot_description is not None:
        return robot_of(traj, traj_where)  # a log without its robot: the one of the trajectory it ran
    return robot_of(SimpleNamespace(robot=log["robot"], robot_description=log.get("robot_description")), where)


def export(source: str | os.PathLike | Any, path: str | os.PathLike, trajectory: str | os.PathLike | Any | None = None,
           options: ExportOptions | None = None) -> dict[str, Any]:
    """Export the trajectory or execution log at ``source`` (or a ``Trajectory``) to ``path``; returns a summary
    (``output``, ``format``, ``topics``: message count per topic and ``time_offset_s``: s added to every time of
    the source in the bag, or ``rows`` for CSV, whose times are the source's). For a log,
    ``trajectory`` adds the executed plan (``planned`` joint states and the scene). ``options``: the format (default:
    from ``path``) and whether an existing bag folder that roarmctl did not write is replaced (``ExportOptions``)."""
    options = options or ExportOptions()
    fmt = options.format or format_for(path)
    if fmt == "bag":  # refuse before the work
        from roarmctl.export.ros import is_bag_we_wrote

        check_output_folder(path, options.force, made_by_us=is_bag_we_wrote)
        note_output_folder(path)  # a signal from here on is reported with what is at `path`
    streams = streams_for(source, trajectory)
    return write(streams, path, fmt, options.force)


def write(streams: Streams, path: str | os.PathLike, fmt: str, force: bool = False) -> dict[str, Any]:
    """Write already-built ``Streams`` in format ``fmt`` ('mcap', 'bag', 'csv'); see ``export``."""
    if fmt == "csv":
        from roarmctl.export.table import csv_text

        text = csv_text(streams)
        out = atomic_write_text(path, text)
        return {"output": str(out), "format": fmt, "rows": text.count("\n") - 1}
    from roarmctl.export.ros import time_offset, write_bag

    out, counts = write_bag(streams, path, "mcap" if fmt == "mcap" else "sqlite3", force)
    return {"output": str(out), "format": fmt, "topics": counts, "time_offset_s": time_offset(streams)}
