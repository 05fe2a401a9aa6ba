"""Properties of the one timing path (``time_parameterise``) on seeded random paths, each checked on the returned
samples by a method that does not go through the timing code:

* the samples start at 0 s, are at most ``sample_dt`` apart, begin and end exactly at the end waypoints at rest;
* joint velocities and accelerations keep their limits; the jerk by finite differences of the accelerations at the
  output rate keeps its limit; with a TCP speed limit, the TCP speed (Jacobian, and finite differences of FK) keeps
  it; with torque limits, RNEA of the samples (with the held payload) keeps them;
* the velocities are the derivative of the positions (trapezoid rule between samples), the positions lie on the
  waypoints' cubic spline (scipy's, not-a-knot) at the reported path parameter ``s``, which runs from 0 to the
  waypoints' chord length;
* ``jerk_filter`` is the moving-average width: 0 without jerk limits; with them, the path parameter only speeds up
  during the first ``jerk_filter`` seconds and only slows down during the last (the FIR filter of a rest-to-rest
  profile).

Cases cover the edge cases of the timing path, including results over a limit that are slowed down in time (the
test asserts that this happens): multi-joint random walks, very short moves, a tiny segment between long ones,
one-joint lines (timed again either way: the cached profile), RoArm-M3 motions bound by a TCP speed limit and by
torque limits with a payload at the TCP. Two former defects have a test of their own: the last output interval
shorter than the jerk check's step, and a tiny segment whose bend no jerk filter width tames.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import roarmctl.motion.jerk_filter as jerk_filter
import roarmctl.motion.timing as timing
from roarmctl.errors import InfeasibleError, PlanningError
from roarmctl.motion.timing import TorqueModel, dedupe, time_parameterise
from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.loader import load_robot
from roarmctl.robot.model import Inertial


def _promises(tp, wp, vmax, amax, jmax, dt, tcp=None, torque=None) -> dict[str, float]:
    """Assert every promise of ``tp`` (timing of waypoints ``wp`` (K, n) under the given limits, sampled every ``dt``);
    ``tcp`` = (speed (q, qd) -> (N,) m/s by the Jacobian, FK positions q -> (N, 3) m, limit m/s), ``torque`` = (RNEA
    q, qd, qdd -> (N, n) N m, limits (n,)). Returns the largest sampled share of each limit."""
    wp = dedupe(np.asarray(wp, dtype=float))
    t, q, qd, qdd, s = tp.times, tp.q, tp.qd, tp.qdd, tp.s
    h = np.diff(t)
    assert t[0] == 0.0 and np.all(h > 0) and np.all(h <= dt * (1 + 1e-9))
    assert np.array_equal(q[0], wp[0]) and np.array_equal(q[-1], wp[-1])
    assert not np.any(qd[[0, -1]]) and not np.any(qdd[[0, -1]])
    shares = {"v": float(np.max(np.abs(qd) / vmax)), "a": float(np.max(np.abs(qdd) / amax))}
    assert shares["v"] <= 1.0 and shares["a"] <= 1.0
    # qd is the derivative of q: the trapezoid rule's error between samples is at most max|qdd| h^2 / 4 (with a
    # 1.5x allowance for accelerations between samples, which are not promised)
    assert np.all(np.abs(np.diff(q, axis=0) - h[:, None] * (qd[1:] + qd[:-1]) / 2) <= 1.5 * amax * h[:, None] ** 2 / 4 + 1e-12)
    if jmax is None:
        assert tp.jerk_filter == 0.0
    else:
        jerk = np.abs(np.diff(qdd, axis=0)) / h[:, None]
        shares["j"] = float(np.max(jerk / jmax))
        assert shares["j"] <= 1 + 1e-9
        assert 0.0 < tp.jerk_filter < t[-1]
    # the path parameter and the geometry: the same waypoints through scipy's not-a-knot spline at s
    ss = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1))])
    assert s[0] == 0.0 and s[-1] == pytest.approx(ss[-1], rel=1e-12, abs=1e-15) and np.all(np.diff(s) >= 0)
    on_path = CubicSpline(ss, wp, bc_type="not-a-knot")(s) if len(wp) > 2 else wp[0] + np.outer(s / ss[-1], wp[-1] - wp[0])
    assert np.max(np.abs(on_path - q)) < 1e-8
    if tp.jerk_filter > 0 and len(t) > 2:  # FIR filter of width w: speeds up only in [0, w], slows down only in [T - w, T]
        d2 = np.diff(np.diff(s) / h)
        tol = 1e-9 * max(1.0, float(np.max(np.diff(s) / h)))
        assert np.all(d2[t[2:] <= tp.jerk_filter] >= -tol) and np.all(d2[t[:-2] >= t[-1] - tp.jerk_filter] <= tol)
    if tcp is not None:
        speed, fk, limit = tcp
        shares["tcp"] = float(np.max(speed(q, qd)) / limit)
        assert shares["tcp"] <= 1.0
        # chord speeds of FK: between samples the speed may pass the sampled one by a little (0.2 % seen at 20 ms)
        assert np.max(np.linalg.norm(np.diff(fk(q), axis=0), axis=1) / h) <= limit * (1 + 5e-3)
    if torque is not None:
        rnea, limits = torque
        shares["tau"] = float(np.max(np.abs(rnea(q, qd, qdd)) / limits))
        assert shares["tau"] <= 1.0
    return shares


@pytest.fixture
def slowdowns(monkeypatch) -> list[float]:
    """The factors of every slowing down in time (``jerk_filter._slowed``) during the test."""
    factors: list[float] = []
    real = jerk_filter._slowed

    def counted(path, prof, w, factor, jm, **kwargs):
        factors.append(factor)
        return real(path, prof, w, factor, jm, **kwargs)

    monkeypatch.setattr(jerk_filter, "_slowed", counted)
    return factors


def _walk(rng, k: int, n: int, step: float) -> np.ndarray:
    return np.cumsum(np.vstack([rng.uniform(-0.5, 0.5, n), rng.uniform(-step, step, (k - 1, n))]), axis=0)


@pytest.mark.slow
def test_random_joint_paths_keep_every_promise(slowdowns):
    """Random walks in 2-6 joints (with and without jerk limits, sample steps of 10, 5 and 13.7 ms), very short ones
    (0.1-10 mrad) and paths with a segment of 1 urad-10 mrad between long ones."""
    rng = np.random.default_rng(20261202)
    shares = []
    for case in range(24):
        n, k = int(rng.integers(2, 7)), int(rng.integers(2, 9))
        wp = _walk(rng, k, n, 0.6)
        vmax, amax = rng.uniform(0.3, 3.0, n), rng.uniform(0.5, 12.0, n)
        jmax = amax * 10 ** rng.uniform(0.5, 2.0, n) if case % 3 else None
        if 8 <= case < 14:  # very short moves
            wp = wp[0] + (wp - wp[0]) * 10 ** rng.uniform(-4, -2)
        if case >= 18:  # a tiny segment between long ones
            i = int(rng.integers(0, k))
            wp = np.insert(wp, i + 1, wp[i] + rng.uniform(-1, 1, n) * 10 ** rng.uniform(-6, -2), axis=0)
        dt = (0.01, 0.005, 0.0137)[case % 3]
        shares.append(_promises(time_parameterise(wp, vmax, amax, jmax, sample_dt=dt), wp, vmax, amax, jmax, dt))
    assert len(slowdowns) >= 3  # results over a limit were slowed down in time, and kept every promise
    assert max(max(s["v"], s["a"]) for s in shares) > 0.99  # the limits are used, not a much gentler profile
    assert max(s.get("j", 0.0) for s in shares) > 0.95


def test_one_joint_lines_timed_again_either_way_keep_every_promise():
    """One joint along a line, 0.1 mrad to 3 rad, with and without jerk limits: timed, timed again (the cached
    profile) and the other way."""
    timing._ONE_JOINT_LINES.clear()
    for d in (1e-4, 3e-3, 0.05, 0.4, 1.3, 3.0):
        for jmax in (np.array([60.0]), None):
            v, a = np.array([1.5]), np.array([3.6])
            for wp in (np.array([[0.2], [0.2 + d]]), np.array([[0.2], [0.2 + d]]), np.array([[0.2 + d], [0.2]])):
                _promises(time_parameterise(wp, v, a, jmax), wp, v, a, jmax, 0.01)
    assert len(timing._ONE_JOINT_LINES) == 12


@pytest.fixture(scope="module")
def roarm():
    return load_robot("roarm_m3_pro")


def _arm(robot, grip: float):
    """Full joint vectors (N, dof) for arm joints (N, 5), the gripper held at ``grip`` rad."""
    arm = list(robot.arm_indices)

    def full(qa: np.ndarray) -> np.ndarray:
        f = np.zeros((len(qa), robot.dof))
        f[:, -1] = grip
        f[:, arm] = qa
        return f

    return arm, full


def _roarm_path(rng, robot, arm) -> np.ndarray:
    lo, hi = np.maximum(robot.lower[arm], -2.5), np.minimum(robot.upper[arm], 2.5)
    k = int(rng.integers(2, 6))
    wp = np.clip(rng.uniform(lo + 0.2, hi - 0.2) + np.cumsum(np.vstack([np.zeros(5), rng.uniform(-0.5, 0.5, (k - 1, 5))]), axis=0), lo, hi)
    if k >= 3 and rng.random() < 0.5:  # a short segment in the middle
        wp = np.insert(wp, 2, wp[1] + rng.uniform(-1, 1, 5) * 10 ** rng.uniform(-3, -2), axis=0)
    return wp


def test_roarm_motions_under_a_tcp_speed_limit_keep_every_promise(roarm, slowdowns):
    """RoArm-M3 arm motions under its joint limits (scaled down at random), jerk limits in most, and a TCP speed
    limit of 3-30 cm/s that binds; the TCP speed checked by the Jacobian and by finite differences of FK."""
    rng = np.random.default_rng(7)
    arm, full = _arm(roarm, 0.5)
    shares = []
    for case in range(8):
        wp = _roarm_path(rng, roarm, arm)
        vmax, amax = roarm.velocity_limits[arm] * rng.uniform(0.3, 1.0), roarm.acceleration_limits[arm] * rng.uniform(0.3, 1.0)
        jmax = roarm.jerk_limits[arm] * rng.uniform(0.2, 1.0) if case % 4 else None
        limit = float(rng.uniform(0.03, 0.3))
        tp = time_parameterise(wp, vmax, amax, jmax, tcp_velocity_per_ds=lambda qa, dqa: roarm.kin.tcp_velocity(full(qa), dqa),
                               max_tcp_speed=limit)
        tcp = (lambda q, qd: np.linalg.norm(roarm.kin.tcp_velocity(full(q), qd), axis=1),
               lambda q: roarm.kin.fk(full(q))[:, :3, 3], limit)
        shares.append(_promises(tp, wp, vmax, amax, jmax, 0.01, tcp=tcp))
    assert sum(s["tcp"] > 0.97 for s in shares) >= 4  # the TCP speed limit binds
    assert slowdowns  # and some results over it were slowed down in time


def test_roarm_motions_under_torque_limits_with_a_payload_keep_every_promise(roarm):
    """RoArm-M3 arm motions with 0.1-0.5 kg at the TCP under its effort limits (scaled to 0.5-1): RNEA of the
    samples keeps every limit, or the arm cannot hold the load at all (then gravity alone, checked by RNEA at
    rest along the motion's straight joint line, must need more than a limit somewhere)."""
    rng = np.random.default_rng(11)
    arm, full = _arm(roarm, 0.2)
    shares, held = [], 0
    for case in range(10):
        wp = _roarm_path(rng, roarm, arm)
        vmax, amax = roarm.velocity_limits[arm], roarm.acceleration_limits[arm] * rng.uniform(0.6, 1.0)
        jmax = roarm.jerk_limits[arm] if case % 3 else None
        payload = {roarm.tcp_link: Inertial(float(rng.uniform(0.1, 0.5)), np.array([0.0, 0.0, 0.02]), np.eye(3) * 1e-4)}
        limits = roarm.effort_limits[arm] * rng.uniform(0.5, 1.0)

        def rnea(q, qd, qdd, payload=payload):
            fd, fdd = np.zeros((len(q), roarm.dof)), np.zeros((len(q), roarm.dof))
            fd[:, arm], fdd[:, arm] = qd, qdd
            return inverse_dynamics(roarm, full(q), fd, fdd, payload=payload)[:, arm]

        try:
            tp = time_parameterise(wp, vmax, amax, jmax, torque=TorqueModel(rnea, limits, [roarm.joint_names[i] for i in arm], "load"))
        except PlanningError:  # a subclass of InfeasibleError: no timing found is a failure here
            raise
        except InfeasibleError:
            at_rest = np.asarray(wp, dtype=float)
            assert np.max(np.abs(rnea(at_rest, np.zeros_like(at_rest), np.zeros_like(at_rest))) / limits) > 0.9
            continue
        held += 1
        shares.append(_promises(tp, wp, vmax, amax, jmax, 0.01, torque=(rnea, limits)))
    assert held >= 5 and max(s["tau"] for s in shares) > 0.97  # motions were timed, and torque bound some


def test_jerk_holds_on_a_last_sample_interval_shorter_than_the_check_step():
    """A 0.13 mrad back-and-forth of one joint ends 1.89 ms after its last 10 ms sample. The jerk is checked on a 2 ms
    grid that runs past the end, so its last step spreads the final change of acceleration (0.19 rad/s^2) over 2 ms
    (96 rad/s^3, inside the 98.5 limit) although it happens within 1.89 ms: it was 101 rad/s^3 on the samples. The
    output samples' own jerk is checked too, and a result over it slowed down in time."""
    wp = np.array([[0.4375587], [0.4375072], [0.4374695], [0.4375395]])
    vmax, amax, jmax = np.array([0.97]), np.array([5.11]), np.array([98.5])
    _promises(time_parameterise(wp, vmax, amax, jmax), wp, vmax, amax, jmax, 0.01)


def test_a_tiny_segment_between_long_ones_is_timed_when_a_slower_timing_keeps_every_limit():
    """A 3-joint path with a 1.4 mrad segment between 0.2-0.6 rad ones. Timed under half the velocity and a quarter of
    the acceleration limits (the same jerk limits) its samples keep the full limits, so a valid timing exists; under
    the full limits the jerk filter finds no width at any margin (the bend itself makes the jerk): the call raised
    PlanningError (exit 3: re-plan); now the profile is slowed down in time just enough for its jerk."""
    wp = np.array([[0.407, -0.222, -0.41], [0.363, -0.575, 0.047], [0.218, -1.139, -0.15], [0.219, -1.138, -0.15],
                   [0.194, -1.388, 0.219], [0.045, -0.968, 0.206]])
    vmax, amax, jmax = np.array([0.87, 0.7, 2.46]), np.array([7.25, 11.96, 4.13]), np.array([128.6, 224.9, 17.1])
    slower = time_parameterise(wp, vmax / 2, amax / 4, jmax)
    _promises(slower, wp, vmax, amax, jmax, 0.01)  # a valid timing under the full limits
    _promises(time_parameterise(wp, vmax, amax, jmax), wp, vmax, amax, jmax, 0.01)


@pytest.mark.xfail(strict=True, reason="issue 39, open: the margin loop returns the first margin slowed by at most "
                   "timing.SLOWDOWN_KEEP, and which margin that is jumps with the limit (docs/benchmarks.md, 'A looser TCP "
                   "speed limit, a longer motion')")
def test_a_looser_tcp_speed_limit_never_gives_a_longer_motion(roarm):
    """RoArm-M3 arm motions drawn as in the TCP speed test above, each timed at a TCP limit L0 of 5-30 cm/s and at L0 x
    1.01 ... 1.10: every motion the tighter limit allows the looser one allows too, so a looser limit must not give a
    longer motion, to 1 % (the filter width search stops within about 3 % of a 1.25x step of the narrowest width that
    passes, and a slowing down in time overshoots by SLOWDOWN_SLACK: at most a few tenths of a percent of a motion;
    the defect shows as 2-22 %). Also tests/test_timing.py's slowed-a-lot waypoints at 12.4 and 12.5 cm/s (8.94 s and
    9.82 s when this was written)."""
    rng = np.random.default_rng(11)
    arm, full = _arm(roarm, 0.5)
    worse = []
    for case in range(23):
        wp = _roarm_path(rng, roarm, arm)
        vmax, amax = roarm.velocity_limits[arm] * rng.uniform(0.3, 1.0), roarm.acceleration_limits[arm] * rng.uniform(0.3, 1.0)
        jmax = roarm.jerk_limits[arm] * rng.uniform(0.2, 1.0)
        limit = float(rng.uniform(0.05, 0.3))
        durations = [time_parameterise(wp, vmax, amax, jmax, tcp_velocity_per_ds=lambda qa, dqa: roarm.kin.tcp_velocity(full(qa), dqa),
                                       max_tcp_speed=limit * (1 + 0.01 * k)).duration for k in range(11)]
        excess = np.asarray(durations) / np.minimum.accumulate(durations) - 1
        if excess.max() > 0.01:
            worse.append(f"case {case}: +{excess.max():.1%} at {limit * (1 + 0.01 * int(np.argmax(excess))):.4f} m/s")
    full0 = _arm(roarm, 0.0)[1]
    wp = np.array([[0.8171, -0.2311, 0.5175, -0.3131, 0.6578], [1.1758, -0.0234, 0.6107, -0.4982, 0.9665],
                   [0.9675, 0.4141, 0.4426, -0.3698, 0.5196], [1.1448, 0.8314, 0.6448, -0.4192, 0.6398],
                   [1.0165, 1.1818, 0.2470, -0.8313, 0.4386]])
    vmax, amax = np.array([1.792, 1.344, 1.613, 1.971, 2.240]), np.array([4.835, 3.868, 4.835, 5.802, 5.802])
    jmax = np.array([11.40, 9.12, 11.40, 13.69, 13.69])
    tight, loose = (time_parameterise(wp, vmax, amax, jmax, tcp_velocity_per_ds=lambda qa, dqa: roarm.kin.tcp_velocity(full0(qa), dqa),
                                      max_tcp_speed=limit).duration for limit in (0.124, 0.125))
    if loose > 1.01 * tight:
        worse.append(f"slowed-a-lot waypoints: {tight:.3f} s at 0.124 m/s, {loose:.3f} s at 0.125 m/s")
    assert not worse, "; ".join(worse)
