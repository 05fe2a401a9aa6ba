"""Every way to stop `execute` holds the arm and writes the log (issue 13, finding 2 and 6).

`roarmctl execute` runs as a subprocess against the firmware simulator over a real pty (in this
process, so its true servo positions are observable); the signals are real signals.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from devtraj import HOME, min_jerk
from simwait import run_on

from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.robot.loader import load_robot

pytestmark = pytest.mark.slow  # real time: signals sent to commands streaming to the simulated arm

ROBOT = load_robot("roarm_m3_pro")


def spawn(args: list[str], **kw) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "roarmctl", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True, **kw)


def tcp(q):
    return ROBOT.kin.fk(ROBOT.full_q(np.atleast_2d(q)))[:, :3, 3]


def motion_commands(sim) -> int:
    return sum(c.get("T") == 102 for _, c in sim.received())


def stop_mid_motion(tmp_path: Path, signals: list[tuple[int, float]]):
    """Stream a 3 s move, send ``signals`` [(signum, delay before it)] once 40 commands are out."""
    traj = min_jerk([HOME, [1.2, 0.4, 1.9, -0.5, 0.3, 0.5]], [3.0])
    p = tmp_path / "t.traj.json"
    traj.save(p)
    log = tmp_path / "t.exec.json"
    with PtySimulator(SimConfig(), process=True) as sim:
        proc = spawn(["execute", str(p), "--port", sim.path, "--yes"])
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and motion_commands(sim) < 40:
            time.sleep(0.01)
        t_sig = time.monotonic()
        for signum, delay in signals:
            time.sleep(delay)
            proc.send_signal(signum)
        _, err = proc.communicate(timeout=20)
        run_on(sim, 0.8)  # on the firmware's clock: the hold has run and the arm stood still
        ts, q, torque = sim.recording()
    return proc.returncode, err, json.loads(log.read_text()) if log.exists() else None, traj, (ts, q, torque, t_sig), tmp_path


def assert_held(data, traj, rec, tmp_path):
    ts, q, torque, t_sig = rec
    assert torque.all()  # never torque off
    hold = [s["cmd"] for s in data["sent"] if s["cmd"]["T"] == 102][-1]
    assert hold["spd"] > 0 and data["hold"]["kind"] == "path"
    assert not [s for s in data["sent"] if s["cmd"]["T"] in (0, 210)]
    later = q[ts > ts[-1] - 0.3]
    assert np.ptp(later, axis=0).max() < 1e-6  # it stopped moving
    at_sig = q[np.searchsorted(ts, t_sig)]
    assert np.linalg.norm(tcp(later[-1]) - tcp(at_sig)) < 0.04  # near where it was
    assert np.linalg.norm(tcp(later[-1]) - tcp(traj.positions[-1])) > 0.05  # not at the end
    # the log says what was sent: its message counts exactly the motion commands in the log
    n = sum(1 for s in data["sent"] if "tick" in s)
    assert data["summary"]["commands"] == n and f"after {n} of " in data["summary"]["message"]
    assert not list(tmp_path.glob(".*.tmp"))


@pytest.mark.parametrize("signum,code,outcome", [(signal.SIGTERM, 143, "terminated"), (signal.SIGHUP, 129, "terminated")])
def test_sigterm_and_sighup_mid_motion_hold_and_log(tmp_path, signum, code, outcome):
    rc, err, data, traj, rec, _ = stop_mid_motion(tmp_path, [(signum, 0.0)])
    assert rc == code, err
    assert err.count("\n") == 1 and signal.Signals(signum).name in err
    assert data is not None and data["summary"]["outcome"] == outcome
    assert_held(data, traj, rec, tmp_path)


@pytest.mark.parametrize("spacing", [0.0, 0.005, 0.06])
def test_repeated_ctrl_c_still_holds_and_logs(tmp_path, spacing):
    rc, err, data, traj, rec, _ = stop_mid_motion(tmp_path, [(signal.SIGINT, 0.0)] + [(signal.SIGINT, spacing)] * 4)
    assert rc == 130, err  # not killed by the signal (-2)
    assert err.count("\n") == 1 and "interrupt" in err.lower()
    assert data is not None and data["summary"]["outcome"] == "interrupted"
    assert_held(data, traj, rec, tmp_path)


def test_ctrl_c_then_sigterm_keeps_the_first_reason(tmp_path):
    rc, err, data, traj, rec, _ = stop_mid_motion(tmp_path, [(signal.SIGINT, 0.0), (signal.SIGTERM, 0.01)])
    assert rc == 130 and data["summary"]["outcome"] == "interrupted", err
    assert_held(data, traj, rec, tmp_path)


def test_failed_handshake_writes_a_log(tmp_path):
    p = tmp_path / "s.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    with PtySimulator(SimConfig(firmware="m2"), process=True) as sim:
        proc = spawn(["execute", str(p), "--port", sim.path, "--yes"])
        _, err = proc.communicate(timeout=20)
        moved = [c for _, c in sim.received() if c.get("T") in (101, 102, 104)]
    assert proc.returncode == 4 and not moved, err
    data = json.loads((tmp_path / "s.exec.json").read_text())
    assert data["summary"]["outcome"] == "failed" and "M2" in data["summary"]["message"]
    assert "no motion command was sent" in data["summary"]["message"] and data["summary"]["commands"] == 0
    assert data["sent"] and data["received"]  # what the handshake exchanged


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP, signal.SIGINT])
def test_sim_device_removes_its_link_on_every_stop(tmp_path, signum):
    link = tmp_path / "ttyROARM"
    proc = spawn(["sim-device", "--no-boot", "--json", "--link", str(link)])
    port = json.loads(proc.stdout.readline())["port"]
    assert port == str(link) and link.is_symlink()
    proc.send_signal(signum)
    assert proc.wait(timeout=10) == 0
    assert not link.is_symlink() and not link.exists()


def test_sigterm_during_a_write_leaves_no_temporary_file(tmp_path):
    # slow the write down (fsync sleeps) so that SIGTERM lands inside it, in the real CLI
    p = tmp_path / "s.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    out = tmp_path / "cmds.jsonl"
    script = ("import os, time, sys\n"
              "real = os.fsync\n"
              "os.fsync = lambda fd: (open(sys.argv[2] + '.writing', 'w').close(), time.sleep(30), real(fd))\n"
              "from roarmctl.cli import main\n"
              "main(['execute', sys.argv[1], '--output', sys.argv[2]])\n")
    proc = subprocess.Popen([sys.executable, "-c", script, str(p), str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not Path(str(out) + ".writing").exists():
        time.sleep(0.02)
    assert list(tmp_path.glob(".cmds.jsonl.*.tmp"))  # the write is under way
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 143, err
    assert not list(tmp_path.glob(".cmds.jsonl.*.tmp")) and not out.exists()
    assert err.count("\n") == 1 and "SIGTERM" in err
