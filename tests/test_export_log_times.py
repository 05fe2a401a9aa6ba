"""Exporting an execution log whose feedback lines arrived together: each measured state is stamped when the
servos were read (arrival minus the reply's wire time at 115200 baud 8N1 and the firmware's work), so a long
line that arrived with a short one was read earlier, and the earliest state need not be the first in the log."""

from __future__ import annotations

import json
from pathlib import Path

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
    log = {"format": "roarmctl.execlog/1", "robot": "roarm_m3_pro", "speed_scale": 1.0,
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
