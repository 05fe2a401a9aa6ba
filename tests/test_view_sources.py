"""The view's reading of an execution log's commands onto the plan's clock (roarmctl.viz.web.sources)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roarmctl import api
from roarmctl.device.schedule import DEFAULT_STRATEGY, build_schedule, sample
from roarmctl.export.streams import JointStates
from roarmctl.viz.web.sources import commanded_on_plan_clock

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def traj_and_robot():
    traj = api.plan(ROOT / "plans" / "pick_place.yaml").trajectory
    return traj, api.load_robot(traj.robot)


@pytest.mark.parametrize("lowered", [[], [(0.33, 31.0)], [(0.3, 31.0), (0.6, 26.0)]])
def test_commands_of_a_stream_that_lowered_its_rate_land_where_the_plan_has_them(traj_and_robot, lowered):
    """A stream that lowered its rate for a slow firmware (the streamer rebuilds its schedule from a tick on at the
    new rate and logs rate_changes) is put on the plan's clock so that every command's target is the plan's pose at
    the time it is drawn: checked against the trajectory itself, sampled there (one rate for the whole run drew the
    later commands up to seconds early, and their TCP speed spiked)."""
    traj, robot = traj_and_robot
    rate = 50.0
    schedule = build_schedule(traj, robot, rate=rate)
    changes = []
    for share, hz in lowered:  # as the streamer's _lower_rate does: the schedule's tail again at the lower rate
        k = int(share * len(schedule))
        schedule = schedule[:k] + build_schedule(traj, robot, rate=hz, start=schedule[k - 1].t + 1.0 / hz)
        changes.append({"tick": k, "t": schedule[k].t, "from_hz": rate, "to_hz": hz})
        rate = hz
    ticks = np.arange(len(schedule))
    sent = JointStates(np.array([tk.t for tk in schedule]), np.array([tk.target for tk in schedule]), ticks=ticks)
    # the log's rate is the last one the stream ran at, as the streamer writes it (stream_result.run_log)
    log = {"rate": rate, "strategy": DEFAULT_STRATEGY, "duration": traj.duration, "rate_changes": changes}
    times, positions = commanded_on_plan_clock(log, sent)
    assert len(times) == len(schedule)
    np.testing.assert_allclose(positions, sample(traj, times), atol=1e-9)


@pytest.mark.slow  # plans pick_place and executes it on the simulated queued build with a slow loop (~1 s of CPU)
def test_a_run_that_lowered_its_rate_is_drawn_on_the_plan(tmp_path, virtual_sim):
    """The queued 20260701 build with a 22 ms loop pass makes the streamer lower its rate; the page of its log
    (without the trajectory it carries, as an older roarmctl wrote it) draws the commanded TCP where the plan has it
    (RMS under 5 mm: the servo sag offset) and no faster than the plan's peak. The run is on the virtual clock
    (``virtual_sim``: the same firmware and servo models, no pty; 11 s of waiting in real time); the real-time run
    that lowers its rate is tests/device/test_execute.py's."""
    import base64
    import json

    from clirun import roarmctl

    from roarmctl.viz.web.sources import load_view_source, source_document

    def _decode(a: str) -> np.ndarray:  # the page document's arrays: base64 of little-endian float32
        return np.frombuffer(base64.b64decode(a), dtype="<f4")

    def _rms(a: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.asarray(a, dtype=float) ** 2)))

    traj_file = tmp_path / "pp.traj.json"
    api.plan(ROOT / "plans" / "pick_place.yaml").trajectory.save(traj_file)
    log = tmp_path / "run.json"
    done = roarmctl("execute", str(traj_file), "--sim", "--yes", "--firmware", "m3-2026", "--loop-pass", "22",
                    "--log", str(log))
    assert done.returncode == 0, done.stderr
    data = json.loads(log.read_text())
    assert data["rate_changes"], "the slow loop should have lowered the rate"
    del data["trajectory"]
    older = tmp_path / "older.json"
    older.write_text(json.dumps(data))
    alone, whole = source_document(load_view_source(older)), source_document(load_view_source(older, traj_file))
    t_a, tcp_a = _decode(alone["times"]), _decode(alone["tcp"]).reshape(-1, 3)
    t_w, tcp_w = _decode(whole["times"]), _decode(whole["tcp"]).reshape(-1, 3)
    planned_at = np.column_stack([np.interp(t_a, t_w, tcp_w[:, k]) for k in range(3)])
    assert _rms(np.linalg.norm(tcp_a - planned_at, axis=1)) < 0.005
    assert _decode(alone["speed"]).max() < 1.05 * _decode(whole["speed"]).max()
