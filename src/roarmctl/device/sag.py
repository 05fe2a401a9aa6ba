"""The servos' sag under a steady load, and the goal offset that cancels it.

The ST3235's position loop is P only (the firmware writes P = 16, I = 0: ``roarmctl.device.st3235``): a
joint that holds a steady torque ``tau`` stands ``tau / K`` off its goal, ``K`` the loop's stiffness
(13.6 N m/rad per servo, twice that on the shoulder). Gravity is such a torque: the RoArm-M3 holding the
0.2 kg weight of ``plans/payload.yaml`` at 0.35 m sags about 2 cm (``roarmctl simulate``). Offsetting each
goal by the gravity torque of the planned pose (the held payload included) over ``K`` puts the servo's
standing error where the plan is: ``goal = plan + tau_g(plan, payload) / K``. Only the steady part is
cancelled (the loop still lags a moving goal); the gripper's own load is left alone.

``offsets(robot, traj, times, q)``: the offsets (N, dof) rad for planned poses ``q`` (N, dof) at
trajectory times ``times`` (N,) s; zeros for a robot without inertias or without a RoArm wire map.

``wanted(sag, ideal=...)``: whether a run compensates. The one default of ``execute`` (CLI and
``roarmctl.api``) and ``simulate``: on, unless asked otherwise (``--no-sag``, ``sag=False``) or the servos
are the simulator's ideal ones (they do not sag, so an offset would only move them off the plan). Why on:
docs/physics.md, "Sag, and --sag".
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.device import st3235
from roarmctl.device.protocol import WireMap
from roarmctl.errors import RoarmError
from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.model import Inertial, Robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory


def wanted(sag: bool | None, *, ideal: bool = False) -> bool:
    """Whether goals are sag-compensated: ``sag`` when given (True/False); by default (None) on, except for
    ``ideal`` servos (the firmware simulator's kinematic ones, which stand exactly at their goals)."""
    return (not ideal) if sag is None else bool(sag)


def _set_down(traj: Trajectory, release: float) -> float:
    """When the held object is set down (s): the start of the gripper segment that ends with its release
    (the table carries it while the jaws open), else the release itself."""
    for s in traj.segments:
        if s.kind == "gripper" and s.start - 1e-9 <= release <= s.end + 1e-9:
            return float(s.start)
    return release


def offsets(robot: Robot, traj: Trajectory, times: npt.ArrayLike, q: np.ndarray) -> np.ndarray:
    """Goal offsets (N, dof) rad that cancel the servos' sag under gravity at the planned poses ``q``
    (N, dof) at trajectory times ``times`` (N,) s, the payloads of ``traj`` held from their grasp until
    they are set down (the release's gripper segment starts); zero for the gripper, and everywhere when the
    robot has no inertias. Each offset is at most the loop's full-duty error (``1 / (KP * steps per rad)``,
    141 steps, 12.4 deg at P = 16)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    times = np.atleast_1d(np.asarray(times, dtype=float))
    out = np.zeros_like(q)
    try:
        wm = WireMap(robot)
    except RoarmError:
        return out
    stiff = np.full(robot.dof, np.inf)
    for w, i in zip(wm.fields, wm.index):
        if robot.gripper is None or w.joint != robot.gripper.joint:
            stiff[i] = st3235.stiffness(w.field)
    held = np.full(len(times), -1)
    for k, p in enumerate(traj.payloads):
        held[(times >= float(p["start"])) & (times < _set_down(traj, float(p["end"])))] = k
    zero = np.zeros(robot.dof)
    try:
        for k in np.unique(held):
            rows = held == k
            load = None
            if k >= 0:
                p = traj.payloads[int(k)]
                load = {p["link"]: Inertial(float(p["mass"]), np.asarray(p["com"], dtype=float),
                                            np.asarray(p["inertia"], dtype=float))}
            n = int(np.count_nonzero(rows))
            tau = inverse_dynamics(robot, q[rows], np.tile(zero, (n, 1)), np.tile(zero, (n, 1)), payload=load)
            out[rows] = np.atleast_2d(tau) / stiff
        # never more than the error at which the loop gives full duty: a load beyond stall (a payload mass the
        # planner would refuse) is not held by a larger offset, only driven harder into the limit
        full = 1.0 / (st3235.KP * st3235.STEPS_PER_RAD)
        np.clip(out, -full, full, out=out)
    except RoarmError:  # no inertial data: nothing to compensate with
        return np.zeros_like(q)
    return out
