"""Following on the simulated arms, in real time (slow): a simulated leader (the firmware simulator, its torque off,
a scripted hand as 'teach --sim --guide' uses) whose frames go stale, freeze, jump by pi, arrive as NaN or stop, and
a policy's JSON lines over a pipe with targets inside the table, out of limits, across the singularity, a 1 s gap
and a 10x step. For each: what the follower's simulated firmware ran (its own record) is within limits, clear and
within the step budget; the arm held (the hold's two copies); the log says why; the exit code is 4. A clean leader
is followed within a tracking error stated here."""

from __future__ import annotations

import numpy as np
import pytest
from followsim import (
    HOME,
    ROBOT,
    Policy,
    assert_nothing_unsafe_ran,
    commanded,
    policy_line,
    ramp,
    run,
    swing,
    tracking,
)

from roarmctl.device.follow_guard import SourceLost
from roarmctl.device.follow_session import LeaderSpec, leader_tracking
from roarmctl.device.sim_config import Bogus

pytestmark = pytest.mark.slow


def leader_with(**faults) -> LeaderSpec:
    """A simulated leader moved by the swing, with the simulator's faults from 3 s after its start (on an idle
    machine following has begun by then; on a busy one the faults may come first, and must be refused all the same)."""
    return LeaderSpec(guide=swing(8.0), faults=dict(faults, faults_from=3.0))


def assert_held_and_lost(done, exc, *words: str) -> None:
    assert isinstance(exc, SourceLost) and exc.exit_code == 4
    if done is None:  # a busy machine: the fault came before the leader's start, which refused it (nothing moved)
        assert exc.message.startswith("leader: "), exc
        return
    log = done.result.log
    assert done.result.outcome == "aborted" and log["hold"] is not None and log["hold"]["copies"] == 2
    text = exc.message + " ".join(r["reason"] for r in log["summary"]["targets"]["refusals"])
    assert any(w in text for w in words), text
    q = assert_nothing_unsafe_ran(done)
    if log["hold"]["kind"] == "setpoint":  # the hold is the last goal run: the last set-point again
        assert np.allclose(q[-1], q[-2], atol=2e-4)


@pytest.mark.parametrize("fault, faults, words", [
    ("stale", {"unpowered": True}, ("frozen", "no frame", "no valid feedback")),  # reads fail, the last values repeat, slowly
    ("frozen", {"fail_reads": dict.fromkeys(("base", "shoulder", "elbow", "wrist", "roll", "hand"), 1.0),
                "read_timeout": 0.001}, ("frozen",)),
    ("jump by pi", {"bogus": (Bogus("b", "3.1416", frames=0),)}, ("servo step 0", "faster than", "budget")),
    ("NaN", {"bogus": (Bogus("s", "nan", frames=0),)}, ("not a valid feedback frame",)),
    ("stop", {"mute_after": 0}, ("no frame", "no valid feedback")),
])
def test_a_faulty_leader_is_refused_the_arm_holds_and_following_ends(fault, faults, words):
    done, exc = run(leader=leader_with(**faults), frozen_after=0.5, max_refusals=3, timeout=1.0)
    assert_held_and_lost(done, exc, *words)


def test_a_clean_leader_is_followed_within_the_stated_tracking_error():
    done, exc = run(leader=LeaderSpec(guide=swing(8.0)), duration=4.0)
    assert exc is None and done.result.outcome == "completed"
    tg = done.result.summary()["targets"]
    # a leader's frames are dated by their arrival: a loaded host that reads two late and the next on time shrinks
    # the time between them, and the step budget may refuse one (idle: none; 8 processes per core: 1 in 139)
    assert tg["refused"] <= 0.05 * tg["accepted"] and set(tg["by_kind"]) <= {"step"}, tg
    assert_nothing_unsafe_ran(done)
    trk = tracking(done)
    # A bound that holds on a machine loaded 8-10 runnable processes per core (measured there: 0.04-0.093 rad RMS,
    # 0.42-0.52 s behind; idle: 0.005 rad, 0.17 s, bench/bench_follow.py) and fails an arm that does not follow: the
    # leader's base swings 0.5 rad, so one that stood still would be 0.3 rad RMS off
    assert trk["rms_rad"] < 0.15 and trk["latency_s"] < 0.95, trk


TABLE_LEAN = np.array([0.0, 0.6, 1.5708, 0.0, 0.0, 0.0])  # the shoulder leans into the table
UP = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # the arm straight up: singular
START = ramp(0.0, HOME, HOME + [0.2, 0, 0, 0, 0, 0], 10)  # 1 s of a clean 10 Hz policy


def policy(after: list) -> Policy:
    return Policy(START + after)


@pytest.mark.parametrize("case, after, words", [
    ("inside the table", ramp(1.0, HOME + [0.2, 0, 0, 0, 0, 0], TABLE_LEAN, 30), ("table",)),
    ("out of limits", [policy_line(1.0 + 0.1 * k, HOME + [0.2, 0, 0, 0, 0, 2.0]) for k in range(8)], ("outside",)),
    ("across the singularity", ramp(1.0, HOME + [0.2, 0, 0, 0, 0, 0], UP, 40), ("singular",)),
    ("a 1 s gap", [policy_line(2.2, HOME + [0.2, 0, 0, 0, 0, 0])], ("no frame",)),
    ("a 10x step", [policy_line(1.0 + 0.1 * k, HOME + [2.2, 0, 0, 0, 0, 0]) for k in range(8)], ("budget",)),
])
def test_a_bad_policy_stream_is_refused_the_arm_holds_and_following_ends(case, after, words):
    done, exc = run(policy=policy(after), max_refusals=5, timeout=0.5)
    assert_held_and_lost(done, exc, *words)
    _, q = commanded(done)
    assert np.max(q[:, 0]) <= 0.2 + 2e-4  # never beyond the last accepted target's base


def test_malformed_lines_count_as_refusals_and_a_clean_end_completes():
    lines = START + [(1.0, "not json"), (1.05, '{"t": 1.05, "joints": [0, 0]}')] \
        + ramp(1.1, HOME + [0.2, 0, 0, 0, 0, 0], HOME + [0.3, 0, 0, 0, 0, 0], 5)
    # a silence bound well above the lines' 0.05-0.1 s spacing: what is tested is the malformed lines, not the silence
    # (with the default 0.5 s a host loaded 15 runnable processes on 2 cores once delayed the policy's lines 0.62 s)
    done, exc = run(policy=Policy(lines), max_refusals=5, timeout=3.0)
    assert exc is None and done.result.outcome == "completed"
    assert done.result.summary()["targets"]["by_kind"] == {"source": 2}
    q = assert_nothing_unsafe_ran(done)
    assert np.allclose(q[-1], HOME + [0.3, 0, 0, 0, 0, 0], atol=2e-4)


def test_a_dataset_episode_replays_within_tolerance_of_its_states_and_the_run_is_recorded(tmp_path):
    """An episode written with the LeRobot writer (issue 34's): a minimum-jerk move from home and back at 30 fps,
    state = action. 'follow --sim --dataset D --episode 0 --record R' replays it; the follower's true joints (its
    simulator's record) follow the episode's states within 0.1 rad RMS at the best lag, and R holds the followed
    episode: its actions are the replayed targets, its states the measured joints."""
    from clirun import roarmctl

    from roarmctl.export.lerobot.dataset import DatasetSpec, Episode, read_actions, read_episodes, write_dataset

    fps = 30
    t = np.arange(0, 3.0 + 1e-9, 1 / fps)
    u = np.clip(t / 1.5, 0, 1)
    s = np.where(t <= 1.5, 10 * u**3 - 15 * u**4 + 6 * u**5, 1.0)
    w = np.clip((t - 1.5) / 1.5, 0, 1)
    s = s - np.where(t > 1.5, 10 * w**3 - 15 * w**4 + 6 * w**5, 0.0)
    goal = np.array([0.5, 0.2, -0.3, 0.4, 0.3, 0.8])
    q = HOME + np.outer(s, goal)
    spec = DatasetSpec(fps, ROBOT.name, list(ROBOT.joint_names))
    write_dataset(tmp_path / "src", spec, [Episode("reach", q.astype(np.float32), q.astype(np.float32))])
    res = roarmctl("follow", "--sim", "--dataset", str(tmp_path / "src"), "--episode", "0",
                   "--record", str(tmp_path / "rec"), "--log", str(tmp_path / "log.json"))
    assert res.returncode == 0, res.stderr
    assert "recorded the episode" in res.stderr
    import json

    log = json.loads((tmp_path / "log.json").read_text())
    tg = log["summary"]["targets"]
    # a host stalled beyond max_lag delivers the frames due meanwhile late: those are refused as stale (idle: none)
    assert tg["accepted"] >= 0.9 * len(t) and set(tg["by_kind"]) <= {"stale"}, tg
    # the follower's measured joints (validated feedback) against the episode's states, at the best lag
    meas = np.array(log["measured"])
    first = next(e["t"] for e in log["targets"] if "refused" not in e)
    trk = leader_tracking((meas[:, 0], meas[:, 1:], None), (first + t - t[0], q, None))
    # idle: about 0.004 rad RMS, 0.012 at worst; loaded 10 processes per core: 0.028 / 0.084. An arm that stood still
    # would be 0.2 rad RMS off (the base goes 0.5 rad and back)
    assert trk["rms_rad"] < 0.1 and trk["max_rad"] < 0.3, trk
    # the recording: one episode, its actions the replayed targets (float32), its states within reach of them
    eps = read_episodes(tmp_path / "rec")
    assert len(eps) == 1 and eps[0].task == "follow"
    _ts, act = read_actions(tmp_path / "rec", 0)
    assert np.allclose(act[0], q[0], atol=1e-6) and np.allclose(act[-1], q[-1], atol=1e-3)
    assert np.min(np.abs(act[:, None, :] - q[None].astype(np.float32)).max(axis=2), axis=1).max() < 1e-6  # each row one of q's
    # at the end the arm is at the last target, within the servos' lag: following ends with the last set-point and does
    # not wait for the arm to settle (idle: under 0.01 rad; loaded 10 processes per core: 0.02)
    assert np.max(np.abs(eps[0].state - q[-1]), axis=1)[-1] < 0.05
