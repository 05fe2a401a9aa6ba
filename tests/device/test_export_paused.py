"""An exported run in which the plan paused for a stalled host: every stream is on the run's clock, the planned
set-point stands still through the pause, and the planned and measured arm at a measured stamp give the error the
streamer itself judged that frame by (on the plan's own clock). Fake clock and link: deterministic, no real time."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_streamer import ROBOT, traj

from roarmctl.device.execlog import write_log
from roarmctl.device.streamer import StreamConfig, Streamer
from roarmctl.device.virtual import VirtualClock, VirtualLink
from roarmctl.export import streams_for


def test_export_of_a_paused_run_holds_the_plan_and_matches_the_streamers_tracking(tmp_path: Path) -> None:
    clock = VirtualClock()
    link = VirtualLink(clock)
    t = traj(1.0)

    def hook(k: int) -> None:
        if k == 25:
            clock.now += 0.15  # the process got no CPU for this long, where the TCP moves fastest

    st = Streamer(link, ROBOT, t, StreamConfig(rate=50), clock=clock, sleep=clock.sleep, hook=hook)
    res = st.run()
    assert res.outcome == "completed" and len(st.paused) == 1
    (at, d), = res.log["paused"]
    log_path, traj_path = write_log(tmp_path / "run.exec.json", res.log), tmp_path / "run.traj.json"
    t.save(traj_path)
    streams = streams_for(log_path, traj_path)
    planned, measured = streams.joint_states["planned"], streams.joint_states["measured"]
    # the plan's samples, then a sample where the pause ends: the set-point stood still at the plan's pose at `at`
    # (tick 25 lies on the plan's 10 ms grid: its own sample is the pause's start)
    assert len(planned.times) == len(t.times) + 1
    k = int(np.argmin(np.abs(planned.times - at)))
    assert planned.times[k] == pytest.approx(at, abs=1e-9) and planned.times[k + 1] == pytest.approx(at + d, abs=1e-9)
    assert np.allclose(planned.positions[k], planned.positions[k + 1]) and not planned.velocities[k + 1].any()
    assert np.allclose(planned.positions[k], t.positions[np.searchsorted(t.times, at - 1e-9)])
    assert planned.times[k + 2] == pytest.approx(t.times[k + 1] + d, abs=1e-9)  # later samples: later by the pause
    # measured states at read_t; the planned set-point there (interpolated between the 10 ms samples) is the one the
    # streamer judged the frame against: the same TCP error, after the pause too
    read = {round(e["read_t"], 6): e for e in res.log["received"] if "read_t" in e}
    assert sorted(read) == pytest.approx(sorted(measured.times[np.isin(np.round(measured.times, 6), list(read))]))
    fk = lambda q: ROBOT.kin.fk(ROBOT.full_q(q))[..., :3, 3]  # noqa: E731
    qp = np.column_stack([np.interp(measured.times, planned.times, planned.positions[:, j]) for j in range(ROBOT.dof)])
    ours = dict(zip(np.round(measured.times, 6), np.linalg.norm(fk(measured.positions) - fk(qp), axis=1)))
    logged = [(e["t"], e["error_m"]) for e in res.log["tracking"]]
    assert len(logged) > 20 and sum(tt > at + d for tt, _ in logged) > 10  # frames read after the pause
    diff = np.array([abs(ours[round(tt, 6)] - e) for tt, e in logged])
    # m: linear between the plan's 10 ms samples against the streamer's cubic Hermite, and the log's 1 um rounding
    assert diff.max() < 0.05e-3
