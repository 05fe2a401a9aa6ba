"""The serial link to the arm: open safely, wait out a reboot, handshake, send lines, read feedback.

Every failure a user meets becomes one ``DeviceError`` line naming the cause and the fix (exit 4):
no such port, port busy, permission denied, device silent, wrong firmware, link lost.
"""

from __future__ import annotations

import errno
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from roarmctl.device import protocol
from roarmctl.device.protocol import Feedback, LineBuffer, encode, parse_feedback, parse_json_line
from roarmctl.errors import DeviceError

DIALOUT_HINT = "on Linux: sudo usermod -aG dialout $USER, then log out and back in"


@dataclass
class LinkTimings:
    """Handshake timing (s). A silent device is reported after about ``settle + silent_after``."""

    read_timeout: float = 0.02
    write_timeout: float = 1.0
    settle: float = 0.3  # listen this long after opening for a boot banner
    boot_quiet: float = 1.0  # after banner text, wait until the device has been quiet this long
    boot_timeout: float = 15.0  # the longest a reboot (boot moves included) may take
    silent_after: float = 2.5  # no T:1051 answer to T:105 requests within this -> device silent
    poll_interval: float = 0.25  # between T:105 requests during the handshake


@dataclass
class Received:
    """A line from the device: when it arrived (s, link clock), its text, and its parsed feedback if any."""

    t: float
    line: str
    feedback: Feedback | None = None


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
        #: The protocol model the trajectory is for ("m3" or "m2", ``WireMap.model``); the handshake
        #: refuses a device that answers like the other one.
        self.expect = "m3"
        self.boot_text: list[str] = []
        self.received: list[Received] = []  # every line read, in order (the execution log)
        self.sent: list[tuple[float, dict[str, Any]]] = []
        self.closed = False

    # ------------------------------------------------------------------ open
    def open(self) -> Link:
        """Open with DTR and RTS low *before* opening (no ESP32 reset where the driver allows), exclusive."""
        import serial

        t = self.timings
        try:
            ser = serial.serial_for_url(self.port, do_not_open=True)
            ser.baudrate = protocol.BAUDRATE
            ser.timeout = t.read_timeout
            ser.write_timeout = t.write_timeout
            ser.dtr = False
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
        if "Invalid URL" in text or "expected" in text:
            return DeviceError(f"cannot open {self.port}: {text}", "give a device path like /dev/ttyUSB0 or a pyserial URL")
        return DeviceError(f"cannot open serial port {self.port}: {text}")

    def close(self) -> None:
        """Close the port (once; later calls do nothing)."""
        if self.ser is not None and not self.closed:
            self.closed = True
            try:
                self.ser.close()
            except Exception:  # noqa: BLE001 - closing a dead port must not mask the real error
                pass

    def __enter__(self) -> Link:
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ I/O
    def send(self, cmd: dict[str, Any], fresh_line: bool = False) -> float:
        """Write one command line; return the time it was handed to the driver.

        ``fresh_line`` prefixes a newline: if an interrupted write left half a line in flight, the
        firmware drops that fragment (malformed) instead of merging it with this command.
        """
        import serial

        data = (b"\n" if fresh_line else b"") + encode(cmd)
        t = self.clock()
        try:
            self.ser.write(data)
        except serial.SerialTimeoutException:
            raise DeviceError(f"link lost: writing to {self.port} timed out",
                              "check the USB cable and the arm's power; the arm may have rebooted") from None
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"link lost: cannot write to {self.port} ({exc})",
                              "check the USB cable and the arm's power; the arm may have rebooted") from None
        self.sent.append((t, cmd))
        return t

    def poll(self) -> list[Received]:
        """Read what has arrived (without waiting); return the complete lines, parsed."""
        import serial

        try:
            n = self.ser.in_waiting
            data = self.ser.read(n) if n else b""
        except (serial.SerialException, OSError) as exc:
            raise DeviceError(f"link lost: cannot read from {self.port} ({exc})",
                              "check the USB cable and the arm's power; the arm may have rebooted") from None
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
                raise DeviceError(f"link lost: cannot read from {self.port} ({exc})",
                                  "check the USB cable and the arm's power") from None
            out += self._lines(data)
        return out

    def _lines(self, data: bytes) -> list[Received]:
        if not data:
            return []
        t = self.clock()
        out = []
        for raw in self.lines.feed(data):
            text = raw.decode("utf-8", errors="replace")
            r = Received(t, text, parse_feedback(raw))
            out.append(r)
        self.received += out
        return out

    def discard_input(self) -> None:
        """Drop whatever the device sent that has not been read yet."""
        try:
            self.ser.reset_input_buffer()
        except Exception:  # noqa: BLE001
            pass
        self.lines.clear()

    # ------------------------------------------------------------------ handshake
    def handshake(self) -> Feedback:
        """Wait out a reboot, silence unsolicited output, and require a valid M3 ``T:1051``.

        Returns the first feedback. Raises DeviceError when the device is silent or is not an M3.
        """
        t = self.timings
        start = self.clock()
        got = self.read_for(t.settle)
        booting = any(parse_json_line(r.line) is None and r.line.strip() for r in got)
        if booting:  # banner text: the ESP32 rebooted on open; wait until it has been quiet
            self.boot_text += [r.line for r in got]
            quiet_since = self.clock()
            while self.clock() - quiet_since < t.boot_quiet and self.clock() - start < t.boot_timeout:
                more = [r for r in self.read_for(0.1) if r.feedback is None]
                if more:
                    self.boot_text += [r.line for r in more]
                    quiet_since = self.clock()
        self.send(protocol.quiet_command())
        self.read_for(0.05)
        self.discard_input()
        deadline = self.clock() + t.silent_after + (t.boot_timeout if booting else 0.0)
        last_other: str | None = None
        while self.clock() < deadline:
            self.send(protocol.feedback_request())
            for r in self.read_for(t.poll_interval):
                if r.feedback is not None:
                    return self._check_firmware(r.feedback)
                if r.line.strip():
                    last_other = r.line.strip()
        hint = "check that the arm is powered (12 V) and on, that this is its serial port, and that the baud rate is 115200"
        extra = f"; last line: {last_other[:60]!r}" if last_other else ""
        raise DeviceError(f"device silent: no feedback from {self.port} within {t.silent_after:.1f} s{extra}", hint)

    def _check_firmware(self, fb: Feedback) -> Feedback:
        self.firmware = fb.firmware
        if fb.firmware == "m2" and self.expect != "m2":
            raise DeviceError(f"{self.port} answers like RoArm-M2 firmware (feedback has b s e t, no wrist/roll), "
                              f"but the trajectory is for a RoArm-M3",
                              "plan for the M2 (robot: roarm_m2_s) or connect the M3")
        if fb.firmware.startswith("m3") and self.expect == "m2":
            raise DeviceError(f"{self.port} answers like RoArm-M3 firmware ({fb.firmware}), but the trajectory is for a "
                              f"RoArm-M2", "plan for the M3 (robot: roarm_m3_pro) or connect the M2")
        if fb.firmware == "m2":
            return fb
        if not fb.firmware.startswith("m3"):
            raise DeviceError(f"{self.port} sent feedback this tool does not recognise: {fb.raw}",
                              "expected RoArm-M3 firmware 0.84 T:1051 frames")
        return fb

    def request_feedback(self, timeout: float = 0.3) -> Feedback | None:
        """Send ``T:105`` and wait for the next ``T:1051``; None on timeout."""
        self.send(protocol.feedback_request())
        end = self.clock() + timeout
        while self.clock() < end:
            for r in self.read_for(min(0.02, max(0.0, end - self.clock()))):
                if r.feedback is not None:
                    return r.feedback
        return None
