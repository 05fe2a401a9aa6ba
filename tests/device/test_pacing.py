"""The poll rate and the link budget follow the build met: the 20260701 build (one queued line per
loop pass, 324-byte answers that block its loop) is polled at half the rate, and the budget counts the
answers it really prints. The real ``Link`` connects to the firmware model over a ``VirtualSerial`` and the streamer
runs on the model's clock (roarmctl.device.virtual): no real time."""

from __future__ import annotations

import pytest
from devtraj import HOME, min_jerk

from roarmctl.device.sim_config import SimConfig
from roarmctl.device.streamer import StreamConfig, Streamer
from roarmctl.device.virtual import VirtualClock, serial_link
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")


@pytest.mark.parametrize("firmware,polls", [("m3-0.84", 25.0), ("m3-2026", 12.5)])
def test_polls_and_budget_follow_the_build(firmware, polls):
    clock = VirtualClock()
    link = serial_link(SimConfig(firmware=firmware), clock)
    link.connect()
    traj = min_jerk([HOME, [0.4, 0.2, 1.7, -0.2, 0.1, 0.3]], [0.8])
    res = Streamer(link, ROBOT, traj, StreamConfig(), clock=clock, sleep=clock.sleep).run()
    link.close()
    assert res.outcome == "completed"
    log = res.log
    answers = [len(r["line"]) + 2 for r in log["received"] if "feedback" in r]
    budget = log["link_budget"]
    assert budget["down_bytes_per_s"] == pytest.approx(polls * max(answers), rel=0.02)
    assert (max(answers) > 300) == (firmware == "m3-2026")  # its torque flags and voltage
    # polls actually sent during the motion (one every 50/polls ticks, from the first tick on)
    ticks = [e["t"] for e in log["sent"] if "tick" in e]
    asked = [e for e in log["sent"] if e["cmd"].get("T") == 105 and ticks[0] <= e["t"] <= ticks[-1]]
    assert polls * (ticks[-1] - ticks[0]) - 2 <= len(asked) <= polls * (ticks[-1] - ticks[0]) + 2
