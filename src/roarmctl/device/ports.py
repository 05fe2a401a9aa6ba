"""List serial ports and mark the likely RoArm (its ESP32 board has a CP2102; CH340/CH9102 clones too)."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass
from pathlib import Path

#: USB VID:PID of the bridges seen on ESP32 robot driver boards.
LIKELY_ARM = {
    (0x10C4, 0xEA60): "CP210x (RoArm-M3 driver board)",
    (0x1A86, 0x7523): "CH340",
    (0x1A86, 0x55D4): "CH9102",
}


@dataclass
class PortInfo:
    """A serial port as the OS lists it: device path, description, USB vendor and product id."""

    device: str
    description: str
    vid: int | None
    pid: int | None
    serial_number: str | None
    by_id: str | None  # stable /dev/serial/by-id/... path, if the system has one
    likely_arm: bool
    bridge: str | None

    def as_dict(self) -> dict:
        """The port as a JSON-ready dict (``vid_pid`` as ``VVVV:PPPP``)."""
        return {
            "device": self.device, "description": self.description,
            "vid_pid": f"{self.vid:04X}:{self.pid:04X}" if self.vid is not None and self.pid is not None else None,
            "serial_number": self.serial_number, "by_id": self.by_id,
            "likely_arm": self.likely_arm, "bridge": self.bridge,
        }


def _by_id() -> dict[str, str]:
    out = {}
    d = Path("/dev/serial/by-id")
    if d.is_dir():
        for link in sorted(d.iterdir()):
            try:
                out[os.path.realpath(link)] = str(link)
            except OSError:
                pass
    return out


def list_ports() -> list[PortInfo]:
    """Serial ports on this machine, likely arms first."""
    from serial.tools import list_ports as lp

    links = _by_id()
    ports = []
    for p in lp.comports():
        bridge = LIKELY_ARM.get((p.vid, p.pid)) if p.vid is not None else None
        ports.append(PortInfo(p.device, p.description or "", p.vid, p.pid, p.serial_number,
                              links.get(os.path.realpath(p.device)), bridge is not None, bridge))
    ports.sort(key=lambda p: (not p.likely_arm, p.device))
    return ports


def port_holders(port: str) -> list[tuple[int, str]]:
    """Other processes that have ``port`` open: [(pid, process name)], from Linux's ``/proc/*/fd``.

    A port opened without a lock (ModemManager probes new ttyACM/ttyUSB devices like this) is not
    refused by our exclusive open, yet it can swallow the arm's replies. Elsewhere, or for processes
    we may not inspect, the list is empty. For a pseudo-terminal, a process that also holds the
    master side (``/dev/ptmx``) is the device itself (a simulator), not a competitor.
    """
    if not sys.platform.startswith("linux") or not os.path.isdir("/proc"):
        return []
    try:
        target = os.path.realpath(port)
        os.stat(target)
    except (OSError, ValueError):
        return []
    is_pty = target.startswith("/dev/pts/")
    me = os.getpid()
    found = []
    try:
        procs = [d for d in os.listdir("/proc") if d.isdigit() and int(d) != me]
    except OSError:
        return []
    for pid in procs:
        fd_dir = f"/proc/{pid}/fd"
        try:
            fds = os.listdir(fd_dir)
        except OSError:
            continue
        holds = master = False
        for fd in fds:
            try:
                link = os.readlink(f"{fd_dir}/{fd}")
            except OSError:
                continue
            if link == target:
                holds = True
            elif link in ("/dev/ptmx", "/dev/pts/ptmx"):
                master = True
        if holds and not (is_pty and master):
            try:
                name = Path(f"/proc/{pid}/comm").read_text().strip()
            except OSError:
                name = "?"
            found.append((int(pid), name))
    return found
