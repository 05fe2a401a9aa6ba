"""The serial link to the arm: open it without a reset, connect as the firmware expects, send lines,
read feedback.

Every failure a user meets becomes one ``DeviceError`` line naming the cause and the fix (exit 4):
no such port, port busy, permission denied, device silent, wrong firmware, torque off, supply out of
range, link lost. What ``connect()`` sends and why is in ``docs/guide.md`` ("Talking to the
firmware"); the facts come from Waveshare's RoArm-M3 example firmware (public copy
github.com/jhacksman/RoArm-M3, 0.84 build under ``leader_follower_mode/firmware/esp32/
RoArm-M3_example-250108/RoArm-M3_example/``; line numbers below are of that copy).
"""

from __future__ import annotations

import errno
import re
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from roarmctl.device import espnow, protocol
from roarmctl.device.espnow import EspNowMode
from roarmctl.device.feedback import MAX_SUPPLY_V, MIN_SUPPLY_V
from roarmctl.device.protocol import Feedback, LineBuffer, encode, parse_feedback_report, wire_seconds
from roarmctl.errors import DeviceError

DIALOUT_HINT = "on Linux: sudo usermod -aG dialout $USER, then log out and back in"
LOST_HINT = "check the USB cable and the arm's power; the arm may have rebooted"
BUILD_NAMES = {"m3-0.84": "RoArm-M3 0.84 build (RoArm-M3_example-250108)",
               "m3-2026": "RoArm-M3 20260701 build (RoArm-M3_example_20260701)",
               "m2": "RoArm-M2 firmware"}
#: s a command line may take at the firmware beyond its wire time in a measurement that is kept at once (the 0.84
#: build's serialCtrl() runs every complete line of a pass, U:384-407: about 0; the 20260701 build runs one queued
#: line per loop pass, about 3-5 ms each); a longer one is measured again
QUEUED_LINE_TIME = 0.002
LINE_TIME_TRIES = 4  # measurements of the line time at most (the least is kept; a busy host only adds)
#: The last line setup() prints: the ESP-NOW set-up's MAC address (esp_now_ctrl.h lines 36-47 of the 0.84 copy); the
#: flash mission "boot" runs right after it and is aborted by any input waiting then (RoArm-M3_advance.h 8-15)
SETUP_END = re.compile(r"^\s*[0-9A-Fa-f]{2}(:[0-9A-Fa-f]{2}){5}\s*$")


@dataclass
class LinkTimings:
    """Connection timing (s)."""

    read_timeout: float = 0.01
    write_timeout: float = 1.0
    listen: float = 0.3  # first look after opening: feedback frames, boot text or silence
    silent_window: float = 2.0  # setup() starts with delay(1200) + 500 ms of silence (I:53, I:81): wait it out, and a little more
    boot_timeout: float = 15.0  # the longest a set-up may take (0.84 in Wi-Fi station mode: up to 15 s) before a probe
    after_setup: float = 0.5  # after the set-up's last line (the MAC address): its boot mission starts; then probe
    quiet_confirm: float = 0.15  # T:605 took effect when no unsolicited frame came for this long
    silent_after: float = 2.0  # no answer to T:105 probes within this -> device silent
    mission_wait: float = 0.5  # the longest the boot mission's listing ({"T":602}) is waited for


@dataclass
class Received:
    """One line read: host time (s), its text, and the parsed T:1051 (None for other lines)."""

    t: float
    line: str
    feedback: Feedback | None = None


@dataclass
class DeviceInfo:
    """What ``connect()`` learned. Times in s."""

    firmware: str  # "m3-0.84", "m3-2026", "m2"
    rtt: float  # median T:105 -> T:1051 round trip
    line_time: float  # time the firmware takes per command line beyond the wire (0.84: ~0; 20260701: a loop pass)
    queued: bool  # the firmware runs one line per loop pass
    streamed: bool  # it was streaming feedback unasked (InfoPrint 2) when we came
    booted: bool  # it was starting up when we came (boot text seen)
    first: Feedback
    voltage: float | None = None  # V, builds that report it
    torque: dict[str, int] | None = None  # torque-enable flag per joint, builds that report it
    sent: list[str] = field(default_factory=list)  # what connect() sent, in order
    waited: str | None = None  # what connect() waited for before its first line, in one sentence
    esp_now: EspNowMode | None = None  # the ESP-NOW mode found at connect, given back when the link closes

    @property
    def build(self) -> str:
        """The build's name as Waveshare ships it."""
        return BUILD_NAMES.get(self.firmware, self.firmware)

    def describe(self) -> str:
        """One line for the display and the log."""
        pace = (f"one command per loop pass, {self.line_time * 1e3:.1f} ms each" if self.queued
                else "all waiting commands each loop pass")
        extra = f"; supply {self.voltage:.2f} V, torque on" if self.voltage is not None else \
            "; this build reports neither torque nor supply voltage"
        waited = f"; {self.waited}" if self.waited else ""
        return f"{self.build}: round trip {self.rtt * 1e3:.0f} ms, {pace}{extra}{waited}"

    def as_dict(self) -> dict[str, Any]:
        """The facts as a JSON-ready dict (the execution log's ``device``)."""
        return {"firmware": self.firmware, "build": self.build, "rtt_s": round(self.rtt, 5),
                "line_time_s": round(self.line_time, 5), "queued": self.queued, "streamed_unasked": self.streamed,
                "was_booting": self.booted, "voltage_v": self.voltage, "torque": self.torque, "sent": self.sent,
                "waited_for": self.waited,
                "esp_now": None if self.esp_now is None else dict(self.esp_now.as_dict(), restored_on_close=True)}


class LinkLike(Protocol):
    """What the streamer, the follower and the hold use of a link: ``Link`` on a serial port, or
    ``roarmctl.device.virtual.VirtualLink`` (the firmware model on a virtual clock, for tests and benches).
    Times are the link's ``clock`` (s)."""

    @property
    def port(self) -> str:
        """The port's name (for messages and the log)."""
        ...

    @property
    def firmware(self) -> str | None:
        """The build ``connect()`` found ("m3-0.84", "m3-2026", "m2")."""
        ...

    @property
    def info(self) -> DeviceInfo | None:
        """What ``connect()`` measured."""
        ...

    @property
    def sent(self) -> list[tuple[float, dict[str, Any]]]:
        """Every line written, with its time, in order."""
        ...

    @property
    def received(self) -> list[Received]:
        """Every line read, in order."""
        ...

    @property
    def clock(self) -> Callable[[], float]:
        """The link's clock (s)."""
        ...

    @property
    def sleep(self) -> Callable[[float], None]:
        """Wait on the link's clock (s)."""
        ...

    def send(self, cmd: dict[str, Any], fresh_line: bool = False) -> float:
        """Write one command line; return the time it was handed over."""
        ...

    def poll(self) -> list[Received]:
        """The complete lines that have arrived (without waiting), parsed."""
        ...

    def request(self, timeout: float = 0.3, ahead: list[dict[str, Any]] | None = None,
                earlier: int = 0) -> Received | None:
        """Send ``T:105`` after the lines ``ahead`` and wait up to ``timeout`` s for its answer, passing over the
        ``earlier`` answers due before it; None on timeout."""
        ...


class Link:
    """One open serial port to a RoArm. Times are from ``clock`` (monotonic, s)."""

    def __init__(self, port: str, *, timings: LinkTimings | None = None,
                 clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
        self.port = port
        self.timings = timings or LinkTimings()
        self.clock = clock
        self.sleep = sleep
        self.ser: Any = None
        self.lines = LineBuffer()
        self.firmware: str | None = None
        self.info: DeviceInfo | None = None
        #: The protocol model the trajectory is for ("m3" or "m2", ``WireMap.model``); connect()
        #: refuses a device that answers like the other one.
        self.expect = "m3"
        #: Refuse to connect when torque is off (False for teach, which wants the arm limp).
        self.require_torque = True
        self.boot_text: list[str] = []
        self.received: list[Received] = []  # every line read, in order (the execution log)
        self.sent: list[tuple[float, dict[str, Any]]] = []
        self.closed = False
        self._restore_info_print: int | None = None
        self.waited: str | None = None  # what connect() waited for before its first line
        self.esp_now: EspNowMode | None = None  # the ESP-NOW mode found at connect (given back on close)

    # ------------------------------------------------------------------ open
    def open(self) -> Link:
        """Open the port as Waveshare's roarm-sdk does (roarm_sdk/roarm.py: ``rts = False`` set
        before ``open()``, DTR left asserted), exclusive.

        pyserial applies DTR and then RTS right after the operating system opened the port with
        both asserted (serialposix.py lines 334-338). With DTR asserted and RTS released the lines
        never pass through DTR released + RTS asserted, the reset state of the usual ESP32
        auto-program circuit (the one esptool drives to reset the chip), so opening never reboots
        the arm. Clearing both before ``open()`` would: pyserial releases DTR while RTS is still up.
        """
        import serial

        t = self.timings
        try:
            ser = serial.serial_for_url(self.port, do_not_open=True)
            ser.baudrate = protocol.BAUDRATE
            ser.timeout = t.read_timeout
            ser.write_timeout = t.write_timeout
            ser.dtr = True
            ser.rts = False
            if hasattr(ser, "exclusive"):
                ser.exclusive = True
            ser.open()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise self._open_error(exc) from None
        self.ser = ser
        return self

    def _open_error(self, exc: Exception) -> DeviceError:
        code = getattr(exc, "errno", None)
        if code is None and exc.args and isinstance(exc.args[0], int):
            code = exc.args[0]
        text = str(exc)
        if code == errno.ENOENT or "No such file" in text or "could not find port" in text.lower():
            return DeviceError(f"no such serial port: {self.port}",
                               "plug the arm in (middle USB-C port) and list ports with 'roarmctl ports'")
        if sys.platform.startswith("win") and ("denied" in text or code == errno.EACCES):
            # Windows reports a port held by another program as "Access is denied"
            return DeviceError(f"serial port {self.port} is busy or not accessible",
                               "close other programs using it (serial monitors, other roarmctl runs), then retry")
        if code == errno.EACCES or "Permission denied" in text:
            return DeviceError(f"permission denied opening {self.port}", DIALOUT_HINT)
        if code in (errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK) or "lock" in text.lower() or "busy" in text.lower():
            return DeviceError(f"serial port {self.port} is busy (another program has it open)",
                               "close other roarmctl runs, serial monitors, or the ROS driver, then retry")
        if code in (errno.EISDIR, errno.ENOTTY) or "Is a directory" in text or "Inappropriate ioctl" in text:
            what = "a folder" if code == errno.EISDIR or "Is a directory" in text else "not a terminal device"
            return DeviceError(f"{self.port} is not a serial port ({what})",
                               "give the arm's port, e.g. /dev/ttyUSB0; 'roarmctl ports' lists them")
        if "Invalid URL" in text or "expected" in text:
            return DeviceError(f"cannot open {self.port}: {text}", "give a device path like /dev/ttyUSB0 or a pyserial URL")
        return DeviceError(f"cannot open serial port {self.port}: {text}")

    def close(self) -> None:
        """Give the firmware its ESP-NOW mode (as found at connect) and its feedback stream (when it had one) back,
        and close the port."""
        if self.ser is not None and not self.closed:
            restore = [] if self.esp_now is None else [{"T": 301, "mode": self.esp_now.mode}]
            if self._restore_info_print is not None:
                restore.append({"T": 605, "cmd": self._restore_info_print})
            try:
                for cmd in restore:
                    self.send(cmd)
                self.ser.flush()
            except Exception:  # noqa: BLE001 - a dead port: nothing to restore
                pass
            self.closed = True
            try:
                self.ser.close()
            except Exception:  # noqa: BLE001 - closing a dead port must not mask the real error
                pass

    def __enter__(self) -> Link:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ I/O
    def send(self, cmd: dict[str, Any], fresh_line: bool = False) -> float:
        """Write one command line; return the time it was handed to the driver.

        ``fresh_line`` prefixes a newline: if an interrupted write left half a line in flight, the
        firmware drops that fragment (malformed) instead of merging it with this command.
        """
        return self.send_lines([cmd], fresh_line)

    def send_lines(self, cmds: list[dict[str, Any]], fresh_line: bool = False) -> float:
        """Write several command lines in one write (nothing of this process can come between them); return the
        time they were handed to the driver."""
        import serial

        data = (b"\n" if fresh_line else b"") + b"".join(encode(c) for c in cmds)
        t = self.clock()
        try:
            self.ser.write(data)
        except serial.SerialTimeoutException:
            raise DeviceError(f"link lost: writing to {self.port} timed out", LOST_HINT) from None
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"link lost: cannot write to {self.port} ({exc})", LOST_HINT) from None
        self.sent += [(t, c) for c in cmds]
        return t

    def poll(self) -> list[Received]:
        """Read what has arrived (without waiting); return the complete lines, parsed."""
        import serial

        try:
            n = self.ser.in_waiting
            data = self.ser.read(n) if n else b""
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"link lost: cannot read from {self.port} ({exc})", LOST_HINT) from None
        return self._lines(data)

    def read_for(self, seconds: float) -> list[Received]:
        """Read lines for up to ``seconds`` (blocking reads of ``read_timeout`` each)."""
        import serial

        out: list[Received] = []
        end = self.clock() + seconds
        while self.clock() < end:
            try:
                data = self.ser.read(max(1, self.ser.in_waiting))
            except (serial.SerialException, OSError) as exc:
                raise DeviceError(f"link lost: cannot read from {self.port} ({exc})", LOST_HINT) from None
            out += self._lines(data)
        return out

    def _lines(self, data: bytes) -> list[Received]:
        if not data:
            return []
        t = self.clock()
        out = []
        for raw in self.lines.feed(data):
            text = raw.decode("utf-8", errors="replace")
            out.append(Received(t, text, parse_feedback_report(raw)))
        self.received += out
        return out

    def discard_input(self) -> None:
        """Drop whatever the device sent that has not been read yet."""
        try:
            self.ser.reset_input_buffer()
        except Exception:  # noqa: BLE001
            pass
        self.lines.clear()

    def request_feedback(self, timeout: float = 0.3) -> Feedback | None:
        """Send ``T:105`` and wait for the next ``T:1051``; None on timeout."""
        r = self.request(timeout)
        return None if r is None else r.feedback

    def request(self, timeout: float = 0.3, ahead: list[dict[str, Any]] | None = None,
                earlier: int = 0) -> Received | None:
        """Send ``T:105`` (after the lines ``ahead``, in the same write) and wait for its ``T:1051`` line (its time
        and text too); None on timeout. ``earlier``: answers still due to ``T:105`` lines sent before this one; the
        firmware answers in order, so that many frames come first and are passed over (they stay in ``received``)."""
        self.send_lines([*(ahead or []), protocol.feedback_request()])
        end = self.clock() + timeout
        while self.clock() < end:
            for r in self.read_for(min(0.02, max(0.0, end - self.clock()))):
                if r.feedback is not None:
                    if earlier <= 0:
                        return r
                    earlier -= 1
        return None

    # ------------------------------------------------------------------ connect
    def handshake(self) -> Feedback:
        """``connect()``, returning its first feedback (kept for callers of the old name)."""
        return self.connect().first

    def connect(self) -> DeviceInfo:
        """Meet the firmware where it is, without disturbing a start-up, and make it a quiet,
        local, measured link:

        1. listen: unasked T:1051 frames mean the loop runs with InfoPrint 2 (factory default);
           text means it is starting up: wait for its first frame (nothing is sent during setup(),
           where any input aborts the boot mission, A:8-15); silence: wait out setup()'s silent
           stretch before the first probe;
        2. ``{"T":605,"cmd":0}`` and confirm it (no unasked frame for ``quiet_confirm``);
        3. ``{"T":301,"mode":0}``: leave ESP-NOW follower mode (the default, C:16), so no leader arm
           nearby can drive this one during the run; the mode found (``roarmctl.device.espnow``: the boot
           mission's, read from the start-up text or with ``{"T":602}``) is given back by ``close()``;
        4. measure the T:105 round trip and the firmware's time per command line, and tell the build
           from its answers (the 20260701 build adds torque flags and supply voltage to T:1051 and
           queues one line per loop pass);
        5. where the build reports them: refuse when torque is off or the supply is out of range.
        Raises DeviceError (device silent, wrong firmware, torque off, supply out of range).
        """
        t = self.timings
        start = self.clock()
        got = self.read_for(t.listen)
        frames = [r for r in got if r.feedback is not None]
        text = [r.line for r in got if r.feedback is None and r.line.strip()]
        booted = bool(text) and not frames
        self.boot_text += text
        if booted:
            frames = self._wait_for_boot(start)
        elif not frames:  # silent: the loop runs quietly, or setup() is in its silent stretch
            while not frames and self.clock() - start < t.silent_window:
                more = self.read_for(0.05)
                frames = [r for r in more if r.feedback is not None]
                text = [r.line for r in more if r.feedback is None and r.line.strip()]
                if text and not frames:
                    self.boot_text += text
                    booted = True
                    frames = self._wait_for_boot(start)
                    break
        streamed = bool(frames)
        sent: list[str] = []
        if streamed:
            self._quiet(sent)
            self._restore_info_print = 2
        else:
            self.send(protocol.quiet_command())
            sent.append("T:605 cmd 0")
        first = self._probe()
        self._check_model(first.feedback)
        self.esp_now = self._find_esp_now(sent)
        self.send({"T": 301, "mode": 0})
        sent.append("T:301 mode 0")
        rtt, line_time = self._measure()
        sent.append("T:105 x3, T:605 x6 + T:105 (timing)")
        last = self._probe()
        fb = last.feedback
        assert fb is not None  # _probe returns a T:1051 line
        self._check_model(fb)
        # the build says how it reads the UART (its T:1051 names it: torque flags and voltage are the 20260701
        # build's); the measured line time only describes it: beside two CPU hogs the 0.84 build once measured
        # 3.3 ms a line, the least of four tries, where the 20260701 build measures 4.4-5 ms
        queued = fb.firmware == "m3-2026"
        voltage = torque = None
        if "v" in fb.raw:
            v = protocol.number(fb.raw.get("v"))
            voltage = None if v is None else v / 100.0
            torque = {k: int(protocol.number(fb.raw.get(k)) or 0) for k in fb.raw if k.startswith("torswitch")}
        info = DeviceInfo(fb.firmware, rtt, line_time, queued, streamed, booted, fb, voltage, torque, sent, self.waited,
                          self.esp_now)
        self.info = info
        self.firmware = fb.firmware
        self._check_power(info)
        return info

    def _wait_for_boot(self, start: float) -> list[Received]:
        """Start-up text seen: wait, sending nothing, for the end of set-up: the loop's first unasked frame
        (InfoPrint 2), or its last set-up line (the MAC address, ``SETUP_END``) and ``after_setup`` more for its boot
        mission to start; at most ``boot_timeout`` s from opening (then a probe tells a running arm from a dead one).
        ``self.waited`` says which, in one sentence."""
        t = self.timings
        setup_end: float | None = None
        while self.clock() - start < t.boot_timeout:
            more = self.read_for(0.1)
            frames = [r for r in more if r.feedback is not None]
            if frames:
                self.waited = f"waited {self.clock() - start:.1f} s for the arm's set-up to end (its first feedback frame)"
                return frames
            text = [r.line for r in more if r.line.strip()]
            self.boot_text += text
            if any(SETUP_END.match(line) for line in text):
                setup_end = self.clock()
            if setup_end is not None and self.clock() - setup_end >= t.after_setup:
                self.waited = (f"waited {self.clock() - start:.1f} s for the arm's set-up to end (its MAC address line, "
                               f"then {t.after_setup:.1f} s for its boot mission)")
                return []
        last = f" (last text: {self.boot_text[-1][:40]!r})" if self.boot_text else ""
        self.waited = f"waited {t.boot_timeout:.0f} s for the arm's set-up to end, without its last line{last}; probing"
        return []

    def _find_esp_now(self, sent: list[str]) -> EspNowMode:
        """The ESP-NOW mode the arm's boot mission set: from its listing in the start-up text, else from the listing
        ``{"T":602}`` prints (read until its end line, at most ``mission_wait`` s), else the firmware's default."""
        if espnow.listing_ended(self.boot_text):
            found = espnow.mode_from_listing(self.boot_text, "listed at start-up")
            if found is not None:
                return found
        self.send(espnow.BOOT_MISSION_INFO)
        sent.append("T:602 (boot mission)")
        text: list[str] = []
        end = self.clock() + self.timings.mission_wait
        while self.clock() < end and not espnow.listing_ended(text):
            text += [r.line for r in self.read_for(0.02) if r.feedback is None]
        return espnow.mode_from_listing(text, 'read with {"T":602}') or espnow.unread()

    def _quiet(self, sent: list[str]) -> None:
        """T:605 cmd 0, confirmed by a window without unasked frames (up to three tries)."""
        t = self.timings
        for _ in range(3):
            self.send(protocol.quiet_command())
            sent.append("T:605 cmd 0")
            last_frame = self.clock()
            end = self.clock() + 1.0
            while self.clock() < end:
                if any(r.feedback is not None for r in self.read_for(0.02)):
                    last_frame = self.clock()
                elif self.clock() - last_frame >= t.quiet_confirm:
                    return
        raise DeviceError(f"{self.port} keeps streaming feedback after {{\"T\":605,\"cmd\":0}} (sent 3 times)",
                          "another program may be switching it back on (close the web page or other clients), then retry")

    def _probe(self) -> Received:
        """A T:1051 answer to T:105, or DeviceError (device silent). Probes that went unanswered within their wait may
        still be answered (a slow loop): the firmware answers in order, so the answer kept is the last probe's, once
        every probe sent has had its answer or 0.3 s passed without one; what came before is passed over (before,
        three late answers shifted the pairing and the round trip was measured as 28 ms instead of 55)."""
        t = self.timings
        deadline = self.clock() + t.silent_after
        last_other: str | None = None
        asked = 0
        while self.clock() < deadline:
            asked += 1
            r = self.request(min(0.5, max(0.05, deadline - self.clock())))
            if r is not None:
                answers, quiet_from = 1, self.clock()
                while answers < asked and self.clock() - quiet_from < 0.3:
                    late = [x for x in self.read_for(0.02) if x.feedback is not None]
                    if late:
                        r, answers, quiet_from = late[-1], answers + len(late), self.clock()
                return r
            others = [x.line.strip() for x in self.received[-5:] if x.feedback is None and x.line.strip()]
            last_other = others[-1] if others else last_other
        hint = "check that the arm is powered (12 V) and on, that this is its serial port, and that the baud rate is 115200"
        extra = f"; last line: {last_other[:60]!r}" if last_other else ""
        raise DeviceError(f"device silent: no feedback from {self.port} within {t.silent_after:.1f} s{extra}", hint)

    def _measure(self) -> tuple[float, float]:
        """(median T:105 round trip, firmware time per command line beyond the wire), s.

        Six harmless lines (``{"T":605,"cmd":0}`` again) ahead of a T:105: a firmware that runs
        every waiting line in one pass answers one round trip (plus their wire time) later, one that
        runs a line per loop pass six passes later. The seven lines go out in one write. A busy host only
        ever adds to what it measures (a late read: 3.8 ms a line was once seen on the 0.84 build beside
        two CPU hogs), so a result above ``QUEUED_LINE_TIME`` is measured again, up to
        ``LINE_TIME_TRIES`` times, and the least is kept (against the least round trip). It describes the
        build's pace (the display, the link budget); which build it is comes from its answers.
        """
        rtts = []
        for _ in range(3):
            t0 = self.clock()
            r = self.request(0.5)
            if r is not None:
                rtts.append(r.t - t0)
        if not rtts:
            raise DeviceError(f"device silent: {self.port} stopped answering T:105", LOST_HINT)
        filler = protocol.quiet_command()
        k = 6
        wire = wire_seconds(k * len(encode(filler)))
        best: float | None = None
        for _ in range(LINE_TIME_TRIES):
            t0 = self.clock()
            r = self.request(0.5 + k * 0.05, ahead=[filler] * k)
            if r is None:
                continue
            line_time = max(0.0, (r.t - t0 - min(rtts) - wire) / k)
            best = line_time if best is None else min(best, line_time)
            if best <= QUEUED_LINE_TIME:
                break
        return statistics.median(rtts), 0.0 if best is None else best

    def _check_model(self, fb: Feedback | None) -> None:
        if fb is None:
            return
        if fb.firmware == "m2" and self.expect != "m2":
            raise DeviceError(f"{self.port} answers like RoArm-M2 firmware (feedback has b s e t, no wrist/roll), "
                              f"but the trajectory is for a RoArm-M3",
                              "plan for the M2 (robot: roarm_m2_s) or connect the M3")
        if fb.firmware.startswith("m3") and self.expect == "m2":
            raise DeviceError(f"{self.port} answers like RoArm-M3 firmware ({fb.firmware}), but the trajectory is for a "
                              f"RoArm-M2", "plan for the M3 (robot: roarm_m3_pro) or connect the M2")
        if fb.firmware not in BUILD_NAMES:
            raise DeviceError(f"{self.port} sent feedback this tool does not recognise: {str(fb.raw)[:80]}",
                              "expected RoArm-M3 firmware (0.84 or 20260701 build) T:1051 frames")

    def _check_power(self, info: DeviceInfo) -> None:
        if info.voltage is not None and not MIN_SUPPLY_V < info.voltage < MAX_SUPPLY_V:
            raise DeviceError(f"{self.port}: the arm's supply reads {info.voltage:.2f} V, outside "
                              f"{MIN_SUPPLY_V:.2f}-{MAX_SUPPLY_V:.2f} V (the firmware's own alarm range)",
                              "connect the arm's 12 V supply and switch it on, then retry")
        off = [k[len("torswitch"):] for k, v in (info.torque or {}).items() if v == 0]
        if off and self.require_torque:
            names = dict(zip("BSETRG", ("base", "shoulder", "elbow", "wrist", "roll", "gripper")))
            raise DeviceError(f"{self.port}: torque is off on {', '.join(names.get(x, x) for x in off)} "
                              "(torque flags in the feedback)",
                              "the arm would not hold a pose: switch torque on where the arm stands (roarmctl teach "
                              "does it safely), or check the servo power, then retry")
