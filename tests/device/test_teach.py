"""Leaving `teach` never moves the arm (issue 24): on q, Ctrl-C, SIGTERM and a lost link, the first command
after the teaching is a T:102 at the measured pose, then torque goes on, and the arm stays where it was.

`roarmctl teach --port` runs as a subprocess against the firmware simulator (served from this process, so
its true servo positions and the commands it ran are observable) whose limp servos a scripted hand moves
(`--guide`'s model); keys come through a real pseudo-terminal, signals are real signals.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from roarmctl.device.guide import Guide, guided_servos
from roarmctl.device.simulator import PtySimulator, SimConfig

pytestmark = pytest.mark.slow  # real time: a hand script and a subprocess on the simulated arm

POSE = [0.35, 0.45, 1.1, 0.35, 0.2, 1.1]  # URDF: where the hand leaves the arm (5 joints + gripper)
COUNT = 2 * np.pi / 4096


class Teach:
    """``roarmctl teach`` in a subprocess with a pseudo-terminal as its keyboard; stderr collected by a thread."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.master, slave = os.openpty()
        env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="120")
        self.proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "teach", *args], stdin=slave,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=cwd)
        os.close(slave)
        self.lines: list[str] = []
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.lines.append(line.rstrip("\n"))

    def wait_for(self, predicate, timeout: float = 60.0) -> str:
        """The first stderr line for which ``predicate(line)`` holds (fails after ``timeout`` s)."""
        end = time.monotonic() + timeout
        seen = 0
        while time.monotonic() < end:
            while seen < len(self.lines):
                if predicate(self.lines[seen]):
                    return self.lines[seen]
                seen += 1
            if self.proc.poll() is not None and seen >= len(self.lines):
                break
            time.sleep(0.02)
        raise AssertionError("not seen; stderr:\n" + "\n".join(self.lines[-30:]))

    def key(self, text: str) -> None:
        os.write(self.master, text.encode())

    def finish(self, timeout: float = 30.0) -> int:
        code = self.proc.wait(timeout)
        self._reader.join(5)
        os.close(self.master)
        return code


def executed_until_torque_on(sim, timeout: float = 10.0) -> list:
    """The commands the simulated firmware ran, once it ran the torque-on (its serving thread and its queue
    may lag the teach process's exit on a loaded machine), and once the simulator's own clock has run 0.5 s past
    it for the servos to settle (counted on its recording, not on the wall: a loaded machine only takes longer).
    ``timeout`` (s, wall) only detects a hang."""
    end = time.monotonic() + timeout
    on = None
    while time.monotonic() < end:
        on = next((t for _, t, c in sim.executed() if c == {"T": 210, "cmd": 1}), None)
        if on is not None and sim.recording()[0][-1] >= on + 0.5:
            break
        time.sleep(0.05)
    assert on is not None, "the torque-on never ran"
    return sim.executed()


def status_q(line: str) -> np.ndarray | None:
    """The joints of a plain-mode status line ``[ t s] q a b c d e f | sigma ...``."""
    if "] q " not in line:
        return None
    return np.array([float(v) for v in line.split("] q ", 1)[1].split("|", 1)[0].split()])


def at_pose(line: str) -> bool:
    q = status_q(line)
    return q is not None and bool(np.abs(q - POSE).max() < 3 * COUNT)


@pytest.mark.parametrize("how", ["q", "ctrl-c", "sigterm", "lost link"])
def test_leaving_sets_the_measured_pose_before_torque_on(tmp_path, how):
    guide = Guide(np.array([0.8]), np.array([POSE]))
    with PtySimulator(SimConfig(), servos=guided_servos(guide)) as sim:
        t = Teach(["--port", sim.path, "--yes", "-o", "taught.yaml", "--raw", "raw.json"], tmp_path)
        t.wait_for(lambda s: "torque off" in s)
        t.wait_for(at_pose)
        t.key("\r")  # one waypoint, so that there is a recording to save
        t.wait_for(lambda s: "recorded waypoint 1" in s)
        t.key("\ru")  # and one more, undone
        t.wait_for(lambda s: "undone: waypoint 2" in s)
        if how == "q":
            t.key("q")
        elif how == "ctrl-c":
            t.proc.send_signal(signal.SIGINT)
        elif how == "sigterm":
            t.proc.send_signal(signal.SIGTERM)
        else:
            sim.firmware.cfg.silent = True  # the arm stops answering (commands still arrive)
        code = t.finish()
        executed = executed_until_torque_on(sim)
        ts, q, torque = sim.recording()
    assert code == {"q": 0, "ctrl-c": 130, "sigterm": 143, "lost link": 4}[how], "\n".join(t.lines[-20:])
    if how == "lost link":
        assert "link lost" in t.lines[-1] or any("link lost" in s for s in t.lines)
    cmds = [(when, c) for _, when, c in executed]
    off = next(i for i, (_, c) in enumerate(cmds) if c.get("T") == 210 and c.get("cmd") == 0)
    after = [(w, c) for w, c in cmds[off + 1:] if c.get("T") not in (105, 605)]
    # the first command after teaching is the hold at the measured pose, then torque on
    assert after[0][1]["T"] == 102 and after[1][1] == {"T": 210, "cmd": 1}, after[:3]
    hold_t, hold = after[0]
    log = json.loads((tmp_path / "raw.json").read_text())
    assert log["hold"]["cmd"] == hold
    last_fb = [e["feedback"] for e in log["received"] if "feedback" in e and e["t"] <= log["hold"]["t"]][-1]
    for k in ("base", "shoulder", "elbow", "wrist", "roll"):  # the measured pose, as the arm reported it
        assert hold[k] == pytest.approx(last_fb[k[0] if k != "roll" else "r"] if k != "wrist" else last_fb["t"], abs=6e-5)
    assert hold["hand"] == pytest.approx(last_fb["g"], abs=6e-5)
    # ... which is where the arm truly was: no jump when torque came on, nor after
    true_then = q[np.searchsorted(ts, hold_t) - 1]
    assert np.abs(true_then - POSE).max() < 1e-9
    wire = np.array([hold["base"], hold["shoulder"], hold["elbow"], hold["wrist"], hold["roll"], np.pi - hold["hand"]])
    assert np.abs(wire - true_then).max() < 1.5 * COUNT
    later = q[ts >= hold_t]
    assert np.abs(later - true_then).max() <= 1.5 * COUNT  # servo goals are whole steps: at most one step off
    assert torque[ts > hold_t + 0.05].all()
    # the recording was saved (atomically): one waypoint at the pose
    text = (tmp_path / "taught.yaml").read_text()
    assert "start: current" in text and text.count("- move:") == 1
    assert log["outcome"] == {"q": "quit", "ctrl-c": "interrupted", "sigterm": "terminated", "lost link": "link lost"}[how]


def test_guide_goes_with_sim_and_one_source():
    from clirun import roarmctl

    r = roarmctl("teach", "--port", "/dev/null", "--sim")
    assert r.returncode == 2 and "exactly one" in r.stderr
    r = roarmctl("teach", "--port", "/dev/nonexistent", "--guide", "x.yaml", "--yes")
    assert r.returncode == 2 and "--sim" in r.stderr


def test_live_display_on_a_terminal_shows_the_measure_and_quits(tmp_path):
    """On a terminal (stderr a pty) the rich display runs: joints, TCP, the measure and its band, the keys."""
    master, slave = os.openpty()
    env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="120", TERM="xterm")
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "teach", "--sim", "-o", "t.yaml"], stdin=slave,
                            stdout=subprocess.PIPE, stderr=slave, env=env, cwd=tmp_path)
    os.close(slave)
    seen = b""
    end = time.monotonic() + 60
    try:
        while time.monotonic() < end and not all(w in seen for w in (b"sigma_min", b"CLEAR", b"TCP desk", b"q quit")):
            if select.select([master], [], [], 0.1)[0]:
                try:
                    seen += os.read(master, 65536)
                except OSError:
                    break
        os.write(master, b"q")
        code = proc.wait(30)
        while select.select([master], [], [], 0.2)[0]:
            try:
                chunk = os.read(master, 65536)
            except OSError:
                break
            if not chunk:
                break
            seen += chunk
    finally:
        os.close(master)
    assert all(w in seen for w in (b"sigma_min", b"CLEAR", b"TCP desk", b"q quit")), seen[-2000:]
    assert code == 0 and b"nothing recorded" in seen


def test_20260701_build_is_warned_about_and_taught(tmp_path):
    """That build folds the arm to its rest pose before it releases torque (no feedback meanwhile): teach says so
    before torque goes off, waits the fold out, then teaches and leaves as on the 0.84 build."""
    guide = Guide(np.array([1.0]), np.array([POSE]))
    with PtySimulator(SimConfig(firmware="m3-2026"), servos=guided_servos(guide)) as sim:
        t = Teach(["--port", sim.path, "--yes", "-o", "taught.yaml"], tmp_path)
        warned = t.wait_for(lambda s: "REST POSE" in s)
        t.wait_for(lambda s: "torque off" in s)
        t.wait_for(at_pose)
        t.key("\rq")
        code = t.finish()
        executed = [c for _, _, c in executed_until_torque_on(sim)]
    assert code == 0 and "Move_to_location" in warned
    off = executed.index({"T": 210, "cmd": 0})
    after = [c for c in executed[off + 1:] if c.get("T") not in (105, 605)]
    assert after[0]["T"] == 102 and after[1] == {"T": 210, "cmd": 1}
    assert np.array([after[0][k] for k in ("base", "shoulder", "elbow", "wrist", "roll")]) == pytest.approx(POSE[:5], abs=2 * COUNT)
    assert (tmp_path / "taught.yaml").read_text().count("- move:") == 1
