"""The firmware model behind a link-shaped object, on a virtual clock: the streamer, the follower and the hold run
against it with no serial port and no real time, so the same inputs give the same bytes on an idle or a busy machine.

``VirtualClock`` is a clock (``clock()``, s) and its ``sleep``, which advances it and waits for nothing;
``VirtualLink`` is a ``LinkLike`` whose wire is ideal and instant, its other end the firmware model
(``roarmctl.device.firmware.Firmware``) stepped to the clock's time at every read; ``VirtualSerial`` puts the same
model under the real ``Link`` instead (``serial_link``), so ``connect()`` and the link's own reads run on the clock too.
Tests and benches use them; the product's links are ``roarmctl.device.link.Link`` on a serial port (or the
simulator's pty).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.firmware import Firmware
from roarmctl.device.link import DeviceInfo, Link, LinkLike, Received
from roarmctl.device.protocol import encode, feedback_request, parse_feedback_report, quiet_command
from roarmctl.device.servos import ServoModel
from roarmctl.device.sim_config import SimConfig
from roarmctl.errors import DeviceError

__all__ = ["VirtualClock", "VirtualLink", "VirtualSerial", "VirtualSimulator", "queued_link", "serial_link"]

SILENT_HINT = "give the model a loop pass it can answer within (loop_pass under 0.5 s)"


class VirtualClock:
    """A clock that moves only when told: ``sleep(dt)`` or ``now += dt`` (s; starts at ``start``)."""

    def __init__(self, start: float = 100.0) -> None:
        self.now = start

    def __call__(self) -> float:
        """The time now (s)."""
        return self.now

    def sleep(self, dt: float) -> None:
        """Advance the clock by ``dt`` s (a negative ``dt`` waits for nothing)."""
        self.now += max(0.0, dt)


class VirtualLink:
    """The firmware model behind a ``LinkLike`` on ``clock`` (an ideal, instant wire).

    ``write_latency``: s each ``send`` takes (the clock advances by it: a slow driver); ``stall``: the firmware reads
    nothing (``SimConfig.deaf``). ``fw`` is the model (its ``recording()`` and ``executed`` say what the arm did).
    """

    def __init__(self, clock: VirtualClock, write_latency: float = 0.0, stall: bool = False) -> None:
        self.port = "fake"
        self.firmware: str | None = "m3-0.84"
        self.info: DeviceInfo | None = None
        self.clock = clock
        self.sleep = clock.sleep
        self.fw = Firmware(SimConfig(info_print=0, deaf=stall), t0=clock())
        self.sent: list[tuple[float, dict[str, Any]]] = []
        self.received: list[Received] = []
        self.write_latency = write_latency

    def send(self, cmd: dict[str, Any], fresh_line: bool = False) -> float:
        """Hand one line to the model; return the time it was written (before the write's latency)."""
        t = self.clock()
        self.clock.now += self.write_latency  # a slow driver: the schedule must not drift
        self.sent.append((t, cmd))
        self.fw.receive((b"\n" if fresh_line else b"") + encode(cmd), t)
        return t

    def poll(self) -> list[Received]:
        """Step the model to now; return the lines it printed, parsed."""
        self.fw.advance(self.clock())
        out = []
        for raw in self.fw.pop_output(self.clock()).split(b"\r\n"):
            if raw:
                out.append(Received(self.clock(), raw.decode(), parse_feedback_report(raw)))
        self.received += out
        return out

    def request(self, timeout: float = 0.3, ahead: list[dict[str, Any]] | None = None,
                earlier: int = 0) -> Received | None:
        """As ``Link.request``: send ``T:105`` after the lines ``ahead`` and read every 5 ms of the clock for its
        answer (``earlier`` answers due before it passed over); None when none came within ``timeout`` s."""
        for cmd in ahead or []:
            self.send(cmd)
        self.send(feedback_request())
        end = self.clock() + timeout
        while self.clock() < end:
            self.clock.now += 0.005
            for r in self.poll():
                if r.feedback is not None:
                    if earlier <= 0:
                        return r
                    earlier -= 1
        return None


class VirtualSerial:
    """A serial port whose other end is the firmware model ``fw`` on ``clock``: what ``Link`` uses of pyserial's
    ``Serial`` (``write``, ``in_waiting``, ``read`` with its ``timeout``, ``reset_input_buffer``, ``flush``,
    ``close``), so the real ``Link.connect()`` and everything after it run on virtual time. A read with nothing
    there moves the clock to the model's next event (a loop pass, a line done on the wire), at most ``timeout`` s."""

    def __init__(self, fw: Firmware, clock: VirtualClock, timeout: float = 0.01) -> None:
        self.fw = fw
        self.clock = clock
        self.timeout = timeout
        self._rx = bytearray()

    def _pull(self) -> None:
        self.fw.advance(self.clock())
        self._rx += self.fw.pop_output(self.clock())

    def write(self, data: bytes) -> int:
        """Bytes that reach the firmware's UART now (the model times their wire)."""
        self.fw.receive(data, self.clock())
        return len(data)

    @property
    def in_waiting(self) -> int:
        """Bytes that have arrived and were not read yet."""
        self._pull()
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        """Up to ``size`` bytes; with none there, wait on the clock for the first, at most ``timeout`` s."""
        self._pull()
        end = self.clock() + self.timeout
        while not self._rx and self.clock() < end:
            self.clock.now = min(end, max(self.fw.next_event(), self.clock() + 1e-4))
            self._pull()
        out = bytes(self._rx[:size])
        del self._rx[:size]
        return out

    def reset_input_buffer(self) -> None:
        """Drop what arrived and was not read."""
        self._pull()
        self._rx.clear()

    def flush(self) -> None:
        """Nothing waits to be written: each write reached the model at once."""

    def close(self) -> None:
        """Nothing to release."""


def serial_link(config: SimConfig, clock: VirtualClock) -> Link:
    """A ``Link`` (opened: its port a ``VirtualSerial``) to a new firmware model of ``config`` started now on
    ``clock``, its timings on that clock; its ``ser.fw`` is the model."""
    link = Link("virtual", clock=clock, sleep=clock.sleep)
    link.ser = VirtualSerial(Firmware(config, t0=clock()), clock, link.timings.read_timeout)
    return link


class VirtualSimulator:
    """The firmware simulator of ``execute --sim`` (``roarmctl.device.simulator.PtySimulator``'s face: ``start``,
    ``path``, ``attach``, ``recording``, ``lateness``, ``recent_lateness``, ``executed``, ``stop``) on ``clock``: the same
    firmware model and servo model, behind a ``VirtualSerial`` instead of a pty, so a whole execution runs in virtual
    time (``roarmctl.device.session.run_execution(simulator=...)``). ``servos``: the servo model or a zero-argument
    factory, as ``PtySimulator``'s (default the ideal kinematic servos)."""

    def __init__(self, config: SimConfig | None = None, clock: VirtualClock | None = None, *,
                 servos: ServoModel | Callable[[], ServoModel] | None = None) -> None:
        self.config = config or SimConfig()
        self.clock = clock or VirtualClock()
        self._servos = servos
        self.firmware: Firmware | None = None
        self.path = ""  # "virtual" once started

    def start(self) -> VirtualSimulator:
        """Power the model up now (on the clock), unless it runs already: a second run finds the arm where the first
        left it, as a second command on ``sim-device``'s pty does; return self."""
        if self.firmware is not None:
            return self
        servos = self._servos
        model = servos() if callable(servos) and not isinstance(servos, ServoModel) else servos
        self.firmware = Firmware(self.config, t0=self.clock(), servos=model)
        self.path = "virtual"
        return self

    @property
    def sleep(self) -> Callable[[float], None]:
        """The host's wait beside the model: the clock's (it advances the clock)."""
        return self.clock.sleep

    def attach(self, link: Link) -> None:
        """Open ``link`` (on this clock: ``Link(..., clock=sim.clock, sleep=sim.sleep)``) on the model (after
        ``start``): its port a ``VirtualSerial``."""
        link.port = self.path
        link.ser = VirtualSerial(self._model(), self.clock, link.timings.read_timeout)

    def _model(self) -> Firmware:
        if self.firmware is None:
            raise RuntimeError("the virtual simulator was never started")
        return self.firmware

    def recording(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,) s on the clock, joints (N, 6) rad in the URDF convention, torque on (N,))."""
        return self._model().recording()

    def executed(self) -> list[tuple[float, float, dict]]:
        """Every command the model ran: (its last byte at the UART, when it ran, the parsed object)."""
        return list(self._model().executed)

    def lateness(self) -> np.ndarray:
        """(0, 2): a model on a virtual clock is never late."""
        return np.zeros((0, 2))

    def recent_lateness(self) -> float:
        """0 s: never late."""
        return 0.0

    def stop(self) -> None:
        """Nothing runs: the model stays readable (and can be connected to again)."""


if TYPE_CHECKING:  # mypy holds the virtual link to the protocol the streamer is typed against
    _CONFORMS: type[LinkLike] = VirtualLink


def queued_link(clock: VirtualClock, loop_pass: float) -> VirtualLink:
    """The 20260701 build (one queued line per loop pass) with passes of ``loop_pass`` s, its round trip and time per
    line measured as ``Link.connect()`` measures them (T:105 alone; six filler lines ahead of one)."""
    link = VirtualLink(clock)
    link.firmware = "m3-2026"
    base = 6 * 0.0005 * 1.3 + 0.002  # the model's own pass on that build: six servo reads and its other work
    link.fw = Firmware(SimConfig(firmware="m3-2026", info_print=0, loop_period=loop_pass - base), t0=clock())
    rtts = []
    for _ in range(3):
        t0 = clock()
        r = link.request(0.5)
        if r is None:
            raise DeviceError("device silent: the firmware model did not answer T:105", SILENT_HINT)
        rtts.append(r.t - t0)
    t0 = clock()
    for _ in range(6):
        link.send(quiet_command())
    r = link.request(1.0)
    if r is None or r.feedback is None:
        raise DeviceError("device silent: the firmware model did not answer T:105", SILENT_HINT)
    line_time = (r.t - t0 - min(rtts)) / 6
    link.info = DeviceInfo("m3-2026", float(np.median(rtts)), line_time, True, False, False, r.feedback)
    link.sent.clear()
    link.received.clear()
    return link
