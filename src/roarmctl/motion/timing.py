"""Time-optimal, jerk-limited parameterisation of a joint path: the one timing path of roarmctl.

A geometric path (waypoints in joint space, joined by a clamped cubic spline) becomes a timed
trajectory that starts and ends at rest and respects, at every output sample:

* joint velocity and acceleration limits, optionally a maximum TCP speed and joint torque limits
  (inverse dynamics by the library's RNEA): all as constraints inside TOPP-RA, the torque one only
  once the sampled torque of a result comes within ``TORQUE_LAZY_SHARE`` of a limit (it costs two
  RNEA passes over the grid and rarely binds);
* joint jerk limits: TOPP-RA's result is bang-bang in the path acceleration (jerk unbounded), so
  the path position s(t) is passed through a moving-average (FIR) filter of width ``w``:
  s_w(t) = (1/w) * integral of s over [t - w, t]. Then ds_w/dt = (s(t) - s(t - w)) / w and
  d2s_w/dt2 = (sdot(t) - sdot(t - w)) / w, so the path acceleration becomes continuous with a
  bounded rate, the path itself is unchanged (straight lines and collision-checked curves stay
  as they are), the motion still starts and ends at rest, and it lasts ``w`` longer. This is
  the FIR construction of Biagiotti and Melchiorri ("FIR filters for online trajectory planning
  with time- and frequency-domain specifications", Control Engineering Practice 20(12), 2012)
  applied to the path parameter. ``w`` grows until the sampled joint jerk is inside the limits.

Everything is re-checked on the samples. Where the filtered profile pokes over a velocity,
acceleration or TCP-speed limit (the filter averages the path speed over a stretch where the path
bends, by 1-5 % on curved paths), the motion is slowed down in time by the factor the samples call
for: the path speed divided by ``f`` at every grid point divides joint and TCP velocities by ``f``
and path accelerations by ``f**2`` on the same path (``_slowed``), so one TOPP-RA run suffices where
tightening its limits needed two or three. Where that does not pass (torque, which gravity keeps
from scaling, or a jerk check), TOPP-RA runs again with limits tightened by ``SAFETY_STEPS``.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import InfeasibleError, PlanningError

if TYPE_CHECKING:
    from types import ModuleType

    import toppra

# Limits handed to TOPP-RA are this fraction of the true ones, so that the sampled (and filtered)
# trajectory stays inside the true limits; tightened step by step if not.
SAFETY_STEPS = (0.995, 0.98, 0.95, 0.9, 0.8, 0.7, 0.6)
SAFETY = SAFETY_STEPS[0]
FINE_DT = 0.002  # s: grid on which the jerk is checked (finite differences of the acceleration)
# A timed result over a limit by ratio r on its samples is slowed by r * (1 + SLOWDOWN_SLACK) (the square root
# of it for accelerations), at most SLOWDOWN_TRIES times, before TOPP-RA runs again at the next margin.
SLOWDOWN_TRIES, SLOWDOWN_SLACK = 3, 1e-3
# A result slowed down by more than SLOWDOWN_KEEP in all is kept aside while the next margin is timed: its jerk filter,
# chosen for the faster profile, can be far wider than the next margin needs (a motion up to 1.9x as long was seen);
# the shorter of the two is returned.
SLOWDOWN_KEEP = 1.05
FILTER_GROWTH = 1.25  # each try widens the jerk filter by this factor
FILTER_TRIES = 16
# When the filter had to widen past PLATEAU_TRIGGER times its narrowest width a / j, the profile is timed
# again with a cruise at its top speed (``_plateau_profile``) of PLATEAU_SHARES times that width (the next
# one if no filter up to the cruise's length passes), the filter widened by PLATEAU_GROWTH per try.
PLATEAU_TRIGGER, PLATEAU_SHARES, PLATEAU_GROWTH = 1.2, (1.1, 1.3), 1.04
# Torque is left out of TOPP-RA while the sampled torque of the result stays under this share of every
# limit (it needs two RNEA calls per grid point and rarely binds); above it, the torque constraint is added
# (at the margin's share of the limits) and the margin timed again. The samples must keep the limits either way.
TORQUE_LAZY_SHARE = 0.9

InverseDynamics = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
# TOPP-RA grid: at least GRID_MIN points over the path (GRID_PER_WAYPOINT per waypoint, up to GRID_MAX) and at
# least GRID_PER_SEGMENT intervals between any two waypoints. A cubic spline changes curvature
# fastest over a short segment between long ones; a uniform grid with one or two points there let
# sampled accelerations overshoot by 25 % (obstacle.yaml, seeds 15, 27, 44). TOPP-RA's own Python costs
# ~14 us per grid point and run. The samples are checked against every limit after TOPP-RA (and slowed
# down where over), so a coarser grid can only cost motion time (or, too coarse, a margin): 5 points per
# waypoint rather than 10 (a straight line's 13 waypoints get 80 points, not 130) changed the summed motion
# time of obstacle, multi_object, pick_place and payload.yaml over seeds 1-15 (60 plans) by -0.000 % (single
# plans -0.07 .. +0.19 %), with the same TOPP-RA runs and 21 % fewer grid points; GRID_MIN 40 changed little
# more there (+0.02 %) but failed a built case of a short segment between long ones (tests/test_timing.py) at
# every margin. Earlier, 80 rather than 100 points cost 0.02-0.06 % on the wall and post queries of
# bench/bench_vs_mplib.py.
GRID_MIN, GRID_MAX, GRID_PER_SEGMENT, GRID_PER_WAYPOINT = 80, 800, 4, 5


@dataclass
class TimedPath:
    """Samples of a timed path: ``times`` (N,) s from 0, ``q``/``qd``/``qdd`` (N, n) in rad, rad/s, rad/s^2.

    ``jerk_filter`` is the width (s) of the moving-average filter that bounded the jerk (0: none);
    ``s`` (N,) the path parameter at each sample (cumulative joint-space chord length of the
    waypoints, rad), so callers can find when the motion passes a given waypoint.
    """

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jerk_filter: float = 0.0
    s: np.ndarray | None = None

    @property
    def duration(self) -> float:
        """Length in time (s)."""
        return float(self.times[-1])


@dataclass
class TorqueModel:
    """Joint torque limits for TOPP-RA.

    ``inverse_dynamics(q, qd, qdd)`` maps (G, n) path-joint states to (G, n) torques (N m), batched;
    ``limits`` (n,) N m (inf: none); ``names`` (n,) joint names for messages; ``load`` says what is
    held, for messages (e.g. "'cube' (0.20 kg)").
    """

    inverse_dynamics: InverseDynamics
    limits: np.ndarray
    names: Sequence[str]
    load: str = ""


def dedupe(waypoints: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Drop consecutive duplicate waypoints (TOPP-RA needs a strictly increasing path parameter): each waypoint
    of ``waypoints`` (K, n) within ``tol`` (every coordinate) of the one before it."""
    if len(waypoints) < 2:
        return waypoints.copy()
    keep = np.concatenate([[True], np.max(np.abs(np.diff(waypoints, axis=0)), axis=1) > tol])
    return waypoints[keep]


def import_toppra() -> ModuleType:
    """``import toppra`` (returns the module), with the submodules timing uses.

    What it costs in a fresh process (bench/bench_startup.py): toppra's package ``__init__`` imports all of
    toppra: its interpolators (scipy.interpolate, which timing needs for the spline through the waypoints),
    its solver wrappers (scipy.sparse) and ``toppra.algorithm``, which imports ``matplotlib.pyplot`` at module
    level for plotting methods that planning never calls. None of that can be left out by ordinary means: a
    submodule's import runs its package's ``__init__`` first.
    """
    import toppra
    import toppra.algorithm  # noqa: F401
    import toppra.constraint  # noqa: F401

    return toppra


def _quiet_toppra() -> None:
    """Keep only toppra's CRITICAL log messages (it warns about awkward grid points while it works). toppra's
    own ``setup_logging`` adds another console handler at every call: a long-lived process repeated each
    message once per motion it had timed."""
    logger = logging.getLogger("toppra")
    if logger.level != logging.CRITICAL:
        logger.setLevel(logging.CRITICAL)


def toppra_grid(ss: np.ndarray) -> np.ndarray:
    """TOPP-RA grid (G,) over path parameters ``ss`` (K,) of the waypoints (strictly increasing):
    about uniform at ``ss[-1] / clip(GRID_PER_WAYPOINT K, GRID_MIN, GRID_MAX)``, with the waypoints on the grid
    and at least ``GRID_PER_SEGMENT`` intervals per segment."""
    h = ss[-1] / int(np.clip(GRID_PER_WAYPOINT * len(ss), GRID_MIN, GRID_MAX))
    d = np.diff(ss)
    m = np.maximum(GRID_PER_SEGMENT, np.rint(d / h)).astype(int)
    seg = np.repeat(np.arange(len(d)), m)
    frac = (np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m)) / m[seg]
    return np.append(ss[seg] + frac * d[seg], ss[-1])


_LIMIT_CONSTRAINTS: dict[tuple[bytes, bytes], tuple] = {}
# One joint moved along a line (the gripper) -> (profile, filter width, sample times) of its timing: the same for
# the same length and limits either way (TOPP-RA sees q' = +-1 and q'' = 0), and a plan opens and closes the jaws
# by the same amounts.
_ONE_JOINT_LINES: dict[tuple, tuple] = {}


def _joint_limit_constraints(constraint: ModuleType, vlim: np.ndarray, alim: np.ndarray) -> list:
    """toppra's joint velocity and acceleration constraints for limits ``vlim``/``alim`` (n,), reused across
    calls (they hold only the limits; building one formats every limit into a string, about 0.5 ms)."""
    key = (vlim.tobytes(), alim.tobytes())
    pair = _LIMIT_CONSTRAINTS.get(key)
    if pair is None:
        if len(_LIMIT_CONSTRAINTS) > 256:
            _LIMIT_CONSTRAINTS.clear()
        pair = _LIMIT_CONSTRAINTS[key] = (constraint.JointVelocityConstraint(vlim), constraint.JointAccelerationConstraint(alim))
    return list(pair)


@functools.cache
def _own_constraint_types() -> tuple[type, type]:
    """roarmctl's two toppra constraint classes (defined once, after toppra is imported): a bound on the path speed
    alone, and joint torque in toppra's canonical form."""
    from toppra.constraint import DiscretizationType
    from toppra.constraint.linear_constraint import LinearConstraint

    class SdotBoundConstraint(LinearConstraint):
        """x = sdot^2 <= ``x_upper`` (G,) at every grid point."""

        def __init__(self, x_upper: np.ndarray) -> None:
            super().__init__()
            self.discretization_type = DiscretizationType.Collocation
            self.x_upper = x_upper

        def compute_constraint_params(self, path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray,
                                      *args: object, **kwargs: object) -> tuple:
            self.dof = path.dof
            xbound = np.empty((len(gridpoints), 2))
            xbound[:, 0], xbound[:, 1] = 0.0, self.x_upper
            return None, None, None, None, None, None, xbound

    class TorqueConstraint(LinearConstraint):
        """|a sddot + b sdot^2 + c| <= ``limits`` (n,) N m, with ``terms`` = (a, b, c) (G, n) each."""

        def __init__(self, terms: tuple[np.ndarray, np.ndarray, np.ndarray], limits: np.ndarray) -> None:
            super().__init__()
            self.discretization_type = DiscretizationType.Collocation
            self.identical = True  # F, g are the same at every grid point
            self.terms, self.limits = terms, limits

        def compute_constraint_params(self, path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray,
                                      *args: object, **kwargs: object) -> tuple:
            self.dof = path.dof
            n = path.dof
            F = np.vstack([np.eye(n), -np.eye(n)])
            g = np.concatenate([self.limits, self.limits])
            a, b, c = self.terms
            return a, b, c, F, g, None, None

    return SdotBoundConstraint, TorqueConstraint


def _sdot_bound_constraint(x_upper: np.ndarray) -> toppra.constraint.LinearConstraint:
    """A toppra constraint bounding the path speed alone: x = sdot^2 <= ``x_upper`` (G,) at every
    grid point (computed once per path by the caller, not per margin)."""
    return _own_constraint_types()[0](x_upper)


def _tcp_speed_constraint(speed_per_ds: np.ndarray, max_speed: float) -> toppra.constraint.LinearConstraint:
    """The TCP speed bound |dp/ds| * sdot <= max_speed; ``speed_per_ds`` (G,) is |dp/ds| (m per unit of s) on the grid."""
    with np.errstate(divide="ignore"):
        return _sdot_bound_constraint(np.where(speed_per_ds > 1e-12, (max_speed / np.maximum(speed_per_ds, 1e-12)) ** 2, 1e12))


GEOMETRIC_JERK_SHARE = 0.5  # of each jerk limit, for the path's own term q3(s) * sdot^3


def _path_jerk(path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray) -> np.ndarray:
    """|q3(s)| (G, n) at each grid point: the slope of q2 per grid interval, the larger of the two
    intervals at each point (the spline's q3 is constant between knots; toppra's spline gives up to q2)."""
    d3 = np.abs(np.diff(path(gridpoints, 2), axis=0)) / np.maximum(np.diff(gridpoints), 1e-12)[:, None]
    return np.maximum(np.vstack([d3[:1], d3]), np.vstack([d3, d3[-1:]]))


def _geometric_jerk_constraint(at: np.ndarray, jmax: np.ndarray) -> toppra.constraint.LinearConstraint:
    """Bound the path speed where the path itself turns fast: |q3(s)| * sdot^3 <= share * jerk limit.

    Joint jerk is q1 s3 + 3 q2 s1 s2 + q3 s1^3 (qk, sk: k-th derivatives of the path and of s(t)):
    filtering s(t) bounds the first two terms, but the last comes from the path's geometry (a cubic
    spline's third derivative, constant between knots) and only a lower speed bounds it. As a bound
    on x = sdot^2 it is a TOPP-RA constraint. ``at`` (G, n) is ``_path_jerk`` on the grid.
    """
    with np.errstate(divide="ignore", over="ignore"):
        bound = np.min(np.where(at > 1e-9, (GEOMETRIC_JERK_SHARE * jmax / np.maximum(at, 1e-9)) ** (2 / 3), 1e12), axis=1)
    return _sdot_bound_constraint(np.minimum(bound, 1e12))


def _torque_terms(model: TorqueModel, path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray,
                  gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """toppra's canonical torque form on the grid, tau = a(s) sddot + b(s) sdot^2 + c(s), each (G, n) N m.

    Same form as ``toppra.constraint.JointTorqueConstraint`` (which calls the dynamics once per grid
    point and state); here two batched RNEA calls cover the whole grid, ``gravity`` (G, n) being c(s),
    the holding torques already computed by ``check_holding`` on the same grid.
    """
    p, ps, pss = path(gridpoints), path(gridpoints, 1), path(gridpoints, 2)
    zero = np.zeros_like(p)
    a = model.inverse_dynamics(p, zero, ps) - gravity
    b = model.inverse_dynamics(p, ps, pss) - gravity
    return a, b, gravity


def _torque_constraint(terms: tuple[np.ndarray, np.ndarray, np.ndarray],
                       limits: np.ndarray) -> toppra.constraint.LinearConstraint:
    """A toppra constraint |a sddot + b sdot^2 + c| <= ``limits`` (n,) N m from ``_torque_terms``."""
    return _own_constraint_types()[1](terms, limits)


def check_holding(model: TorqueModel, q: np.ndarray, label: str) -> np.ndarray:
    """Raise InfeasibleError (exit 3) when gravity alone needs more torque than a limit at any of ``q`` (G, n);
    otherwise return those holding torques (G, n) N m (signed)."""
    q = np.atleast_2d(q)
    zero = np.zeros_like(q)
    hold = model.inverse_dynamics(q, zero, zero)
    tau = np.abs(hold)
    ratio = tau / model.limits
    k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
    if ratio[k, j] > 1.0:
        over = [f"{model.names[i]} needs {tau[k, i]:.2f} N m (limit {model.limits[i]:.2f} N m)"
                for i in np.argsort(-ratio[k]) if ratio[k, i] > 1.0]
        what = f"{model.load} even at rest" if model.load else "itself at rest"
        raise InfeasibleError(f"{label}: the arm cannot hold {what}: {'; '.join(over)}",
                              "use a lighter load, move it closer to the base, or check limits.effort in the robot description")
    return hold


_Samples = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # integral of s, s, sdot, sddot (_Profile.eval)


class _Profile:
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
        self._last: tuple[np.ndarray, _Samples] | None = None  # (t, eval(t)) of the last _eval_grid call
        self.jerk_answers: dict = {}  # _jerk_ok's answers for this profile ("path": the path they are for)

    def slowed(self, factor: float) -> _Profile:
        """The same profile ``factor`` times slower: path speed / factor at every grid point (times * factor, path
        accelerations / factor**2)."""
        return _Profile(self.grid, self.sd / factor)

    def _eval_grid(self, t: np.ndarray) -> _Samples:
        """``eval(t)``, reusing the previous call's values where ``t`` and the previous ``t`` agree: the jerk
        check asks for the same fine grid (growing with the filter width) at every width it tries. ``eval`` is
        elementwise in ``t``, so the result is the same bit for bit."""
        last = self._last
        if last is not None:
            lt, lv = last
            m = min(len(t), len(lt))
            if m and np.array_equal(t[:m], lt[:m]):
                if len(t) <= len(lt):
                    k = len(t)
                    return lv[0][:k], lv[1][:k], lv[2][:k], lv[3][:k]
                more = self.eval(t[m:])
                out = (np.concatenate([lv[0], more[0]]), np.concatenate([lv[1], more[1]]),
                       np.concatenate([lv[2], more[2]]), np.concatenate([lv[3], more[3]]))
                self._last = (t, out)
                return out
        out = self.eval(t)
        self._last = (t, out)
        return out

    def eval(self, t: np.ndarray) -> _Samples:
        """Integral of s, s, sdot, sddot at times ``t`` (any shape); at rest before 0 and after the end."""
        t = np.asarray(t, dtype=float)
        i = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.sdd) - 1)
        tau = np.clip(t, 0.0, self.T) - self.t[i]
        a, v, s0 = self.sdd[i], self.sd[i], self.s[i]
        s = s0 + v * tau + a * tau**2 / 2
        S = self.S[i] + s0 * tau + v * tau**2 / 2 + a * tau**3 / 6
        before, after = t < 0, t > self.T
        S = np.where(before, 0.0, np.where(after, S + self.s_end * (t - self.T), S))
        sdot = np.where(before | after, 0.0, v + a * tau)
        sddot = np.where(before | after, 0.0, a)
        s = np.where(before, 0.0, s)
        return S, s, sdot, sddot

    def filtered(self, t: np.ndarray, w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """s, sdot, sddot of the moving average of width ``w`` (s) at times ``t``; ``w`` = 0: unfiltered."""
        if w <= 0:
            _, s, v, a = self.eval(t)
            return s, v, a
        S1, s1, v1, _ = self._eval_grid(t)
        S0, s0, v0, _ = self.eval(t - w)
        s = np.clip((S1 - S0) / w, 0.0, self.s_end)
        return s, (s1 - s0) / w, (v1 - v0) / w


def _sample(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, times: np.ndarray,
            w: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """q, qd, qdd (N, n) and s (N,) at ``times``."""
    s, sd, sdd = prof.filtered(times, w)
    ps = path(s, 1)
    return path(s), ps * sd[:, None], ps * sdd[:, None] + path(s, 2) * (sd**2)[:, None], s


def _ends_at_rest(samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], wp: np.ndarray,
                  s_end: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``_sample``'s q, qd, qdd, s with the exact end waypoints of ``wp`` (K, n), velocity and acceleration 0 there,
    and the path parameter exactly 0 and ``s_end`` (the filtered s can end an ulp short, after a sample already at
    ``s_end``)."""
    q, qd, qdd, s = samples
    q[0], q[-1] = wp[0], wp[-1]
    qd[0] = qd[-1] = qdd[0] = qdd[-1] = 0.0
    s[0], s[-1] = 0.0, s_end
    return q, qd, qdd, s


def _jerk_ok(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w: float, jmax: np.ndarray) -> bool:
    """Whether the jerk of ``prof`` filtered at width ``w`` (s), sampled every FINE_DT, keeps ``jmax`` (n,):
    with s, sdot, sddot of ``prof.filtered`` on the grid t = 0, FINE_DT, ... past ``prof.T + w``, the joint
    accelerations qdd = q'(s) sddot + q''(s) sdot^2 (as in ``_sample``) change by at most jmax * FINE_DT
    (to 1e-9) from one sample to the next.

    Answers are kept on ``prof`` per path (the filter search asks again for w0, which the plateau test asked)."""
    memo = prof.jerk_answers
    if memo.get("path") is not path:
        memo.clear()
        memo["path"] = path
    key = (w, jmax.tobytes())
    if key not in memo:
        t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
        s, sd, sdd = prof.filtered(t, w)
        qdd = path(s, 1) * sdd[:, None] + path(s, 2) * (sd**2)[:, None]  # as in _sample, without the positions
        memo[key] = bool(np.all(np.abs(np.diff(qdd, axis=0)) / FINE_DT <= jmax * (1 + 1e-9)))
    return memo[key]


def _filter_width(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w0: float, jm: np.ndarray,
                  growth: float = FILTER_GROWTH, tries: int = FILTER_TRIES) -> float | None:
    """The narrowest filter width (s, from ``w0`` up by factors of ``growth``, then narrowed to within about
    3 % of a step) for which the sampled jerk of ``prof`` is inside ``jm``; None if none within ``tries``."""
    w, lo = w0, 0.0
    for _ in range(tries):
        if _jerk_ok(path, prof, w, jm):
            break
        lo, w = w, w * growth
    else:
        return None
    for _ in range(3 if lo > 0 else 0):  # narrow it down (each step halves the excess width)
        mid = 0.5 * (lo + w)
        lo, w = (lo, mid) if _jerk_ok(path, prof, mid, jm) else (mid, w)
    return w


def _plateau_cap(prof: _Profile, hold: float) -> float | None:
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

    # 30 bisection steps of c in [0, top] on cruise(c) = sum(frac * ds) / c >= hold, frac the share of each grid
    # interval where sdot^2 > c^2: 1 where x_lo >= c^2, 0 where x_hi <= c^2, else (x_hi - c^2) / span
    def cruise(c: float) -> float:
        c2 = c * c
        frac = np.where(x_lo >= c2, 1.0, np.where(x_hi <= c2, 0.0, (x_hi - c2) / span))
        return float(np.sum(frac * ds)) / c

    lo, hi = 0.0, top
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cruise(mid) >= hold else (lo, mid)
    return lo if lo > 0.0 else None


def _plateau_profile(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
                     gridpoints: np.ndarray, prof: _Profile, hold: float,
                     alim: np.ndarray | None = None) -> _Profile | None:
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
        clipped = _Profile(gridpoints, np.minimum(prof.sd, c))
        ps, pss = path(gridpoints, 1), path(gridpoints, 2)

        def grid_acc(p: _Profile) -> np.ndarray:
            """|joint accelerations| (2 (G - 1), n) of ``p`` at both ends of every grid interval."""
            x = p.sd ** 2
            return np.abs(np.concatenate([ps[:-1] * p.sdd[:, None] + pss[:-1] * x[:-1, None],
                                          ps[1:] * p.sdd[:, None] + pss[1:] * x[1:, None]]))

        # TOPP-RA keeps its constraints to its solver's tolerance (its own result can be over alim by ~1e-8 at a
        # grid point; run again under the cap it returned the clipped profile to ~1e-9 s): the clipped profile must
        # keep alim, or go over it by no more than TOPP-RA's own result did, joint by joint
        if np.all(grid_acc(clipped) <= np.maximum(alim * (1 + 1e-9), np.max(grid_acc(prof), axis=0))):
            return clipped
    instance = algo.TOPPRA(constraints + [_sdot_bound_constraint(np.full(len(gridpoints), c * c))], path,
                           gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
    instance.compute_parameterization(0.0, 0.0)
    data = instance.problem_data
    if data.sd_vec is None or data.return_code.name != "Ok":
        return None
    return _Profile(np.asarray(data.gridpoints, dtype=float), np.asarray(data.sd_vec, dtype=float))


def _plateau(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
             gridpoints: np.ndarray, prof: _Profile, w0: float, jm: np.ndarray,
             alim: np.ndarray | None) -> tuple[_Profile, float] | None:
    """``_plateau_profile`` with a cruise of PLATEAU_SHARES times ``w0`` (the next share if no filter up to the
    cruise's length passes) and its filter width; None if none passes."""
    for share in PLATEAU_SHARES:
        capped = _plateau_profile(algo, constraints, path, gridpoints, prof, share * w0, alim)
        if capped is None:
            return None
        # the filter must stay narrower than the cruise: widen it in small steps up to there
        wc = _filter_width(path, capped, w0, jm, PLATEAU_GROWTH, int(np.log(share) / np.log(PLATEAU_GROWTH)) + 1)
        if wc is not None:
            return capped, wc
    return None


def _slowed(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w: float, factor: float,
            jm: np.ndarray | None, keep_width: bool = True) -> tuple[_Profile, float] | None:
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


def _jerk_ratio(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w: float, jm: np.ndarray) -> float:
    """The largest sampled joint jerk of ``prof`` filtered at width ``w`` (s) as a share of ``jm`` (n,): on the grid
    of ``_jerk_ok`` (every FINE_DT from 0 past the end), the largest change of a joint acceleration per FINE_DT over
    jm * FINE_DT."""
    t = np.arange(0.0, prof.T + w + FINE_DT, FINE_DT)
    qdd = _sample(path, prof, t, w)[2]
    return float(np.max(np.abs(np.diff(qdd, axis=0)) / (FINE_DT * jm)))


def _jerk_slowdown(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w0: float,
                   jm: np.ndarray) -> tuple[_Profile, float] | None:
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


def _jerk_filtered(algo: ModuleType, constraints: list, path: toppra.interpolator.AbstractGeometricPath,
                   gridpoints: np.ndarray, prof: _Profile, alim: np.ndarray, jm: np.ndarray,
                   alim_known: bool) -> tuple[_Profile, float] | None:
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
_Sampled = tuple[_Profile, float, np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray], bool, float]


def _sampled_within_limits(path: toppra.interpolator.AbstractGeometricPath, prof: _Profile, w: float, wp: np.ndarray,
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
        q, qd, qdd, s_samples = _ends_at_rest(_sample(path, prof, times, w), wp, prof.s_end)
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


def time_parameterise(
    waypoints: np.ndarray,
    vmax: np.ndarray,
    amax: np.ndarray,
    jmax: np.ndarray | None = None,
    *,
    tcp_velocity_per_ds: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    max_tcp_speed: float | None = None,
    torque: TorqueModel | None = None,
    sample_dt: float = 0.01,
    label: str = "segment",
) -> TimedPath:
    """Time ``waypoints`` (K, n), at rest at both ends, sampled every ``sample_dt`` s.

    ``vmax``/``amax`` (n,) are the (already scaled) joint limits, ``jmax`` (n,) rad/s^3 the jerk
    limits (None: jerk unbounded, TOPP-RA's bang-bang profile). ``tcp_velocity_per_ds(q, dq_ds)``
    maps (G, n) path samples and their path derivatives to TCP velocity per unit path parameter
    (G, 3); with ``max_tcp_speed`` (m/s) it bounds the TCP speed inside TOPP-RA. ``torque`` adds
    joint torque limits (and first checks that the arm can hold still anywhere on the path).
    Raises InfeasibleError (exit 3) when the arm cannot hold the load, PlanningError (exit 3) when
    TOPP-RA finds no parameterisation.
    """
    ta = import_toppra()
    algo, constraint = ta.algorithm, ta.constraint

    _quiet_toppra()
    wp = dedupe(np.asarray(waypoints, dtype=float))
    n = wp.shape[1]
    if len(wp) < 2:
        z = np.zeros((1, n))
        return TimedPath(np.zeros(1), wp[:1].copy(), z, z.copy(), 0.0, np.zeros(1))
    vmax, amax = np.asarray(vmax, dtype=float), np.asarray(amax, dtype=float)
    chord = np.linalg.norm(np.diff(wp, axis=0), axis=1)
    ss = np.concatenate([[0.0], np.cumsum(chord)])
    path = ta.SplineInterpolator(ss, wp, bc_type="not-a-knot")
    gridpoints = toppra_grid(ss)
    hold = check_holding(torque, path(gridpoints), label) if torque is not None else None
    torque_limited = torque is not None and bool(np.any(np.isfinite(torque.limits)))
    tcp = None if max_tcp_speed is None or tcp_velocity_per_ds is None else (tcp_velocity_per_ds, max_tcp_speed)
    # Constraint pieces that do not depend on the margin: computed once per path, on the one grid.
    speed_per_ds = None if tcp is None else np.linalg.norm(tcp[0](path(gridpoints), path(gridpoints, 1)), axis=1)
    jm = None if jmax is None else np.asarray(jmax, dtype=float)
    path_jerk = None if jm is None else _path_jerk(path, gridpoints)
    line_key = None
    if n == 1 and len(wp) == 2 and tcp is None and torque is None:
        line_key = (float(ss[-1]), vmax.tobytes(), amax.tobytes(), None if jm is None else jm.tobytes(), float(sample_dt))
        known = _ONE_JOINT_LINES.get(line_key)
        if known is not None:
            prof, w, times = known
            times = times.copy()  # the caller owns its arrays
            q, qd, qdd, s_samples = _ends_at_rest(_sample(path, prof, times, w), wp, prof.s_end)
            if np.all(np.abs(qd) <= vmax) and np.all(np.abs(qdd) <= amax):  # as they were for that motion
                return TimedPath(times, q, qd, qdd, w, s_samples)
    torque_terms = None  # lazily: only once a sampled torque comes close to a limit (TORQUE_LAZY_SHARE)
    kept: tuple[TimedPath, _Profile] | None = None  # a passing result slowed by more than SLOWDOWN_KEEP, and its profile

    def result(timed: TimedPath, timed_prof: _Profile) -> TimedPath:
        """``timed`` or the kept result, whichever is shorter (the one-joint cache remembers that one)."""
        if kept is not None and kept[0].duration <= timed.duration:
            timed, timed_prof = kept
        if line_key is not None:
            if len(_ONE_JOINT_LINES) > 256:
                _ONE_JOINT_LINES.clear()
            _ONE_JOINT_LINES[line_key] = (timed_prof, timed.jerk_filter, timed.times.copy())
        return timed

    i = 0
    while i < len(SAFETY_STEPS):
        safety = SAFETY_STEPS[i]
        constraints = _joint_limit_constraints(constraint, vmax * safety, amax * safety)
        if tcp is not None and speed_per_ds is not None:
            constraints.append(_tcp_speed_constraint(speed_per_ds, tcp[1] * safety))
        if jm is not None and path_jerk is not None:
            constraints.append(_geometric_jerk_constraint(path_jerk, jm * safety))
        if torque_terms is not None and torque is not None:
            constraints.append(_torque_constraint(torque_terms, np.where(np.isfinite(torque.limits), torque.limits * safety, 1e9)))
        instance = algo.TOPPRA(constraints, path, gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
        instance.compute_parameterization(0.0, 0.0)
        data = instance.problem_data
        if data.sd_vec is None or data.return_code.name != "Ok":
            if kept is not None:
                return result(*kept)
            raise PlanningError(f"{label}: TOPP-RA found no time parameterisation under the limits",
                                "the path may pass through a point where the limits allow no motion; re-plan with another seed")
        prof = _Profile(np.asarray(data.gridpoints, dtype=float), np.asarray(data.sd_vec, dtype=float))
        w = 0.0
        if jm is not None:
            filtered = _jerk_filtered(algo, constraints, path, gridpoints, prof, amax * safety, jm, torque_terms is None)
            if filtered is None:
                i += 1
                continue
            prof, w = filtered
        prof, w, times, (q, qd, qdd, s_samples), ok, slowed_by = _sampled_within_limits(
            path, prof, w, wp, sample_dt, vmax, amax, jm, tcp)
        if ok and torque is not None:
            tau = np.abs(torque.inverse_dynamics(q, qd, qdd))
            if torque_limited and torque_terms is None and hold is not None and np.any(tau > TORQUE_LAZY_SHARE * torque.limits):
                # close to a limit without the torque constraint: add it and time this margin again
                torque_terms = _torque_terms(torque, path, gridpoints, hold)
                continue
            ok = bool(np.all(tau <= torque.limits))
        if ok:
            timed = TimedPath(times, q, qd, qdd, w, s_samples)
            if slowed_by <= SLOWDOWN_KEEP or i + 1 == len(SAFETY_STEPS):
                return result(timed, prof)
            if kept is None or timed.duration < kept[0].duration:
                kept = (timed, prof)
        i += 1
    if kept is not None:
        return result(*kept)
    raise PlanningError(f"{label}: the timed samples exceed the limits even with a {1 - SAFETY_STEPS[-1]:.0%} margin",
                        "re-plan with another seed")
