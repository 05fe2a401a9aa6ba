"""The follow guard, target by target, on hand-made sources: each refusal class, the step budget against the
robot's own limits, the segment check against the checker's own judgement of the states on the segment, the
run of refusals and silence ending the source. No port, no clock: times are the targets' own."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.device.follow_guard import Guard, GuardLimits, SourceLost, Target
from roarmctl.errors import DeviceError, InputError
from roarmctl.motion.collision import CollisionChecker, interpolate
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")
HOME = np.array([0.0, 0.0, 1.5708, 0.0, 0.0, 0.0])


def box(name: str, xyz, size) -> SceneItem:
    pose = np.eye(4)
    pose[:3, 3] = xyz
    return SceneItem(name, "obstacle", "box", pose, size=size)


TABLE = box("table", (0.35, 0.0, 0.1), (0.3, 0.4, 0.2))  # top at z = 0.2 m, in front of the arm
POST = box("post", (0.3, 0.0, 0.35), (0.04, 0.04, 0.1))  # where the forearm is at HOME: in the way of a base swing
CHECKER = CollisionChecker(ROBOT, Scene([TABLE]), singularity_margin=0.02)
POST_CHECKER = CollisionChecker(ROBOT, Scene([TABLE, POST]), singularity_margin=0.02)


def guard(**kw) -> Guard:
    return Guard(ROBOT, CHECKER, GuardLimits(**kw), start=HOME)


def feed(g: Guard, qs, dt: float = 0.1, t0: float = 0.0):
    """Targets ``dt`` apart (stamp = arrival); the verdicts."""
    return [g.check(Target(t0 + (k + 1) * dt, np.asarray(q, float), t0 + (k + 1) * dt)) for k, q in enumerate(qs)]


def ramp(a, b, n):
    return [np.asarray(a) + (np.asarray(b) - np.asarray(a)) * (k + 1) / n for k in range(n)]


def test_a_smooth_clear_source_is_accepted_and_becomes_the_last_target():
    g = guard()
    goal = HOME + [0.4, 0.1, -0.1, 0.2, 0.3, 0.5]
    verdicts = feed(g, ramp(HOME, goal, 20))
    assert all(v.accepted for v in verdicts) and g.accepted == 20 and g.refused == 0
    assert np.allclose(g.last_q, goal)


@pytest.mark.parametrize("bad, kind, words", [
    (HOME + [math.nan, 0, 0, 0, 0, 0], "not_finite", "not a finite number"),
    (HOME + [0, 0, 0, 0, 0, math.inf], "not_finite", "not a finite number"),
    (HOME + [0, 0, 0, 0, 0, 2.0], "joint_limit", "outside"),  # gripper beyond 1.5
])
def test_non_finite_and_out_of_limit_targets_are_refused(bad, kind, words):
    g = guard(step_tolerance=0.5)
    v = feed(g, [HOME, bad])[1]
    assert v.kind == kind and words in v.reason and np.allclose(g.last_q, HOME)


def test_a_target_inside_the_table_is_refused_and_a_segment_through_the_post_too():
    g = guard(start_tolerance=3.0)  # the first target: only the start tolerance bounds its step
    inside = np.array([0.0, 0.5, 1.57, 0.0, 0.0, 0.0])
    assert not CHECKER.is_valid(inside[:5])
    v = g.check(Target(1.0, inside, 1.0))
    assert v.kind == "collision" and "table" in v.reason and "at the target" in v.reason
    # both ends clear, the straight segment between them (a base swing) through the post
    a, b = HOME + [0.6, 0, 0, 0, 0, 0], HOME + [-0.6, 0, 0, 0, 0, 0]
    seg = interpolate(a[:5], b[:5], 0.01)
    assert POST_CHECKER.is_valid(a[:5]) and POST_CHECKER.is_valid(b[:5]) and not POST_CHECKER.validity_batch(seg).all()
    g2 = Guard(ROBOT, POST_CHECKER, GuardLimits(start_tolerance=3.0), start=a)
    v = g2.check(Target(1.0, b, 1.0))
    assert v.kind == "collision" and "post" in v.reason and "of the way" in v.reason


def test_a_target_across_the_singularity_is_refused_as_such():
    g = guard(start_tolerance=3.0)
    straight_up = np.array([0.0, 0.0, 0.1, 0.0, 0.0, 0.0])  # elbow stretched: the arm straight up
    v = g.check(Target(1.0, straight_up, 1.0))
    assert v.kind == "singularity" and "singular" in v.reason


def test_the_step_budget_is_the_robots_velocity_limit_times_the_time():
    """Independent: the robot's published limits (the description), not the guard's arithmetic."""
    tol = 0.02
    for j in range(ROBOT.dof):
        for scale, ok in ((0.95, True), (1.05, False)):
            g = guard(step_tolerance=tol, acceleration_scale=1.0)
            dt = 0.05
            feed(g, [HOME], dt)
            step = np.zeros(ROBOT.dof)
            # a step at the velocity bound needs the acceleration to get there: go through a ramp first
            v_lim = ROBOT.velocity_limits[j]
            step[j] = (v_lim * dt + tol) * scale
            g.velocity = step / dt  # as if it were moving at that speed already
            sign = -1 if HOME[j] + step[j] > ROBOT.upper[j] - 0.3 else 1
            v = g.check(Target(2 * dt, HOME + sign * step, 2 * dt))
            assert v.accepted == ok, (j, scale, v.reason)
            if not ok:
                assert v.kind == "step" and "velocity budget" in v.reason


def test_a_ten_times_too_large_step_is_refused_and_so_is_the_jumped_value_that_stays():
    g = guard()
    feed(g, ramp(HOME, HOME + [0.2, 0, 0, 0, 0, 0], 10), dt=0.1)
    last = g.last_q.copy()
    big = last + [2.0, 0, 0, 0, 0, 0]  # 10x a 0.2 rad/0.1 s budget at 2 rad/s
    vs = [g.check(Target(1.1 + 0.1 * k, big, 1.1 + 0.1 * k)) for k in range(3)]
    assert [v.kind for v in vs] == ["step"] * 3  # 2 rad needs 1 s at 2 rad/s
    assert np.allclose(g.last_q, last)
    assert g.check(Target(1.5, last + [0.01, 0, 0, 0, 0, 0], 1.5)).accepted  # back near the last accepted one


def test_stale_late_and_frozen_frames_are_refused():
    g = guard(max_lag=0.2, frozen_after=0.5, max_refusals=100)
    feed(g, [HOME, HOME + 0.001])
    assert g.check(Target(0.2, HOME + 0.002, 0.3)).kind == "stale"  # not after the previous stamp
    assert g.check(Target(0.15, HOME + 0.002, 0.35)).kind == "stale"  # older
    assert g.check(Target(0.3, HOME + 0.002, 0.7)).kind == "stale"  # delivered 0.4 s late
    # frozen: bit-identical values for more than 0.5 s of source time
    q = HOME + 0.003
    vs = [g.check(Target(1.0 + 0.1 * k, q, 1.0 + 0.1 * k + 0.001)) for k in range(9)]
    kinds = [v.kind for v in vs]
    assert kinds[:6] == ["ok"] * 6 and set(kinds[6:]) == {"frozen"}
    assert g.check(Target(2.0, q + 1e-4, 2.001)).accepted  # moving again


def test_a_run_of_refusals_ends_the_source_and_so_does_silence():
    g = guard(max_refusals=3)
    feed(g, [HOME])
    bad = HOME + [0, 0, 0, 0, 0, math.nan]
    g.check(Target(0.2, bad, 0.2))
    g.check(Target(0.3, bad, 0.3))
    with pytest.raises(SourceLost) as info:
        g.check(Target(0.4, bad, 0.4))
    assert isinstance(info.value, DeviceError) and info.value.exit_code == 4 and "3 targets refused in a row" in info.value.message
    g = guard(timeout=0.5)
    feed(g, [HOME])
    g.check_silence(0.55)
    with pytest.raises(SourceLost, match=r"no frame for 0\.5"):
        g.check_silence(0.61)


def test_the_first_target_must_start_where_the_arm_stands():
    g = guard(start_tolerance=0.15)
    v = g.check(Target(0.0, HOME + [0.3, 0, 0, 0, 0, 0], 0.0))
    assert v.kind == "step" and "start the source where the arm stands" in v.reason


@pytest.mark.parametrize("field, value", [("timeout", math.nan), ("timeout", -1.0), ("velocity_scale", 0.0),
                                          ("velocity_scale", 1.5), ("max_refusals", 0), ("resolution", math.inf),
                                          ("max_refusals", 2.5)])
def test_limits_check_their_own_bounds(field, value):
    with pytest.raises(InputError, match=field):
        GuardLimits(**{field: value})


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3), st.floats(-0.6, 0.6), st.floats(-1.0, 1.0),
                          st.floats(-1.0, 1.0), st.floats(0.0, 1.5)), min_size=1, max_size=4),
       st.floats(0.02, 0.2))
def test_every_accepted_target_is_valid_reachable_in_budget_and_on_a_clear_segment(goals, dt):
    """Property: whatever the source sends, what the guard accepts is (checked independently, with the checker's
    batch call and the robot's limits) within limits, clear at every 5 mm state of its segment, within the budget."""
    g = Guard(ROBOT, CHECKER, GuardLimits(max_refusals=1000), start=HOME)
    prev, prev_t, t = HOME.copy(), 0.0, 0.0
    qs = [np.asarray(q) for goal in goals for q in ramp(HOME, np.asarray(goal) + [0, 0, 1.5708, 0, 0, 0], 6)]
    for q in qs:
        t += dt
        if g.check(Target(t, q, t)).accepted:
            assert ROBOT.within_limits(q)
            seg = interpolate(prev, q, 0.005)
            assert CHECKER.validity_batch(seg[:, :5], gripper=seg[:, 5]).all()
            step = np.abs(q - prev)
            if g.accepted == 1:  # the first: within the start tolerance of the arm
                assert np.all(step <= 0.15 + 1e-12)
            else:
                assert np.all(step <= ROBOT.velocity_limits * (t - prev_t) + 0.02 + 1e-12)
            prev, prev_t = q, t
