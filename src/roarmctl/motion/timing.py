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
and path accelerations by ``f**2`` on the same path (``jerk_filter._slowed``), so one TOPP-RA run suffices where
tightening its limits needed two or three. Where that does not pass (torque, which gravity keeps
from scaling, or a jerk check), TOPP-RA runs again with limits tightened by ``SAFETY_STEPS``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from roarmctl.errors import PlanningError
from roarmctl.motion.jerk_filter import Profile, ends_at_rest, jerk_filtered, sample, sampled_within_limits
from roarmctl.motion.toppra_constraints import (
    TorqueModel,
    check_holding,
    geometric_jerk_constraint,
    import_toppra,
    joint_limit_constraints,
    joint_path,
    path_jerk,
    quiet_toppra,
    tcp_speed_constraint,
    toppra_grid,
    torque_constraint,
    torque_terms,
)

__all__ = ["SAFETY", "SAFETY_STEPS", "TimedPath", "TorqueModel", "check_holding", "dedupe", "import_toppra",
           "time_parameterise"]

# Limits handed to TOPP-RA are this fraction of the true ones, so that the sampled (and filtered)
# trajectory stays inside the true limits; tightened step by step if not.
SAFETY_STEPS = (0.995, 0.98, 0.95, 0.9, 0.8, 0.7, 0.6)
SAFETY = SAFETY_STEPS[0]
# A result slowed down by more than SLOWDOWN_KEEP in all is kept aside while the next margin is timed: its jerk filter,
# chosen for the faster profile, can be far wider than the next margin needs (a motion up to 1.9x as long was seen);
# the shorter of the two is returned.
SLOWDOWN_KEEP = 1.05
# Torque is left out of TOPP-RA while the sampled torque of the result stays under this share of every
# limit (it needs two RNEA calls per grid point and rarely binds); above it, the torque constraint is added
# (at the margin's share of the limits) and the margin timed again. The samples must keep the limits either way.
TORQUE_LAZY_SHARE = 0.9


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



def dedupe(waypoints: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Drop consecutive duplicate waypoints (TOPP-RA needs a strictly increasing path parameter): each waypoint
    of ``waypoints`` (K, n) within ``tol`` (every coordinate) of the one before it."""
    if len(waypoints) < 2:
        return waypoints.copy()
    keep = np.concatenate([[True], np.max(np.abs(np.diff(waypoints, axis=0)), axis=1) > tol])
    return waypoints[keep]


# One joint moved along a line (the gripper) -> (profile, filter width, sample times) of its timing: the same for
# the same length and limits either way (TOPP-RA sees q' = +-1 and q'' = 0), and a plan opens and closes the jaws
# by the same amounts.
_ONE_JOINT_LINES: dict[tuple, tuple] = {}


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

    quiet_toppra()
    wp = dedupe(np.asarray(waypoints, dtype=float))
    n = wp.shape[1]
    if len(wp) < 2:
        z = np.zeros((1, n))
        return TimedPath(np.zeros(1), wp[:1].copy(), z, z.copy(), 0.0, np.zeros(1))
    vmax, amax = np.asarray(vmax, dtype=float), np.asarray(amax, dtype=float)
    chord = np.linalg.norm(np.diff(wp, axis=0), axis=1)
    ss = np.concatenate([[0.0], np.cumsum(chord)])
    path = joint_path(ta, ss, wp)
    gridpoints = toppra_grid(ss)
    hold = check_holding(torque, path(gridpoints), label) if torque is not None else None
    torque_limited = torque is not None and bool(np.any(np.isfinite(torque.limits)))
    tcp = None if max_tcp_speed is None or tcp_velocity_per_ds is None else (tcp_velocity_per_ds, max_tcp_speed)
    # Constraint pieces that do not depend on the margin: computed once per path, on the one grid.
    speed_per_ds = None if tcp is None else np.linalg.norm(tcp[0](path(gridpoints), path(gridpoints, 1)), axis=1)
    jm = None if jmax is None else np.asarray(jmax, dtype=float)
    jerk_of_path = None if jm is None else path_jerk(path, gridpoints)
    line_key = None
    if n == 1 and len(wp) == 2 and tcp is None and torque is None:
        line_key = (float(ss[-1]), vmax.tobytes(), amax.tobytes(), None if jm is None else jm.tobytes(), float(sample_dt))
        known = _ONE_JOINT_LINES.get(line_key)
        if known is not None:
            prof, w, times = known
            times = times.copy()  # the caller owns its arrays
            q, qd, qdd, s_samples = ends_at_rest(sample(path, prof, times, w), wp, prof.s_end)
            if np.all(np.abs(qd) <= vmax) and np.all(np.abs(qdd) <= amax):  # as they were for that motion
                return TimedPath(times, q, qd, qdd, w, s_samples)
    torque_abc = None  # lazily: only once a sampled torque comes close to a limit (TORQUE_LAZY_SHARE)
    kept: tuple[TimedPath, Profile] | None = None  # a passing result slowed by more than SLOWDOWN_KEEP, and its profile

    def result(timed: TimedPath, timed_prof: Profile) -> TimedPath:
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
        constraints = joint_limit_constraints(constraint, vmax * safety, amax * safety)
        if tcp is not None and speed_per_ds is not None:
            constraints.append(tcp_speed_constraint(speed_per_ds, tcp[1] * safety))
        if jm is not None and jerk_of_path is not None:
            constraints.append(geometric_jerk_constraint(jerk_of_path, jm * safety))
        if torque_abc is not None and torque is not None:
            constraints.append(torque_constraint(torque_abc, np.where(np.isfinite(torque.limits), torque.limits * safety, 1e9)))
        instance = algo.TOPPRA(constraints, path, gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
        instance.compute_parameterization(0.0, 0.0)
        data = instance.problem_data
        if data.sd_vec is None or data.return_code.name != "Ok":
            if kept is not None:
                return result(*kept)
            raise PlanningError(f"{label}: TOPP-RA found no time parameterisation under the limits",
                                "the path may pass through a point where the limits allow no motion; re-plan with another seed")
        prof = Profile(np.asarray(data.gridpoints, dtype=float), np.asarray(data.sd_vec, dtype=float))
        w = 0.0
        if jm is not None:
            filtered = jerk_filtered(algo, constraints, path, gridpoints, prof, amax * safety, jm, torque_abc is None)
            if filtered is None:
                i += 1
                continue
            prof, w = filtered
        prof, w, times, (q, qd, qdd, s_samples), ok, slowed_by = sampled_within_limits(
            path, prof, w, wp, sample_dt, vmax, amax, jm, tcp)
        if ok and torque is not None:
            tau = np.abs(torque.inverse_dynamics(q, qd, qdd))
            if torque_limited and torque_abc is None and hold is not None and np.any(tau > TORQUE_LAZY_SHARE * torque.limits):
                # close to a limit without the torque constraint: add it and time this margin again
                torque_abc = torque_terms(torque, path, gridpoints, hold)
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
