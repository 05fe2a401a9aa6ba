"""The real CLI against the firmware simulator over real pseudo-terminals.

The simulator runs in this process (a thread behind a pty) so the test can read its recorded true
servo positions; the CLI runs in-process or, where a signal or a pulled cable is needed, as a
subprocess that opens the pty like /dev/ttyUSB0.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from devtraj import HOME, min_jerk, pick_place

from roarmctl.cli import run as run_cli
from roarmctl.device.protocol import encode
from roarmctl.device.schedule import DEFAULT_STRATEGY, STRATEGIES
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.device.streamer import default_latency, sample
from roarmctl.robot.loader import load_robot

pytestmark = pytest.mark.slow  # real time: trajectories streamed to the simulated arm

ROBOT = load_robot("roarm_m3_pro")




def spawn(args: list[str]) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "roarmctl", *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)


def tcp(q):
    return ROBOT.kin.fk(ROBOT.full_q(np.atleast_2d(q)))[:, :3, 3]


@pytest.fixture
def traj_file(tmp_path) -> Path:
    p = tmp_path / "pp.traj.json"
    pick_place().save(p)
    return p


def test_the_same_run_on_the_virtual_clock_tracks_the_plan_closely(traj_file, capsys, virtual_sim):
    """The motion of the real-time test below, streamed to the same firmware and servo models on a virtual clock: no
    host or simulator waits for a core, so the tracking is the plan's and the streamer's alone and the same on any
    machine (1.69 mm RMS, 4.60 mm at worst when written)."""
    rc = run_cli(["execute", str(traj_file), "--sim", "--yes", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["outcome"] == "completed", out
    sim = out["simulator"]
    assert sim["rms_mm"] < 2.5 and sim["max_mm"] < 7.0 and sim["torque_always_on"], sim
    assert len(virtual_sim) == 1 and sim["lateness_max_ms"] == 0.0  # the run was the virtual one


def test_sim_run_follows_the_plan_and_keeps_time(traj_file, capsys):
    rc = run_cli(["execute", str(traj_file), "--sim", "--yes", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["outcome"] == "completed", out  # on a failure: the error and hint the CLI printed
    sim = out["simulator"]
    print(f"\nTCP tracking error (true, simulator): RMS {sim['rms_mm']:.2f} mm, max {sim['max_mm']:.2f} mm "
          f"(aligned within the measured lateness, up to {sim['lateness_max_ms']:.1f} ms: RMS {sim['rms_aligned_mm']:.2f}, "
          f"max {sim['max_aligned_mm']:.2f} mm); lateness p50 {out['lateness_ms']['p50']:.2f} ms p99 {out['lateness_ms']['p99']:.2f} ms")
    # the tolerance widens only by what was measured late (host sends and the simulated firmware's wake-ups). Idle:
    # 1.6 mm RMS; beside a loaded suite (a clean-clone CI run with other jobs, load 10-20) 5.5 mm: the simulator is a
    # process of its own and what its servos lag while it waits for a core is not all measured as lateness. Its worst
    # sample is set by the longest such wait (21 mm beside two CPU hogs, RMS 3.4): the tight bounds of this motion's
    # tracking are its virtual-clock twin's below; here real time's own promises (the schedule, every tick) are asserted
    assert sim["rms_aligned_mm"] < 8.0
    assert sim["torque_always_on"]
    log = json.loads(Path(out["log"]).read_text())
    ticks = [s for s in log["sent"] if "tick" in s]
    # absolute schedule: command k goes out at k/50 s plus the pauses of the plan before it (where a busy host came
    # after the next tick was due: logged) plus its own measured lateness: no drift over 7.4 s
    t = np.array([s["t"] for s in ticks])
    k = np.array([s["tick"] for s in ticks])
    late = np.array([s["lateness"] for s in ticks])
    due = np.minimum(k / 50.0, log["duration"])
    waited = np.array([sum(d for at, d in log["paused"] if at <= tk + 1e-9) for tk in due])
    assert np.all(np.abs(t - due - waited - late) < 1e-3) and late.min() > -1e-3
    assert k.tolist() == list(range(len(ticks))) and "skipped" not in log  # every tick, in order: none to count
    assert any("feedback" in r for r in log["received"])


def test_sim_tracks_the_planned_blended_jerk_limited_pick_and_place(tmp_path, capsys, virtual_sim):
    """The bundled plan as planned (blended joins, jerk limits), streamed to the simulated arm."""
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "planned.traj.json"
    assert run_cli(["plan", str(root / "plans" / "pick_place.yaml"), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    assert json.loads(out.read_text())["blends"]
    rc = run_cli(["execute", str(out), "--sim", "--yes", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert rc == 0 and res["outcome"] == "completed", res
    print(f"\nplanned pick-and-place on the simulator: TCP RMS {res['simulator']['rms_mm']:.2f} mm, "
          f"max {res['simulator']['max_mm']:.2f} mm")
    assert res["simulator"]["rms_aligned_mm"] < 5.0


def test_speed_scale_slows_down(tmp_path, capsys, virtual_sim):
    p = tmp_path / "short.traj.json"
    min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]], [1.0]).save(p)
    rc = run_cli(["execute", str(p), "--sim", "--yes", "--json", "--speed-scale", "0.5", "--rate", "25",
                  "--log", str(tmp_path / "slow.json")])
    out = json.loads(capsys.readouterr().out)
    log = json.loads((tmp_path / "slow.json").read_text())
    assert rc == 0 and log["duration"] == pytest.approx(2.0)
    ticks = [s for s in log["sent"] if "tick" in s]
    # the flags reach the stream: 25 Hz over the 2 s the scale gives, every tick in order, each on time on the
    # simulator's (virtual) clock
    assert [s["tick"] for s in ticks] == list(range(51)) and log["rate"] == 25
    assert max(abs(s["t"] - s["tick"] / 25) for s in ticks) < 1e-9
    assert out["simulator"]["rms_aligned_mm"] < 5.0


def test_ctrl_c_mid_motion_holds_where_it_was(tmp_path):
    traj = min_jerk([HOME, [1.2, 0.4, 1.9, -0.5, 0.3, 0.5]], [3.0])
    p = tmp_path / "t.traj.json"
    traj.save(p)
    with PtySimulator(SimConfig(), process=True) as sim:
        proc = spawn(["execute", str(p), "--port", sim.path, "--yes"])
        log = tmp_path / "t.exec.json"
        # wait until streaming has begun (the simulator has executed motion commands), then Ctrl-C
        deadline = time.monotonic() + 300  # a hang detector: a fresh interpreter on a busy machine takes its time
        while time.monotonic() < deadline and sum(c.get("T") == 102 for _, c in sim.received()) < 40:
            time.sleep(0.02)
        assert sum(c.get("T") == 102 for _, c in sim.received()) >= 40, "streaming did not begin within 300 s"
        proc.send_signal(signal.SIGINT)
        t_int = time.monotonic()
        _, err = proc.communicate(timeout=120)
        # 0.8 s of the simulator's own clock past the last line it ran (the hold, then the link's goodbye), not of
        # the wall: its recording then shows where the arm came to rest, however busy the machine
        last = sim.executed()[-1][1]
        while time.monotonic() < deadline and sim.recording()[0][-1] < last + 0.8:
            time.sleep(0.02)
        ts, q, torque = sim.recording()
    assert proc.returncode == 130, err
    assert "interrupt" in err.lower()
    assert torque.all()  # never torque off
    data = json.loads(log.read_text())
    assert data["summary"]["outcome"] == "interrupted"
    hold = [s["cmd"] for s in data["sent"] if s["cmd"]["T"] == 102][-1]
    assert hold["T"] == 102 and hold["spd"] > 0 and data["hold"]["kind"] == "path"
    at_int = q[np.searchsorted(ts, t_int)]
    later = q[ts > ts[-1] - 0.3]
    assert np.ptp(later, axis=0).max() < 1e-6  # it stopped moving
    # ... near where it was when interrupted, far from the trajectory's end
    assert np.linalg.norm(tcp(later[-1]) - tcp(at_int)) < 0.03
    assert np.linalg.norm(tcp(later[-1]) - tcp(traj.positions[-1])) > 0.05


def test_link_lost_mid_motion_exits_4_with_log(tmp_path):
    traj = min_jerk([HOME, [1.0, 0.3, 1.9, -0.5, 0.3, 0.5]], [3.0])
    p = tmp_path / "t.traj.json"
    traj.save(p)
    sim = PtySimulator(SimConfig(), process=True).start()
    proc = spawn(["execute", str(p), "--port", sim.path, "--yes", "--log", str(tmp_path / "lost.json")])
    # the cut comes mid-motion: after 30 motion commands, however long a fresh interpreter takes to get there on a
    # busy machine (with 10 s allowed, two CPU hogs once made the cut land during its connect: outcome "failed")
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and sum(c.get("T") == 102 for _, c in sim.received()) < 30 and proc.poll() is None:
        time.sleep(0.02)
    assert sum(c.get("T") == 102 for _, c in sim.received()) >= 30, "the run never got 30 motion commands out"
    sim.disconnect()
    _, err = proc.communicate(timeout=120)  # a guard against a hang, not a measure: no wall-clock assert
    assert proc.returncode == 4, err
    assert "link lost" in err
    data = json.loads((tmp_path / "lost.json").read_text())
    assert data["summary"]["outcome"] == "link_lost" and len(data["sent"]) >= 30


def test_silent_device_exits_4_within_seconds(traj_file, capsys, tmp_path):
    # the same command without a device first: what it loads and checks before it opens the port (seconds of a
    # busy machine's CPU) is not the silent device's wait, which the bound is about
    assert run_cli(["execute", str(traj_file), "--output", str(tmp_path / "warm.jsonl")]) == 0
    with PtySimulator(SimConfig(silent=True), process=True) as sim:
        rc = run_cli(["execute", str(traj_file), "--port", sim.path, "--yes"])
    err = capsys.readouterr().err
    # the link gives up after its own bound (Link.silent_after, on its clock) and says so: no wall-clock assert here
    assert rc == 4 and f"device silent: no feedback from {sim.path} within 2.0 s" in err, err


def test_m2_firmware_is_refused(traj_file, capsys):
    with PtySimulator(SimConfig(firmware="m2"), process=True) as sim:
        rc = run_cli(["execute", str(traj_file), "--port", sim.path, "--yes"])
        moved = [c for _, c in sim.received() if c.get("T") in (101, 102, 104)]
    assert rc == 4 and "M2" in capsys.readouterr().err and not moved


def test_newer_firmware_build_is_accepted_and_reboot_banner_waited_out(tmp_path, capsys):
    p = tmp_path / "s.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    with PtySimulator(SimConfig(firmware="m3-2026", boot=True, time_factor=0.5), process=True) as sim:
        rc = run_cli(["execute", str(p), "--port", sim.path, "--yes", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0 and out["outcome"] == "completed", out  # on a failure: the error and hint the CLI printed
    assert json.loads((tmp_path / "s.exec.json").read_text())["firmware"] == "m3-2026"


def test_not_at_start_is_refused_then_move_to_start(tmp_path, capsys):
    start = [0.5, 0.2, 1.8, -0.3, 0.0, 0.0]
    p = tmp_path / "away.traj.json"
    min_jerk([start, [0.6, 0.25, 1.8, -0.3, 0.0, 0.0]], [0.5]).save(p)
    with PtySimulator(SimConfig(), process=True) as sim:
        rc = run_cli(["execute", str(p), "--port", sim.path, "--yes"])
        err = capsys.readouterr().err
        assert rc == 3 and "not at the trajectory's start" in err and "--move-to-start" in err
        assert not [c for _, c in sim.received() if c.get("T") == 102]
        rc = run_cli(["execute", str(p), "--port", sim.path, "--yes", "--move-to-start"])
        assert rc == 0, capsys.readouterr().err


def test_port_errors_are_one_clear_line(traj_file, capsys, tmp_path):
    log = tmp_path / "previous.exec.json"
    log.write_text('{"a": "successful run"}')
    rc = run_cli(["execute", str(traj_file), "--port", "/dev/ttyNOPE0", "--yes", "--log", str(log)])
    err = capsys.readouterr().err
    assert rc == 4 and err.count("\n") == 1 and "no such serial port" in err
    assert log.read_text() == '{"a": "successful run"}'  # nothing was exchanged: the last run's log stays
    import serial

    with PtySimulator(SimConfig(), process=True) as sim:
        holder = serial.Serial()
        holder.port, holder.exclusive = sim.path, True
        holder.open()
        try:
            rc = run_cli(["execute", str(traj_file), "--port", sim.path, "--yes"])
        finally:
            holder.close()
    err = capsys.readouterr().err
    assert rc == 4 and "busy" in err


def test_refuses_to_prompt_without_a_terminal(traj_file, capsys, monkeypatch):
    monkeypatch.setattr(sys, "stdin", open(os.devnull))
    rc = run_cli(["execute", str(traj_file), "--port", "/dev/ttyNOPE0"])
    assert rc == 2 and "--yes" in capsys.readouterr().err


def test_exactly_one_target(traj_file, capsys):
    assert run_cli(["execute", str(traj_file)]) == 2
    assert run_cli(["execute", str(traj_file), "--sim", "--output", "x.jsonl"]) == 2
    assert run_cli(["execute", str(traj_file), "--output", "x.jsonl", "--rate", "200"]) == 2


def test_output_file_exact_bytes_mapping_and_times(traj_file, tmp_path):
    out = tmp_path / "cmds.jsonl"
    # --no-sag: the plan's own goals, checked against the plan here (the compensation's offsets, on by default,
    # are roarmctl.device.sag's: tests/test_physics.py, test_execute_and_simulate_send_the_same_compensated_commands)
    assert run_cli(["execute", str(traj_file), "--output", str(out), "--rate", "50", "--no-sag"]) == 0
    raw = out.read_bytes()
    lines = raw.split(b"\n")[:-1]
    assert raw.endswith(b"\n")
    traj = pick_place()
    rows = [json.loads(x) for x in lines]
    motion = [r for r in rows if r["cmd"]["T"] == 102]
    assert len(motion) == math.ceil(traj.duration * 50 - 1e-9) + 1
    lat = default_latency(50) + STRATEGIES[DEFAULT_STRATEGY].lead  # the default aims ahead by the servos' lag too
    for line, r in zip(lines, rows):
        cmd = r["cmd"]
        # exact bytes: the command inside the line is exactly what goes on the wire
        assert line == b'{"t":' + repr(r["t"]).encode() + b',"cmd":' + encode(cmd)[:-1] + b"}"
    for k, r in enumerate(motion):
        cmd = r["cmd"]
        assert r["t"] == pytest.approx(min(k / 50, traj.duration), abs=1e-9)
        q = sample(traj, min(r["t"] + 0.02 + lat, traj.duration))
        got = [cmd[f] for f in ("base", "shoulder", "elbow", "wrist", "roll")]
        assert got == pytest.approx(q[:5], abs=6e-5)
        assert cmd["hand"] == pytest.approx(math.pi - q[5], abs=6e-5)  # hand = pi - q_gripper
        assert cmd["spd"] >= 50 and cmd["acc"] == 0
    assert motion[-1]["cmd"]["base"] == pytest.approx(traj.positions[-1][0], abs=6e-5)


def test_stalled_arm_aborts_on_tracking_error_and_holds_where_it_is(traj_file, capsys):
    # the shoulder's servo is blocked: the arm does not follow, the feedback says so
    with PtySimulator(SimConfig(stuck=("shoulder",)), process=True) as sim:
        rc = run_cli(["execute", str(traj_file), "--port", sim.path, "--yes", "--max-error", "20"])
        _ts, _q, torque = sim.recording()
    err = capsys.readouterr().err
    assert rc == 4 and "tracking error" in err and "exceeds 20 mm" in err
    data = json.loads(traj_file.with_name("pp.exec.json").read_text())
    assert data["summary"]["outcome"] == "aborted"
    # the arm is not where it was told to go: the hold is its last measured pose (stop pushing)
    assert data["hold"]["kind"] == "measured" and torque.all()
    hold = [s for s in data["sent"] if s["cmd"]["T"] == 102][-data["hold"]["copies"]]  # its first copy
    measured = [e for e in data["received"] if "tcp_world_m" in e and e["t"] <= hold["t"]][-1]
    for key, fb in (("base", "b"), ("elbow", "e"), ("wrist", "t")):
        assert hold["cmd"][key] == pytest.approx(measured["feedback"][fb], abs=1e-3)


def test_a_device_that_ignores_input_is_refused_at_connect(traj_file, capsys):
    # it streams feedback (InfoPrint 2) but takes no command: T:605 is never confirmed
    with PtySimulator(SimConfig(deaf=True), process=True) as sim:
        rc = run_cli(["execute", str(traj_file), "--port", sim.path, "--yes"])
        executed = sim.executed()
    err = capsys.readouterr().err
    assert rc == 4 and "keeps streaming feedback" in err and not executed


def test_ports_marks_the_likely_arm(monkeypatch, capsys):
    from serial.tools import list_ports_common

    def fake():
        a = list_ports_common.ListPortInfo("/dev/ttyUSB0")
        a.vid, a.pid, a.description = 0x10C4, 0xEA60, "CP2102 USB to UART Bridge Controller"
        b = list_ports_common.ListPortInfo("/dev/ttyS0")
        return [b, a]

    monkeypatch.setattr("serial.tools.list_ports.comports", fake)
    assert run_cli(["ports", "--json"]) == 0
    ports = json.loads(capsys.readouterr().out)["ports"]
    assert ports[0]["device"] == "/dev/ttyUSB0" and ports[0]["likely_arm"] and ports[0]["vid_pid"] == "10C4:EA60"
    assert not ports[1]["likely_arm"]


def test_sim_device_serves_until_ctrl_c():
    proc = spawn(["sim-device", "--no-boot", "--json"])
    port = json.loads(proc.stdout.readline())["port"]
    import serial

    with serial.Serial(port, 115200, timeout=0.5) as s:
        s.write(b'{"T":605,"cmd":0}\n{"T":105}\n')
        lines = [s.readline() for _ in range(3)]
    assert any(b'"T":1051' in x and x.endswith(b"}\r\n") for x in lines)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(timeout=5) == 0


def test_permission_denied_names_the_dialout_fix():
    from roarmctl.device.link import Link

    err = Link("/dev/ttyUSB0")._open_error(__import__("serial").SerialException(13, "could not open port /dev/ttyUSB0: [Errno 13] Permission denied: '/dev/ttyUSB0'"))
    assert err.exit_code == 4 and "permission denied" in err.message and "usermod -aG dialout" in err.hint


def test_execute_sim_rehearses_a_slow_20260701_loop(tmp_path, capsys, virtual_sim):
    """``execute --sim`` takes sim-device's build and the loop pass: on the 20260701 build at 22 ms a pass the stream
    measures the slow firmware and goes on at a lower rate, and the motion keeps its time. (Before: --sim ran only the
    0.84 build with boot off.)"""
    p = tmp_path / "short.traj.json"
    min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]], [1.5]).save(p)
    rc = run_cli(["execute", str(p), "--sim", "--servos", "ideal", "--yes", "--json", "--firmware", "m3-2026",
                  "--loop-pass", "22", "--log", str(tmp_path / "slow.json")])
    capsys.readouterr()
    log = json.loads((tmp_path / "slow.json").read_text())
    assert rc == 0 and log["firmware"] == "m3-2026" and log["device"]["queued"]
    assert log["device"]["line_time_s"] > 0.015  # the 22 ms pass, as connect() measured it
    assert log["rate_changes"] and log["rate"] < 50 and log["firmware_lag_ms"]["polls"] > 3


@pytest.mark.parametrize("args, why", [(["--loop-pass", "22"], "--loop-pass: only with --sim"),
                                       (["--firmware", "m3-2026"], "--firmware: only with --sim"),
                                       (["--sim", "--loop-pass", "nan"], "--loop-pass: nan ms is outside"),
                                       (["--sim", "--loop-pass", "1"], "--loop-pass: 1 ms is outside"),
                                       (["--sim", "--firmware", "m2"], "--firmware m2: the trajectory is for a RoArm-M3"),
                                       (["--sim", "--firmware", "x"], "--firmware: unknown 'x'")])
def test_execute_sim_options_are_checked(tmp_path, capsys, args, why):
    p = tmp_path / "short.traj.json"
    min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]], [1.0]).save(p)
    extra = [] if "--sim" in args else ["--port", "/dev/null"]
    rc = run_cli(["execute", str(p), "--yes", *extra, *args])
    err = capsys.readouterr().err
    assert rc == 2 and why in err and "Traceback" not in err


@pytest.mark.parametrize("face", ["cli", "api"])
def test_one_execute_builds_its_schedule_once_and_refuses_before_anything_opens(tmp_path, monkeypatch, face):
    """The schedule of a run is built once (by the streamer, before the port opens or the simulator starts), whether
    the CLI or the API executes (each built it once more to check it first). Counted by wrapping build_schedule
    where the streamer and the API call it, and the simulator's start."""
    import roarmctl.api as rc
    import roarmctl.device.streamer as streamer_mod
    from roarmctl.device.simulator import PtySimulator as Pty

    calls, starts = [], []
    real, real_start = streamer_mod.build_schedule, Pty.start
    monkeypatch.setattr(streamer_mod, "build_schedule", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(rc, "build_schedule", lambda *a, **k: calls.append(1) or real(*a, **k), raising=False)
    monkeypatch.setattr(Pty, "start", lambda self: starts.append(1) or real_start(self))
    p = tmp_path / "short.traj.json"
    min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.5]).save(p)
    if face == "cli":
        assert run_cli(["execute", str(p), "--sim", "--yes", "--servos", "ideal", "--log", str(tmp_path / "x.exec.json")]) == 0
    else:
        assert rc.execute(p, sim=True, servos="ideal")["outcome"] == "completed"
    assert len(calls) == 1 and len(starts) == 1
