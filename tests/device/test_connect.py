"""Connecting like the vendor: nothing sent during the firmware's start-up, feedback quieted and the
quiet confirmed, ESP-NOW follower mode left, the build told apart and shown, torque and supply
checked where the build reports them. The firmware model is the witness: the real ``Link`` talks to it over a
``VirtualSerial`` on the virtual clock (roarmctl.device.virtual), so every time asserted is the model's; a few
runs through the CLI keep the real pty (marked slow)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from devtraj import HOME, min_jerk

from roarmctl.cli import run as run_cli
from roarmctl.device.firmware import Firmware
from roarmctl.device.link import Link
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.device.virtual import VirtualClock, serial_link

MOTION = (101, 102, 104, 1041, 121, 122)


def connected(cfg: SimConfig) -> tuple[Link, Firmware, VirtualClock]:
    """A ``Link`` to a firmware model of ``cfg`` switched on now, on a virtual clock; not connected yet."""
    clock = VirtualClock()
    link = serial_link(cfg, clock)
    return link, link.ser.fw, clock


def wait(fw: Firmware, clock: VirtualClock, seconds: float) -> None:
    """Let ``seconds`` pass on the clock, the model running through them."""
    clock.sleep(seconds)
    fw.advance(clock())


@pytest.fixture
def short(tmp_path) -> Path:
    p = tmp_path / "s.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    return p


def test_a_starting_arm_gets_no_line_before_its_setup_ends_and_its_boot_mission_runs():
    mission = ('{"T":114,"led":64}',)
    link, fw, _ = connected(SimConfig(boot=True, time_factor=0.5, boot_mission=mission))
    info = link.connect()
    link.close()
    assert info.booted and info.streamed and info.firmware == "m3-0.84"
    assert fw.boot_mission_aborted is False  # the mission ran: nothing was waiting in the buffer
    executed = [c for _, _, c in fw.executed]
    assert executed[0] == json.loads(mission[0])  # the boot mission's own line came first
    ours = [t for t, _, c in fw.executed if c.get("T") in (605, 105, 301)]
    # the first of our lines reached the UART after setup had ended (3.2 s in at time factor 0.5)
    assert ours and min(ours) >= fw.booting_until, (min(ours), fw.booting_until)


def test_a_quiet_starting_arm_is_left_alone_until_its_set_up_ends_and_the_wait_is_said_in_one_line():
    """Opened at power-on, an arm whose loop prints nothing unasked (InfoPrint 0): the boot moves are 3.7 s of silence
    after the servo check's line, and the MAC address line ends set-up about 6 s in. Nothing goes out before it, the
    boot mission runs, and the connection says what it waited for. Before: a probe 4 s after the last text, about
    5.7 s in, during set-up: the boot mission was aborted."""
    mission = ('{"T":114,"led":64}',)
    link, fw, clock = connected(SimConfig(boot=True, info_print=0, boot_mission=mission))
    t_open = clock()
    info = link.connect()
    ours = [t for t, _, c in fw.executed if c.get("T") in (605, 105, 301)]
    link.close()
    assert info.booted and not info.streamed
    assert fw.boot_mission_aborted is False
    assert ours and min(ours) >= fw.booting_until > t_open + 6.0, (min(ours), fw.booting_until, t_open)
    assert "MAC address line" in info.waited and info.waited in info.describe()
    assert info.as_dict()["waited_for"] == info.waited


def test_input_during_setup_would_abort_the_boot_mission():
    """What the waiting protects: a line sent during setup() aborts the boot mission (A:8-15)."""
    link, fw, clock = connected(SimConfig(boot=True, time_factor=0.5, boot_mission=('{"T":114,"led":64}',)))
    wait(fw, clock, 0.3)
    link.ser.write(b'{"T":105}\n')
    wait(fw, clock, 4.0)
    assert min(t for t, _, c in fw.executed if c.get("T") == 105) < fw.booting_until  # it came during set-up
    assert fw.boot_mission_aborted is True


def test_quiet_confirmed_esp_now_left_build_measured_and_feedback_restored():
    link, fw, clock = connected(SimConfig())
    info = link.connect()
    during = (fw.info_print, fw.esp_now_mode)
    wait(fw, clock, 0.2)
    frames = sum(r.feedback is not None for r in link.read_for(0.2))
    link.close()
    wait(fw, clock, 0.1)
    assert info.streamed and during[0] == 0 and frames == 0  # quiet, and quiet it stayed
    assert during[1] == 0
    assert fw.info_print == 2  # the firmware got its factory feedback stream back
    # the build is told by its answers, not by the host's clock: its measured line time is about 0 (on a pty it once
    # read 3.76 ms beside two CPU hogs, and 3.3 ms as the least of four tries, where the queuing build reads 4.4-5 ms)
    assert not info.queued and info.firmware == "m3-0.84"
    # the round trip: a T:105 in, one loop pass, six servo reads, a ~230-byte line out (~20 ms of wire)
    assert 0.02 < info.rtt < 0.06
    assert info.voltage is None and "reports neither torque nor supply voltage" in info.describe()


def test_the_newer_build_is_told_apart_by_its_answers_and_its_pace():
    link, fw, _ = connected(SimConfig(firmware="m3-2026"))
    info = link.connect()
    passes = float(np.median(fw.passes))
    link.close()
    assert info.firmware == "m3-2026" and info.queued
    assert info.line_time == pytest.approx(passes, rel=0.5)  # one command per loop pass
    assert info.voltage == pytest.approx(12.0) and set(info.torque.values()) == {1}
    assert "20260701 build" in info.describe()


@pytest.mark.slow  # real time: the CLI on the simulated arm's pty
def test_the_display_and_the_log_name_the_build(short, capsys, monkeypatch):
    import io

    from rich.console import Console

    from roarmctl.cli import common

    screen = io.StringIO()
    terminal = Console(file=screen, force_terminal=True, width=200)
    monkeypatch.setattr(common, "console", lambda stderr=False: terminal if stderr else Console(file=io.StringIO()))
    with PtySimulator(SimConfig(firmware="m3-2026"), process=True) as sim:
        rc = run_cli(["execute", str(short), "--port", sim.path, "--yes"])
    shown = screen.getvalue()
    assert rc == 0 and "firmware: RoArm-M3 20260701 build" in shown and "link budget:" in shown
    log = json.loads(short.with_name("s.exec.json").read_text())
    assert log["device"]["firmware"] == "m3-2026" and log["device"]["queued"] is True


def test_a_leader_arm_cannot_drive_this_one_once_connected():
    link, fw, clock = connected(SimConfig(esp_now_leader=True))
    wait(fw, clock, 0.5)
    before = np.array(fw.servos.positions())
    link.connect()
    # put the arm elsewhere; a follower would be dragged back to the leader's pose every 50 ms
    link.send({"T": 102, "base": -0.3, "shoulder": 0, "elbow": 1.5708, "wrist": 0, "roll": 0, "hand": 3.1416,
               "spd": 0, "acc": 0})
    wait(fw, clock, 0.6)
    after = np.array(fw.servos.positions())
    link.close()
    leader_base = 2047 - round(0.6 / (2 * np.pi) * 4096)
    assert before[0] == pytest.approx(leader_base, abs=1)  # it did follow the leader before we came
    assert after[0] == pytest.approx(2047 + round(0.3 / (2 * np.pi) * 4096), abs=1)  # and not after


@pytest.mark.parametrize("fault,words", [({"torque_off": True}, "torque is off on base"),
                                         ({"voltage": 5.2}, "supply reads 5.20 V"),
                                         ({"unpowered": True}, "supply reads 0.00 V")])
@pytest.mark.slow  # real time: the CLI on the simulated arm's pty
def test_torque_off_or_supply_out_of_range_is_refused_before_any_motion(short, capsys, fault, words):
    with PtySimulator(SimConfig(firmware="m3-2026", **fault), process=True) as sim:
        rc = run_cli(["execute", str(short), "--port", sim.path, "--yes"])
        moved = [c for _, c in sim.received() if c.get("T") in MOTION]
    err = capsys.readouterr().err
    assert rc == 4 and words in err and err.count("\n") == 1 and not moved


@pytest.mark.parametrize("cfg,found,how", [
    (SimConfig(boot=True, time_factor=0.5, boot_mission=('{"T":114,"led":64}', '{"T":301,"mode":1}')), 1,
     "listed at start-up"),
    (SimConfig(), 3, 'read with {"T":602}'),
    (SimConfig(firmware="m3-2026"), 3, 'read with {"T":602}'),
])
def test_the_esp_now_mode_found_at_connect_is_given_back_when_the_link_closes(cfg, found, how):
    """Connecting leaves ESP-NOW (no leader may drive the arm during a run); closing gives back the mode the boot
    mission set (a leader set-up here) or the firmware's default, follower. Before, it stayed off until a reboot."""
    link, fw, clock = connected(cfg)
    info = link.connect()
    before_close = fw.esp_now_mode
    link.close()
    wait(fw, clock, 0.2)
    after = fw.esp_now_mode
    asked = [c for _, _, c in fw.executed if c.get("T") == 602]
    assert before_close == 0 and after == found
    assert info.esp_now is not None and info.esp_now.mode == found and how in info.esp_now.source
    assert bool(asked) == (how != "listed at start-up")  # the start-up text already listed it: not asked again
    logged = info.as_dict()["esp_now"]
    assert logged["found"] == found and logged["restored_on_close"] is True
