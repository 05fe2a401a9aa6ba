"""TOPP-RA's side of the timing: its import, the grid over a path, and the constraints roarmctl hands it.

Joint velocity and acceleration limits (toppra's own constraints, kept across calls), a bound on the path speed
alone (used for the TCP speed limit, for the path's own jerk term and for a cruise cap), and joint torque in
toppra's canonical form from batched inverse dynamics. ``roarmctl.motion.timing`` runs TOPP-RA with them;
``roarmctl.motion.jerk_filter`` makes its result jerk-limited.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import InfeasibleError

if TYPE_CHECKING:
    from types import ModuleType

    import toppra

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
# every margin, as does 50. Earlier, 80 rather than 100 points cost 0.02-0.06 % on the wall and post queries of
# bench/bench_vs_mplib.py. 60 rather than 80 (bench/bench_knobs.py, queries a-e at seeds 100-139): the median and mean
# durations within 0.05 %, each motion -1.4 .. +0.46 %; api.plan's CPU 0.95-0.96x on b-e; the bundled plans
# (seeds 1-3) within -0.01 .. +0.07 %; the short-segment case still times at its margin, the slowed-a-lot case of
# tests/test_timing.py shows its behaviour at another TCP limit.
GRID_MIN, GRID_MAX, GRID_PER_SEGMENT, GRID_PER_WAYPOINT = 60, 800, 4, 5
# A path of two waypoints is a straight line in joint space (q'' = 0: no curvature for the grid to follow; the joint
# limits are the same everywhere on it, only the TCP speed and torque bounds vary, slowly): GRID_LINE intervals,
# not GRID_MIN. Over every such timing of queries a-e (seeds 100-111) and of four bundled plans (seeds 1-4), 30
# rather than 80 changed single motion times by -0.09 .. +0.14 % (summed +0.01 %) and cut their timing by a third.
GRID_LINE = 30



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

    _solvers_asked_once(toppra)
    return toppra


_SOLVERS_KNOWN = False  # _solvers_asked_once has run


def _solvers_asked_once(toppra: ModuleType) -> None:
    """toppra asks importlib whether qpoases and cvxpy are installed at every TOPP-RA instance it makes
    (``ReachabilityAlgorithm.__init__`` calls ``toppra.solverwrapper.available_solvers``): two searches of
    ``sys.path``, about 0.2 ms a timing, as much as a free motion's spline. Which packages are installed does not
    change while a process plans, so the answer is found once and given again (the same tuple; toppra picks its
    solver from it as before: seidel, with neither installed)."""
    global _SOLVERS_KNOWN
    if _SOLVERS_KNOWN:
        return
    wrapper = toppra.solverwrapper
    found = wrapper.available_solvers(output_msg=False)

    def available_solvers(output_msg: bool = True) -> tuple:
        """toppra's ``available_solvers``, answered from the first call."""
        if output_msg:
            print(found)  # noqa: T201 (toppra's own behaviour when asked to say it)
        return found

    wrapper.available_solvers = available_solvers
    _SOLVERS_KNOWN = True


def quiet_toppra() -> None:
    """Keep only toppra's CRITICAL log messages (it warns about awkward grid points while it works). toppra's
    own ``setup_logging`` adds another console handler at every call: a long-lived process repeated each
    message once per motion it had timed."""
    logger = logging.getLogger("toppra")
    if logger.level != logging.CRITICAL:
        logger.setLevel(logging.CRITICAL)


def toppra_grid(ss: np.ndarray) -> np.ndarray:
    """TOPP-RA grid (G,) over path parameters ``ss`` (K,) of the waypoints (strictly increasing):
    about uniform at ``ss[-1] / clip(GRID_PER_WAYPOINT K, GRID_MIN, GRID_MAX)`` (``ss[-1] / GRID_LINE`` for two
    waypoints, a straight line), with the waypoints on the grid and at least ``GRID_PER_SEGMENT`` intervals per
    segment."""
    h = ss[-1] / (GRID_LINE if len(ss) == 2 else min(max(GRID_PER_WAYPOINT * len(ss), GRID_MIN), GRID_MAX))
    d = np.diff(ss)
    m = np.maximum(GRID_PER_SEGMENT, np.rint(d / h)).astype(int)
    seg = np.repeat(np.arange(len(d)), m)
    frac = (np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m)) / m[seg]
    return np.append(ss[seg] + frac * d[seg], ss[-1])


def joint_path(ta: ModuleType, ss: np.ndarray, wp: np.ndarray) -> toppra.SplineInterpolator:
    """toppra's not-a-knot cubic spline through waypoints ``wp`` (K, n) at path parameters ``ss`` (K,).

    Through three waypoints that spline is the parabola through them, which scipy's CubicSpline finds with a dense
    ``scipy.linalg.solve`` (every other count is solved banded); with scipy 1.17 on a busy 2-core machine that 3 x 3
    solve cost up to 8 ms of CPU (OpenBLAS waking its threads; 0.04 ms with OPENBLAS_NUM_THREADS=1), where the
    whole spline through four waypoints costs 0.2 ms. The same parabola is given here by its slopes at both ends (a clamped spline, solved banded); it
    agrees with scipy's not-a-knot spline to 1e-15 (relative) in value, slope and curvature."""
    if len(ss) != 3:
        return ta.SplineInterpolator(ss, wp, bc_type="not-a-knot")
    h0, h1 = ss[1] - ss[0], ss[2] - ss[1]
    d0, d1 = (wp[1] - wp[0]) / h0, (wp[2] - wp[1]) / h1
    half_curvature = (d1 - d0) / (h0 + h1)  # the parabola's second derivative / 2
    return ta.SplineInterpolator(ss, wp, bc_type=((1, d0 - half_curvature * h0), (1, d1 + half_curvature * h1)))


_LIMIT_CONSTRAINTS: dict[tuple[bytes, bytes], tuple] = {}


def joint_limit_constraints(constraint: ModuleType, vlim: np.ndarray, alim: np.ndarray) -> list:
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


def sdot_bound_constraint(x_upper: np.ndarray) -> toppra.constraint.LinearConstraint:
    """A toppra constraint bounding the path speed alone: x = sdot^2 <= ``x_upper`` (G,) at every
    grid point (computed once per path by the caller, not per margin)."""
    return _own_constraint_types()[0](x_upper)


def tcp_speed_constraint(speed_per_ds: np.ndarray, max_speed: float) -> toppra.constraint.LinearConstraint:
    """The TCP speed bound |dp/ds| * sdot <= max_speed; ``speed_per_ds`` (G,) is |dp/ds| (m per unit of s) on the grid."""
    with np.errstate(divide="ignore"):
        return sdot_bound_constraint(np.where(speed_per_ds > 1e-12, (max_speed / np.maximum(speed_per_ds, 1e-12)) ** 2, 1e12))


GEOMETRIC_JERK_SHARE = 0.5  # of each jerk limit, for the path's own term q3(s) * sdot^3


def path_jerk(path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray) -> np.ndarray:
    """|q3(s)| (G, n) at each grid point: the slope of q2 per grid interval, the larger of the two
    intervals at each point (the spline's q3 is constant between knots; toppra's spline gives up to q2)."""
    d3 = np.abs(np.diff(path(gridpoints, 2), axis=0)) / np.maximum(np.diff(gridpoints), 1e-12)[:, None]
    return np.maximum(np.vstack([d3[:1], d3]), np.vstack([d3, d3[-1:]]))


def geometric_jerk_constraint(at: np.ndarray, jmax: np.ndarray) -> toppra.constraint.LinearConstraint:
    """Bound the path speed where the path itself turns fast: |q3(s)| * sdot^3 <= share * jerk limit.

    Joint jerk is q1 s3 + 3 q2 s1 s2 + q3 s1^3 (qk, sk: k-th derivatives of the path and of s(t)):
    filtering s(t) bounds the first two terms, but the last comes from the path's geometry (a cubic
    spline's third derivative, constant between knots) and only a lower speed bounds it. As a bound
    on x = sdot^2 it is a TOPP-RA constraint. ``at`` (G, n) is ``path_jerk`` on the grid.
    """
    with np.errstate(divide="ignore", over="ignore"):
        bound = np.min(np.where(at > 1e-9, (GEOMETRIC_JERK_SHARE * jmax / np.maximum(at, 1e-9)) ** (2 / 3), 1e12), axis=1)
    return sdot_bound_constraint(np.minimum(bound, 1e12))


def torque_terms(model: TorqueModel, path: toppra.interpolator.AbstractGeometricPath, gridpoints: np.ndarray,
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


def torque_constraint(terms: tuple[np.ndarray, np.ndarray, np.ndarray],
                       limits: np.ndarray) -> toppra.constraint.LinearConstraint:
    """A toppra constraint |a sddot + b sdot^2 + c| <= ``limits`` (n,) N m from ``torque_terms``."""
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
