"""Which servos drive which joints of a robot.

* A RoArm (a description with a RoArm wire map, ``roarmctl.device.protocol.WireMap``): one ST3235
  per firmware joint, two on the shoulder (servos 12 and 13, RoArm-M3_config.h of Waveshare's RoArm-M3
  example firmware; the M2 has the same pair), the gripper's torque limited to 30 % as the firmware
  does at boot (``RoArmM3_handTorqueCtrl(300)`` in RoArm-M3_example.ino). A servo's steps relate to the
  joint through the firmware's own feedback formula (``calculateRadByFeedback``, RoArm-M3_module.h) and
  the description's wire map, so a goal the firmware writes lands where the firmware expects it.
* Any other robot: a generic position servo per actuated joint from its effort and velocity limits
  (``roarmctl.physics.servo.generic_spec``); a joint without an effort limit gets twice the largest
  torque the planned motion needs (inverse dynamics), at least 1 N m (assumed, and said so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.device import st3235
from roarmctl.device.fwmath import position_to_rad
from roarmctl.device.protocol import M3_FIELDS, WireMap
from roarmctl.errors import DescriptionError, RoarmError
from roarmctl.physics.mjcf import JointDynamics
from roarmctl.physics.servo import ST3235, ServoBank, ServoSpec, generic_spec
from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.model import Robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory


@dataclass
class Actuation:
    """The servos of a robot: ``bank`` (channels), ``fields`` (the firmware joint field of each channel,
    or None for a generic drive), ``firmware_index`` (channel -> index in ``roarmctl.device.protocol.M3_FIELDS``,
    or -1), ``streamed`` (True: goals come from firmware commands; False: the drives follow the plan)
    and ``notes`` (assumptions made)."""

    bank: ServoBank
    fields: list[str | None]
    firmware_index: list[int]
    streamed: bool
    notes: list[str] = field(default_factory=list)

    def dynamics(self, robot: Robot) -> dict[str, JointDynamics]:
        """Joint name -> armature and back-EMF damping the servos add (for the MJCF)."""
        arm = self.bank.armature()
        damp = self.bank.joint_damping()
        out: dict[str, JointDynamics] = {}
        for c, j in enumerate(self.bank.joint):
            name = robot.joint_names[j]
            d = out.setdefault(name, JointDynamics())
            d.armature += float(arm[c])
            d.damping += float(damp[c])
        return out


def _feedback_line(index: int) -> tuple[float, float]:
    """(alpha, beta) of the firmware's feedback formula rad = alpha + beta * steps for joint ``index``."""

    a = position_to_rad(index, 0.0)
    return a, position_to_rad(index, 1.0) - a


def for_robot(robot: Robot, traj: Trajectory | None = None) -> Actuation:
    """The servos of ``robot``; ``traj`` (optional) sizes generic drives without effort limits."""

    try:
        wm = WireMap(robot) if robot.wire else None
    except DescriptionError:
        wm = None
    if wm is not None:
        joint, spec, count, sign, zero, limit, fw = [], [], [], [], [], [], []
        fields: list[str | None] = []
        for w, i in zip(wm.fields, wm.index):
            k = M3_FIELDS.index(w.field)
            alpha, beta = _feedback_line(k)
            # steps = (wire - alpha) / beta with wire = offset + sign * q
            joint.append(i)
            spec.append(ST3235)
            count.append(st3235.SERVOS_PER_FIELD.get(w.field, 1))
            sign.append(math.copysign(1.0, w.sign / beta))
            zero.append((w.offset - alpha) / beta)
            limit.append(st3235.TORQUE_LIMIT.get(w.field, 1.0))
            fields.append(w.field)
            fw.append(k)
        bank = ServoBank(joint, spec, count, sign, zero, limit)
        return Actuation(bank, fields, fw, streamed=True, notes=[st3235.STIFFNESS_NOTE])
    return _generic(robot, traj)


def _generic(robot: Robot, traj: Trajectory | None) -> Actuation:
    notes: list[str] = []
    actuated = [i for i, n in enumerate(robot.joint_names)]
    effort = np.full(robot.dof, np.inf) if robot.effort_limits is None else np.asarray(robot.effort_limits, dtype=float)
    need = _needed_torque(robot, traj)
    specs: list[ServoSpec] = []
    for i in actuated:
        e = float(effort[i])
        if not math.isfinite(e) or e <= 0:
            e = max(1.0, 2.0 * float(need[i]))
            notes.append(f"joint {robot.joint_names[i]} has no effort limit: its drive gets {e:.3g} N m "
                         "(twice the planned motion's peak torque, at least 1 N m; assumed)")
        specs.append(generic_spec(robot.joint_names[i], e, float(robot.velocity_limits[i])))
    notes.append(f"{robot.name}: generic position drives (stall = effort limit, no-load speed = twice the velocity "
                 "limit, full torque at 0.05 rad of error, velocity and torque feed-forward; assumed) follow the planned motion")
    n = len(actuated)
    bank = ServoBank(actuated, specs, np.ones(n), np.ones(n), np.zeros(n))
    return Actuation(bank, [None] * n, [-1] * n, streamed=False, notes=notes)


def _needed_torque(robot: Robot, traj: Trajectory | None) -> np.ndarray:
    """Largest |torque| (dof,) N m of the planned motion (zeros without a trajectory or inertias)."""
    if traj is None:
        return np.zeros(robot.dof)

    try:
        tau = inverse_dynamics(robot, traj.positions, traj.velocities, traj.accelerations)
    except RoarmError:
        return np.zeros(robot.dof)
    return np.max(np.abs(np.atleast_2d(tau)), axis=0)
