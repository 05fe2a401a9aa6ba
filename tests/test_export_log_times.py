"""The times of an exported execution log. Each measured state is stamped when the servos were read: the log's
``read_t`` where the stream judged the frame, else (a log without it) arrival minus the reply's wire time at 115200
baud 8N1 and the firmware's work, so a long line that arrived with a short one was read earlier, and the earliest
state need not be the first in the log. Every stream of one export is on the log's clock (the run's time), so the
planned and the measured arm at one stamp give the streamer's own tracking error."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from clirun import planned_and_run_on_sim

from roarmctl.cli import run as run_cli
from roarmctl.device.protocol import feedback_read_time


def feedback_line(extra: int) -> tuple[str, dict]:
    """A T:1051 feedback line of the M3 firmware with ``extra`` more numeric fields (a newer build prints
    torques, flags and the voltage too: about 330 bytes against about 90)."""
    fb: dict = {"T": 1051, "x": 0.3, "y": 0.0, "z": 0.2, "b": 0.0, "s": 0.0, "e": 1.57, "t": 0.0, "r": 0.0, "g": 3.14}
    fb.update({f"f{k}": 12.345 for k in range(extra)})
    return json.dumps(fb, separators=(",", ":")), fb


def test_out_of_order_read_times_export_from_the_earliest(tmp_path: Path) -> None:
    short, fb_short = feedback_line(0)
    long, fb_long = feedback_line(24)
    # both lines complete at t = 5 ms: the long one (about 20 ms more wire time) was read well before the first
    received = [{"t": 0.005, "line": short, "feedback": fb_short}, {"t": 0.005, "line": long, "feedback": fb_long}]
    reads = [feedback_read_time(r["t"], r["line"]) for r in received]
    assert reads[1] < min(0.0, reads[0])  # the case: the second state is the earliest, and before time 0
    cmd = {"T": 102, "base": 0.0, "shoulder": 0.0, "elbow": 1.57, "wrist": 0.0, "roll": 0.0, "hand": 3.14,
           "spd": 0, "acc": 10}
    # an older log: no read_t, and the skipped ticks that logs carried before the plan's clock paused instead
    log = {"format": "roarmctl.execlog/1", "robot": "roarm_m3_pro", "speed_scale": 1.0, "skipped": {"late": 2, "behind": 0},
           "sent": [{"t": 0.0, "cmd": cmd}], "received": received}
    src = tmp_path / "run.exec.json"
    src.write_text(json.dumps(log))
    out = tmp_path / "run.mcap"
    assert run_cli(["export", str(src), "-o", str(out)]) == 0

    from rosbags.rosbag2 import Reader

    times: dict[str, list[int]] = {}
    with Reader(out) as reader:
        for conn, t, _ in reader.messages():
            times.setdefault(conn.topic, []).append(t)
    t0 = min(reads)  # every time is shifted by the earliest sample, so nothing is negative
    assert sorted(times["/joint_states/measured"]) == sorted(round((r - t0) * 1e9) for r in reads)
    assert times["/joint_states/commanded"] == [round(-t0 * 1e9)]


@pytest.mark.slow
def test_a_run_exports_measured_states_at_read_t_and_the_logs_tracking_error(tmp_path: Path) -> None:
    """A short run on the simulator (real time, its physics servos), exported as MCAP, bag folder and CSV with the
    trajectory it ran: each measured stamp is the frame's read_t (plus the bag's stated offset), and the planned
    set-point at a measured stamp is the one the streamer judged that frame against (its logged tracking error)."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from roarmctl.robot.loader import load_robot

    traj, log_path = planned_and_run_on_sim(tmp_path, "robot: roarm_m3_pro\nstart: home\ntasks:\n"
                                            "  - move: {xyz: [0.25, 0.10, 0.08]}\n  - move: {xyz: [0.20, -0.10, 0.15]}\n")
    log = json.loads(log_path.read_text())
    frames = [r for r in log["received"] if "feedback" in r and "tcp_world_m" in r]
    judged = [r for r in frames if "read_t" in r]
    assert len(judged) > 20 and log["tracking"]
    # a frame the stream did not judge (before it started) has no read_t: its arrival less the line's wire time and
    # the firmware's 4 ms
    read = np.sort([r.get("read_t", r["t"] - (len(r["line"]) + 2) / 11520 - 0.004) for r in frames])
    assert min(r["t"] - r["read_t"] for r in judged) > (len(judged[0]["line"]) + 2) / 11520  # never the arrival
    robot = load_robot("roarm_m3_pro")
    tracked = {round(e["t"], 6): e["error_m"] for e in log["tracking"]}  # its t: when the servos were read
    ts = get_typestore(Stores.ROS2_JAZZY)
    for out in (tmp_path / "run.mcap", tmp_path / "run_bag"):
        assert run_cli(["export", str(log_path), "-t", str(traj), "-o", str(out), "--json"]) == 0
        topics: dict[str, list] = {}
        with Reader(out) as reader:
            for conn, t, raw in reader.messages():
                if conn.topic.startswith("/joint_states/"):
                    msg = ts.deserialize_cdr(raw, conn.msgtype)
                    assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == t
                    topics.setdefault(conn.topic, []).append((t * 1e-9, np.array(msg.position[:robot.dof])))
        # the bag starts at its earliest sample: here the feedback read before the motion
        offset = -min(0.0, read[0], min(s["t"] for s in log["sent"]))
        measured = sorted(topics["/joint_states/measured"], key=lambda m: m[0])
        assert np.abs(np.array([t for t, _ in measured]) - offset - read).max() < 2e-9  # s: the bag's 1 ns
        planned_t = np.array([t for t, _ in topics["/joint_states/planned"]]) - offset
        planned_q = np.array([q for _, q in topics["/joint_states/planned"]])
        ours, theirs = [], []
        for t, q in measured:
            logged = tracked.get(round(t - offset, 6))
            if logged is None:
                continue
            qp = np.array([np.interp(t - offset, planned_t, planned_q[:, j]) for j in range(robot.dof)])
            ours.append(np.linalg.norm(robot.kin.fk(q)[:3, 3] - robot.kin.fk(qp)[:3, 3]))
            theirs.append(logged)
        assert len(ours) == len(tracked)  # every tracked frame found at its read_t
        # mm: the streamer interpolates the plan (cubic Hermite), the export's planned samples are 10 ms apart
        # (linear here), and the log rounds to 1 um; measured 0.008 mm at most
        assert np.abs(np.array(ours) - np.array(theirs)).max() < 0.05e-3
    assert run_cli(["export", str(log_path), "-t", str(traj), "-o", str(tmp_path / "run.csv")]) == 0
    with open(tmp_path / "run.csv") as f:
        rows = list(csv.DictReader(f))
    csv_t = np.sort([float(r["time_s"]) for r in rows if r["source"] == "measured"])  # the log's own times
    assert np.abs(csv_t - read).max() < 1e-6  # its 6 decimals


def test_a_read_t_after_its_line_arrived_is_a_damaged_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line, fb = feedback_line(0)
    for bad, said in ((0.02, "read_t: 0.02 is too large (must be <= 0.01)"), ("soon", "read_t: expected a number")):
        log = {"format": "roarmctl.execlog/1", "robot": "roarm_m3_pro", "sent": [],
               "received": [{"t": 0.01, "read_t": bad, "line": line, "feedback": fb}]}
        src = tmp_path / "bad.exec.json"
        src.write_text(json.dumps(log))
        assert run_cli(["export", str(src), "-o", str(tmp_path / "bad.csv")]) == 2
        assert f"received[0].{said}" in capsys.readouterr().err


@pytest.mark.parametrize("scale", [1.0, 0.37])
def test_the_planned_stream_is_the_plan_at_the_plans_own_clock(scale: float) -> None:
    """At any run time x, the exported planned set-point (read between its samples) is the plan at the plan's own
    time there (``schedule.plan_clock``: standing still through each pause), for pauses on the plan's sample grid,
    off it, and one the log rounded to 1 us."""
    from roarmctl.device.schedule import plan_clock, sample
    from roarmctl.export.streams import planned_states
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    t = np.round(np.arange(101) * 0.01, 9)
    w = 2 * np.pi * np.outer(t, [0.5, 0.3, 0.4, 0.6, 0.2, 0.1])
    traj = Trajectory(robot.name, list(robot.joint_names), t, 0.3 * np.sin(w), 0.3 * np.cos(w) * 2 * np.pi * np.array(
        [0.5, 0.3, 0.4, 0.6, 0.2, 0.1]), np.zeros((101, 6)))
    grid = t / scale  # the run-speed plan times of the samples
    paused = [(round(float(grid[20]), 6), 0.13), (float(grid[50]) + 0.0043, 0.25), (float(grid[80]) - 2e-7, 0.05)]
    st = planned_states(traj, scale, paused)
    assert np.all(np.diff(st.times) >= 0) and len(st.times) == 101 + 1 + 2 + 1  # the off-grid pause: both ends
    x = np.linspace(0.0, st.times[-1], 4001)
    got = np.column_stack([np.interp(x, st.times, st.positions[:, j]) for j in range(6)])
    want = sample(traj, plan_clock(x, paused) * scale)
    # rad: linear between 10 ms samples against the cubic Hermite (0.3 rad at up to 0.6 Hz: |q''| 4.3 rad/s^2,
    # h^2/8 |q''| = 5.3e-5 rad)
    assert np.abs(got - want).max() < 6e-5
