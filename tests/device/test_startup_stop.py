"""A stop signal during start-up, before the first motion line (issue 35): exit 130 with one line, a complete
execution log that says where it stopped, and an arm that does not move: nothing sent during the firmware's set-up,
and after connecting a hold where the arm stands. The signals are real signals to a real `roarmctl execute`; the
moments are found by watching the simulated firmware and the process (its open port), not by the clock."""

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
from simwait import run_on, until

from roarmctl.device.simulator import PtySimulator, SimConfig

pytestmark = pytest.mark.slow  # real time: a command connecting to the simulated arm


def spawn(args: list[str]) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "roarmctl", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)


def holds_open(pid: int, path: str) -> bool:
    """Whether process ``pid`` has ``path`` open (Linux: /proc/PID/fd)."""
    try:
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return False
    for fd in fds:
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}") == path:
                return True
        except OSError:
            continue
    return False


def wait_for(cond, proc: subprocess.Popen, limit: float = 60.0) -> None:
    end = time.monotonic() + limit
    while not cond():
        assert proc.poll() is None, proc.communicate(timeout=10)
        assert time.monotonic() < end, "the moment never came"
        time.sleep(0.005)


@pytest.fixture
def plan(tmp_path) -> Path:
    p = tmp_path / "t.traj.json"
    min_jerk([HOME, [1.2, 0.4, 1.9, -0.5, 0.3, 0.5]], [3.0]).save(p)
    return p


def test_ctrl_c_while_connect_waits_for_set_up_sends_nothing_and_logs(plan):
    """Opened at power-on (a quiet arm: about 6 s of set-up): Ctrl-C while connect waits sends not one byte (the boot
    mission still runs) and the log says it stopped before streaming."""
    log = plan.with_name("t.exec.json")
    log.write_text("{}")  # an earlier run's log: replaced, not left to be read as this run's
    with PtySimulator(SimConfig(boot=True, info_print=0, boot_mission=('{"T":114,"led":64}',)), process=True) as sim:
        proc = spawn(["execute", str(plan), "--port", sim.path, "--yes"])
        try:
            wait_for(lambda: holds_open(proc.pid, sim.path), proc)
            time.sleep(0.3)
            at_signal = sim.state()
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=30)
        finally:
            proc.kill()
        # the rest of set-up on the firmware's clock: the boot mission runs or is aborted
        st = until(sim, lambda st: st["now"] > st["booting_until"] + 0.5)
        got = sim.received()
    assert at_signal["now"] < at_signal["booting_until"]  # the stop came while the arm was setting up
    assert proc.returncode == 130 and err.count("\n") == 1 and "before streaming" in err, err
    data = json.loads(log.read_text())
    assert data["summary"]["outcome"] == "interrupted" and data["summary"]["commands"] == 0
    assert "stopped by Ctrl-C before streaming" in data["summary"]["message"]
    ours = [c for _, c in got if c != {"T": 114, "led": 64}]  # the boot mission's own line is the firmware's
    assert data["sent"] == [] and not ours, ours  # not a byte during set-up
    assert st["boot_mission_aborted"] is False


def test_ctrl_c_after_connecting_holds_where_the_arm_stands_and_logs(plan):
    """Ctrl-C once connected (the ESP-NOW line seen, the start not checked yet or being checked): the arm stays where
    it stands, the log is complete (the device as connect found it, the hold), exit 130."""
    log = plan.with_name("t.exec.json")
    with PtySimulator(SimConfig(), process=True) as sim:
        proc = spawn(["execute", str(plan), "--port", sim.path, "--yes"])
        try:
            wait_for(lambda: any(c.get("T") == 301 for _, c in sim.received()), proc)
            t_sig = time.monotonic()
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=30)
        finally:
            proc.kill()
        run_on(sim, 0.5)
        ts, q, torque = sim.recording()
        executed = [c for _, _, c in sim.executed()]
    assert proc.returncode == 130 and err.count("\n") == 1 and "Ctrl-C" in err, err
    data = json.loads(log.read_text())
    s = data["summary"]
    assert s["outcome"] == "interrupted" and s["commands"] == 0, s
    assert data["device"] is None or data["device"]["firmware"] == "m3-0.84"
    assert all(e["cmd"]["T"] not in (0, 210) for e in data["sent"])  # never torque off
    moves = [c for c in executed if c.get("T") == 102]
    assert len(moves) <= 2  # at most the hold and its second copy: no motion line of the plan
    assert torque.all()
    after = q[ts >= t_sig]
    assert np.ptp(q, axis=0).max() < 1e-3 and np.ptp(after, axis=0).max() < 1e-3  # it never moved


def test_a_stop_while_the_simulator_starts_logs_and_leaves_no_child(plan, monkeypatch):
    """execute --sim: a stop signal while the firmware's process starts (slow with the physics servos) raises
    Interrupted with its log written, and the child is ended (before, no log, and the child could outlive the run)."""
    from roarmctl.device import simulator as simmod
    from roarmctl.device.options import StreamConfig
    from roarmctl.device.session import run_execution
    from roarmctl.errors import Interrupted
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot

    started: list[simmod.PtySimulator] = []
    real_start = simmod.PtySimulator.start

    def start_then_stop(self):
        started.append(self)
        self._proc.start()  # the child runs; the stop comes before its port is known
        raise KeyboardInterrupt

    monkeypatch.setattr(simmod.PtySimulator, "start", start_then_stop)
    log = plan.with_name("t.exec.json")
    robot = load_robot("roarm_m3_pro")
    with pytest.raises(Interrupted) as caught:
        run_execution(load_trajectory(plan), robot, StreamConfig(), sim=True, log_path=log, confirm=lambda m: True)
    monkeypatch.setattr(simmod.PtySimulator, "start", real_start)
    assert caught.value.exit_code == 130 and "before the port was opened" in caught.value.message
    data = json.loads(log.read_text())
    assert data["summary"]["outcome"] == "interrupted" and data["sent"] == [] and data["summary"]["commands"] == 0
    assert started and not started[0]._proc.is_alive()
