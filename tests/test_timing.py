"""TOPP-RA timing: limits hold on the samples, rest-to-rest, and the duration is the time-optimal one."""

import numpy as np
import pytest

from roarmctl.motion.timing import SAFETY, dedupe, time_parameterise
from roarmctl.robot.loader import load_robot


def test_single_joint_move_matches_trapezoid_time():
    """A straight move of one joint: the optimum is the trapezoid T = d/v + v/a (hand-derived)."""
    d, v, a = 1.2, 0.8, 2.0
    wp = np.array([[0.0, 0.3], [d, 0.3]])
    tp = time_parameterise(wp, np.array([v, 5.0]), np.array([a, 5.0]))
    expected = d / (v * SAFETY) + (v * SAFETY) / (a * SAFETY)
    assert tp.duration == pytest.approx(expected, rel=0.02)
    assert np.max(np.abs(tp.qd[:, 0])) <= v + 1e-9
    assert np.max(np.abs(tp.qdd[:, 0])) <= a + 1e-9
    assert np.allclose(tp.q[[0, -1]], wp)
    assert np.allclose(tp.qd[[0, -1]], 0.0)
    assert np.allclose(tp.q[:, 1], 0.3)  # the other joint does not move


def test_short_move_is_triangular():
    """Too short to reach full speed: T = 2 sqrt(d/a) (hand-derived)."""
    d, a = 0.1, 2.0
    tp = time_parameterise(np.array([[0.0], [d]]), np.array([5.0]), np.array([a]))
    assert tp.duration == pytest.approx(2 * np.sqrt(d / (a * SAFETY)), rel=0.02)


def test_samples_respect_limits_on_a_curved_path():
    rng = np.random.default_rng(3)
    wp = np.cumsum(rng.uniform(-0.3, 0.3, size=(8, 5)), axis=0)
    vmax, amax = np.array([1.0, 0.7, 0.9, 1.1, 1.3]), np.array([2.0, 1.5, 2.5, 3.0, 3.0])
    tp = time_parameterise(wp, vmax, amax, sample_dt=0.005)
    assert np.all(np.abs(tp.qd) <= vmax + 1e-9)
    assert np.all(np.abs(tp.qdd) <= amax + 1e-9)
    assert np.all(np.diff(tp.times) > 0)
    # velocities are the derivative of positions (finite differences, independent of toppra's own)
    fd = np.gradient(tp.q, tp.times, axis=0)
    assert np.max(np.abs(fd[2:-2] - tp.qd[2:-2])) < 0.05


def test_tcp_speed_limit_is_a_constraint_inside_toppra():
    robot = load_robot("roarm_m3_pro")
    arm = robot.arm_indices
    wp = np.array([[0.0, 0.0, 1.57, 0.0, 0.0], [1.2, 0.5, 1.0, 0.8, 0.0]])

    def tcp_v(q, dq):
        jv = robot.kin.jacobian(robot.full_q(q))[:, :3, :]
        return np.einsum("nij,nj->ni", jv, dq)

    free = time_parameterise(wp, robot.velocity_limits[arm], robot.acceleration_limits[arm])
    capped = time_parameterise(wp, robot.velocity_limits[arm], robot.acceleration_limits[arm],
                               tcp_velocity_per_ds=tcp_v, max_tcp_speed=0.1)
    def speed(tp):
        p = robot.kin.fk(robot.full_q(tp.q))[:, :3, 3]  # finite differences of FK: independent of the Jacobian
        return np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(tp.times)
    assert speed(free).max() > 0.2  # the limit matters for this move
    assert speed(capped).max() <= 0.1 + 1e-3
    assert capped.duration > free.duration


def test_duplicates_are_dropped_and_a_point_path_is_at_rest():
    wp = np.array([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    assert len(dedupe(wp)) == 2
    tp = time_parameterise(np.array([[0.5, 0.5], [0.5, 0.5]]), np.ones(2), np.ones(2))
    assert tp.duration == 0.0 and np.allclose(tp.q, 0.5)
