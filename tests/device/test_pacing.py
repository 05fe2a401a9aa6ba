"""The poll rate and the link budget follow the build met: the 20260701 build (one queued line per
loop pass, 324-byte answers that block its loop) is polled at half the rate, and the budget counts the
answers it really prints."""

from __future__ import annotations

import json

import pytest
from devtraj import HOME, min_jerk

from roarmctl.cli import run as run_cli
from roarmctl.device.simulator import PtySimulator, SimConfig

pytestmark = pytest.mark.slow  # real time


@pytest.mark.parametrize("firmware,polls", [("m3-0.84", 25.0), ("m3-2026", 12.5)])
def test_polls_and_budget_follow_the_build(tmp_path, capsys, firmware, polls):
    p = tmp_path / "short.traj.json"
    min_jerk([HOME, [0.4, 0.2, 1.7, -0.2, 0.1, 0.3]], [0.8]).save(p)
    with PtySimulator(SimConfig(firmware=firmware), process=True) as sim:
        assert run_cli(["execute", str(p), "--port", sim.path, "--yes", "--json"]) == 0
    capsys.readouterr()
    log = json.loads(p.with_name("short.exec.json").read_text())
    answers = [len(r["line"]) + 2 for r in log["received"] if "feedback" in r]
    budget = log["link_budget"]
    assert budget["down_bytes_per_s"] == pytest.approx(polls * max(answers), rel=0.02)
    assert (max(answers) > 300) == (firmware == "m3-2026")  # its torque flags and voltage
    # polls actually sent during the motion (one every 50/polls ticks, from the first tick on)
    ticks = [e["t"] for e in log["sent"] if "tick" in e]
    asked = [e for e in log["sent"] if e["cmd"].get("T") == 105 and ticks[0] <= e["t"] <= ticks[-1]]
    assert len(asked) <= polls * (ticks[-1] - ticks[0]) + 2
