"""``roarmctl execute`` (stream a trajectory to the arm, the simulator, or a file), ``sim-device``
(the firmware simulator on a pseudo-terminal) and ``ports`` (serial ports, likely arm marked)."""

import re
import sys
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from roarmctl.cli import common, signals
from roarmctl.device.ports import list_ports, port_holders
from roarmctl.device.session import run_execution
from roarmctl.errors import InputError
from roarmctl.fileio import atomic_write_bytes

if TYPE_CHECKING:
    from collections.abc import Callable

    from rich.console import Console

    from roarmctl.device.schedule import Tick
    from roarmctl.device.servos import ServoModel
    from roarmctl.device.sim_config import Bogus, SimConfig
    from roarmctl.device.streamer import Status, StreamConfig
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

SERVOS_HELP = ("The simulated servos: physics (default: MuJoCo, the ST3235 model with lag, gravity and torque limits; "
               "docs/physics.md) or ideal (each servo runs its trapezoid exactly, no lag, no gravity).")
SAG_HELP = ("Offset each goal by the servos' sag under gravity and the held payload (the ST3235's P-only loop; "
            "docs/physics.md): on by default, --no-sag sends the plan's own goals.")
STRATEGY_HELP = ("Streaming strategy: timed-lead, timed, timed-acc, per-joint, timed-shared, dense, dense-ahead "
                 "(compared in docs/guide.md, 'Talking to the firmware').")


def register(app: typer.Typer) -> None:
    """Add ``execute``, ``sim-device`` and ``ports`` to the app."""
    app.command("execute")(execute)
    app.command("sim-device")(sim_device)
    app.command("ports")(ports)


def default_log_path(traj: Path) -> Path:
    """Where a run of ``NAME.traj.json`` logs by default: ``NAME.exec.json`` beside it."""
    name = traj.name
    stem = name[: -len(".traj.json")] if name.endswith(".traj.json") else traj.stem
    return traj.with_name(f"{stem}.exec.json")


# --------------------------------------------------------------------------- execute
def execute(
    traj_path: Path = typer.Argument(..., metavar="TRAJ", help="Trajectory file (*.traj.json) from 'roarmctl plan'."),
    port: str | None = typer.Option(None, "--port", "-p", help="Serial port of the arm (/dev/ttyUSB0, COM3, or a pyserial URL)."),
    sim: bool = typer.Option(False, "--sim", help="Run against the built-in firmware simulator (over a real pseudo-terminal)."),
    output: Path | None = typer.Option(None, "--output", "-o", help="Write the commands that would be sent (JSON lines) instead; no device."),
    rate: float = typer.Option(50.0, "--rate", help="Commands per second (at most 90 at 115200 baud)."),
    speed_scale: float = typer.Option(1.0, "--speed-scale", help="Slow the motion down: 0.5 = half speed (0.001 <= S <= 1)."),
    strategy: str = typer.Option("timed-lead", "--strategy", help=STRATEGY_HELP),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation before moving the arm."),
    move_to_start: bool = typer.Option(False, "--move-to-start", help="If the arm is not at the first point, plan a collision-checked, timed motion there first (the trajectory's scene, limits and planner)."),
    from_current: bool = typer.Option(False, "--from-current", help="If the arm is not at the first point, plan the first free motion again from where it is."),
    max_error: float = typer.Option(30.0, "--max-error", help="Abort (and hold) when the TCP tracking error exceeds this (mm)."),
    sag: bool | None = typer.Option(None, "--sag/--no-sag", help=SAG_HELP + " With --sim --servos ideal off by default (ideal servos do not sag)."),
    servos: str | None = typer.Option(None, "--servos", help="With --sim: the simulated servos, physics (the default: MuJoCo, "
                                      "the ST3235 model with its 46 ms lag, gravity, the trajectory's scene and payload; "
                                      "docs/physics.md) or ideal (each runs its trapezoid exactly, no lag, no gravity)."),
    firmware: str | None = typer.Option(None, "--firmware", help="With --sim: which firmware to imitate, as sim-device: "
                                        "m3-0.84 (default for an M3), m3-2026 (one queued line per loop pass), m2."),
    boot: bool = typer.Option(False, "--boot/--no-boot", help="With --sim: start like a powered-on arm (boot text, silence, "
                              "boot moves), as sim-device does by default."),
    loop_pass: float | None = typer.Option(None, "--loop-pass", metavar="MS", help="With --sim: the firmware's loop pass (ms; "
                                           "default the model's own, about 3 ms on 0.84 and 6 ms on 20260701): rehearse a slow loop."),
    log: Path | None = typer.Option(None, "--log", help="Execution log (JSON); default: next to TRAJ as NAME.exec.json."),
    json_out: bool = typer.Option(False, "--json", help="Print one JSON summary object on stdout, nothing else."),
) -> None:
    """Stream a trajectory to the RoArm (--port), the simulator (--sim), or a file (--output).

    Before moving it checks the arm answers like the robot the trajectory is for (M3 or M2), that it stands at the trajectory's first
    point, and asks for confirmation (real arms only) unless --yes. Ctrl-C makes the arm hold where
    it is (torque stays on) and exits 130; a lost link exits 4. Every command and every feedback
    line is written to the execution log.
    """
    from roarmctl.device.streamer import StreamConfig, build_schedule
    from roarmctl.motion.validate import robot_of, validate_trajectory
    from roarmctl.physics.sim_servos import check_servos, sim_servos

    chosen = [n for n, v in (("--port", port), ("--sim", sim or None), ("--output", output)) if v]
    if len(chosen) != 1:
        raise InputError("give exactly one of --port PORT, --sim, --output FILE" + (f" (got {', '.join(chosen)})" if chosen else ""),
                         "e.g. roarmctl execute pick_place.traj.json --port /dev/ttyUSB0")
    if not 0 < max_error <= 1000:  # StreamConfig's bound is in m; a NaN is refused here too
        raise InputError(f"--max-error: {max_error:g} mm is outside (0, 1000]", "the TCP tracking bound, e.g. 30")
    if servos is not None and not sim:
        raise InputError("--servos: only with --sim (a real arm has its own servos)")
    given = [n for n, v in (("--firmware", firmware), ("--boot", boot or None), ("--loop-pass", loop_pass)) if v is not None]
    if given and not sim:
        raise InputError(f"{given[0]}: only with --sim (a real arm has its own firmware)")
    servos = servos or "physics"
    check_servos(servos, sim=sim)
    common.not_the_input(output, traj_path, "--output")
    common.not_the_input(log or default_log_path(traj_path), traj_path, "--log")
    traj = validate_trajectory(traj_path)  # limits, speeds and steps: nothing unchecked reaches the port
    robot = robot_of(traj, str(traj_path))
    factory, sag = sim_servos(robot, traj, servos, sim=sim, sag=sag)
    if move_to_start and from_current:
        raise InputError("give one of --move-to-start and --from-current, not both")
    cfg = StreamConfig(rate=rate, speed_scale=speed_scale, strategy=strategy, max_error=max_error / 1e3,
                       move_to_start=move_to_start, from_current=from_current, sag=sag)
    if output is not None:
        schedule = build_schedule(traj, robot, rate=rate, speed_scale=speed_scale, strategy=strategy, sag=sag)
        _write_output(output, schedule)
        # "commands" means the same everywhere (--port, --sim, --output, the log's summary): the
        # motion commands, one T:102 per tick; gripper T:101 lines sent beside them are counted apart
        gripper = sum(len(tk.extra) for tk in schedule)
        info = {"output": str(output), "commands": len(schedule), "gripper_commands": gripper, "lines": len(schedule) + gripper,
                "duration": schedule[-1].t, "rate": rate, "strategy": strategy, "speed_scale": speed_scale}
        if json_out:
            common.print_json(info)
        else:
            extra = f" + {gripper} gripper commands" if gripper else ""
            common.console(stderr=True).print(f"wrote {info['commands']} motion commands{extra} ({schedule[-1].t:.2f} s at {rate:g} Hz) to {common.shown(output)}")
        return
    if port is not None and not yes and not sys.stdin.isatty():
        raise InputError("refusing to ask for confirmation: stdin is not a terminal", "pass --yes to execute without asking")
    sim_config = None
    if sim:
        from roarmctl.device.protocol import WireMap

        model = WireMap(robot).model
        sim_config = sim_build(firmware or ("m2" if model == "m2" else "m3-0.84"), loop_pass, boot=boot)
        if (sim_config.firmware == "m2") != (model == "m2"):
            raise InputError(f"--firmware {sim_config.firmware}: the trajectory is for a RoArm-{(model or 'm3').upper()}",
                             "give the firmware of the arm it is for")
    _run(traj, traj_path, robot, cfg, port, sim, yes, log or default_log_path(traj_path), json_out, factory, sim_config)


def _write_output(path: Path, schedule: "list[Tick]") -> None:
    from roarmctl.device.protocol import encode

    lines = [b'{"t":' + repr(round(tk.t, 6)).encode() + b',"cmd":' + encode(cmd)[:-1] + b"}\n"
             for tk in schedule for cmd in tk.commands]
    atomic_write_bytes(path, b"".join(lines))


def sim_build(firmware: str, loop_pass: float | None, **fields: Any) -> "SimConfig":
    """The simulator's ``SimConfig`` for ``--firmware`` and ``--loop-pass`` (ms: the whole pass, the model's own
    work included), checked; ``fields``: the other ``SimConfig`` fields."""
    from roarmctl.device.sim_config import SimConfig, own_pass

    if firmware not in ("m3-0.84", "m3-2026", "m2"):
        raise InputError(f"--firmware: unknown '{firmware}'", "choose m3-0.84, m3-2026 or m2")
    period = 0.0
    if loop_pass is not None:
        least = own_pass(firmware) * 1e3
        if not least <= loop_pass <= 1000.0:  # NaN fails both
            raise InputError(f"--loop-pass: {loop_pass:g} ms is outside {least:.1f}..1000 ms",
                             f"the model's own pass on {firmware} is {least:.1f} ms; e.g. 22 for a slow 20260701 loop")
        period = loop_pass / 1e3 - own_pass(firmware)
    return SimConfig(firmware=firmware, loop_period=period, **fields)


def _run(traj: "Trajectory", traj_path: Path, robot: "Robot", cfg: "StreamConfig", port: "str | None", sim: bool,
         yes: bool, log_path: Path, json_out: bool, sim_servos: "Callable[[], ServoModel] | None" = None,
         sim_config: "SimConfig | None" = None) -> None:
    err = common.console(stderr=True)
    live = _Display(err, len(robot.joint_names), robot) if (err.is_terminal and not json_out) else None

    def confirm(message: str) -> bool:
        if yes or sim:
            return True
        return typer.confirm(message, default=False, err=True)

    if not sim:
        assert port is not None  # one of --port, --sim, --output (checked by the command; --output does not stream)
        holders = [f"{pid} ({name})" for pid, name in port_holders(port)]
        if holders:  # one line, however many (a shell's /dev/null given as the port is open in every shell)
            more = f" and {len(holders) - 3} more" if len(holders) > 3 else ""
            common.warn(f"{port} is also open in process{'es' if len(holders) > 1 else ''} {', '.join(holders[:3])}{more}; "
                        "it may swallow the arm's replies (stop it, e.g. 'sudo systemctl stop ModemManager')")

    def note(sentence: str) -> None:
        if not json_out:
            err.print(f"note: {common.shown(sentence)}")

    def log_error(path: Path, exc: Exception) -> None:
        common.warn(f"could not write the execution log {path} ({getattr(exc, 'strerror', None) or exc}); pass --log FILE")

    def info(line: str) -> None:  # what connecting learned: part of the display (a terminal), always in the log
        if live is not None:
            err.print(line, highlight=False, soft_wrap=True)

    run = run_execution(traj, robot, cfg, port=port, sim=sim, log_path=log_path, confirm=confirm,
                        on_status=partial(_status, live.update if live else None), on_start=live.start if live else None,
                        on_note=note, on_end=live.stop if live else None, shield=signals.shielded,
                        on_log_error=log_error, on_info=info, sim_servos=sim_servos, sim_config=sim_config)
    result, port = run.result, run.port
    summary = result.summary() | {"log": str(log_path), "notes": result.log.get("notes", []),
                                  "final_pose": result.log.get("final_pose")}
    if run.simulator is not None:
        summary["simulator"] = run.simulator
    if json_out:
        common.print_json(summary)
        return
    out = common.console()
    trk, lat = summary["tracking_mm"], summary["lateness_ms"]
    out.print(f"[bold green]done[/]: {summary['commands']} motion commands in {run.traj.duration / cfg.speed_scale:.2f} s on {common.shown(port)}")
    out.print(f"schedule lateness p50 {lat['p50']:.2f} ms, p99 {lat['p99']:.2f} ms, max {lat['max']:.2f} ms")
    if trk["rms"] is not None:
        out.print(f"TCP tracking error (feedback): RMS {trk['rms']:.1f} mm, max {trk['max']:.1f} mm over {trk['samples']} samples")
    if run.simulator is not None and summary["simulator"]["rms_mm"] is not None:
        s = summary["simulator"]
        out.print(f"TCP tracking error (simulator, true): RMS {s['rms_mm']:.2f} mm, max {s['max_mm']:.2f} mm")
    if summary["final_pose"]:
        out.print("arm at: " + ", ".join(f"{k.rsplit('_', 1)[0]} ({', '.join(f'{v:.4g}' for v in xyz)}) {k.rsplit('_', 1)[1]}"
                                         for k, xyz in summary["final_pose"].items()))
    out.print(f"log: {common.shown(log_path)}")


class _Display:
    """The live view on stderr: progress, time, lateness, tracking error, commanded vs measured joints."""

    def __init__(self, console: "Console", dof: int, robot: "Robot | None" = None) -> None:
        self.console = console
        self.dof = dof
        self.robot = robot
        self.live: Any = None
        self._n = 0

    def start(self) -> None:
        from rich.live import Live

        self.live = Live(console=self.console, auto_refresh=False, transient=False)
        self.live.start()

    def stop(self) -> None:
        if self.live is not None:
            self.live.stop()

    def update(self, st: "Status") -> None:
        self._n += 1
        if self.live is None or (self._n % 8 and st.k != st.n - 1):
            return  # about 6 redraws/s at 50 Hz: drawing costs time the schedule needs
        import numpy as np
        from rich.progress_bar import ProgressBar
        from rich.table import Table

        grid = Table.grid(padding=(0, 2))
        grid.add_row(ProgressBar(total=st.n, completed=st.k + 1, width=40),
                     f"{st.t:6.2f} / {st.duration:.2f} s",
                     f"late {st.lateness * 1e3:5.2f} ms",
                     "err   -   " if st.error is None else f"err {st.error * 1e3:5.1f} mm")
        joints = Table("", *[f"j{i + 1}" for i in range(self.dof)], box=None, pad_edge=False)
        joints.add_row("cmd deg", *[f"{v:7.1f}" for v in np.degrees(st.commanded)])
        if st.measured is not None:
            joints.add_row("meas deg", *[f"{v:7.1f}" for v in np.degrees(st.measured)])
        outer = Table.grid()
        outer.add_row(grid)
        outer.add_row(joints)
        if st.measured is not None and self.robot is not None:  # where the TCP is, in both frames
            from roarmctl.robot.frames import device_point, to_frame

            p = self.robot.kin.fk(st.measured)[:3, 3]
            text = f"TCP world ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
            for name, fr in (getattr(self.robot, "frames", {}) or {}).items():
                f = to_frame(fr, device_point(self.robot, fr, st.measured))
                text += f"   {name} ({f[0]:.1f}, {f[1]:.1f}, {f[2]:.1f}) {fr.unit}"
            outer.add_row(text)
        self.live.update(outer, refresh=True)


# --------------------------------------------------------------------------- sim-device
def sim_device(
    firmware: str | None = typer.Option(None, "--firmware", help="Which firmware to imitate: m3-0.84 (default), m3-2026, m2."),
    servos: str | None = typer.Option(None, "--servos", help=SERVOS_HELP + " With --guide: ideal."),
    model: str | None = typer.Option(None, "--model", help="Imitate this robot's firmware, from its description's wire map "
                                        "(e.g. roarm_m2_s -> m2, roarm_m3_pro -> m3-0.84)."),
    info_print: int = typer.Option(2, "--info-print", help="InfoPrint level at start (factory 2 = continuous feedback)."),
    boot: bool = typer.Option(True, "--boot/--no-boot", help="Start like a powered-on arm: boot text, silence, boot moves."),
    loop_pass: float | None = typer.Option(None, "--loop-pass", metavar="MS", help="The firmware's loop pass (ms; default the "
                                           "model's own, about 3 ms on 0.84 and 6 ms on 20260701): rehearse a slow loop."),
    link: Path | None = typer.Option(None, "--link", help="Also make this symlink to the pseudo-terminal (e.g. /tmp/ttyROARM)."),
    json_out: bool = typer.Option(False, "--json", help="Print {\"port\": PATH, \"pty\": PTY, \"firmware\": NAME} as JSON (port: the --link if given)."),
    fail_reads: list[str] = typer.Option([], "--fail-reads", metavar="JOINT=P", help="Fault: each read of JOINT's servo fails "
                                         "with probability P (it then keeps its old value, 0 steps if it never read; 100 ms lost). Repeatable."),
    unpowered: bool = typer.Option(False, "--unpowered", help="Fault: servo supply off (every read fails; 20260701: v = 0, torque flags 0)."),
    voltage: float = typer.Option(12.0, "--voltage", help="Fault: supply voltage (V); the 20260701 build warns outside 6.00-12.90 V."),
    torque_off: bool = typer.Option(False, "--torque-off", help="Fault: the servos start limp (20260701 reports torque flags 0)."),
    esp_now_leader: bool = typer.Option(False, "--esp-now-leader", help="Fault: a leader arm nearby broadcasts its pose; "
                                        "this arm obeys while in ESP-NOW follower mode (the default)."),
    bogus: list[str] = typer.Option([], "--bogus", metavar="KEY=VALUE[@N[xM]]", help="Fault: print T:1051 key KEY as the raw "
                                    "text VALUE, from the first frame after N motion commands, for M frames (0 = all; "
                                    "default 1). E.g. e=2.9@40x5, b=4.0, g=0. Repeatable."),
    mute_after: int | None = typer.Option(None, "--mute-after", metavar="N", help="Fault: print nothing after N motion commands."),
    stuck: list[str] = typer.Option([], "--stuck", metavar="JOINT", help="Fault: JOINT's servo is blocked and never moves. Repeatable."),
    deaf: bool = typer.Option(False, "--deaf", help="Fault: nothing sent to the arm arrives."),
    silent: bool = typer.Option(False, "--silent", help="Fault: the arm never says anything."),
    boot_mission: list[str] = typer.Option([], "--boot-mission", metavar="JSON", help="A line of the flash mission 'boot' "
                                           "(run at start-up unless serial input is waiting). Repeatable."),
    guide: Path | None = typer.Option(None, "--guide", metavar="FILE", help="While torque is off, a hand moves the arm "
                                      "along FILE: a YAML list of {t: s, joints: [rad x 5], gripper: rad} (docs/guide.md, "
                                      "'Teaching by hand')."),
) -> None:
    """Start the firmware simulator on a pseudo-terminal, print its path, and serve until Ctrl-C.

    Any program can open the path like the arm's /dev/ttyUSB0: roarmctl itself, Waveshare's
    roarm_sdk, or a terminal (115200 baud, JSON lines). The fault options rehearse what a real arm
    can do to its host.
    """
    from roarmctl.device.simulator import PtySimulator

    if model is not None:
        from roarmctl.device.protocol import WireMap
        from roarmctl.robot.loader import load_robot

        kind = WireMap(load_robot(model, trust_sidecar=True)).model
        if firmware is not None and (firmware == "m2") != (kind == "m2"):
            raise InputError(f"--firmware {firmware} does not match --model {model} (a RoArm-{(kind or 'm3').upper()})",
                             "give one of them")
        firmware = firmware or ("m2" if kind == "m2" else "m3-0.84")
    firmware = firmware or "m3-0.84"
    if firmware not in ("m3-0.84", "m3-2026", "m2"):
        raise InputError(f"--firmware: unknown '{firmware}'", "choose m3-0.84, m3-2026 or m2")
    if info_print not in (0, 1, 2):
        raise InputError("--info-print: must be 0, 1 or 2")
    config = sim_build(firmware, loop_pass, info_print=info_print, boot=boot, unpowered=unpowered, voltage=voltage,
                       torque_off=torque_off, esp_now_leader=esp_now_leader, mute_after=mute_after, deaf=deaf,
                       silent=silent, fail_reads=_joint_values("--fail-reads", fail_reads),
                       bogus=tuple(_bogus(b) for b in bogus), stuck=tuple(_joint("--stuck", j) for j in stuck),
                       boot_mission=tuple(boot_mission))
    if not 0 < voltage < 100:
        raise InputError(f"--voltage: {voltage:g} V is not a supply voltage")
    servos = servos or ("ideal" if guide is not None else "physics")
    if servos not in ("physics", "ideal"):
        raise InputError(f"--servos: '{servos}' is not physics or ideal")
    if link is not None:
        _check_link(link)
    factory: Callable[[], ServoModel] | None = None
    if guide is not None:
        from roarmctl.device.guide import guided_servos, load_guide

        if servos != "ideal":
            raise InputError("--guide moves the ideal servos; the physics servos do not take a hand yet", "drop --servos physics")
        factory = guided_servos(load_guide(guide), config.max_speed)
    elif servos == "physics":
        from roarmctl.physics.servo_backend import for_firmware
        from roarmctl.robot.loader import load_robot

        arm = load_robot(model, trust_sidecar=True) if model is not None else load_robot("roarm_m2_s" if firmware == "m2" else "roarm_m3_pro")
        factory = for_firmware(arm)
    # the firmware in a process of its own (its own clock, real-time priority where allowed): a serving thread still
    # stepping MuJoCo when a stop signal ended this interpreter crashed it (SIGSEGV) on a busy machine
    simulator = PtySimulator(config, servos=factory, process=True).start()
    made_link = False
    try:  # Ctrl-C, SIGTERM and SIGHUP (roarmctl.cli.signals) end it the same way: exit 0, link removed
        path = simulator.path
        if link is not None:
            try:
                if link.is_symlink():
                    link.unlink()
                link.symlink_to(simulator.path)
                made_link = True
                path = str(link)
            except OSError as exc:
                raise InputError(f"--link: cannot create {link} ({exc.strerror})") from None
        if json_out:
            common.print_json({"port": path, "pty": simulator.path, "firmware": firmware})
        else:
            print(path)
            model = "RoArm-M2" if firmware == "m2" else "RoArm-M3"
            common.console(stderr=True).print(f"simulating {model} firmware {firmware} on {simulator.path}; Ctrl-C to stop")
        sys.stdout.flush()
        while simulator.alive():
            simulator.join(0.5)
            signals.check()  # a stop whose exception Python discarded (in a finalizer) still stops the simulator
        if simulator.error is not None:
            raise simulator.error
    except KeyboardInterrupt:
        pass
    finally:
        with signals.shielded():
            simulator.stop()
            if made_link and link is not None and link.is_symlink():
                link.unlink()


def _check_link(link: Path) -> None:
    """A ``--link`` path may be replaced only when it is free or a symlink to a pseudo-terminal (what sim-device makes,
    left by a run killed outright); anything else is the user's (a file, a link elsewhere), and it was removed."""
    if not link.is_symlink():
        if link.exists():
            raise InputError(f"--link: {link} exists and is not a symlink sim-device made", "give another name")
        return
    try:
        target = str(link.readlink())
    except OSError as exc:
        raise InputError(f"--link: cannot read {link} ({exc.strerror})") from None
    if not target.startswith("/dev/pts/"):
        raise InputError(f"--link: {link} is a symlink to {target}, not to a pseudo-terminal sim-device made",
                         "give another name, or remove the link yourself")


def _status(show: "Callable[[Any], None] | None", status: Any) -> None:
    """After each tick of the motion: a stop whose exception Python discarded (raised inside a finalizer or a
    garbage-collector callback) is raised here, so the arm holds as on any Ctrl-C; then the display, if any."""
    signals.check()
    if show is not None:
        show(status)


def _joint(option: str, name: str) -> str:
    from roarmctl.device.servos import JOINTS

    if name not in JOINTS:
        raise InputError(f"{option}: unknown joint '{name}'", f"one of {', '.join(JOINTS)}")
    return name


def _joint_values(option: str, items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        name, _, value = item.partition("=")
        try:
            p = float(value)
        except ValueError:
            raise InputError(f"{option}: '{item}' is not JOINT=P", "e.g. --fail-reads base=0.05") from None
        if not 0 <= p <= 1:
            raise InputError(f"{option}: probability {p:g} is outside [0, 1]")
        out[_joint(option, name)] = p
    return out


def _bogus(text: str) -> "Bogus":
    from roarmctl.device.simulator import Bogus

    m = re.fullmatch(r"([A-Za-z]+)=([^@]+)(?:@(\d+)(?:x(\d+))?)?", text)
    if m is None:
        raise InputError(f"--bogus: '{text[:40]}' is not KEY=VALUE[@N[xM]]", "e.g. --bogus e=2.9@40x5")
    return Bogus(m.group(1), m.group(2), int(m.group(3) or 0), int(m.group(4)) if m.group(4) is not None else 1)


# --------------------------------------------------------------------------- ports
def ports(json_out: bool = typer.Option(False, "--json", help="Print one JSON object.")) -> None:
    """List serial ports; the likely arm (CP210x 10C4:EA60, CH340 1A86:7523) is marked."""
    found = list_ports()
    if json_out:
        common.print_json({"ports": [p.as_dict() for p in found]})
        return
    if not found:
        common.console(stderr=True).print("no serial ports found (is the arm plugged in? use its middle USB-C port)")
        return
    from rich.table import Table

    t = Table(title="Serial ports")
    for col in ("", "device", "VID:PID", "description", "stable path"):
        t.add_column(col)
    for p in found:
        d = p.as_dict()
        t.add_row("[bold green]arm?[/]" if p.likely_arm else "", p.device, d["vid_pid"] or "-",
                  p.description + (f" [{p.bridge}]" if p.bridge else ""), p.by_id or "-")
    common.console().print(t)
    if any(p.likely_arm for p in found):
        common.console().print("use: roarmctl execute TRAJ --port " + next(p.by_id or p.device for p in found if p.likely_arm))
