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
    log = {"rate": 50.0, "strategy": DEFAULT_STRATEGY, "duration": traj.duration, "rate_changes": changes}
    times, positions = commanded_on_plan_clock(log, sent)
    assert len(times) == len(schedule)
    np.testing.assert_allclose(positions, sample(traj, times), atol=1e-9)
