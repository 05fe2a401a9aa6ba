"""OMPL joint-space planner: paths re-checked independently, determinism, errors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from roarmctl.errors import InputError, PlanningError
from roarmctl.motion.collision import CollisionChecker, interpolate
from roarmctl.motion.ompl_planner import (
    PLANNERS,
    CeilingError,
    plan_joint_path,
    plan_joint_path_with_stats,
    simplify_path,
    step_lengths,
)
from roarmctl.motion.scene import SceneItem, example_scene
from roarmctl.robot.loader import load_robot

# TCP low beside the wall of the example scene, on either side of it.
LEFT = np.array([-0.45, 0.9, 0.87, 1.5, 0.0])
RIGHT = np.array([0.45, 0.9, 0.87, 1.5, 0.0])
HOME = np.array([0.0, 0.0, 1.5708, 0.0, 0.0])


@pytest.fixture(scope="module")
def robot():
    return load_robot("roarm_m3_pro")


def fresh_checker(robot):
    return CollisionChecker(robot, example_scene())


def assert_path_valid(robot, path, q_start, q_goal, resolution):
    """Every state of the path at ``resolution / 4``, checked by a checker the planner never saw."""
    np.testing.assert_array_equal(path[0], q_start)
    np.testing.assert_array_equal(path[-1], q_goal)
    checker = fresh_checker(robot)
    dense = np.vstack([interpolate(a, b, resolution / 4) for a, b in itertools.pairwise(path)])
    valid = checker.validity_batch(dense)
    assert valid.all(), checker.explain(dense[np.argmin(valid)])


def test_wall_blocks_the_straight_line(robot):
    checker = fresh_checker(robot)
    assert checker.is_valid(LEFT) and checker.is_valid(RIGHT)
    assert not checker.segment_valid(LEFT, RIGHT, 0.01)
    mid = checker.first_invalid(interpolate(LEFT, RIGHT, 0.01))
    assert "hits obstacle 'wall'" in checker.explain(interpolate(LEFT, RIGHT, 0.01)[mid])


@pytest.mark.parametrize("planner", PLANNERS)
def test_planner_goes_around_the_wall(robot, planner):
    checker = fresh_checker(robot)
    path, stats = plan_joint_path_with_stats(checker, LEFT, RIGHT, planner=planner, seed=7, time_budget=10.0)  # a ceiling: planners stop on a count of checks
    assert not stats.direct
    assert path.shape[1] == 5 and len(path) >= 3
    assert np.max(np.linalg.norm(np.diff(path, axis=0), axis=1)) <= 0.1 + 1e-12  # densified (max_step)
    assert_path_valid(robot, path, LEFT, RIGHT, 0.01)
    assert stats.checks > 0 and stats.solve_time > 0


@pytest.mark.parametrize("planner", [p for p in PLANNERS if p != "PRM"])
def test_same_seed_same_path(robot, planner):
    a = plan_joint_path(fresh_checker(robot), LEFT, RIGHT, planner=planner, seed=11, time_budget=5.0)
    b = plan_joint_path(fresh_checker(robot), LEFT, RIGHT, planner=planner, seed=11, time_budget=5.0)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a, b)


def test_different_seeds_explore_differently(robot):
    paths = [plan_joint_path_with_stats(fresh_checker(robot), LEFT, RIGHT, seed=s)[1].raw_waypoints for s in (1, 2, 3, 4)]
    stats = [plan_joint_path_with_stats(fresh_checker(robot), LEFT, RIGHT, seed=s)[1].checks for s in (1, 2, 3, 4)]
    assert len(set(stats)) > 1 or len(set(paths)) > 1


def test_straight_line_fast_path(robot):
    checker = fresh_checker(robot)
    goal = HOME + np.array([0.3, 0.1, -0.2, 0.2, 0.5])
    path, stats = plan_joint_path_with_stats(checker, HOME, goal, resolution=0.01)
    assert stats.direct and stats.solve_time == 0.0
    np.testing.assert_allclose(path, interpolate(HOME, goal, 0.1))
    assert_path_valid(robot, path, HOME, goal, 0.01)
    raw = plan_joint_path(checker, HOME, goal, max_step=None)
    np.testing.assert_array_equal(raw, np.vstack([HOME, goal]))


def test_unknown_planner_lists_the_valid_ones(robot):
    with pytest.raises(InputError) as err:
        plan_joint_path(fresh_checker(robot), HOME, HOME, planner="RRTsharp")
    assert "RRTsharp" in str(err.value) and all(p in str(err.value) for p in PLANNERS)


def test_start_in_collision_names_the_pair(robot):
    scene = example_scene()
    scene.items.append(SceneItem.box("crate", (0.05, 0.05, 0.05), fresh_checker(robot).tcp_pose(HOME)[:3, 3]))
    checker = CollisionChecker(robot, scene)
    with pytest.raises(PlanningError) as err:
        plan_joint_path(checker, HOME, LEFT)
    assert "start configuration" in str(err.value) and "hits obstacle 'crate'" in str(err.value)
    assert err.value.exit_code == 3
    with pytest.raises(PlanningError, match=r"goal configuration .* joint limit"):
        plan_joint_path(fresh_checker(robot), LEFT, np.array([0.0, 0.0, 3.1, 0.0, 0.0]))


def test_no_path_within_the_work_budget(robot):
    with pytest.raises(PlanningError) as err:
        plan_joint_path(fresh_checker(robot), LEFT, RIGHT, seed=0, max_checks=100)
    assert "no collision-free path from" in str(err.value) and "within 100 state checks" in str(err.value)
    assert "max_checks" in err.value.hint


def test_wall_clock_ceiling_is_an_error_not_a_different_path(robot):
    """A ceiling hit must never hand back whatever was found by then (that would depend on load)."""
    with pytest.raises(CeilingError) as err:
        plan_joint_path(fresh_checker(robot), LEFT, RIGHT, time_budget=1e-5)
    assert "safety ceiling of 1e-05 s" in str(err.value) and "planner.time_budget" in err.value.hint
    assert err.value.exit_code == 3
    raw = plan_joint_path(fresh_checker(robot), LEFT, RIGHT, simplify_attempts=0, max_step=None)
    with pytest.raises(CeilingError, match="shortcutting"):
        simplify_path(fresh_checker(robot), raw, time_budget=0.0)


def test_attached_object_is_planned_around(robot):
    # Carry a stick from LEFT to RIGHT: the path must keep the stick off the wall too.
    checker = CollisionChecker(robot, example_scene())
    checker.remove_item("cube")  # LEFT would hold the stick in it
    frames = robot.kin.link_frames(robot.full_q(LEFT))
    link5 = frames[robot.kin.link_index["link5"]]
    pose = link5.copy()
    pose[:3, 3] = frames[robot.kin.tcp_index][:3, 3] + link5[:3, 2] * 0.02
    checker.add_item(SceneItem("stick", "object", "box", pose, size=(0.01, 0.01, 0.05)))
    checker.set_grasp_target("stick")
    checker.attach("stick", LEFT)
    path = plan_joint_path(checker, LEFT, RIGHT, seed=3)
    dense = np.vstack([interpolate(a, b, 0.0025) for a, b in itertools.pairwise(path)])
    assert checker.validity_batch(dense).all()


def test_simplify_path_shortens_and_stays_valid(robot):
    from roarmctl.motion.ompl_planner import simplify_path

    checker = fresh_checker(robot)
    raw, _stats = plan_joint_path_with_stats(checker, LEFT, RIGHT, seed=2, simplify_attempts=0, max_step=None)
    short = simplify_path(checker, raw, seed=2, attempts=60)
    length = lambda p: float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1)))  # noqa: E731
    assert length(short) <= length(raw) + 1e-12
    assert_path_valid(robot, short, LEFT, RIGHT, 0.01)
    np.testing.assert_array_equal(simplify_path(checker, raw, seed=2, attempts=60), short)


def test_step_lengths_are_numpys_norms_bit_for_bit():
    # the shortcutting picks its points from these lengths (and their running sums): a last-bit difference from
    # np.linalg.norm would change the paths planned with a seed
    rng = np.random.default_rng(9)
    for k, n in itertools.product((1, 2, 3, 7, 40), (1, 5, 6, 7, 9, 16)):
        path = rng.normal(0.0, rng.uniform(1e-6, 3.0), (k, n))
        expected = np.linalg.norm(np.diff(path, axis=0), axis=1)
        got = step_lengths(path)
        assert got.shape == expected.shape and got.tobytes() == expected.tobytes()
        seg = got.tolist()
        cum = list(itertools.accumulate(seg, initial=0.0))
        assert np.array(cum).tobytes() == np.concatenate([[0.0], np.cumsum(got)]).tobytes()


def test_simplifying_a_pruned_path_skips_the_greedy_pass_with_the_same_result(robot):
    """simplify_path(pruned=True) leaves out the greedy vertex pass on what plan_joint_path_with_stats(
    simplify_attempts=0) returned (that pass's result): the same path as with the pass, with fewer state checks."""
    for seed in range(8):
        checker = fresh_checker(robot)
        raw, _stats = plan_joint_path_with_stats(checker, LEFT, RIGHT, seed=seed, simplify_attempts=0, max_step=None)
        before = checker.check_count
        full = simplify_path(checker, raw, seed=seed)
        full_checks, before = checker.check_count - before, checker.check_count
        np.testing.assert_array_equal(simplify_path(checker, raw, seed=seed, pruned=True), full)
        assert checker.check_count - before < full_checks


def test_the_greedy_pass_keeps_its_own_result():
    """The greedy pass (with the de-duplication that follows it) run on its own result keeps every vertex: what
    pruned=True relies on. Random polylines with repeated vertices, in the example scene with the wall."""
    from roarmctl.motion.ompl_planner import _drop_vertices, _random_shortcuts

    robot = load_robot("roarm_m3_pro")
    checker = fresh_checker(robot)
    rng = np.random.default_rng(4)
    for _ in range(30):
        k = int(rng.integers(3, 12))
        path = LEFT + (RIGHT - LEFT) * np.linspace(0, 1, k)[:, None] + rng.normal(0, 0.25, (k, 5)) * [1, 0.3, 0.3, 0.3, 1]
        path = np.clip(path, checker._lower, checker._upper)
        path[0], path[-1] = LEFT, RIGHT
        path = np.repeat(path, rng.integers(1, 3, k), axis=0)  # some vertices twice
        once = _random_shortcuts(checker, path, 0.01, None, 0, 5.0)
        np.testing.assert_array_equal(_drop_vertices(checker, once, 0.01), once)
