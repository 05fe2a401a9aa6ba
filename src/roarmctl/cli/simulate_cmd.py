"""``roarmctl simulate``: play a trajectory's commands into the physics model (MuJoCo) and report what
the arm and the objects did: tracking, torque, sag, unintended contacts, placements."""

from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import typer

from roarmctl.cli import common, signals
from roarmctl.cli.execute_cmd import SAG_HELP, STRATEGY_HELP
from roarmctl.errors import InfeasibleError, InputError
from roarmctl.fileio import check_writable

if TYPE_CHECKING:
    from collections.abc import Callable

_W = TypeVar("_W")  # what the simulation work returns
#: Seconds of simulated motion past which a slowed-down run (``--speed-scale`` < 1) is announced with a warning.
LONG_RUN_S = 120.0


def register(app: typer.Typer) -> None:
    """Add ``simulate`` to ``app``."""
    app.command("simulate")(simulate)


def default_run_path(traj: Path) -> Path:
    """``dir/name.traj.json`` -> ``dir/name.run.json``."""
    name = traj.name
    stem = name[: -len(".traj.json")] if name.endswith(".traj.json") else traj.stem
    return traj.with_name(f"{stem}.run.json")


def simulate(
    traj_path: Path = typer.Argument(..., metavar="TRAJ", help="Trajectory file (*.traj.json) from 'roarmctl plan'."),
    output: Path | None = typer.Option(None, "--output", "-o", help="Write the run file (an execution log with the physics report and tracks)."),
    json_out: bool = typer.Option(False, "--json", help="Print one JSON object (joints, tcp, contacts, objects, ok, run, model) on stdout."),
    tolerance: float = typer.Option(10.0, "--tolerance", help="An object counts as placed within this distance of its place pose (mm)."),
    rate: float = typer.Option(50.0, "--rate", help="Commands per second, as execute would send them."),
    speed_scale: float = typer.Option(1.0, "--speed-scale", help="Slow the motion down, as execute would: 0.5 = half speed."),
    strategy: str = typer.Option("timed-lead", "--strategy", help=STRATEGY_HELP),  # execute's default
    sag: bool | None = typer.Option(None, "--sag/--no-sag", help=SAG_HELP + " As execute sends it."),
    settle: float = typer.Option(1.0, "--settle", help="Seconds simulated after the last command (the arm and objects come to rest)."),
    robot_desc: str | None = typer.Option(None, "--robot", help="Simulate on this description instead of the trajectory's robot (same joint names), e.g. one with its CAD meshes."),
) -> None:
    """Run a trajectory on a physics model of the arm (servos, gravity, payload, contact) and report.

    The servos get the commands execute would send (same schedule); the report gives per-joint
    tracking and peak torque against stall, the TCP error and sag at rest, every contact the plan did
    not intend, and whether each picked object was lifted and placed. Exit 3 when an object is not
    placed within --tolerance, an unintended contact happens, or a pick's object is not in the
    trajectory's scene. The servos' stiffness is the ST3235's position loop at the firmware's P gain
    (16), calibrated on a sister servo (STS3215) and assumed proportional to P (docs/physics.md).
    """
    from roarmctl.motion.validate import robot_of, validate_trajectory
    from roarmctl.robot.loader import load_robot

    if not 0.1 <= tolerance <= 1000.0:  # the flag's mm; the options object's bound is in m (and NaN fails here too)
        raise InputError(f"--tolerance: {tolerance:g} mm is out of range", "use 0.1 to 1000 mm")
    if output is not None:
        check_writable(output)  # before the run: a path that cannot be written fails at once
        common.not_the_input(output, traj_path, "-o")
    traj = validate_trajectory(traj_path)
    robot = load_robot(robot_desc) if robot_desc is not None else robot_of(traj, str(traj_path))
    if robot_desc is not None:
        if list(robot.joint_names) != list(traj.joint_names):
            raise InputError(f"--robot {robot_desc}: its joints ({', '.join(robot.joint_names)}) are not the trajectory's "
                             f"({', '.join(traj.joint_names)})", "give a description of the same arm")
        from roarmctl.motion.validate import check_against_robot

        check_against_robot(traj, robot, str(traj_path))
    from roarmctl.device.execlog import write_log
    from roarmctl.device.sag import wanted
    from roarmctl.physics.report import measure, run_log
    from roarmctl.physics.run import Options
    from roarmctl.physics.run import simulate as run
    from roarmctl.physics.setup import build

    options = Options(rate=rate, strategy=strategy, speed_scale=speed_scale, settle=settle, tolerance=tolerance / 1e3,
                      sag=wanted(sag))  # execute's default: the physics servos sag
    sag = options.sag
    schedule = None
    if robot.wire:  # built once, here: its input errors come before the model is built
        from roarmctl.device.schedule import build_schedule

        schedule = build_schedule(traj, robot, rate=rate, speed_scale=speed_scale, strategy=strategy, sag=sag)
    motion = traj.duration / speed_scale + settle
    if speed_scale < 1.0 and motion > LONG_RUN_S:  # physics costs per simulated second: 1,000x slower, 1,000x longer
        common.warn(f"--speed-scale {speed_scale:g} makes {motion:,.0f} s of motion to simulate ({1 / speed_scale:,.0f}x "
                    f"the trajectory's {traj.duration:.1f} s; the physics takes about as long or longer): give a larger "
                    "--speed-scale, or Ctrl-C to stop")
    setup = build(traj, robot)
    setup, rec = _with_progress(lambda progress: run(traj, robot, options, setup=setup, progress=progress, schedule=schedule),
                                traj.duration / speed_scale + settle, json_out)
    report = measure(traj, robot, setup, rec, options)
    if output is not None:

        write_log(output, run_log(traj, robot, setup, rec, options, report, source=robot_desc))
    if json_out:
        common.print_json({k: report[k] for k in ("ok", "joints", "tcp", "contacts", "objects", "unmatched_payloads", "run", "model")}
                          | ({"run_file": str(output)} if output is not None else {}))
    else:
        _render(report, output)
    if not report["ok"]:
        bad = [o for o in report["objects"] if not o["placed"]]
        parts = [f"'{o['name']}' {'not lifted' if not o['lifted'] else 'placed'} {o['error_mm']:.1f} mm from its place pose"
                 for o in bad]
        if report["contacts"]:
            c = report["contacts"][0]
            who = c.get("link") or c.get("item")
            parts.append(f"{len(report['contacts'])} unintended contact(s), first {who} with {c['with']} at {c['start_s']:.2f} s")
        for u in report["unmatched_payloads"]:
            parts.append(f"payload {u['payload']} (grasp at {u['grasp_s']:.2f} s) picks no object of the trajectory's "
                         "scene: nothing there to lift")
        hint = f"tolerance {tolerance:g} mm; see the report" + (f" and {output}" if output else "")
        if report["unmatched_payloads"] and not bad and not report["contacts"]:
            hint = "plan it again with the object in the plan's scene (an item of role object where the pick is)"
        sag_mm = report["tcp"]["sag_mm"]
        if not sag and any(o["lifted"] for o in bad) and sag_mm is not None and sag_mm > tolerance / 2:
            hint = f"the servos sag up to {sag_mm:.0f} mm at rest: drop --no-sag (execute compensates by default); " + hint
        raise InfeasibleError("simulate: " + "; ".join(parts), hint)


def _with_progress(work: "Callable[[Callable[[float, float], None] | None], _W]", total: float, quiet: bool) -> "_W":
    """Run ``work(progress)`` with a rich progress bar on stderr (a terminal only, not with --json). Each report also
    raises a stop signal whose exception Python discarded (``signals.check``), with or without the bar."""
    err = common.console(stderr=True)
    if quiet or not err.is_terminal:
        return work(lambda done, tot: signals.check())
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("simulating"), BarColumn(), TextColumn("{task.completed:.1f}/{task.total:.1f} s"),
                  TimeElapsedColumn(), console=err, transient=True) as bar:
        task = bar.add_task("sim", total=total)
        def progress(done: float, tot: float) -> None:
            signals.check()
            bar.update(task, completed=done, total=tot)

        return work(progress)


def _render(report: dict, output: Path | None) -> None:
    from rich.table import Table

    out = common.console()
    t = Table(title="Joints (tracking against the plan; servo torque against stall)")
    for col in ("joint", "RMS", "max", "peak torque", "stall", "share", "at stall", "plan needs"):
        t.add_column(col)
    for j in report["joints"]:
        unit = j["unit"]
        need = "-"
        if "needed_nm" in j:
            need = f"{j['needed_nm']:.2f} N m" + (" [bold red](over stall)[/]" if j["over_stall"] else "")
        t.add_row(common.shown(j["name"]), f"{j['rms']:.2f} {unit}", f"{j['max']:.2f} {unit}",
                  f"{j['peak_torque_nm']:.2f} N m" if "peak_torque_nm" in j else "-",
                  f"{j['stall_nm']:.2f} N m" if "stall_nm" in j else "-",
                  f"{100 * j['peak_share_of_stall']:.0f} %" if "peak_share_of_stall" in j else "-",
                  "[bold red]yes[/]" if j.get("at_stall") else "no", need)
    out.print(t)
    tcp = report["tcp"]
    out.print(f"TCP error: RMS {tcp['rms_mm']:.1f} mm, max {tcp['max_mm']:.1f} mm (against the plan {tcp['lag_ms']:.0f} ms "
              f"late: RMS {tcp['rms_after_lag_mm']:.1f} mm); final {tcp['final_mm']:.1f} mm"
              + (f"; sag at rest up to {tcp['sag_mm']:.1f} mm" if tcp["sag_mm"] is not None else ""))
    for r in tcp["rests"]:
        out.print(f"  at rest {r['start_s']:.2f}-{r['end_s']:.2f} s ({common.shown(r['label'])}): {r['error_mm']:.1f} mm off, "
                  f"{r['below_mm']:.1f} mm below" + (f" (goals raised {r['compensated_mm']:.1f} mm against the sag)"
                                                     if "compensated_mm" in r else ""))
    for o in report["objects"]:
        verdict = "[green]placed[/]" if o["placed"] else ("[red]not lifted[/]" if not o["lifted"] else "[red]not placed[/]")
        out.print(f"object {common.shown(o['name'])} ({o['mass_kg'] * 1e3:.0f} g): {verdict}, {o['error_mm']:.1f} mm and {o['error_deg']:.1f} deg "
                  f"from its place pose (lifted {o['lift_mm']:.0f} mm)")
    if report["contacts"]:
        out.print(f"[red]{len(report['contacts'])} unintended contact(s)[/]:")
        for c in report["contacts"]:
            who = c.get("link") or c.get("item")
            out.print(f"  {common.shown(who)} with {common.shown(c['with'])} from {c['start_s']:.2f} to {c['end_s']:.2f} s, {c['depth_mm']:.2f} mm deep")
    else:
        out.print("no unintended contact")
    for note in report["model"]["notes"]:
        out.print(f"note: {common.shown(note)}")
    run = report["run"]
    out.print(f"simulated {run['simulated_s']:.2f} s in {run['wall_s']:.2f} s (x{run['real_time_factor']})"
              + (f"; run file {common.shown(output)}" if output is not None else ""))
