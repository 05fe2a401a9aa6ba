"""The simulated arm on a real pseudo-terminal: the firmware model (``roarmctl.device.firmware``)
served on a pty that any program opens like ``/dev/ttyUSB0``.

An ESP32 keeps its own time: nothing on the host can pause it. ``PtySimulator(process=True)`` gives
the simulated firmware the same independence: it runs in a child process of its own (no shared
interpreter lock with the program under test), on the system's monotonic clock, and measures how
late it woke against its own schedule (``lateness()``), so that a busy machine's stalls are
measured rather than guessed. ``process=False`` serves it from a thread (``sim-device``, which is a
process of its own anyway, and tests that want the model object itself).

The recording (true servo positions over time: ``recording()``, URDF convention, gripper q =
pi - hand) and the executed commands (``executed()``) are there for tests and benches to compare
the motion with the plan.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import select
import signal
import sys
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.firmware import Firmware
from roarmctl.device.fwmath import (
    INIT_RAD,
    command_to_goal,
    deg_register,
    firmware_fk,
    firmware_ik,
    position_to_rad,
    steps,
    urdf_from_firmware,
)
from roarmctl.device.servos import JOINTS, KinematicServos, ServoModel
from roarmctl.device.sim_config import Bogus, SimConfig

if TYPE_CHECKING:
    from multiprocessing.connection import Connection
    from multiprocessing.sharedctypes import Synchronized

    from roarmctl.device.link import Link

__all__ = [
    "INIT_RAD",
    "JOINTS",
    "Bogus",
    "Firmware",
    "KinematicServos",
    "PtySimulator",
    "ServoModel",
    "SimConfig",
    "command_to_goal",
    "deg_register",
    "firmware_fk",
    "firmware_ik",
    "position_to_rad",
    "steps",
    "urdf_from_firmware",
]

LATE = 0.002  # a wake-up this much after the firmware's next event counts as lateness (s)
RECENT = 0.25  # s over which recent_lateness() takes its maximum
SLICE = 0.05  # s of firmware time advanced between two looks at the stop flag
JOIN = 10.0  # s stop() waits for the serving thread (it sees the stop within a SLICE of model time)
ASK_TIMEOUT = 120.0  # s a question to the simulator's process may take (a recording of minutes, on a loaded machine)


class _Server:
    """The serving loop: pty bytes in, the model advanced to the clock, its finished lines out."""

    def __init__(self, fw: Firmware, master: int, clock: Callable[[], float], recent: Any = None) -> None:
        self.fw = fw
        self.master = master
        self.clock = clock
        self.late: deque[tuple[float, float]] = deque(maxlen=100_000)  # (when, how late) above LATE
        self.recent = recent  # a shared double: the largest lateness of the last RECENT s
        self.priority = "normal"  # how the serving process is scheduled
        self._recent: deque[tuple[float, float]] = deque()

    def _note_late(self, now: float, late: float) -> None:
        if late > LATE:
            self.late.append((now, late))
            self._recent.append((now, late))
        while self._recent and self._recent[0][0] < now - RECENT:
            self._recent.popleft()
        if self.recent is not None:
            self.recent.value = max((x for _, x in self._recent), default=0.0)

    def serve(self, stopped: Callable[[], bool], extra: list[int] | None = None,
              on_extra: Callable[[], bool] | None = None) -> None:
        fw, fds = self.fw, [self.master, *(extra or [])]
        while not stopped():
            now = self.clock()
            due = fw.next_event()
            ready, _, _ = select.select(fds, [], [], max(0.0, min(due - now, 0.05)))
            now = self.clock()
            self._note_late(now, 0.0 if ready else now - due)
            if extra and any(fd in ready for fd in extra) and on_extra is not None and not on_extra():
                return
            if self.master in ready:
                try:
                    data = os.read(self.master, 4096)
                except OSError:
                    data = b""
                if data:
                    fw.receive(data, now)
            if not self._advance(now, stopped):
                return
            out = fw.pop_output(now)
            if out:
                try:
                    os.write(self.master, out)
                except OSError:
                    pass  # nobody reads and the buffer is full (or closed): lost, like bytes on an open UART


    def _advance(self, now: float, stopped: Callable[[], bool]) -> bool:
        """The model up to ``now`` in slices of ``SLICE`` s, so that a stop is seen within a slice even when a
        stall of the machine left much to catch up (physics servos step MuJoCo through all of it: a thread
        still inside it when the interpreter exits crashes the process). False if stopped meanwhile."""
        fw = self.fw
        t = fw.now
        while t + SLICE < now:
            if stopped():
                return False
            t += SLICE
            fw.advance(t)
        fw.advance(now)
        return True


def _open_pty() -> tuple[int, int, str]:
    master, slave = os.openpty()
    tty.setraw(slave)
    tty.setraw(master)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def _raise_priority() -> str:
    """Let the simulated firmware run when it is due, as an ESP32 would, where the system allows it:
    the lowest real-time priority (it sleeps most of the time: a few % of a core), else a better
    nice value, else nothing. Returns what it got."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        return "SCHED_FIFO 1"
    except (OSError, AttributeError):
        pass
    try:
        os.nice(-5)
        return "nice -5"
    except OSError:
        return "normal"


def _child(config: SimConfig, servos: ServoModel | Callable[[], ServoModel] | None, conn: Connection,
           recent: Synchronized[float]) -> None:
    """The simulated firmware's own process: serve until told to stop or the parent is gone."""
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)  # the parent's Ctrl-C must not kill the arm before its hold
    priority = _raise_priority()
    master, slave, path = _open_pty()
    model = servos() if callable(servos) and not isinstance(servos, ServoModel) else servos
    fw = Firmware(config, t0=time.monotonic(), servos=model)
    server = _Server(fw, master, time.monotonic, recent)
    server.priority = priority
    conn.send(path)
    state = {"stop": False}

    def on_control() -> bool:
        try:
            msg = conn.recv()
        except (EOFError, OSError):
            return False
        kind = msg[0]
        if kind == "stop":
            conn.send(None)
            return False
        conn.send(_query(fw, server, kind))
        return True

    try:
        server.serve(lambda: state["stop"], extra=[conn.fileno()], on_extra=on_control)
    finally:
        for fd in (master, slave):
            try:
                os.close(fd)
            except OSError:
                pass


def _query(fw: Firmware, server: _Server, kind: str) -> Any:
    if kind == "recording":
        return fw.recording()
    if kind == "executed":
        return list(fw.executed)
    if kind == "lateness":
        return np.array(list(server.late)).reshape(-1, 2)
    if kind == "state":
        return {"now": fw.now, "torque": fw.servos.torque().tolist(), "info_print": fw.info_print,
                "esp_now_mode": fw.esp_now_mode, "stop_flag": fw.stop_flag, "motion_count": fw.motion_count,
                "boot_mission_aborted": fw.boot_mission_aborted, "booting_until": fw.booting_until,
                "rx_dropped": fw._rx_dropped,
                "queue": len(fw._queue), "positions": fw.servos.positions().tolist(), "move_spd": fw.move_spd,
                "spd": [float(x) for x in getattr(fw.servos, "spd", [])],
                "passes_ms": (np.array(fw.passes) * 1e3).tolist()[-2000:], "priority": server.priority}
    raise ValueError(kind)


class PtySimulator:
    """Serve a ``Firmware`` on a pseudo-terminal; ``path`` is the device to open.

    ``servos``: the servo model (an object, or a zero-argument factory; default the ideal
    kinematic servos). ``process=True`` runs the firmware in its own process (see the module
    docstring); then ``firmware`` is not reachable from here and the accessors below ask the child.
    Use as a context manager or call ``start``/``stop``.
    """

    def __init__(self, config: SimConfig | None = None, clock: Callable[[], float] = time.monotonic, *,
                 servos: ServoModel | Callable[[], ServoModel] | None = None, process: bool = False) -> None:
        self.config = config or SimConfig()
        self.clock = clock
        self.sleep: Callable[[float], None] = time.sleep  # the host's wait beside it: real time
        self.path = ""  # the pty's device, once it serves
        self.process = process
        self.error: BaseException | None = None
        self._stopped = False
        self._final: dict[str, Any] = {}  # process mode: what the child knew when it stopped
        if process:
            ctx: Any = mp.get_context("fork" if sys.platform.startswith("linux") else "spawn")
            self._conn, child_conn = ctx.Pipe()
            self._recent = ctx.Value("d", 0.0, lock=False)
            self._proc = ctx.Process(target=_child, args=(self.config, servos, child_conn, self._recent),
                                     name="roarm-sim", daemon=True)
            self._lock = threading.Lock()
        else:
            self.master, self.slave, self.path = _open_pty()
            model = servos() if callable(servos) and not isinstance(servos, ServoModel) else servos
            self.firmware = Firmware(self.config, t0=clock(), servos=model)
            self._server = _Server(self.firmware, self.master, clock)
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._run, name="roarm-sim", daemon=True)

    # ------------------------------------------------------------------ life
    def start(self) -> PtySimulator:
        """Start serving (thread or child process); return self."""
        if self.process:
            self._proc.start()
            if not self._conn.poll(10.0):
                self._proc.kill()
                raise RuntimeError("the simulator process did not start")
            self.path = self._conn.recv()
        else:
            self._thread.start()
        return self

    def attach(self, link: Link) -> None:
        """Open ``link`` on this simulator's pty (after ``start``), as a serial port to the arm is opened."""
        if not self.path:
            raise RuntimeError("start() the simulator before opening a link on it")
        link.port = self.path
        link.open()

    def __enter__(self) -> PtySimulator:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def alive(self) -> bool:
        """Whether it still serves."""
        return self._proc.is_alive() if self.process else self._thread.is_alive()

    def join(self, timeout: float) -> None:
        """Wait up to ``timeout`` s for it to end."""
        (self._proc if self.process else self._thread).join(timeout)

    def stop(self) -> None:
        """Stop serving and close the pseudo-terminal (process mode keeps what the child knew for the accessors)."""
        if self._stopped:
            return
        if self.process and not self.path:
            # never started, or stopped while starting (a stop signal): nothing to ask, only a child to end
            self._stopped = True
            if self._proc.pid is not None and self._proc.is_alive():
                self._proc.kill()
                self._proc.join(1.0)
            self._conn.close()
            return
        if self.process:
            try:
                self._final = {k: self._ask(k) for k in ("recording", "executed", "lateness", "state")}
            except (OSError, EOFError, BrokenPipeError, RuntimeError):  # no answer: it was ended (_broken)
                self._final = {}
            self._stopped = True
            try:
                with self._lock:
                    self._conn.send(("stop",))
                    self._conn.poll(2.0)
            except (OSError, EOFError, BrokenPipeError):
                pass
            self._proc.join(2.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join(1.0)
            self._conn.close()
            return
        self._stopped = True
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=JOIN)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def disconnect(self) -> None:
        """The cable pulled: the pty closes, so the host's reads and writes fail."""
        self.stop()

    def _run(self) -> None:
        try:
            self._server.serve(self._stop.is_set)
        except BaseException as exc:  # noqa: BLE001 - surfaced to tests through .error
            self.error = exc

    # ------------------------------------------------------------------ what happened
    def _ask(self, kind: str) -> Any:
        if not self.process:
            return _query(self.firmware, self._server, kind)
        if self._stopped:
            if kind in self._final:
                return self._final[kind]
            raise RuntimeError(f"the simulator has stopped; ask for {kind!r} before stop()")
        with self._lock:
            try:
                self._conn.send((kind,))
            except OSError:  # BrokenPipeError: the process has ended
                self._broken()
                raise RuntimeError(f"the simulator's process ended before it was asked {kind!r}") from None
            # bounded: a child that died or hangs must fail the caller, not hold it (and a test run) for ever
            if not self._conn.poll(ASK_TIMEOUT):
                alive = self._proc is not None and self._proc.is_alive()
                self._broken()  # a late answer would be taken for the next question's
                raise RuntimeError(f"the simulator's process gave no answer to {kind!r} within {ASK_TIMEOUT:g} s "
                                   f"({'still running' if alive else 'it has ended'})")
            try:
                return self._conn.recv()
            except (EOFError, OSError):
                self._broken()
                raise RuntimeError(f"the simulator's process ended before it answered {kind!r}") from None

    def _broken(self) -> None:
        """The child no longer answers in step: end it, so that ``stop()`` asks nothing more of it."""
        self._final, self._stopped = {}, True
        if self._proc is not None and self._proc.is_alive():
            self._proc.kill()
            self._proc.join(1.0)
        self._conn.close()

    def recording(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,) s on the monotonic clock, joints (N, 6) rad in the URDF convention, torque on (N,))."""
        return self._ask("recording")

    def executed(self) -> list[tuple[float, float, dict]]:
        """Every command the firmware ran: (its last byte at the UART, when it ran, the parsed object)."""
        return self._ask("executed")

    def received(self) -> list[tuple[float, dict]]:
        """Every command the firmware ran: (when it ran, the parsed object)."""
        return [(t, c) for _, t, c in self.executed()]

    def lateness(self) -> np.ndarray:
        """(M, 2): each time the simulated firmware woke more than 2 ms after its schedule: (when, how late), s."""
        return self._ask("lateness")

    def recent_lateness(self) -> float:
        """The largest lateness (s) of the simulated firmware's wake-ups in the last 0.25 s (cheap: no round trip)."""
        if self.process:
            return float(self._recent.value)
        now = self.clock()
        return max((x for t, x in self._server.late if t >= now - RECENT), default=0.0)

    def state(self) -> dict[str, Any]:
        """The firmware's state now (``now``: its clock, s): torque, InfoPrint, ESP-NOW mode, StopFlag, queue, pass times,
        when its set-up ends (``booting_until``), ..."""
        return self._ask("state")
