"""``roarmctl plan``: plan file -> collision-free, singularity-aware, time-optimal trajectory file."""

import sys
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from roarmctl.cli import common, signals
from roarmctl.errors import InputError

if TYPE_CHECKING:
    from collections.abc import Callable

    import numpy as np
    from rich.table import Table

    from roarmctl.motion.pipeline import PlanResult
    from roarmctl.robot.model import Robot


def default_output(plan_path: Path) -> Path:
    """``plans/pick_place.yaml`` -> ``plans/pick_place.traj.json``."""
    return plan_path.with_name(plan_path.stem + ".traj.json")


def run_planner(plan: Path, seed: int | None, quiet: bool,
                current: "Callable[[Robot], np.ndarray] | None" = None) -> "PlanResult":
    """Plan with a rich progress display on stderr (none when ``quiet``); returns the PlanResult.

    ``current(robot)`` measures the arm for ``start: current``. Each stage's report also raises a stop signal whose
    exception Python discarded (``signals.check``): a Ctrl-C stops the planning with or without the display."""
    from roarmctl.motion.pipeline import plan_file

    if quiet or not sys.stderr.isatty():  # no live display in pipes and logs
        return plan_file(plan, seed=seed, current=current, progress=lambda stage, done, total: signals.check())
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    with Progress(SpinnerColumn(), TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total} tasks"),
                  TimeElapsedColumn(), console=common.console(stderr=True), transient=True) as bar:
        job = bar.add_task(f"planning {common.shown(plan.name)}", total=None)

        def progress(stage: str, done: int, total: int) -> None:
            signals.check()
            bar.update(job, description=stage, completed=done, total=total)

        return plan_file(plan, seed=seed, progress=progress, current=current)


def arm_reader(port: str | None, sim: bool, notes: list[str]) -> "Callable[[Robot], np.ndarray] | None":
    """``current(robot)`` for ``start: current``: reads the arm on ``port`` (or a fresh simulator)."""
    if port is not None and sim:
        raise InputError("give one of --port PORT and --sim, not both")
    if port is None and not sim:
        return None

    def current(robot: "Robot") -> "np.ndarray":
        from roarmctl.device.pose import read_configuration

        if sim:
            from roarmctl.device.simulator import PtySimulator, SimConfig

            with PtySimulator(SimConfig()) as simulator:
                q, fb = read_configuration(simulator.path, robot)
        else:
            assert port is not None  # one of --port and --sim (checked above)
            q, fb = read_configuration(port, robot)
        notes.append("start: current = the arm's measured pose: " + ", ".join(f"{v:.4f}" for v in q) + " rad; "
                     f"firmware x/y/z ({fb.xyz[0]:.1f}, {fb.xyz[1]:.1f}, {fb.xyz[2]:.1f}) mm")
        return q

    return current


def register(app: typer.Typer) -> None:
    """Add ``plan`` to the app."""
    @app.command("plan")
    def plan_cmd(
        plan: Path = typer.Argument(..., help="Pick/place plan file (YAML)."),
        output: Path | None = typer.Option(None, "-o", "--output", help="Trajectory file to write (default: next to the plan, .traj.json)."),
        seed: int | None = typer.Option(None, "--seed", help="Random seed (overrides planner.seed; same seed -> same file)."),
        json_out: bool = typer.Option(False, "--json", help="Print a JSON summary instead of the table."),
        port: str | None = typer.Option(None, "--port", "-p", help="For 'start: current': read the arm's pose from this serial port (the arm does not move)."),
        sim: bool = typer.Option(False, "--sim", help="For 'start: current': read it from a fresh firmware simulator (its boot pose)."),
    ) -> None:
        """Plan every task of PLAN, time it with TOPP-RA, re-check it and write the trajectory file.

        A plan with 'start: current' starts where the arm is: give --port (or --sim) to read it.
        """
        from roarmctl.motion.planning.targets import summary as target_summary

        out = output or default_output(plan)
        common.not_the_input(out, plan, "-o")
        measured: list[str] = []
        result = run_planner(plan, seed, quiet=json_out, current=arm_reader(port, sim, measured))
        result.notes[:0] = measured
        if (port is not None or sim) and not measured:  # given, yet nothing asked for the arm: say so, not silently
            result.warnings.append(f"{'--port' if port is not None else '--sim'} was not used: the plan does not start at "
                                   "'current', so the arm was not read (give 'start: current' to plan from where it is)")
        signals.check()  # a stop discarded after the last stage's report: no file
        result.trajectory.save(out)
        traj = result.trajectory
        summary = {
            "ok": True,
            "output": str(out),
            "duration": traj.duration,
            "cycle_time": traj.duration,
            "blends": list(traj.blends),
            "peaks": result.peaks,
            "segments": result.segments,
            "planning_time": result.planning_time,
            "timings": result.timings,
            "points": len(traj.times),
            "events": [{"time_from_start": e.time, "kind": e.kind, "label": e.label} for e in traj.events],
            "targets": traj.targets,
            "targets_summary": target_summary(traj.targets),
            "warnings": result.warnings,
            "notes": result.notes,
        }
        for w in result.warnings:
            common.warn(w)
        if not json_out:
            for n in result.notes:
                sys.stderr.write(f"note: {n}\n")
        if json_out:
            common.print_json(summary)
            return
        from rich.table import Table

        table = Table(title=f"Planned {common.shown(plan.name)}", show_header=False)
        table.add_column("what", style="bold")
        table.add_column("value")
        table.add_row("output", common.shown(out))
        table.add_row("motion duration", f"{traj.duration:.2f} s ({len(traj.times)} points at {traj.sample_rate:g} Hz)")
        table.add_row("segments", str(result.segments))
        table.add_row("events", ", ".join(f"{e.kind} @ {e.time:.2f} s" for e in traj.events) or "none")
        split = ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in result.timings.items())
        table.add_row("planning time", f"{result.planning_time * 1000:.0f} ms ({split})")
        table.add_row("cycle time", f"{traj.duration:.2f} s, {len(traj.blends)} blended joins")
        table.add_row("targets", target_summary(traj.targets))
        common.console().print(table)
        if result.peaks:
            common.console().print(_peaks_table(result.peaks))


def _peaks_table(peaks: dict) -> "Table":
    """Per joint: peak jerk and peak torque, each with its fraction of the robot's limit."""
    from rich.table import Table

    def pct(f: "float | None") -> str:
        return "-" if f is None else f"{100 * f:.0f} %"

    table = Table(title="Peaks per joint (fraction of the limit)")
    table.add_column("joint")
    for name in ("jerk", "of limit", "torque", "of limit"):
        table.add_column(name, justify="right")
    torque = peaks["torque"] or [None] * len(peaks["joints"])
    units = peaks["units"]  # rad/s^3 and N m, or m/s^3 and N for a prismatic joint
    for i, name in enumerate(peaks["joints"]):
        table.add_row(common.shown(name), f"{peaks['jerk'][i]:.{3 if units['jerk'][i].startswith('m') else 1}f} {units['jerk'][i]}",
                      pct(peaks["jerk_fraction"][i]),
                      "-" if torque[i] is None else f"{torque[i]:.3f} {units['torque'][i]}", pct(peaks["torque_fraction"][i]))
    return table
