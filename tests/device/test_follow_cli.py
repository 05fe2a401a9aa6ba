"""``roarmctl follow`` as a user meets it: bad options are one line and exit 2 before anything opens; a policy
process piped into it on the simulated arm ends 0 when its stream ends cleanly and 4 (one line, the arm held, the
log written) when its targets lean into an obstacle of the plan."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from clirun import roarmctl
from followsim import HOME, POLICY, ramp

BENCH = """robot: roarm_m3_pro
start: home
scene:
  obstacles:
    - {name: bench, shape: box, size: [0.3, 0.4, 0.2], xyz: [0.35, 0.0, 0.1]}
tasks:
  - move: {pose: home}
planner: {singularity_margin: 0.02, padding: 0.005}
"""


@pytest.mark.parametrize("args, words", [
    (["follow"], "exactly one of --port PORT and --sim"),
    (["follow", "--sim", "--velocity-scale", "nan"], "--velocity-scale: expected a finite number, got nan"),
    (["follow", "--sim", "--timeout", "-1"], "--timeout: -1 is too small (must be > 0)"),
    (["follow", "--sim", "--max-refusals", "0"], "--max-refusals: expected a whole number from 1 to 1000"),
    (["follow", "--sim", "--rate", "500"], "--rate: 500 is too large (must be <= 90)"),
    (["follow", "--port", "/dev/null"], "pass --yes"),
    (["follow", "--sim", "--leader", "/dev/ttyUSB9", "--leader-guide", "x.yaml"], "give one leader"),
    (["follow", "--sim", "--episode", "3"], "--episode goes with --dataset"),  # these three were ignored, exit 0
    (["follow", "--sim", "--record-fps", "-1"], "go with --record"),
    (["follow", "--sim", "--task", "pick"], "go with --record"),
])
def test_bad_options_are_one_line_and_exit_2(args, words):
    res = roarmctl(*args)
    assert res.returncode == 2, res.stderr
    assert words in res.stderr and "Traceback" not in res.stderr and len(res.stderr.strip().splitlines()) <= 2


def pipe_policy(lines, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    text = json.dumps([(t, json.dumps(o)) for t, o in lines])
    pol = subprocess.Popen([sys.executable, "-c", POLICY, text], stdout=subprocess.PIPE)
    try:
        return subprocess.run([sys.executable, "-m", "roarmctl", "follow", "--sim", *args], stdin=pol.stdout,
                              capture_output=True, text=True, timeout=120, cwd=cwd)
    finally:
        pol.kill()
        pol.wait(5)


@pytest.mark.slow
def test_a_policy_piped_into_follow_ends_0_when_clean_and_4_when_it_leans_into_an_obstacle(tmp_path):
    clean = ramp(0.0, HOME, HOME + [0.3, 0.1, 0, 0, 0, 0.5], 15)
    res = pipe_policy(clean, "--log", "clean.json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "completed" in res.stderr
    log = json.loads((tmp_path / "clean.json").read_text())
    tg = log["summary"]["targets"]
    assert tg["accepted"] + tg["refused"] == 15 and set(tg["by_kind"]) <= {"stale"}  # a stalled host: late frames
    assert np.allclose(log["commanded"][-1][1:], HOME + [0.3, 0.1, 0, 0, 0, 0.5], atol=1e-4)

    lean = ramp(0.0, HOME, np.array([0.0, 0.6, 1.5708, 0.0, 0.0, 0.0]), 30)
    (tmp_path / "bench.yaml").write_text(BENCH)
    res = pipe_policy(lean, "--scene", "bench.yaml", "--log", "lean.json", cwd=tmp_path)
    assert res.returncode == 4, res.stderr
    last = [ln for ln in res.stderr.splitlines() if ln.startswith("error:")]
    assert len(last) == 1 and "refused in a row" in last[0] and "Traceback" not in res.stderr
    log = json.loads((tmp_path / "lean.json").read_text())
    assert log["hold"]["copies"] == 2 and log["summary"]["outcome"] == "aborted"
    assert any("hits obstacle 'bench'" in r["reason"] for r in log["summary"]["targets"]["refusals"])


def test_a_refusal_is_printed_as_it_is_written(monkeypatch):
    """The refusal of a malformed line printed 'expected {"t": s, "joints": , ...}': rich took '[rad, ...]' for markup."""
    from roarmctl.device import follow_session, follow_sources
    from roarmctl.errors import DeviceError

    said = 'refused: line 2: expected {"t": s, "joints": [rad, ...], "gripper": rad} [bold]x[/]'

    def follow_live(*args, on_event, **kwargs):
        on_event(said)
        raise DeviceError("stop here")

    monkeypatch.setattr(follow_session, "follow_live", follow_live)
    monkeypatch.setattr(follow_sources, "StreamSource", lambda robot, fd: None)
    with open("/dev/null") as null:  # the policy's stdin: pytest's own has no file descriptor
        monkeypatch.setattr(sys, "stdin", null)
        res = roarmctl("follow", "--sim", "--yes")
    assert res.returncode == 4 and said in res.stderr, res.stderr
