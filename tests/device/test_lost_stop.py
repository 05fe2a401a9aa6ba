"""A stop whose exception Python discards still stops the command.

The CLI turns the first SIGINT/SIGTERM/SIGHUP into ``StopRequested``, raised wherever the main thread is. Inside a
finalizer, a weakref or garbage-collector callback Python prints such an exception ("Exception ignored in ...") and
drops it; the signal is recorded, so the command must still stop at its next wait (``roarmctl.cli.signals.check``).
Seen on a loaded machine: ``view`` and ``sim-device`` served on after a Ctrl-C, deaf to the next ones. Each case runs
the real command in a fresh interpreter in which the SIGINT is sent, and its handler runs, inside a garbage-collector
callback, once the command waits (view serving, sim-device serving, execute streaming, follow following, teach teaching)
or works (plan planning, simulate simulating: they stop at their next progress report and write no file).
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from devtraj import HOME, min_jerk

ROOT = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow  # fresh interpreters, a simulated arm in real time

SCRIPT = """
import gc, importlib, os, signal, sys, threading

marker, module, cls, method, *args = sys.argv[1:]
state = {"armed": False, "fired": False}

def callback(phase, info):
    if state["armed"] and not state["fired"] and threading.current_thread() is threading.main_thread():
        state["fired"] = True
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(200000):  # the handler runs in here: its exception is one Python discards
            pass
        open(marker, "w").close()  # reached only if the interrupt did not land in the callback

gc.callbacks.append(callback)
owner = getattr(importlib.import_module(module), cls)
original = getattr(owner, method)

def wait_then(self, *a, **k):
    if not state["fired"]:
        state["armed"] = True
        gc.collect()
    return original(self, *a, **k)

setattr(owner, method, wait_then)
sys.argv = ["roarmctl", *args]
from roarmctl.launch import main
main()
"""


@pytest.fixture
def traj_file(tmp_path: Path) -> Path:
    p = tmp_path / "t.traj.json"
    min_jerk([HOME, [0.6, 0.3, 1.8, -0.4, 0.2, 0.5]], [2.0]).save(p)
    return p


@pytest.mark.parametrize("case", ["view", "sim-device", "execute", "follow", "teach", "plan", "simulate"])
def test_a_stop_python_discards_while_the_command_waits_still_stops_it(case, traj_file, tmp_path):
    output = tmp_path / "out.json"  # what plan and simulate would write
    target, args, code = {
        "view": (("roarmctl.viz.web.server", "ViewServer", "serve_forever"), ["view", str(traj_file)], 0),
        "sim-device": (("roarmctl.device.simulator", "PtySimulator", "join"), ["sim-device", "--servos", "ideal"], 0),
        # on the first read of the arm's answers, mid-motion: the arm holds as on any Ctrl-C
        "execute": (("roarmctl.device.streamer", "Streamer", "_read_answers"),
                    ["execute", str(traj_file), "--sim", "--servos", "ideal", "--yes", "--log", str(tmp_path / "t.exec.json")], 130),
        # as following starts (its source, stdin, is at its end): the follower holds as on any Ctrl-C
        "follow": (("roarmctl.device.follow", "Follower", "_loop"),
                   ["follow", "--sim", "--log", str(tmp_path / "t.exec.json")], 130),
        # teaching on the simulated arm (keys from a terminal): the session ends as on any Ctrl-C
        "teach": (("roarmctl.device.teach", "TeachSession", "pump"), ["teach", "--sim", "-o", str(tmp_path / "t.yaml")], 130),
        # at the first motion's first segment check: planning stops at its next stage, no trajectory file
        "plan": (("roarmctl.motion.collision", "CollisionChecker", "segment_valid"),
                 ["plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(output)], 130),
        # at the physics' first step: the simulation stops at its next progress report, no run file
        "simulate": (("roarmctl.physics.servo_backend", "PhysicsServos", "advance"),
                     ["simulate", str(traj_file), "-o", str(output)], 130),
    }[case]
    marker = tmp_path / "the callback finished"
    # a session of its own: a command deaf to the stop is ended with its simulator's process when the wait runs out
    master, slave = os.openpty() if case == "teach" else (None, subprocess.DEVNULL)  # teach reads keys from a terminal
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT, str(marker), *target, *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, stdin=slave, cwd=tmp_path, start_new_session=True)
    if master is not None:
        os.close(slave)
    try:
        out, err = proc.communicate(timeout=120)
    finally:
        with contextlib.suppress(ProcessLookupError):  # anything of it still there: a hang, or a simulator left behind
            os.killpg(proc.pid, signal.SIGKILL)
        if proc.poll() is None:
            proc.communicate(timeout=30)
        if master is not None:
            os.close(master)
    assert not marker.exists()  # the interrupt did land inside the callback, where Python discards it
    assert proc.returncode == code, err
    assert "Exception ignored" not in err and "Traceback" not in err, err
    if case == "view":
        assert "stopped the view" in out
    if case == "execute":
        assert err.strip().splitlines()[-1].startswith("error: interrupted"), err
        log = json.loads((tmp_path / "t.exec.json").read_text())
        assert log["summary"]["outcome"] == "interrupted" and log["hold"] is not None, log["summary"]
    if case in ("plan", "simulate"):
        assert err.strip().splitlines()[-1].startswith("error: interrupted"), err
        assert not output.exists() and sorted(tmp_path.iterdir()) == sorted([traj_file]), sorted(tmp_path.iterdir())
    if case == "follow":
        assert err.strip().splitlines()[-1] == "error: stopped by Ctrl-C; the arm holds where it was", err
        assert json.loads((tmp_path / "t.exec.json").read_text())["summary"]["outcome"] == "interrupted"
