"""One execution of a trajectory on a serial port or the built-in firmware simulator.

Open the port, check the device answers like the robot the trajectory is for, stream, and on every
way out (done, error, Ctrl-C/SIGTERM/SIGHUP, lost link) close the port and write the execution log.
``roarmctl execute`` and ``roarmctl.api.execute`` both run through :func:`run_execution`; they
differ only in how they ask for confirmation and show progress.
"""

from __future__ import annotations

import contextlib
import warnings
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from roarmctl.errors import InputError, Interrupted, RoarmError, signal_name
from roarmctl.fileio import check_writable

if TYPE_CHECKING:
    import numpy as np

    from roarmctl.device.link import Link
    from roarmctl.device.sim_config import SimConfig
    from roarmctl.device.streamer import Result, StreamConfig
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot


class SimulatedArm(Protocol):
    """What an execution uses of the firmware simulator: ``roarmctl.device.simulator.PtySimulator`` (a pty, real time,
    the product's) or ``roarmctl.device.virtual.VirtualSimulator`` (the same model on a virtual clock, for tests)."""

    path: str  # the device it serves on once started ("" before)

    @property
    def clock(self) -> Callable[[], float]:
        """The clock the host's link and streamer run on beside it (s)."""
        ...

    @property
    def sleep(self) -> Callable[[float], None]:
        """The host's wait on that clock (s)."""
        ...

    def start(self) -> object:
        """Power the simulated arm up."""
        ...

    def attach(self, link: Link) -> None:
        """Open ``link`` on it (after ``start``)."""
        ...

    def recording(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,) s, joints (N, 6) rad in the URDF convention, torque on (N,))."""
        ...

    def lateness(self) -> np.ndarray:
        """(M, 2): when and how late (s) the simulated firmware woke after its schedule."""
        ...

    def recent_lateness(self) -> float:
        """The largest of those lateness values (s) in the last moments."""
        ...

    def stop(self) -> None:
        """Stop it (what it recorded stays readable)."""
        ...


def pty_simulator(config: SimConfig, servos: Callable[[], Any] | None) -> SimulatedArm:
    """The simulator of ``execute --sim``: the firmware model of ``config`` in a process of its own, with its own
    time, as the ESP32 does, on a pseudo-terminal; ``servos``: its servo model's factory (None: the ideal ones)."""
    from roarmctl.device.simulator import PtySimulator

    return PtySimulator(config, servos=servos, process=True)


@dataclass
class Execution:
    """What a run did: the streamer's ``result`` (summary and log), the trajectory as run (its start
    re-planned when the arm stood elsewhere), the port used, and for the simulator the true TCP
    tracking error of its servos against the plan (``rms_mm``, ``max_mm``, ``samples``, ``torque_always_on``)."""

    result: Any
    traj: Any
    port: str
    simulator: dict[str, Any] | None


def run_execution(traj: Trajectory, robot: Robot, cfg: StreamConfig, *, port: str | None = None, sim: bool = False,
                  log_path: str | Path | None = None, confirm: Callable[[str], bool],
                  on_status: Callable | None = None, on_start: Callable | None = None,
                  on_note: Callable[[str], None] | None = None, on_end: Callable[[], None] | None = None,
                  shield: Callable[[], AbstractContextManager] = contextlib.nullcontext,
                  on_log_error: Callable[[Path, Exception], None] | None = None,
                  on_info: Callable[[str], None] | None = None,
                  sim_servos: Callable[[], Any] | None = None, sim_config: Any = None,
                  simulator: Callable[[SimConfig, Callable[[], Any] | None], SimulatedArm] | None = None) -> Execution:
    """Stream ``traj`` (a validated ``Trajectory`` for ``robot``) with ``cfg`` (``StreamConfig``).

    Exactly one of ``port`` (a serial port name or pyserial URL) and ``sim=True`` (the firmware
    simulator of the trajectory's robot on a pseudo-terminal). ``confirm(message)`` is asked before
    the arm moves; ``on_status``/``on_start``/``on_note`` feed a progress display, ``on_end`` runs
    when streaming stops (before the port closes). ``shield`` makes the close and the log write
    uninterruptible (the CLI passes its signal shield). ``log_path``: where the execution log goes,
    written on every way out once the port has opened, and on a stop signal from the start (a port that could not
    be opened exchanged nothing and leaves an existing log alone); a stop signal before streaming raises
    ``Interrupted`` (its ``result`` carries the log), as one during it does; a log that cannot be written calls ``on_log_error(path, exc)`` (default: a ``RuntimeWarning``)
    instead of hiding the run's own outcome. ``on_info(line)`` hears what connecting learned (the
    firmware build, round trip, pacing) and the link budget. ``sim_servos``: a zero-argument factory of
    the simulator's servo model (``roarmctl.physics.servo_backend.for_firmware``: the physics servos;
    default the ideal kinematic ones); ``sim_config``: its ``SimConfig`` (build, boot, loop pass; default the
    build of the trajectory's robot, already running, the model's own pass). ``simulator(config, servos)``: makes the
    simulated arm (default ``pty_simulator``, real time; ``roarmctl.device.virtual.VirtualSimulator`` runs the same
    model on a virtual clock, the link and the streamer on that clock too). Errors propagate after the log is written;
    the stream result of a failed run is the exception's ``result`` attribute when it has one.
    """
    from roarmctl.device.execlog import write_log
    from roarmctl.device.link import Link
    from roarmctl.device.protocol import WireMap
    from roarmctl.device.streamer import Streamer

    if (port is None) == (not sim):
        raise InputError("execute: give exactly one of a port or the simulator")
    if log_path is not None:  # a log that cannot be written is found before the arm moves, not after
        check_writable(log_path)
    model = WireMap(robot).model
    arm: SimulatedArm | None = None
    if sim:
        from roarmctl.device.sim_config import SimConfig

        # the simulated arm is the kind the trajectory is for (an M2 trajectory gets the M2 protocol)
        config = sim_config or SimConfig(firmware="m2" if model == "m2" else "m3-0.84")
        arm = (simulator or pty_simulator)(config, sim_servos)

    def replan(q: np.ndarray, mode: str) -> tuple[Trajectory, str]:
        from roarmctl.motion.replan import replan_start

        return replan_start(traj, robot, q, mode)

    if arm is not None:  # the link and the stream on the simulated arm's clock
        link = Link("the simulator", clock=arm.clock, sleep=arm.sleep)
    else:
        link = Link(str(port))
    link.expect = model or "m3"
    # Built before the port opens or the simulator starts (the schedule is pure), so that every way out has a log and
    # a trajectory the firmware cannot take is refused before anything opens; the CLI and the API leave it to this.
    streamer = Streamer(link, robot, traj, cfg, clock=link.clock, sleep=link.sleep, on_status=on_status,
                        confirm=confirm, on_start=on_start, replan=replan, on_note=on_note,
                        extra_lateness=arm.recent_lateness if arm is not None else None, shield=shield)
    result = None
    tracking = None
    opened = stopped = False
    try:
        if arm is not None:
            arm.start()
            arm.attach(link)
            port = link.port
        else:
            link.open()
        opened = True
        info = link.connect()
        if on_info is not None:
            on_info(f"firmware: {info.describe()}")
            on_info(streamer.link_budget().describe())
        try:
            result = streamer.run()
        finally:
            if on_end is not None:
                on_end()
    except RoarmError as exc:
        result = getattr(exc, "result", None) or streamer.result("failed", f"{exc.message}; no motion command was sent")
        raise
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP while starting the simulator, opening or connecting
        signum = getattr(exc, "signum", 2)
        stopped = True
        where = "before streaming" if opened else "before the port was opened"
        message = f"stopped by {signal_name(signum)} {where} (no motion command sent)"
        result = streamer.result("interrupted" if signum == 2 else "terminated", message)
        # the run's own stop, as one after streaming began: its one line, its log, 128 + N
        stop = Interrupted(message, signum=signum)
        stop.result = result  # type: ignore[attr-defined]
        raise stop from None
    finally:
        with shield():  # a signal now must not cut the port's close or the log short
            link.close()
            if result is None:
                result = streamer.result("failed", "stopped before streaming (no motion command sent)")
            if arm is not None:
                try:
                    if arm.path:
                        # streamer.traj: re-planned from the measured pose when the arm was elsewhere
                        tracking = simulator_tracking(arm, robot, streamer.traj, cfg, result)
                        result.log["simulator"] = tracking
                except (RuntimeError, EOFError, OSError) as exc:  # the simulator's process gave no answer or ended:
                    # the run's own outcome and its log stand; the simulator's view of it is missing, said in the log
                    result.log.setdefault("notes", []).append(f"no tracking from the simulator: {exc}"[:300])
                finally:
                    arm.stop()
            # a port that could not be opened exchanged nothing: keep the previous run's log rather than replace it
            # with an empty one (the error itself says what went wrong). A stop signal is this run's end: its log
            # says so, also before the port opened (the previous run's log would read as this one's)
            if log_path is not None and (opened or stopped):
                try:
                    write_log(log_path, result.log)
                except (OSError, InputError) as exc:
                    if on_log_error is None:
                        warnings.warn(f"could not write the execution log {log_path}: {exc}", RuntimeWarning, stacklevel=2)
                    else:
                        on_log_error(Path(log_path), exc)
    return Execution(result, streamer.traj, str(port), tracking)


def simulator_tracking(simulator: SimulatedArm, robot: Robot, traj: Trajectory, cfg: StreamConfig,
                       result: Result) -> dict[str, Any]:
    """TCP error (mm) of the simulator's true servo positions against the plan, over the motion, on the plan's
    time (its pauses for a late host taken out): raw, and aligned within the lateness measured on both sides and
    the lead the servos keep through a pause (``roarmctl.device.tracking``)."""
    from roarmctl.device.schedule import STRATEGIES, default_latency
    from roarmctl.device.tracking import host_lateness, pause_events, true_tracking

    host = host_lateness(result.log.get("sent", []), result.log["rate"])
    paused = result.log.get("paused", ())
    strat = STRATEGIES.get(cfg.strategy) if isinstance(cfg.strategy, str) else cfg.strategy
    ahead = pause_events(paused, default_latency(result.log["rate"]) + (strat.lead if strat is not None else 0.0))
    return true_tracking(robot, traj, simulator.recording(), result.t0, cfg.speed_scale, host_late=host,
                         device_late=simulator.lateness(), paused=paused, ahead=ahead)
