"""The RoArm-M2-S end to end (issue 8): its bundled example plans, executes on the simulator speaking
the M2 protocol (4-field T:102, b s e t feedback), and a trajectory/firmware mismatch is refused
either way before anything moves."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from roarmctl.cli import run as run_cli
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.robot.loader import load_robot

pytestmark = pytest.mark.slow  # real time: a plan run on the simulated M2 arm

ROOT = Path(__file__).resolve().parents[2]




@pytest.fixture(scope="module")
def m2_traj(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("m2") / "m2s.traj.json"
    assert run_cli(["plan", str(ROOT / "plans" / "m2s_pick_place.yaml"), "-o", str(out)]) == 0
    return out


def test_m2_plan_executes_on_the_m2_simulator(m2_traj, capsys, virtual_sim):
    """execute --sim on an M2 trajectory runs the M2 firmware model (on a virtual clock: virtual_sim)."""
    from roarmctl.motion.validate import load_trajectory

    traj = load_trajectory(m2_traj)
    robot = load_robot("roarm_m2_s")
    # ideal servos: --no-sag, the plan's own goals (compensated goals would stand an arm that does not sag off the
    # plan by the offsets; the compensation is tested in tests/test_physics.py)
    rc = run_cli(["execute", str(m2_traj), "--sim", "--servos", "ideal", "--yes", "--json", "--no-sag"])
    out = json.loads(capsys.readouterr().out)
    (sim,) = virtual_sim
    assert sim.config.firmware == "m2"
    received = [c for _, _, c in sim.executed()]
    _, rec, _ = sim.recording()
    assert rc == 0 and out["outcome"] == "completed"
    moves = [c for c in received if c.get("T") == 102]
    assert len(moves) > 100
    assert all(set(c) == {"T", "base", "shoulder", "elbow", "hand", "spd", "acc"} for c in moves)
    # where the arm ended up, read from the simulated servos with Waveshare's M2 driver mapping
    # (base = -q, shoulder = -q, elbow = q, hand = pi - q; the recording shows hand as pi - hand)
    b, s, e, hand = rec[-1, 0], rec[-1, 1], rec[-1, 2], math.pi - rec[-1, 5]
    q_end = np.array([-b, -s, e, math.pi - hand])
    assert np.allclose(q_end[:3], traj.positions[-1, :3], atol=0.01)
    tcp = robot.kin.fk(robot.full_q(q_end))[:3, 3]
    assert np.linalg.norm(tcp - robot.kin.fk(traj.positions[-1])[:3, 3]) < 0.005


def test_m2_trajectory_is_refused_by_m3_firmware(m2_traj, capsys):
    with PtySimulator(SimConfig(firmware="m3-0.84"), process=True) as sim:
        rc = run_cli(["execute", str(m2_traj), "--port", sim.path, "--yes"])
        moved = [c for _, c in sim.received() if c.get("T") in (101, 102, 104)]
    err = capsys.readouterr().err
    assert rc == 4 and "RoArm-M3 firmware" in err and "for a RoArm-M2" in err and not moved


def test_sim_device_model_picks_the_m2_protocol():
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "sim-device", "--model", "roarm_m2_s", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        info = json.loads(proc.stdout.readline())
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    assert info["firmware"] == "m2"
    bad = subprocess.run([sys.executable, "-m", "roarmctl", "sim-device", "--model", "roarm_m2_s", "--firmware", "m3-0.84"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "does not match" in bad.stderr
