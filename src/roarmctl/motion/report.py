"""What a timed trajectory asks of each joint: peak velocity, acceleration, jerk and torque, each also as
a fraction of the robot's limit. Used by ``roarmctl plan`` (table and ``--json``) and ``visualize-path``.

Jerk is the finite difference of the sampled accelerations; torque is the library's RNEA
(``roarmctl.robot.dynamics``) on every sample, with each held object (the trajectory's ``payloads``)
fixed to its link from grasp to release.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.model import Inertial

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot


def payload_bodies(traj: Trajectory) -> list[tuple[float, float, dict]]:
    """The trajectory's payload spans as (start s, end s, {link: Inertial})."""
    out = []
    for p in traj.payloads:
        body = Inertial(float(p["mass"]), np.asarray(p["com"], dtype=float), np.asarray(p["inertia"], dtype=float))
        out.append((float(p["start"]), float(p["end"]), {str(p["link"]): body}))
    return out


def joint_torques(traj: Trajectory, robot: Robot) -> np.ndarray | None:
    """RNEA torques (N, dof) N m at every sample, held objects included; None without inertial data."""
    if not robot.inertials:
        return None
    tau = inverse_dynamics(robot, traj.positions, traj.velocities, traj.accelerations)
    for start, end, body in payload_bodies(traj):
        sel = (traj.times > start + 1e-9) & (traj.times < end - 1e-9)
        if np.any(sel):
            tau[sel] = inverse_dynamics(robot, traj.positions[sel], traj.velocities[sel], traj.accelerations[sel], payload=body)
    return tau


def joint_jerks(traj: Trajectory) -> np.ndarray:
    """Jerk (N-1, dof) rad/s^3 between consecutive samples (finite differences of the accelerations)."""
    if len(traj.times) < 2:
        return np.zeros((0, traj.positions.shape[1]))
    return np.diff(traj.accelerations, axis=0) / np.diff(traj.times)[:, None]


def motion_peaks(traj: Trajectory, robot: Robot) -> dict[str, Any]:
    """Per joint (in ``joint_names`` order): peaks and peak/limit fractions (None where no limit).

    Keys: ``joints``, ``cycle_time`` (s), ``velocity``/``acceleration``/``jerk``/``torque`` (peaks in
    rad/s, rad/s^2, rad/s^3, N m; m/s ... N for prismatic joints, see ``units``; torque None without
    inertial data) and ``*_fraction`` of the robot's limits (velocity and acceleration of the scaled
    limits the plan used).
    """
    lim = traj.limits or {}
    vmax = np.asarray(robot.velocity_limits, dtype=float) * float(lim.get("velocity_scale") or 1.0)
    amax = np.asarray(robot.acceleration_limits, dtype=float) * float(lim.get("acceleration_scale") or 1.0)

    def peak(a: np.ndarray) -> np.ndarray:
        return np.max(np.abs(a), axis=0) if len(a) else np.zeros(len(traj.joint_names))

    def frac(p: np.ndarray, limit: npt.ArrayLike | None) -> list[float | None]:
        if limit is None:
            return [None] * len(p)
        return [float(x / m) if np.isfinite(m) and m > 0 else None for x, m in zip(p, np.asarray(limit, dtype=float))]

    v, a, j = peak(traj.velocities), peak(traj.accelerations), peak(joint_jerks(traj))
    tau = joint_torques(traj, robot)
    t = None if tau is None else peak(tau)
    return {
        "joints": list(traj.joint_names),
        "cycle_time": float(traj.duration),
        "velocity": v.tolist(), "velocity_fraction": frac(v, vmax),
        "acceleration": a.tolist(), "acceleration_fraction": frac(a, amax),
        "jerk": j.tolist(), "jerk_fraction": frac(j, robot.jerk_limits),
        "torque": None if t is None else t.tolist(),
        "torque_fraction": [None] * len(v) if t is None else frac(t, robot.effort_limits),
        # per joint, the units of the peaks above: m/s, m/s^2, m/s^3 and N for a prismatic joint
        "units": {key: [robot.joint_unit(i, power, kind=kind) for i in range(robot.dof)]
                  for key, power, kind in (("velocity", 1, "position"), ("acceleration", 2, "position"),
                                           ("jerk", 3, "position"), ("torque", 0, "effort"))},
    }
