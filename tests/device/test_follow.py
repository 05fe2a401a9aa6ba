"""The follower on a virtual clock and the pure firmware model (no port, no real time): a clean 10 Hz source is
followed smoothly to its end; bad targets are never commanded; a run of refusals, silence or a stop signal hold
the arm at the last set-point sent and raise. What was commanded is read back from the firmware model's own record
of the commands it ran and checked against the checker and the robot's limits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_follow_guard import CHECKER, HOME, ROBOT

from roarmctl.device.follow import FollowConfig, Follower, SourceEnded
from roarmctl.device.follow_guard import GuardLimits, SourceLost, Target
from roarmctl.device.protocol import WireMap
from roarmctl.device.virtual import VirtualClock, VirtualLink
from roarmctl.errors import Interrupted

WM = WireMap(ROBOT)


class ScriptSource:
    """Frames released at their arrival times on the virtual clock; ``None`` as a frame: the source ends;
    an exception: raised when due."""

    name = "script"

    def __init__(self, frames: list) -> None:
        self.frames = sorted(frames, key=lambda f: f[0])
        self.i = 0

    def poll(self, now: float) -> list[Target]:
        out = []
        while self.i < len(self.frames) and self.frames[self.i][0] <= now:
            t, what = self.frames[self.i]
            self.i += 1
            if what is None:
                raise SourceEnded
            if isinstance(what, BaseException):
                raise what
            out.append(Target(t, np.asarray(what, float), now))
        return out

    def refusals(self) -> list[tuple[float, str]]:
        return []

    def close(self) -> None:
        pass


def ramp_frames(t0: float, a, b, n: int, hz: float = 10.0) -> list:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return [(t0 + (k + 1) / hz, a + (b - a) * (k + 1) / n) for k in range(n)]


def follow(frames, **guard):
    clock = VirtualClock()
    link = VirtualLink(clock)
    src = ScriptSource([(clock.now + 0.5 + t, q) for t, q in frames])
    fol = Follower(link, ROBOT, CHECKER, src, FollowConfig(guard=GuardLimits(**guard)), clock=clock, sleep=clock.sleep,
                   timer=lambda: 0.0)
    return fol, link


def ran_setpoints(link) -> np.ndarray:
    """The T:102 goals the firmware model itself ran, as joint vectors (N, dof)."""
    goals = [c for _, _, c in link.fw.executed if c.get("T") == 102] if hasattr(link.fw, "executed") else \
        [c for _, c in link.sent if c["T"] == 102]
    return np.array([WM.from_wire({f: c[f] for f in WM.field_names}) for c in goals])


def assert_all_safe(q: np.ndarray, rate: float = 50.0) -> None:
    assert len(q)
    assert all(ROBOT.within_limits(x, tol=1e-4) for x in q)
    assert CHECKER.validity_batch(q[:, :5], gripper=q[:, 5]).all()
    steps = np.abs(np.diff(q, axis=0))
    assert np.all(steps <= ROBOT.velocity_limits / rate + 2e-4)  # the wire's 4 decimals


def test_a_clean_ten_hz_source_is_followed_smoothly_to_its_last_target():
    goal = HOME + [0.5, 0.2, -0.2, 0.3, 0.4, 0.8]
    frames = ramp_frames(0.0, HOME, goal, 20) + [(2.2, None)]
    fol, link = follow(frames)
    res = fol.run()
    assert res.outcome == "completed"
    q = ran_setpoints(link)
    assert_all_safe(q)
    assert np.allclose(q[-1], goal, atol=2e-4)
    # no staircase: between two 10 Hz targets the set-points keep moving (at most one set-point still per 5)
    base = q[:, 0]
    moving = np.abs(np.diff(base)) > 1e-5
    first, last = np.argmax(moving), len(moving) - np.argmax(moving[::-1])
    assert moving[first:last].mean() > 0.95
    # and the velocity changes smoothly (jerk-limited: no jump of a 10 Hz step's size)
    v = np.diff(base) * 50
    assert np.max(np.abs(np.diff(v))) < ROBOT.acceleration_limits[0] / 50 * 1.05 + 0.01
    assert res.log["summary"]["targets"]["accepted"] == 20


def test_targets_in_the_table_are_never_commanded_and_a_run_of_them_holds_and_ends():
    inside = np.array([0.0, 0.6, 1.5708, 0.0, 0.0, 0.0])  # the shoulder leans into the table
    frames = ramp_frames(0.0, HOME, inside, 30)
    fol, link = follow(frames, max_refusals=5)
    with pytest.raises(SourceLost) as info:
        fol.run()
    res = info.value.result
    assert info.value.exit_code == 4 and "5 targets refused in a row" in info.value.message
    first = res.log["summary"]["targets"]["refusals"][0]
    assert first["kind"] == "collision" and "table" in first["reason"]
    assert res.outcome == "aborted" and res.log["hold"]["kind"] == "setpoint"
    q = ran_setpoints(link)
    assert_all_safe(q)
    hold = [c for _, c in link.sent if c["T"] == 102][-1]
    assert np.allclose(WM.from_wire({f: hold[f] for f in WM.field_names}), q[-2], atol=1e-4)  # the last set-point
    assert not [c for _, c in link.sent if c["T"] in (0, 210)]  # never torque off
    assert sum("refused" in e for _, e in fol.events) == 5


def test_a_source_that_falls_silent_is_lost_after_the_timeout():
    frames = ramp_frames(0.0, HOME, HOME + [0.1, 0, 0, 0, 0, 0], 5)  # then nothing
    fol, link = follow(frames, timeout=0.5)
    with pytest.raises(SourceLost, match=r"no frame for 0\.5"):
        fol.run()
    q = ran_setpoints(link)
    assert_all_safe(q)


def test_a_stop_signal_holds_and_says_so():
    frames = ramp_frames(0.0, HOME, HOME + [0.4, 0, 0, 0, 0, 0], 10) + [(0.55, KeyboardInterrupt())]
    fol, _link = follow(frames)
    with pytest.raises(Interrupted) as info:
        fol.run()
    assert info.value.exit_code == 130 and info.value.result.log["hold"]["copies"] == 2


def test_a_nan_target_is_refused_and_following_goes_on():
    frames = ramp_frames(0.0, HOME, HOME + [0.2, 0, 0, 0, 0, 0], 4) + [(0.45, HOME + [math.nan] * 6)] \
        + ramp_frames(0.5, HOME + [0.2, 0, 0, 0, 0, 0], HOME + [0.3, 0, 0, 0, 0, 0], 3) + [(1.2, None)]
    fol, link = follow(frames)
    res = fol.run()
    assert res.outcome == "completed" and res.log["summary"]["targets"]["by_kind"] == {"not_finite": 1}
    assert np.allclose(ran_setpoints(link)[-1], HOME + [0.3, 0, 0, 0, 0, 0], atol=2e-4)


def test_leader_tracking_finds_a_known_lag_and_error():
    """Two recordings made by hand: the follower is the leader 0.12 s later plus 0.01 rad on the wrist."""
    from roarmctl.device.follow_session import leader_tracking

    t = np.arange(0.0, 4.0, 0.005)
    ql = np.zeros((len(t), 6))
    ql[:, 0] = 0.4 * np.sin(t)
    qf = np.zeros_like(ql)
    qf[:, 0] = 0.4 * np.sin(t - 0.12)
    qf[:, 3] = 0.01
    late = t >= 0.5  # the follower's record starts after the leader's (no reference before the leader's start)
    trk = leader_tracking((t[late], qf[late], None), (t, ql, None))
    assert trk["latency_s"] == pytest.approx(0.12, abs=1e-9)
    assert trk["rms_rad"] == pytest.approx(0.01, abs=1e-4) and trk["max_rad"] == pytest.approx(0.01, abs=1e-4)


def test_a_follow_log_becomes_an_episode_of_held_actions_and_interpolated_states():
    """Hand-made log: targets at 0.0, 0.25 (refused) and 0.3 s; measured every 0.1 s, rising 0.1 rad per 0.1 s."""
    from roarmctl.errors import InputError
    from roarmctl.export.lerobot.follow_record import follow_episode

    a, b = HOME + 0.01, HOME + 0.02
    log = {"targets": [{"t": 0.0, "q": list(a)}, {"t": 0.25, "q": list(HOME + 1.0), "refused": "x"},
                       {"t": 0.3, "q": list(b)}],
           "measured": [[0.1 * k, *(HOME + 0.1 * k)] for k in range(6)]}
    ep = follow_episode(log, ROBOT, 20, "task")
    assert ep.length == 11 and ep.task == "task"  # 0 .. 0.5 s at 20 fps
    assert np.allclose(ep.action[:6], a) and np.allclose(ep.action[6:], b)  # held; the refused one never appears
    assert np.allclose(ep.state[:, 0], HOME[0] + np.arange(11) * 0.05, atol=1e-6)
    with pytest.raises(InputError, match="nothing to record"):
        follow_episode({"targets": [], "measured": []}, ROBOT, 20, "task")


def test_a_replay_releases_each_frame_at_its_time_and_then_ends():
    from roarmctl.device.follow_sources import ReplaySource

    times = np.array([5.0, 5.1, 5.3])
    src = ReplaySource(times, np.vstack([HOME, HOME + 0.01, HOME + 0.02]), "r")
    assert [tg.t for tg in src.poll(100.0)] == [5.0]
    assert src.poll(100.05) == []
    assert [tg.t for tg in src.poll(100.35)] == [5.1, 5.3]
    with pytest.raises(SourceEnded):
        src.poll(100.4)
