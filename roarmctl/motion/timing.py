"""Time-optimal parameterisation of a joint path with TOPP-RA.

A geometric path (waypoints in joint space) becomes a timed trajectory that starts and ends at
rest and respects joint velocity and acceleration limits and, optionally, a maximum TCP speed.
The TCP-speed limit is a constraint inside TOPP-RA (a bound on the squared path speed at every
grid point), not a slow-down applied afterwards.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from roarmctl.errors import PlanningError

# Limits handed to TOPP-RA are this fraction of the true ones, so that the sampled trajectory
# (evaluated between grid points) stays inside the true limits; tightened step by step if not.
SAFETY_STEPS = (0.98, 0.95, 0.9, 0.8)
SAFETY = SAFETY_STEPS[0]


@dataclass
class TimedPath:
    """Samples of a timed path: ``times`` (N,) s from 0, ``q``/``qd``/``qdd`` (N, n) in rad, rad/s, rad/s^2."""

    times: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def dedupe(waypoints: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """Drop consecutive duplicate waypoints (TOPP-RA needs a strictly increasing path parameter)."""
    keep = [0] + [i for i in range(1, len(waypoints)) if np.max(np.abs(waypoints[i] - waypoints[i - 1])) > tol]
    return waypoints[keep]


def _tcp_speed_constraint(tcp_velocity_per_ds: Callable[[np.ndarray, np.ndarray], np.ndarray], max_speed: float):
    """A toppra constraint bounding the TCP speed: |dp/ds| * sdot <= max_speed at every grid point."""
    from toppra.constraint import DiscretizationType
    from toppra.constraint.linear_constraint import LinearConstraint

    class TcpSpeedConstraint(LinearConstraint):
        def __init__(self) -> None:
            super().__init__()
            self.discretization_type = DiscretizationType.Collocation

        def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
            self.dof = path.dof
            q, qs = path(gridpoints), path(gridpoints, 1)
            speed_per_ds = np.linalg.norm(tcp_velocity_per_ds(q, qs), axis=1)
            xbound = np.empty((len(gridpoints), 2))
            xbound[:, 0] = 0.0
            with np.errstate(divide="ignore"):
                xbound[:, 1] = np.where(speed_per_ds > 1e-12, (max_speed / np.maximum(speed_per_ds, 1e-12)) ** 2, 1e12)
            return None, None, None, None, None, None, xbound

    return TcpSpeedConstraint()


def time_parameterise(
    waypoints: np.ndarray,
    vmax: np.ndarray,
    amax: np.ndarray,
    *,
    tcp_velocity_per_ds: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    max_tcp_speed: float | None = None,
    sample_dt: float = 0.01,
    label: str = "segment",
) -> TimedPath:
    """TOPP-RA through ``waypoints`` (K, n), at rest at both ends, sampled every ``sample_dt`` s.

    ``vmax``/``amax`` (n,) are the (already scaled) joint limits. ``tcp_velocity_per_ds(q, dq_ds)``
    maps (G, n) path samples and their path derivatives to TCP velocity per unit path parameter
    (G, 3); with ``max_tcp_speed`` (m/s) it bounds the TCP speed inside TOPP-RA.
    Raises PlanningError when TOPP-RA finds no parameterisation.
    """
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint

    ta.setup_logging("CRITICAL")
    wp = dedupe(np.asarray(waypoints, dtype=float))
    n = wp.shape[1]
    if len(wp) < 2:
        z = np.zeros((1, n))
        return TimedPath(np.zeros(1), wp[:1].copy(), z, z.copy())
    chord = np.linalg.norm(np.diff(wp, axis=0), axis=1)
    ss = np.concatenate([[0.0], np.cumsum(chord)])
    path = ta.SplineInterpolator(ss, wp, bc_type="clamped" if len(wp) > 2 else "not-a-knot")
    tcp_ok = max_tcp_speed is not None and tcp_velocity_per_ds is not None
    for safety in SAFETY_STEPS:
        constraints = [
            constraint.JointVelocityConstraint(np.asarray(vmax, dtype=float) * safety),
            constraint.JointAccelerationConstraint(np.asarray(amax, dtype=float) * safety),
        ]
        if tcp_ok:
            constraints.append(_tcp_speed_constraint(tcp_velocity_per_ds, max_tcp_speed * safety))
        n_grid = int(np.clip(10 * len(wp), 100, 800))
        gridpoints = np.linspace(0.0, ss[-1], n_grid + 1)
        instance = algo.TOPPRA(constraints, path, gridpoints=gridpoints, parametrizer="ParametrizeConstAccel")
        traj = instance.compute_trajectory(0.0, 0.0)
        if traj is None:  # toppra returns None instead of raising
            raise PlanningError(f"{label}: TOPP-RA found no time parameterisation under the limits",
                                "the path may pass through a point where the limits allow no motion; re-plan with another seed")
        duration = float(traj.duration)
        count = max(int(np.ceil(duration / sample_dt)), 1)
        times = np.unique(np.minimum(np.arange(count + 1) * sample_dt, duration))
        q, qd, qdd = traj(times), traj(times, 1), traj(times, 2)
        q[0], q[-1] = wp[0], wp[-1]  # exact ends, at rest
        qd[0] = qd[-1] = 0.0
        # The constraints hold at grid points; between them the spline's curvature can push a
        # sample slightly over. Check the samples and tighten until they are inside.
        ok = np.all(np.abs(qd) <= vmax) and np.all(np.abs(qdd) <= amax)
        if ok and tcp_ok:
            ok = bool(np.max(np.linalg.norm(tcp_velocity_per_ds(q, qd), axis=1)) <= max_tcp_speed)
        if ok:
            return TimedPath(times, q, qd, qdd)
    raise PlanningError(f"{label}: the timed samples exceed the limits even with a {1 - SAFETY_STEPS[-1]:.0%} margin",
                        "re-plan with another seed")
