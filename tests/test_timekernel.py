"""The timing path's C loops (roarmctl/motion/_timekernel.c) give numpy's answers, bit for bit.

Each kernel function is compared with the numpy computation it replaces, written out here: the jerk
check on real TOPP-RA profiles (real toppra, scipy spline) at many filter widths, including limits set
exactly at the sampled jerk and one ulp under it, and the plateau bisection on random profiles.
"""

import numpy as np
import pytest

from roarmctl.motion import _timekernel, timing
from roarmctl.motion.timing import FINE_DT, _Profile, _jerk_ok, _plateau_cap, import_toppra, toppra_grid


def _numpy_jerk(path, prof: _Profile, w: float) -> np.ndarray:
    """max over the fine grid of |qdd_{k+1} - qdd_k| / FINE_DT per joint, in numpy (the filtered profile
    and the spline's derivatives evaluated by _Profile.filtered and scipy)."""
    t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
    s, sd, sdd = prof.filtered(t, w)
    qdd = path(s, 1) * sdd[:, None] + path(s, 2) * (sd**2)[:, None]
    return np.max(np.abs(np.diff(qdd, axis=0)) / FINE_DT, axis=0)


def _kernel(path, prof: _Profile, w: float, lim: np.ndarray) -> bool:
    t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
    x = np.concatenate([t, t - w])
    idx, tau = np.empty(len(x), dtype=np.int64), np.empty(len(x))
    _timekernel.locate(prof.t, prof.T, x, idx, tau)
    bx, c1, c2 = timing._spline_tables(path)
    return _timekernel.jerk_ok(prof.t, prof.s, prof.sd, prof.sdd, prof.S, prof.T, prof.s_end, x, idx, tau, tau**3,
                               float(w), FINE_DT, bx, c1, c2, lim)


def _profiles():
    """(path, profile) of TOPP-RA on random curved paths of 1-6 joints (2-9 waypoints)."""
    ta = import_toppra()
    rng = np.random.default_rng(7)
    for k in range(6):
        n, m = 1 + k % 6, 2 + (3 * k) % 8
        wp = np.cumsum(rng.uniform(-0.4, 0.4, size=(m, n)), axis=0)
        ss = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(wp, axis=0), axis=1))])
        path = ta.SplineInterpolator(ss, wp, bc_type="not-a-knot")
        grid = toppra_grid(ss)
        cons = [ta.constraint.JointVelocityConstraint(rng.uniform(0.5, 1.5, n)),
                ta.constraint.JointAccelerationConstraint(rng.uniform(1.0, 4.0, n))]
        inst = ta.algorithm.TOPPRA(cons, path, gridpoints=grid, parametrizer="ParametrizeConstAccel")
        inst.compute_parameterization(0.0, 0.0)
        yield path, _Profile(np.asarray(inst.problem_data.gridpoints, dtype=float), np.asarray(inst.problem_data.sd_vec, dtype=float))


def test_locate_is_profile_eval_interval_and_offset():
    """locate gives _Profile.eval's interval (searchsorted right, clipped) and time into it, also before 0 and after T."""
    for _, prof in _profiles():
        x = np.concatenate([np.linspace(-0.3, prof.T + 0.3, 997), prof.t, [0.0, prof.T]])
        idx, tau = np.empty(len(x), dtype=np.int64), np.empty(len(x))
        _timekernel.locate(prof.t, prof.T, x, idx, tau)
        ref = np.clip(np.searchsorted(prof.t, x, side="right") - 1, 0, len(prof.sdd) - 1)
        assert np.array_equal(idx, ref)
        assert np.array_equal(tau, np.clip(x, 0.0, prof.T) - prof.t[ref])


def test_jerk_check_matches_numpy_exactly_at_every_width():
    """At each width the kernel passes a limit set exactly at numpy's sampled jerk and fails one a single ulp
    under it (for each joint in turn): its qdd are numpy's bit for bit. And _jerk_ok agrees with numpy's answer."""
    answers = set()
    for path, prof in _profiles():
        w0 = 2 * FINE_DT
        for w in w0 * 1.25 ** np.arange(0, 14, 1.5):
            jerk = _numpy_jerk(path, prof, w)
            assert _kernel(path, prof, w, jerk.copy())
            for j in range(len(jerk)):
                under = jerk.copy()
                under[j] = np.nextafter(jerk[j], 0.0)
                assert not _kernel(path, prof, w, under)
            jmax = np.median(jerk) * np.ones(len(jerk))
            expect = bool(np.all(jerk <= jmax * (1 + 1e-9)))
            fresh = _Profile.__new__(_Profile)
            fresh.__dict__.update(prof.__dict__, jerk_answers={})
            assert _jerk_ok(path, fresh, float(w), jmax) == expect
            answers.add(expect)
    assert answers == {True, False}  # both outcomes were exercised


def test_plateau_bisection_matches_numpy():
    """_plateau_cap (kernel) equals the numpy bisection with np.sum on random profiles of 2-1000 grid points."""
    rng = np.random.default_rng(11)

    def numpy_cap(prof, hold):
        s, sd = prof.s, prof.sd
        x0, x1, ds = sd[:-1] ** 2, sd[1:] ** 2, np.diff(s)
        x_lo, x_hi = np.minimum(x0, x1), np.maximum(x0, x1)
        span = np.maximum(x_hi - x_lo, 1e-300)
        lo, hi = 0.0, float(np.max(sd))
        if hi <= 0.0:
            return None
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            c2 = mid * mid
            frac = np.where(x_lo >= c2, 1.0, np.where(x_hi <= c2, 0.0, (x_hi - c2) / span))
            lo, hi = (mid, hi) if float(np.sum(frac * ds)) / mid >= hold else (lo, mid)
        return lo if lo > 0.0 else None

    found = 0
    for _ in range(200):
        g = int(rng.integers(2, 1000))
        grid = np.concatenate([[0.0], np.cumsum(rng.uniform(1e-4, 0.05, g - 1))])
        sd = np.abs(rng.normal(0.0, 1.0, g))
        sd[0] = sd[-1] = 0.0
        prof = _Profile(grid, sd)
        hold = float(rng.uniform(0.01, 0.5))
        got = _plateau_cap(prof, hold)
        assert got == numpy_cap(prof, hold)
        found += got is not None
    assert found > 50


def test_kernel_rejects_mismatched_arrays():
    with pytest.raises(ValueError):
        _timekernel.locate(np.zeros(1), 1.0, np.zeros(3), np.zeros(3, dtype=np.int64), np.zeros(3))
    with pytest.raises(ValueError):
        _timekernel.plateau_cap(np.zeros(3), np.zeros(3), np.ones(3), np.zeros(2), 0.1, 1.0, np.zeros(3))
