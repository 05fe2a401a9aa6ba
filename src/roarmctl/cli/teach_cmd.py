"""``roarmctl teach``: move the arm by hand with a live singularity warning, record waypoints and gripper
actions, save them as a plan. Leaving (q, Ctrl-C, SIGTERM, a lost link) never moves the arm: the measured
pose becomes every servo's goal, then torque goes on; the recording is saved."""

import math
import os
import select
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

try:  # keys without waiting need a POSIX terminal; elsewhere teach runs without keys
    import termios
    import tty
except ImportError:  # pragma: no cover - Windows
    termios = tty = None  # type: ignore[assignment]

from roarmctl.cli import common, signals
from roarmctl.errors import DeviceError, InputError, Interrupted, signal_name
from roarmctl.fileio import check_writable, note_kept_on_stop
from roarmctl.motion.options import PlannerConfig

if TYPE_CHECKING:
    from collections.abc import Callable

    from rich.console import Console
    from rich.panel import Panel

    from roarmctl.device.teach import Frame, Judge, TeachSession
    from roarmctl.plan.types import Plan
    from roarmctl.robot.model import Robot

KEYS_HELP = "Enter record a waypoint · g grasp/release here · u undo · s save · q quit"
BAND_STYLE = {"clear": "bold green", "near": "bold yellow", "inside": "bold red"}


def register(app: typer.Typer) -> None:
    """Add ``teach`` to the app."""
    app.command("teach")(teach)


def teach(
    port: str | None = typer.Option(None, "--port", "-p", help="Serial port of the arm (/dev/ttyUSB0, COM3, or a pyserial URL)."),
    sim: bool = typer.Option(False, "--sim", help="Teach the built-in firmware simulator (with --guide a scripted hand moves it)."),
    guide: Path | None = typer.Option(None, "--guide", metavar="FILE", help="With --sim: the hand's script, a YAML list of "
                                      "{t: s, joints: [rad x 5], gripper: rad} (t from torque-off; linear in between)."),
    plan: Path | None = typer.Option(None, "--plan", help="A plan whose scene (clearance, collisions), planner margin and robot apply."),
    output: Path = typer.Option(Path("taught.yaml"), "-o", "--output", help="The plan to write (on s, on leaving)."),
    raw: Path | None = typer.Option(None, "--raw", metavar="LOG", help="Also keep the feedback stream as an execution log "
                                    "(JSON; 'roarmctl export LOG -o NAME.mcap' reads it)."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before switching torque off."),
) -> None:
    """Teach by hand: torque off, move the arm, record waypoints; save them as a plan for 'roarmctl plan'.

    Keys: Enter records a waypoint, g a grasp (or release) at this pose, u undoes, s saves, q quits.
    The display shows the joints, the TCP in the desk and firmware frames, the planner's singularity measure
    (smallest singular value of the translational Jacobian) and the manipulability, and warns (with a bell)
    within 2x the planning margin. Leaving by q, Ctrl-C (exit 130), SIGTERM (143) or a lost link (4) first
    sets every servo's goal to the measured pose, then switches torque on: the arm does not move.
    """
    from roarmctl.device.link import Link
    from roarmctl.device.protocol import WireMap
    from roarmctl.device.teach import SURPRISES, Judge, TeachSession
    from roarmctl.motion.pipeline import load_plan_and_robot
    from roarmctl.motion.planning.context import scene_item
    from roarmctl.robot.loader import load_robot

    if (port is None) == (not sim):
        raise InputError("give exactly one of --port PORT and --sim", "e.g. roarmctl teach --sim --guide hand.yaml")
    if guide is not None and not sim:
        raise InputError("--guide goes with --sim (a real arm is moved by your hand)")
    source, robot = (load_plan_and_robot(plan, load=common.load_robot) if plan is not None
                     else (None, load_robot("roarm_m3_pro")))
    WireMap(robot)  # a robot without a RoArm wire map cannot be taught: say so before opening anything
    cfg = source.planner if source is not None else PlannerConfig()
    items = [scene_item(s) for s in source.scene + source.objects] if source is not None else []
    judge = Judge(robot, cfg.singularity_margin, items, cfg.padding)
    if port is not None and not yes and not sys.stdin.isatty():
        raise InputError("refusing to ask for confirmation: stdin is not a terminal", "pass --yes to teach without asking")
    check_writable(output)
    if raw is not None:
        check_writable(raw)

    err = common.console(stderr=True)
    simulator = None
    if sim:
        from roarmctl.device.guide import guided_servos, load_guide
        from roarmctl.device.simulator import PtySimulator, SimConfig

        hand = guided_servos(load_guide(guide)) if guide is not None else None
        simulator = PtySimulator(SimConfig(), servos=hand, process=True).start()
        port = simulator.path
    assert port is not None
    link = Link(port)
    link.expect = WireMap(robot).model or "m3"
    link.require_torque = False
    session: TeachSession | None = None
    keys = _Keys()
    view = _View(err, robot, judge)
    outcome, message = "failed", "stopped before teaching"
    try:
        link.open()
        info = link.connect()
        view.line(f"firmware: {info.describe()}")
        surprise = SURPRISES.get(info.firmware)
        if surprise:
            common.warn(surprise)
        if not (yes or sim) and not typer.confirm("Torque goes off: hold the arm, it will sag. Continue?", default=False, err=True):
            raise Interrupted("not confirmed; torque stays on")
        session = TeachSession(link, robot, judge, keep_raw=raw is not None)
        keys.start()
        session.start()
        view.start()
        outcome, message = _loop(session, keys, view, output, robot, judge, source)
    except KeyboardInterrupt as exc:
        signum = getattr(exc, "signum", 2)
        outcome, message = ("interrupted" if signum == 2 else "terminated"), f"stopped by {signal_name(signum)}"
        raise
    except DeviceError as exc:
        outcome, message = "link lost", exc.message
        raise
    finally:
        with signals.shielded():  # a signal now must not cut the hold, the save or the log short
            keys.stop()
            view.stop()
            held = session.hold_here() if session is not None else None
            if session is not None and session.t0 is not None and held is None:
                common.warn("could not set the servos' goals: the arm is still limp (hold it; check the cable and power)")
            link.close()
            if simulator is not None:
                simulator.stop()
            if session is not None:
                _finish(session, output, raw, robot, judge, source, outcome, message, view)


def _loop(session: "TeachSession", keys: "_Keys", view: "_View", output: Path, robot: "Robot", judge: "Judge",
          source: "Plan | None") -> tuple[str, str]:
    """Feedback, keys and display until q; returns (outcome, message)."""
    from roarmctl.device.teach_plan import save_plan

    fds = [fd for fd in (session.fileno(), keys.fileno()) if fd is not None]
    while True:
        if fds:
            select.select(fds, [], [], 0.02)
        else:
            time.sleep(0.01)
        signals.check()  # a Ctrl-C whose exception Python discarded (in a finalizer) still ends the session
        frame = session.pump()
        for key in keys.read():
            if key in ("\r", "\n"):
                _safely(session.record, view)
            elif key == "g":
                _safely(session.grasp, view)
            elif key == "u":
                session.undo()
            elif key == "s":
                if session.waypoints:
                    save_plan(output, robot, session.waypoints, judge.margin, source)
                    session.event(f"saved {len(session.waypoints)} waypoint(s) to {output}")
                else:
                    session.event("nothing recorded yet")
            elif key == "q":
                session.event("quit")
                return "quit", "quit by the user"
        view.show(session, frame)


def _safely(action: "Callable[[], object]", view: "_View") -> None:
    try:
        action()
    except DeviceError as exc:  # no recent frame to record: said, teaching goes on
        view.line(f"[yellow]not recorded[/]: {common.shown(exc.message)}")


def _finish(session: "TeachSession", output: Path, raw: Path | None, robot: "Robot", judge: "Judge",
            source: "Plan | None", outcome: str, message: str, view: "_View") -> None:
    """Save the recording and the raw log (atomically), then say where they went."""
    from roarmctl.device.execlog import write_log
    from roarmctl.device.teach_plan import save_plan

    view.flush(session)
    written = []  # what a stop signal's line says instead of "nothing was written"
    if session.waypoints:
        try:
            save_plan(output, robot, session.waypoints, judge.margin, source)
            written.append(f"the recording is in {output}")
            view.line(f"saved {len(session.waypoints)} waypoint(s) to {common.shown(output)} (plan it: roarmctl plan {common.shown(output)} --port PORT)")
        except (OSError, InputError) as exc:
            common.warn(f"could not save {output}: {exc}")
    else:
        view.line("nothing recorded: no plan written")
    if raw is not None:
        try:
            write_log(raw, session.raw_log(outcome, message))
            written.append(f"the feedback stream is in {raw}")
            view.line(f"feedback stream: {common.shown(raw)}")
        except (OSError, InputError) as exc:
            common.warn(f"could not write {raw}: {exc}")
    note_kept_on_stop("; ".join(written) or None)


class _Keys:
    """Keys from the terminal on stdin, without waiting (cbreak mode, restored on stop); none without a terminal."""

    def __init__(self) -> None:
        self.fd: int | None = None
        self._saved: Any = None

    def start(self) -> None:
        """Switch the terminal to cbreak mode (keys arrive one by one; Ctrl-C still signals)."""
        try:
            if termios is None or tty is None or not sys.stdin.isatty():
                return
            self.fd = sys.stdin.fileno()
            self._saved = termios.tcgetattr(self.fd)
            tty.setcbreak(self.fd)
        except (OSError, ValueError, ImportError, AttributeError):
            self.fd = None

    def fileno(self) -> int | None:
        """The terminal's descriptor (None: no keys)."""
        return self.fd

    def read(self) -> str:
        """The keys typed since the last call."""
        if self.fd is None:
            return ""
        out = b""
        while select.select([self.fd], [], [], 0)[0]:
            chunk = os.read(self.fd, 64)
            if not chunk:
                break
            out += chunk
        return out.decode("utf-8", errors="ignore")

    def stop(self) -> None:
        """Give the terminal its mode back."""
        if self.fd is not None and self._saved is not None and termios is not None:
            try:
                termios.tcsetattr(self.fd, termios.TCSADRAIN, self._saved)
            except (OSError, termios.error):
                pass
        self.fd = None


class _View:
    """The live display (rich, on a terminal) or, when stderr is not one, the events and a status line
    five times a second (for logs and tests)."""

    def __init__(self, console: "Console", robot: "Robot", judge: "Judge") -> None:
        self.console = console
        self.robot = robot
        self.judge = judge
        self.live: Any = None
        self.shown = 0  # events printed (plain mode)
        self._last = 0.0

    def start(self) -> None:
        """Start the live display (a terminal only)."""
        if self.console.is_terminal:
            from rich.live import Live

            self.live = Live(console=self.console, auto_refresh=False, transient=False)
            self.live.start()

    def stop(self) -> None:
        """Stop the live display (its last frame stays)."""
        if self.live is not None:
            self.live.stop()
            self.live = None

    def line(self, text: str) -> None:
        """One line above the display."""
        self.console.print(text, highlight=False, soft_wrap=True)

    def flush(self, session: "TeachSession") -> None:
        """Events not yet printed (plain mode)."""
        if self.live is None:
            for t, text in session.events[self.shown:]:
                self.line(f"[{t:7.2f} s] {common.shown(text)}")
            self.shown = len(session.events)

    def show(self, session: "TeachSession", frame: "Frame | None") -> None:
        """Redraw (about 10 times a second) and ring the bell on entering the warning band."""
        rang = any(t.startswith("warning") for _, t in session.events[self.shown:])
        if rang:
            self.console.bell()
        if self.live is None:
            self.flush(session)
        now = time.monotonic()
        if now - self._last < (0.1 if self.live is not None else 0.2) or session.frame is None:
            return
        self._last = now
        if self.live is not None:
            self.live.update(render(session, self.judge), refresh=True)
            self.shown = len(session.events)
        else:
            f, m = session.frame, session.frame.measures
            q = " ".join(f"{v:.4f}" for v in f.q)
            self.line(f"[{f.t:7.2f} s] q {q} | sigma {m.sigma:.4f} {m.band} | {f.rate:.0f} Hz")


def _joint_labels(session: "TeachSession") -> list[str]:
    """Column names: the firmware's names of the joints (base, shoulder, ...), else the description's."""
    names = list(session.robot.joint_names)
    for w, i in zip(session.wm.fields, session.wm.index):
        names[i] = "gripper" if w.field == "hand" else w.field
    return names


def render(session: "TeachSession", judge: "Judge") -> "Panel":
    """The live frame: joints, TCP (desk and firmware frames), singularity measure with its band, clearance,
    recorded waypoints, the last events and the keys."""
    from rich.panel import Panel
    from rich.table import Table
    from rich.text import Text

    from roarmctl.device.teach import NEAR_FACTOR

    f = session.frame
    assert f is not None  # shown once the first frame has arrived (_View.show)
    m = f.measures
    grid = Table.grid(padding=(0, 2))
    joints = Table(*["", *_joint_labels(session)], box=None, pad_edge=False)
    joints.add_row("deg", *[f"{math.degrees(v):7.1f}" for v in f.q])
    joints.add_row("rad", *[f"{v:7.4f}" for v in f.q])
    grid.add_row(joints)
    p = f.tcp_world
    tcp = f"TCP desk ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
    for name, (xyz, unit) in f.tcp_frames.items():
        tcp += f"   {name} frame ({xyz[0]:.1f}, {xyz[1]:.1f}, {xyz[2]:.1f}) {unit}"
    if f.firmware_xyz is not None:
        x, y, z = f.firmware_xyz
        tcp += f" (arm: {x:.1f}, {y:.1f}, {z:.1f})"
    grid.add_row(tcp)
    band = Text()
    band.append(f" {m.band.upper():7s}", style=BAND_STYLE[m.band])
    width = 20
    scale = 4 * judge.margin if judge.margin > 0 else 0.2
    filled = max(0, min(width, int(round(width * m.sigma / scale))))
    band.append("█" * filled, style=BAND_STYLE[m.band])
    band.append("·" * (width - filled), style="dim")
    band.append(f"  sigma_min {m.sigma:.4f} m/rad  margin {judge.margin:.4f} (warn < {NEAR_FACTOR * judge.margin:.4f})"
                f"  manipulability {m.manipulability:.2e}")
    grid.add_row(band)
    if m.band != "clear":
        grid.add_row(Text(" WARNING: near a singular pose - small hand motions turn into fast joint motions "
                          + ("(inside the planning margin: plan will refuse this pose)" if m.band == "inside" else ""),
                          style=BAND_STYLE[m.band]))
    if m.clearance is not None:
        grid.add_row(f"clearance {m.clearance * 1e3:.1f} mm to {m.nearest or '-'}")
    wps = session.waypoints[-6:]
    first = len(session.waypoints) - len(wps)
    rows = [f"{first + k + 1:3d} {w.t:6.1f} s  {w.action or 'waypoint':8s} sigma {w.measures.sigma:.4f}"
            + (f"  FLAGGED: {w.flags[0]}" if w.flags else "") for k, w in enumerate(wps)]
    grid.add_row(f"waypoints: {len(session.waypoints)}" + (" (holding)" if session.holding else ""))
    for r in rows:
        grid.add_row(Text(r, style="yellow" if "FLAGGED" in r else ""))
    for t, text in session.events[-2:]:
        grid.add_row(Text(f"[{t:6.1f} s] {text}", style="dim"))
    grid.add_row(Text(f"{KEYS_HELP}   |   {f.rate:.0f} frames/s, {session.validator.refused} refused", style="cyan"))
    return Panel(grid, title="roarmctl teach", subtitle=f"t {f.t:.1f} s")
