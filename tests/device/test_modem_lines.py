"""Opening the port never puts the ESP32 into reset.

The usual ESP32 auto-program circuit (the one esptool drives) holds the chip in reset while DTR is
released and RTS asserted. Linux asserts both lines when a tty is opened; pyserial then applies the
DTR and RTS states it was given, one after the other (serialposix.py, ``open``). This test runs
pyserial's own ``open`` with its modem-line ioctls recorded (a pseudo-terminal has no modem lines,
so the record is the only witness) and replays the line states it produced.
"""

from __future__ import annotations

import errno

import pytest
import serial
import serial.serialposix as sp

from roarmctl.device.link import Link
from roarmctl.device.simulator import PtySimulator, SimConfig

RESET = {"dtr": False, "rts": True}  # EN held low by the auto-program circuit


@pytest.fixture
def modem(monkeypatch):
    """Record every DTR/RTS change pyserial makes; start each open with both asserted, as the
    kernel does when it opens a tty (tty_port_raise_dtr_rts)."""
    states: list[dict[str, bool]] = []
    real_ioctl = sp.fcntl.ioctl
    real_open = sp.os.open

    def fake_open(path, flags, *args):
        fd = real_open(path, flags, *args)
        states.append({"dtr": True, "rts": True})
        return fd

    def fake_ioctl(fd, request, arg=0, *rest):
        if request in (sp.TIOCMBIS, sp.TIOCMBIC):
            bits = int.from_bytes(arg, "little") if isinstance(arg, (bytes, bytearray)) else int(arg)
            new = dict(states[-1])
            for name, mask in (("dtr", sp.TIOCM_DTR), ("rts", sp.TIOCM_RTS)):
                if bits & mask:
                    new[name] = request == sp.TIOCMBIS
            states.append(new)
            return arg
        return real_ioctl(fd, request, arg, *rest)

    monkeypatch.setattr(sp.os, "open", fake_open)
    monkeypatch.setattr(sp.fcntl, "ioctl", fake_ioctl)
    return states


def test_the_link_opens_without_ever_holding_the_reset_state(modem):
    with PtySimulator(SimConfig(), process=True) as sim:
        link = Link(sim.path).open()
        link.close()
    assert modem, "pyserial's open was not observed"
    assert RESET not in modem, modem
    # the states it went through: both asserted by the kernel, then RTS released (as roarm-sdk leaves it)
    assert modem[0] == {"dtr": True, "rts": True} and modem[-1] == {"dtr": True, "rts": False}


def test_the_witness_sees_the_reset_of_a_naive_open(modem):
    """Clearing both lines before ``open()`` (the old way) passes through the reset state: the
    recorder is able to see the failure it guards against."""
    with PtySimulator(SimConfig(), process=True) as sim:
        ser = serial.Serial()
        ser.port, ser.baudrate = sim.path, 115200
        ser.dtr = False
        ser.rts = False
        ser.open()
        ser.close()
    assert RESET in modem


def test_roarm_sdk_opens_the_same_way(modem):
    sdk = pytest.importorskip("roarm_sdk.roarm")
    with PtySimulator(SimConfig(), process=True) as sim:
        client = sdk.roarm(roarm_type="roarm_m3", port=sim.path, baudrate=115200)
        client.disconnect()
    assert RESET not in modem and modem[-1] == {"dtr": True, "rts": False}


def test_a_port_without_modem_lines_still_opens(monkeypatch):
    """Pseudo-terminals and some adapters refuse the modem ioctls (EINVAL/ENOTTY): pyserial ignores
    that, and so does the link."""
    def refuse(fd, request, arg=0, *rest):
        if request in (sp.TIOCMBIS, sp.TIOCMBIC):
            raise OSError(errno.EINVAL, "Invalid argument")
        return real(fd, request, arg, *rest)

    real = sp.fcntl.ioctl
    monkeypatch.setattr(sp.fcntl, "ioctl", refuse)
    with PtySimulator(SimConfig(), process=True) as sim:
        link = Link(sim.path).open()
        assert link.ser.is_open
        link.close()
