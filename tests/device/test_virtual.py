"""The real ``Link`` over a ``VirtualSerial`` (roarmctl.device.virtual): connect and stream a move on the firmware
model's clock. The model's own recording is the witness of where the arm went; the same inputs give the same log,
byte for byte, however busy the machine."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest
from devtraj import HOME, min_jerk, pick_place

from roarmctl.device.session import run_execution
from roarmctl.device.sim_config import SimConfig
from roarmctl.device.streamer import StreamConfig, Streamer
from roarmctl.device.virtual import VirtualClock, VirtualSimulator, serial_link
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")
GOAL = [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]
STEP = 2 * np.pi / 4096  # rad: one ST3235 position step (4096 a turn)


def stream(firmware: str) -> tuple[str, np.ndarray, dict]:
    """Connect to a model of ``firmware`` and stream a 1 s move at 50 Hz; (the log as JSON, the arm's last recorded
    joints, the summary)."""
    clock = VirtualClock()
    link = serial_link(SimConfig(firmware=firmware), clock)
    link.connect()
    res = Streamer(link, ROBOT, min_jerk([HOME, GOAL], [1.0]), StreamConfig(rate=50), clock=clock,
                   sleep=clock.sleep).run()
    link.close()
    _, q, _ = link.ser.fw.recording()
    return json.dumps(res.log, sort_keys=True, default=str), q[-1], res.log["summary"]


@pytest.mark.parametrize("firmware", ["m3-0.84", "m3-2026"])
def test_the_real_link_streams_a_move_to_its_end_on_the_virtual_clock(firmware):
    _, last, summary = stream(firmware)
    assert summary["outcome"] == "completed" and summary["commands"] == 51  # ticks 0..50 of 1 s at 50 Hz
    assert np.abs(last - GOAL).max() <= 2 * STEP  # the model's servos stand at the goal, to their resolution


def test_the_same_run_gives_the_same_log_bytes_on_an_idle_or_a_busy_interpreter():
    idle, _, _ = stream("m3-2026")
    stop = threading.Event()

    def spin() -> None:  # takes the interpreter's time from the run: the virtual clock does not see it
        while not stop.is_set():
            sum(range(1000))

    hog = threading.Thread(target=spin, daemon=True)
    hog.start()
    try:
        busy, _, _ = stream("m3-2026")
    finally:
        stop.set()
        hog.join(timeout=10)
    assert busy == idle


def test_half_speed_sends_the_last_tick_at_twice_the_plans_time_and_the_arm_follows():
    """A 1 s move at speed scale 0.5 and 25 Hz: ticks 0..50 go out at exactly k/25 s of the model's clock (no pause, no
    lateness to allow for), and the model's arm is half way at 1 s and at the goal after 2 s."""
    clock = VirtualClock()
    link = serial_link(SimConfig(), clock)
    link.connect()
    res = Streamer(link, ROBOT, min_jerk([HOME, GOAL], [1.0]), StreamConfig(rate=25, speed_scale=0.5), clock=clock,
                   sleep=clock.sleep).run()
    link.close()
    ticks = [s for s in res.log["sent"] if "tick" in s]
    assert [s["tick"] for s in ticks] == list(range(51)) and not res.log["paused"]
    assert np.allclose([s["t"] for s in ticks], np.arange(51) / 25, atol=1e-9)
    fw = link.ser.fw
    fw.advance(res.t0 + 2.5)
    ts, q, _ = fw.recording()
    halfway = q[np.searchsorted(ts, res.t0 + 1.0)]
    assert np.abs(halfway - (np.asarray(HOME) + np.asarray(GOAL)) / 2).max() < 0.1  # min-jerk: half way at half time
    assert np.abs(q[-1] - GOAL).max() <= 2 * STEP


def execute_on_model(traj, **stream) -> tuple[object, VirtualSimulator]:
    """``run_execution`` (the CLI's and the API's entry) with the simulator on a virtual clock."""
    sims: list[VirtualSimulator] = []

    def simulator(config, servos):
        sims.append(VirtualSimulator(config, VirtualClock(), servos=servos))
        return sims[-1]

    run = run_execution(traj, ROBOT, StreamConfig(**stream), sim=True, confirm=lambda message: True, simulator=simulator)
    return run, sims[0]


@pytest.mark.slow
def test_an_execution_runs_on_the_simulators_clock_on_time_and_the_arm_follows():
    traj = pick_place()
    run, sim = execute_on_model(traj)
    log = run.result.log
    assert log["summary"]["outcome"] == "completed" and run.port == "virtual"
    ticks = [s for s in log["sent"] if "tick" in s]
    k = np.array([s["tick"] for s in ticks])
    assert k.tolist() == list(range(len(ticks))) and len(ticks) == round(traj.duration * 50) + 1
    # the host is never late on the virtual clock: tick k leaves at exactly k/50 s (the log's times are from the start), no pause
    t = np.array([s["t"] for s in ticks])
    assert np.abs(t - np.minimum(k / 50.0, log["duration"])).max() < 1e-9 and not log["paused"]
    assert max(s["lateness"] for s in ticks) < 1e-9
    # the model's recording (the servos' true positions, on the same clock) covers the run and ends where the plan
    # ends; the run's figures of the simulator's tracking were taken from it
    ts, q, torque = sim.recording()
    assert ts[-1] - run.result.t0 >= traj.duration and torque.all() and np.abs(q[-1, :5] - traj.positions[-1, :5]).max() < 3 * STEP
    assert run.simulator is not None and run.simulator["samples"] > 0 and run.simulator["lateness_max_ms"] == 0


def test_an_execution_on_the_virtual_clock_gives_the_same_log_bytes_twice():
    traj = min_jerk([HOME, GOAL], [1.0])
    a, _ = execute_on_model(traj, rate=25)
    b, _ = execute_on_model(traj, rate=25)
    assert json.dumps(a.result.log, sort_keys=True, default=str) == json.dumps(b.result.log, sort_keys=True, default=str)
