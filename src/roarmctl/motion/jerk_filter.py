"""The jerk limit on TOPP-RA's result: its profile in time, the moving-average (FIR) filter on the path parameter,
the cruise at the top speed and the slowing down in time, each checked on the samples.

TOPP-RA's result is bang-bang in the path acceleration; ``Profile.filtered`` averages the path position over a
window of width ``w`` (s), which bounds the rate of change of the path acceleration without changing the path
(the construction is described in ``roarmctl.motion.timing``). ``jerk_filtered`` finds the narrowest width whose
sampled joint jerk keeps the limits; ``sampled_within_limits`` samples the result and slows it down in time where a
sample is over a limit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from roarmctl import _kernel
from roarmctl.motion.toppra_constraints import sdot_bound_constraint

if TYPE_CHECKING:
    from types import ModuleType

    import toppra

FINE_DT = 0.002  # s: grid on which the jerk is checked (finite differences of the acceleration)
# The compiled jerk check's answer is taken where it is certain: a ratio of jerk to limit more than this above 1
# (fails) or every ratio more than this below 1 (passes); its rounding differs from numpy's by ~1e-12 of a limit.
JERK_CHECK_TOL = 1e-10
# None in a kernel built before it had the jerk check (an editable install not rebuilt since): numpy answers alone
_JERK_CHECK = getattr(_kernel, "jerk_check", None)
# A timed result over a limit by ratio r on its samples is slowed by r * (1 + SLOWDOWN_SLACK) (the square root
# of it for accelerations), at most SLOWDOWN_TRIES times, before TOPP-RA runs again at the next margin.
SLOWDOWN_TRIES, SLOWDOWN_SLACK = 3, 1e-3
FILTER_GROWTH = 1.25  # each try widens the jerk filter by this factor
FILTER_TRIES = 16
# When the filter had to widen past PLATEAU_TRIGGER times its narrowest width a / j, the profile is timed
# again with a cruise at its top speed (``_plateau_profile``) of PLATEAU_SHARES times that width (the next
# one if no filter up to the cruise's length passes), the filter widened by PLATEAU_GROWTH per try.
PLATEAU_TRIGGER, PLATEAU_SHARES, PLATEAU_GROWTH = 1.2, (1.1, 1.3), 1.04
PLATEAU_LEVELS = 3  # the cruise speed's bisection decides this many of its 30 steps per batch (_plateau_cap)


_Samples = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # integral of s, s, sdot, sddot (Profile.eval)


class Profile:
    """TOPP-RA's result in time: piecewise-constant path acceleration between grid points."""

    def __init__(self, grid: np.ndarray, sd: np.ndarray) -> None:
        sd = np.maximum(sd, 0.0)
        self.grid = grid
        ds = np.diff(grid)
        dt = 2.0 * ds / np.maximum(sd[:-1] + sd[1:], 1e-12)
        self.t = np.concatenate([[0.0], np.cumsum(dt)])
        self.s, self.sd = grid - grid[0], sd
        self.sdd = (sd[1:] ** 2 - sd[:-1] ** 2) / (2.0 * ds)
        self.T = float(self.t[-1])
        self.s_end = float(self.s[-1])
        # integral of s over [0, t_i]
        self.S = np.concatenate([[0.0], np.cumsum(self.s[:-1] * dt + sd[:-1] * dt**2 / 2 + self.sdd * dt**3 / 6)])
        # per grid interval: its start time, s, sdot, integral of s and its sddot, rows gathered at once by eval
        self._starts = np.stack([self.t[:-1], self.s[:-1], sd[:-1], self.S[:-1], self.sdd])
        self._last: tuple[np.ndarray, tuple] | None = None  # (t, its _eval_grid values) of the last _eval_grid call
        self.jerk_answers: dict = {}  # _jerk_ok's answers for this profile ("path": the path they are for)
        # Profiles clipped from this one (a cruise cap) are the same motion up to some time: ``family`` (shared with
        # them) keeps, per filter width, the earliest failed jerk check found there (``_jerk_ok``); ``same_until``
        # (s) is how long this profile is the family's first one (inf: it is the first).
        self.family: dict = {}
        self.same_until = float("inf")

    def clipped(self, cap: float) -> Profile:
        """This profile with the path speed capped at ``cap`` (sdot) at every grid point, in this one's family: up to
        the last grid point before the first capped one it is the same motion, bit for bit (the same times, s, sdot and
        integral of s at every grid point up to there; what follows a time depends only on what came before)."""
        out = Profile(self.grid, np.minimum(self.sd, cap))
        capped = np.flatnonzero(out.sd != self.sd)
        if len(capped):
            out.family = self.family
            out.same_until = min(self.same_until, float(self.t[capped[0] - 1]) if capped[0] > 0 else -1.0)
        return out

    def slowed(self, factor: float) -> Profile:
        """The same profile ``factor`` times slower: path speed / factor at every grid point (times * factor, path
        accelerations / factor**2)."""
        return Profile(self.grid, self.sd / factor)

    def _eval_grid(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``eval(t)``'s integral of s, s and sdot, reusing the previous call's values where ``t`` and the previous
        ``t`` agree: the jerk check asks for the same fine grid (growing with the filter width) at every width it
        tries. ``eval`` is elementwise in ``t``, so the result is the same bit for bit."""
        last = self._last
        if last is not None:
            lt, lv = last
            m = min(len(t), len(lt))
            if m and np.array_equal(t[:m], lt[:m]):
                if len(t) <= len(lt):
                    k = len(t)
                    return lv[0][:k], lv[1][:k], lv[2][:k]
                more = self.eval(t[m:], acc=False)
                out = (np.concatenate([lv[0], more[0]]), np.concatenate([lv[1], more[1]]), np.concatenate([lv[2], more[2]]))
                self._last = (t, out)
                return out
        S, s, sdot, _ = self.eval(t, acc=False)
        self._last = (t, (S, s, sdot))
        return S, s, sdot

    def eval(self, t: np.ndarray, acc: bool = True) -> _Samples:
        """Integral of s, s, sdot, sddot at times ``t`` (any shape); at rest before 0 and after the end. ``acc``
        False: sddot is left out (returned as None; the filter does not need it)."""
        t = np.asarray(t, dtype=float)
        i = np.searchsorted(self.t, t, side="right") - 1
        np.minimum(np.maximum(i, 0, out=i), len(self.sdd) - 1, out=i)
        t0, s0, v, S0, a = self._starts.take(i, axis=1)
        tau = np.minimum(np.maximum(t, 0.0), self.T) - t0
        tau2 = tau**2
        s = s0 + v * tau + a * tau2 / 2
        S = S0 + s0 * tau + v * tau2 / 2 + a * tau**3 / 6
        before, after = t < 0, t > self.T
        outside = before | after
        S = np.where(before, 0.0, np.where(after, S + self.s_end * (t - self.T), S))
        sdot = np.where(outside, 0.0, v + a * tau)
        sddot = np.where(outside, 0.0, a) if acc else None
        s = np.where(before, 0.0, s)
        return S, s, sdot, sddot  # type: ignore[return-value]

    def filtered(self, t: np.ndarray, w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s, sdot, sddot of the moving average of width ``w`` (s) at times ``t``; ``w`` = 0: unfiltered."""
        if w <= 0:
            _, s, v, a = self.eval(t)
            return s, v, a
        S1, s1, v1 = self._eval_grid(t)
        S0, s0, v0, _ = self.eval(t - w, acc=False)
        s = np.minimum(np.maximum((S1 - S0) / w, 0.0), self.s_end)  # np.clip's values, without its overhead
        return s, (s1 - s0) / w, (v1 - v0) / w


def sample(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, times: np.ndarray,
            w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """q, qd, qdd (N, n) and s (N,) at ``times``."""
    s, sd, sdd = prof.filtered(times, w)
    ps = path(s, 1)
    return path(s), ps * sd[:, None], ps * sdd[:, None] + path(s, 2) * (sd**2)[:, None], s


def ends_at_rest(samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], wp: np.ndarray,
                  s_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``sample``'s q, qd, qdd, s with the exact end waypoints of ``wp`` (K, n), velocity and acceleration 0 there,
    and the path parameter exactly 0 and ``s_end`` (the filtered s can end an ulp short, after a sample already at
    ``s_end``)."""
    q, qd, qdd, s = samples
    q[0], q[-1] = wp[0], wp[-1]
    qd[0] = qd[-1] = qdd[0] = qdd[-1] = 0.0
    s[0], s[-1] = 0.0, s_end
    return q, qd, qdd, s


def _derivative_table(path: toppra.interpolator.AbstractGeometricPath) -> tuple[np.ndarray, np.ndarray] | None:
    """The breakpoints (K,) and the polynomial coefficients (5, K - 1, n) of toppra's spline's first and second
    derivatives (its ``cspld`` and ``cspldd``: scipy PPoly of 3 and 2 coefficients per interval, extended past the
    ends), for the compiled jerk check; None for any other path (the numpy check alone then)."""
    d, e = getattr(path, "cspld", None), getattr(path, "cspldd", None)
    dc, ec = getattr(d, "c", None), getattr(e, "c", None)
    dx, ex = getattr(d, "x", None), getattr(e, "x", None)
    if not (isinstance(dc, np.ndarray) and isinstance(ec, np.ndarray) and dc.ndim == 3 and dc.shape[0] == 3
            and ec.shape == (2,) + dc.shape[1:] and getattr(d, "extrapolate", None) is True
            and getattr(e, "extrapolate", None) is True and isinstance(dx, np.ndarray) and isinstance(ex, np.ndarray)
            and np.array_equal(dx, ex)):
        return None
    return np.ascontiguousarray(dx, dtype=float), np.ascontiguousarray(np.concatenate([dc, ec]), dtype=float)


def _jerk_sampled(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w: float, jmax: np.ndarray,
                  t: np.ndarray) -> int:
    """The jerk check in numpy on the whole grid ``t`` (``_jerk_ok``): -1 if every pair of samples keeps ``jmax``,
    else the first pair (k, k + 1) that does not."""
    s, sd, sdd = prof.filtered(t, w)
    qdd = path(s, 1) * sdd[:, None] + path(s, 2) * (sd**2)[:, None]  # as in sample, without the positions
    jerk = qdd[1:] - qdd[:-1]  # np.diff's values, then in place
    np.abs(jerk, out=jerk)
    jerk /= FINE_DT
    within = (jerk <= jmax * (1 + 1e-9)).all(axis=1)
    return -1 if within.all() else int(np.argmin(within))


def _jerk_ok(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w: float, jmax: np.ndarray) -> bool:
    """Whether the jerk of ``prof`` filtered at width ``w`` (s), sampled every FINE_DT, keeps ``jmax`` (n,):
    with s, sdot, sddot of ``prof.filtered`` on the grid t = 0, FINE_DT, ... past ``prof.T + w``, the joint
    accelerations qdd = q'(s) sddot + q''(s) sdot^2 (as in ``sample``) change by at most jmax * FINE_DT
    (to 1e-9) from one sample to the next.

    The compiled check (``_kernel.jerk_check``) samples from the start and stops at the first pair certainly over a
    limit (more than JERK_CHECK_TOL of it; most widths the search asks fail near the start); what it cannot tell
    for certain, the numpy check on the whole grid (``_jerk_sampled``) answers, so every answer is the numpy check's.

    Answers are kept on ``prof`` per path (the filter search asks again for w0, which the plateau test asked), and a
    failure also on its family (``Profile.clipped``): a profile clipped from another fails at a width where the other
    failed before either was clipped, without being sampled (the plateau's two cruises try the same widths). A
    failure is kept with the time of a failing pair (the first the numpy check finds, the first certain one the
    compiled check finds): any failing pair before the clip is one the clipped profile has too."""
    memo, family = prof.jerk_answers, prof.family
    if memo.get("path") is not path:
        memo.clear()
        memo["path"] = path
        memo["table"] = _derivative_table(path)
    if family.get("path") is not path:
        family.clear()
        family["path"] = path
    key = (w, jmax.tobytes())
    if key not in memo:
        failed_at = family.get(key)
        if failed_at is not None and failed_at <= prof.same_until:
            memo[key] = False  # a profile of its family failed there, where the two are the same motion
            return False
        t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
        status, pair = -1, -1
        table = memo["table"]
        if table is not None and w > 0.0 and len(prof.t) > 1 and _JERK_CHECK is not None:
            status, pair = _JERK_CHECK(prof.t, prof._starts, prof.T, prof.s_end, table[0], table[1], w, FINE_DT,
                                              len(t), np.ascontiguousarray(jmax, dtype=float), JERK_CHECK_TOL)
        if status < 0:
            pair = _jerk_sampled(path, prof, w, jmax, t)
        memo[key] = pair < 0
        if pair >= 0:
            # the failed pair of samples depends on the motion up to its later sample's time (the filter looks back)
            until = float(t[pair + 1])
            if until <= prof.same_until and (failed_at is None or until < failed_at):
                family[key] = until
    return memo[key]


def _filter_width(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w0: float, jm: np.ndarray,
                  growth: float = FILTER_GROWTH, tries: int = FILTER_TRIES, fails_below: float = 0.0) -> float | None:
    """The narrowest filter width (s, from ``w0`` up by factors of ``growth``, then narrowed to within about
    3 % of a step) for which the sampled jerk of ``prof`` is inside ``jm``; None if none within ``tries``."""
    w, lo = w0, 0.0
    for _ in range(tries):
        if w >= fails_below and _jerk_ok(path, prof, w, jm):
            break
        lo, w = w, w * growth
    else:
        return None
    for _ in range(3 if lo > 0 else 0):  # narrow it down (each step halves the excess width)
        mid = 0.5 * (lo + w)
        lo, w = (lo, mid) if mid >= fails_below and _jerk_ok(path, prof, mid, jm) else (mid, w)
    return w


def _plateau_cap(prof: Profile, hold: float) -> float | None:
    """The path speed cap c (sdot) under which ``prof`` would cruise for ``hold`` s: the time the capped
    profile spends at c is (length of s where sdot > c) / c; None if ``prof`` never moves."""
    s, sd = prof.s, prof.sd
    top = float(np.max(sd))
    if top <= 0.0:
        return None

    # sdot^2 is linear in s between grid points (constant path acceleration): the length where sdot > c
    x0, x1, ds = sd[:-1] ** 2, sd[1:] ** 2, np.diff(s)
    x_lo, x_hi = np.minimum(x0, x1), np.maximum(x0, x1)
    span = np.maximum(x_hi - x_lo, 1e-300)
    # Where no interval's span was floored (sdot^2 the same at both ends, a flat top), the share is
    # min(max((x_hi - c^2) / span, 0), 1), the same numbers as the three cases below in fewer passes: rounding is
    # monotone, so x_lo >= c^2 gives x_hi - c^2 >= span, a share >= 1, and x_hi <= c^2 a share <= 0 (never -0.0: x_hi
    # >= +0 and c^2 > 0). A floored span (x_hi = x_lo = c^2 would give 0, not 1) keeps the cases as they are.
    clip = not bool(np.any(x_hi - x_lo < 1e-300))

    # 30 bisection steps of c in [0, top] on cruise(c) = sum(frac * ds) / c >= hold, frac the share of each grid
    # interval where sdot^2 > c^2: 1 where x_lo >= c^2, 0 where x_hi <= c^2, else (x_hi - c^2) / span. The steps
    # are taken PLATEAU_LEVELS at a time: the mids every outcome of those steps could ask (a tree of
    # 2**PLATEAU_LEVELS - 1, each made as the step by step search makes it) are evaluated in one batch of rows (a
    # row's sum is the same as that of its 1-d array), then the search walks down the tree: the same mids, the
    # same sums, the same cap, with a few numpy calls per PLATEAU_LEVELS steps rather than per step.
    lo, hi = 0.0, top
    for _ in range(30 // PLATEAU_LEVELS):
        bounds, mids = [(lo, hi)], []
        for k in range(2**PLATEAU_LEVELS - 1):  # node k: its interval's mid; children 2k + 1 (cruise >= hold), 2k + 2
            a, b = bounds[k]
            mid = 0.5 * (a + b)
            mids.append(mid)
            bounds += [(mid, b), (a, mid)]
        c = np.array(mids)
        c2 = (c * c)[:, None]
        if clip:
            frac = x_hi - c2
            frac /= span
            np.maximum(frac, 0.0, out=frac)
            np.minimum(frac, 1.0, out=frac)
        else:
            frac = np.where(x_lo >= c2, 1.0, np.where(x_hi <= c2, 0.0, (x_hi - c2) / span))
        frac *= ds
        cruise = (frac.sum(axis=1) / c).tolist()
        k = 0
        for _ in range(PLATEAU_LEVELS):
            k = 2 * k + 1 if cruise[k] >= hold else 2 * k + 2
        lo, hi = bounds[k]
    return lo if lo > 0.0 else None


def _plateau_profile(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
                     gridpoints: np.ndarray, prof: Profile, hold: float,
                     alim: np.ndarray | None = None) -> Profile | None:
    """``prof`` timed again under a path speed cap that gives it a cruise of about ``hold`` s at its top speed.

    Where the time-optimal profile switches from full path acceleration straight to full deceleration (a
    motion too short to reach its speed limits), the filter of width w turns that step of 2a into a jerk
    of 2a / w, so w must double to 2 a / j and the motion lasts a / j longer than the jerk-limited optimum.
    A cruise of w between the two halves lets each step of a pass the filter alone: for one joint this is
    exactly the time-optimal double-S profile (the cruise speed v with v^2 / a + v a / j = d). The cap is a
    TOPP-RA constraint like the others, so every other limit still holds.

    The capped profile is the uncapped one clipped at c wherever cruising there (zero path acceleration)
    is allowed, as TOPP-RA's greedy forward pass would make it; with ``alim`` (n,) (the joint acceleration
    limits TOPP-RA got, None: not known) the clipped profile's joint accelerations are checked at the grid
    points and, if they keep ``alim`` (to TOPP-RA's own tolerance), it is taken without running TOPP-RA again."""
    c = _plateau_cap(prof, hold)
    if c is None:
        return None
    if alim is not None:
        clipped = prof.clipped(c)
        ps, pss = path(gridpoints, 1), path(gridpoints, 2)

        def grid_acc(p: Profile) -> np.ndarray:
            """|joint accelerations| (2 (G - 1), n) of ``p`` at both ends of every grid interval."""
            x = p.sd ** 2
            return np.abs(np.concatenate([ps[:-1] * p.sdd[:, None] + pss[:-1] * x[:-1, None],
                                          ps[1:] * p.sdd[:, None] + pss[1:] * x[1:, None]]))

        # TOPP-RA keeps its constraints to its solver's tolerance (its own result can be over alim by ~1e-8 at a
        # grid point; run again under the cap it returned the clipped profile to ~1e-9 s): the clipped profile must
        # keep alim, or go over it by no more than TOPP-RA's own result did, joint by joint
        if np.all(grid_acc(clipped) <= np.maximum(alim * (1 + 1e-9), np.max(grid_acc(prof), axis=0))):
            return clipped
    instance = algo.TOPPRA(constraints + [sdot_bound_constraint(np.full(len(gridpoints), c * c))], path,
                           gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
    instance.compute_parameterization(0.0, 0.0)
    data = instance.problem_data
    if data.sd_vec is None or data.return_code.name != "Ok":
        return None
    return Profile(np.asarray(data.gridpoints, dtype=float), np.asarray(data.sd_vec, dtype=float))


def _plateau(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
             gridpoints: np.ndarray, prof: Profile, w0: float, jm: np.ndarray,
             alim: np.ndarray | None) -> tuple[Profile, float] | None:
    """``_plateau_profile`` with a cruise of PLATEAU_SHARES times ``w0`` (the next share if no filter up to the
    cruise's length passes) and its filter width; None if none passes.

    Where ``prof`` failed its jerk check at PLATEAU_TRIGGER * ``w0`` (as ``jerk_filtered`` asks first) before a
    cruise's cap begins, the cruise's widths narrower than that are taken as failing without sampling them: up to
    there the two are the same motion, and a narrower filter makes a step of path acceleration a larger jerk (its
    change over the width, divided by the width). Over 1,421 timings (queries a-e, seeds 100-139; six bundled plans,
    seeds 1-15) every result was the same, bit for bit, as with every width sampled."""
    failed_at = prof.family.get((PLATEAU_TRIGGER * w0, jm.tobytes())) if prof.family.get("path") is path else None
    for share in PLATEAU_SHARES:
        capped = _plateau_profile(algo, constraints, path, gridpoints, prof, share * w0, alim)
        if capped is None:
            return None
        # the filter must stay narrower than the cruise: widen it in small steps up to there
        narrower = PLATEAU_TRIGGER * w0 if failed_at is not None and failed_at <= capped.same_until else 0.0
        wc = _filter_width(path, capped, w0, jm, PLATEAU_GROWTH, int(np.log(share) / np.log(PLATEAU_GROWTH)) + 1,
                           narrower)
        if wc is not None:
            return capped, wc
    return None


def _slowed(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w: float, factor: float,
            jm: np.ndarray | None, keep_width: bool = True) -> tuple[Profile, float] | None:
    """``prof`` (filtered at width ``w`` s) run ``factor`` (> 1) times slower on the same path, and its filter width.

    The path speed sdot / factor at every grid point makes the unfiltered motion exactly ``factor`` times longer:
    joint and TCP velocities / factor, path accelerations / factor**2 (the joint accelerations q' sddot + q'' sdot**2
    too). Filtered at ``w * factor`` the whole motion is the old one slowed (jerk / factor**3); with ``keep_width``
    the narrower ``w`` is kept when the sampled jerk stays inside ``jm`` (n,) there, which it usually does (the
    profile's steps of path acceleration shrink by factor**2). None if no width tried passes the jerk check."""
    slow = prof.slowed(factor)
    if jm is None or w <= 0.0:
        return slow, w
    for width in ((w, w * factor) if keep_width else (w * factor,)):
        if _jerk_ok(path, slow, width, jm):
            return slow, width
    return None


def _jerk_slowdown_factor(ratio: float) -> float:
    """The slowdown (>= 1) that brings a jerk ``ratio`` times its limit inside it when the filter widens with the
    motion (jerk / f**3), with SLOWDOWN_SLACK to spare; 1 + SLOWDOWN_SLACK when the ratio is not over 1."""
    return max(ratio, 1.0) ** (1.0 / 3.0) * (1.0 + SLOWDOWN_SLACK)


def _jerk_ratio(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w: float, jm: np.ndarray) -> float:
    """The largest sampled joint jerk of ``prof`` filtered at width ``w`` (s) as a share of ``jm`` (n,): on the grid
    of ``_jerk_ok`` (every FINE_DT from 0 past the end), the largest change of a joint acceleration per FINE_DT over
    jm * FINE_DT."""
    t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
    qdd = sample(path, prof, t, w)[2]
    return float(np.max(np.abs(np.diff(qdd, axis=0)) / (FINE_DT * jm)))


def _jerk_slowdown(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w0: float,
                   jm: np.ndarray) -> tuple[Profile, float] | None:
    """For a profile whose jerk no filter width of ``_filter_width``'s search brings inside ``jm`` (n,): the path's
    own shape (a sharp bend on a tiny segment) makes jerk that filtering does not remove, only a lower speed does.

    Of the widths that search tried (``w0`` up by FILTER_GROWTH), each with the slowdown f = (jerk ratio)**(1/3)
    that brings its jerk inside the limits (the motion f times slower, filter f times wider: jerk / f**3), the one
    that ends soonest. The slowed motion is sampled at other instants, where a sharp bend can show more jerk: its
    own ratio then slows it further, up to SLOWDOWN_TRIES times. Returns (slowed profile, its filter width), None if
    its sampled jerk still fails."""
    tried = [(w, _jerk_slowdown_factor(_jerk_ratio(path, prof, w, jm)))
             for w in (w0 * FILTER_GROWTH**k for k in range(FILTER_TRIES))]
    w, f = min(tried, key=lambda wf: wf[1] * (prof.T + wf[0]))  # the first of equal ends, as a strict < keeps
    for _ in range(SLOWDOWN_TRIES):
        slow = prof.slowed(f)
        if _jerk_ok(path, slow, w * f, jm):
            return slow, w * f
        f *= _jerk_slowdown_factor(_jerk_ratio(path, slow, w * f, jm))
    return None


def jerk_filtered(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
                   gridpoints: np.ndarray, prof: Profile, alim: np.ndarray, jm: np.ndarray,
                   alim_known: bool) -> tuple[Profile, float] | None:
    """TOPP-RA's profile ``prof`` (under ``constraints``, joint accelerations ``alim`` (n,)) made jerk-limited: the
    profile and the narrowest filter width (s) whose sampled jerk keeps ``jm`` (n,), or the profile with a cruise at
    its top speed (``_plateau``) when that ends sooner, or, when no width passes, the profile slowed down in time for
    its jerk (``_jerk_slowdown``); None if that fails too. ``alim_known``: TOPP-RA had no constraint besides ``alim``
    that a clipped cruise could break (no torque constraint), so ``_plateau_profile`` may skip its own TOPP-RA run."""
    w0 = max(float(np.max(alim / jm)), 2 * FINE_DT)
    clip_limits = alim if alim_known else None
    plateau, tried = None, False
    if not _jerk_ok(path, prof, w0, jm) and not _jerk_ok(path, prof, PLATEAU_TRIGGER * w0, jm):
        # the filter would have to widen past the trigger: a cruise at the top first; if it beats even
        # the trigger's width it beats any width that passes (no full search needed)
        plateau = _plateau(algo, constraints, path, gridpoints, prof, w0, jm, clip_limits)
        tried = True  # a None is final: _plateau is deterministic in its arguments, which stay the same
        if plateau is not None and plateau[0].T + plateau[1] < prof.T + PLATEAU_TRIGGER * w0:
            return plateau
    w = _filter_width(path, prof, w0, jm)
    if w is None:
        slowed = _jerk_slowdown(path, prof, w0, jm)
        if slowed is None:
            return None
        prof, w = slowed
    if not tried and w > PLATEAU_TRIGGER * w0:
        plateau = _plateau(algo, constraints, path, gridpoints, prof, w0, jm, clip_limits)
    if plateau is not None and plateau[0].T + plateau[1] < prof.T + w:
        return plateau
    return prof, w


# (profile, filter width s, times (N,), (q, qd, qdd (N, n), s (N,)), within the limits, slowed by)
_Sampled = tuple[Profile, float, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], bool, float]


def sampled_within_limits(path: toppra.interpolator.AbstractGeometricPath, prof: Profile, w: float, wp: np.ndarray,
                           sample_dt: float, vmax: np.ndarray, amax: np.ndarray, jm: np.ndarray | None,
                           tcp: tuple[Callable[[np.ndarray, np.ndarray], np.ndarray], float] | None) -> _Sampled:
    """``prof`` filtered at width ``w`` (s) sampled every ``sample_dt`` s, at rest at the end waypoints of ``wp``
    (K, n), and slowed down in time (``_slowed``, at most SLOWDOWN_TRIES times) until the samples keep the joint
    velocity, acceleration and jerk limits ``vmax``, ``amax``, ``jm`` (n,; jm None: no jerk limit) and, with
    ``tcp`` = (tcp_velocity_per_ds, max_tcp_speed) of ``time_parameterise``, the TCP speed (m/s).

    Returns (prof, w, times (N,), (q, qd, qdd (N, n), s (N,)), ok, slowed_by): the profile and width sampled last,
    its samples, whether they keep those limits, and the product of the slowdown factors applied (1: none)."""
    slowed_by = 1.0
    for slowdown in range(SLOWDOWN_TRIES + 1):
        duration = prof.T + w
        count = max(int(np.ceil(duration / sample_dt - 1e-9)), 1)
        times = np.unique(np.minimum(np.arange(count + 1) * sample_dt, duration))
        q, qd, qdd, s_samples = ends_at_rest(sample(path, prof, times, w), wp, prof.s_end)
        # The constraints hold at grid points; between them (and after filtering) a sample can be
        # slightly over. Check the samples and slow the motion down until they are inside.
        ok = bool(np.all(np.abs(qd) <= vmax) and np.all(np.abs(qdd) <= amax))
        tcp_excess = 0.0
        if tcp is not None:
            tcp_top = float(np.max(np.linalg.norm(tcp[0](q, qd), axis=1)))
            ok = ok and tcp_top <= tcp[1]
            tcp_excess = tcp_top / tcp[1]
        # The jerk was checked every FINE_DT up to past the end: the output's last interval, shorter than that,
        # can still be over (the check spread its change of acceleration over a whole FINE_DT).
        jerk = None if jm is None or len(times) < 2 else np.abs(np.diff(qdd, axis=0)) / np.diff(times)[:, None]
        if jerk is not None and jm is not None:
            ok = ok and bool(np.all(jerk <= jm * (1 + 1e-9)))
        if ok or slowdown == SLOWDOWN_TRIES:
            break
        excess = max(float(np.max(np.abs(qd) / vmax)), float(np.sqrt(np.max(np.abs(qdd) / amax))),
                     tcp_excess)
        jerk_excess = 0.0 if jerk is None or jm is None else float(np.max(jerk / jm)) ** (1.0 / 3.0)
        factor = max(excess, jerk_excess) * (1.0 + SLOWDOWN_SLACK)
        slowed = _slowed(path, prof, w, factor, jm, keep_width=jerk_excess <= 1.0)
        if slowed is None:
            break
        prof, w = slowed
        slowed_by *= factor
    return prof, w, times, (q, qd, qdd, s_samples), ok, slowed_by
