"""The servos behind the firmware simulator: the interface it drives, and the kinematic servos.

The simulated firmware (``roarmctl.device.firmware``) talks to its servos only through
:class:`ServoModel`, as the real firmware talks to its ST3235 servos only over the servo bus: it
writes goal registers (position, speed, acceleration), switches torque, and reads the present
position and load. Everything about *how* a servo moves (its speed and acceleration profile, its
position loop, torque, gravity, contact) belongs to the model. ``KinematicServos`` (here) is the
ideal arm: each servo runs its own trapezoid to its goal; the physics servos (MuJoCo,
``roarmctl.physics``) implement the same interface and are wired in by the CLI, so this layer never
imports them.

Joints are the firmware's six (``JOINTS``: base, shoulder, elbow, wrist, roll, hand; the shoulder's
two servos 12/13 are one joint here: the firmware commands them mirrored and reads only servo 12,
RoArm-M3_module.h lines 574-592 of Waveshare's 0.84 example firmware). Units are the servo's own:
positions in steps (4096 per turn, present position as the servo reports it), speed in steps/s,
acceleration in the ACC register's unit of 100 steps/s^2 (Feetech STS register map; Waveshare's
SCServo examples: "A=50 (50*100 steps/s^2)"), load in the firmware's ``ReadLoad`` unit (+-1000 =
+-100 % of the torque limit). Time is the firmware's clock, in seconds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import numpy as np

#: The firmware's joints, in its order (T:102 fields; T:101 joint numbers 1..6).
JOINTS = ("base", "shoulder", "elbow", "wrist", "roll", "hand")
N_JOINTS = len(JOINTS)
ACC_UNIT = 100.0  # steps/s^2 per ACC register count
#: One turn of an STS servo, in steps: the servo holds its goal register to its angle limits (EEPROM registers 9 and 11,
#: 0 and 4095 by default) and its magnetic encoder reads one turn, 0-4095 (Feetech's SMS/STS memory table: SMS_STS.h
#: in github.com/ftservo/FTServo_stm32HAL, and the STS3215/ST3235 register lists)
POSITION_RANGE = (0.0, 4095.0)
#: ST3235 no-load speed: 0.222 s per 60 deg at 12 V (Waveshare's ST3235 page) = 4.72 rad/s = 3072 steps/s.
ST3235_MAX_SPEED = 3072.0


def servo_goal(goal: float) -> float:
    """A goal register write as the servo takes it: held to its angle limits (``POSITION_RANGE``)."""
    return min(max(float(goal), POSITION_RANGE[0]), POSITION_RANGE[1])


def servo_reading(position: float) -> float:
    """A present position as the servo's encoder reports it: one turn, 0-4095 steps (a shaft beyond it wraps)."""
    return float(position) % (POSITION_RANGE[1] + 1.0)


@runtime_checkable
class ServoModel(Protocol):
    """What the firmware's servo bus reaches: six joints (``JOINTS`` order), raw register values.

    The firmware calls ``advance(t)`` before every read and every write, with a non-decreasing ``t``
    (s, the firmware's clock); a model may integrate in any step it likes up to ``t``.
    """

    def command(self, joints: Sequence[int], goal: Sequence[float], spd: Sequence[float],
                acc: Sequence[float]) -> None:
        """Write goal position (steps), speed (steps/s register, 0 = the servo's business) and
        acceleration (register, units of 100 steps/s^2; 0 = the servo's business) of ``joints``
        (indices into ``JOINTS``). A position write while torque is off switches torque on for that
        servo (Feetech STS behaviour, as Waveshare's wiki describes the arm's "torque lock")."""

    def set_torque(self, on: bool, joints: Sequence[int] | None = None) -> None:
        """Torque enable register of ``joints`` (default all). Switched on, a servo drives to its
        goal register, which it kept while limp."""

    def advance(self, t: float) -> None:
        """Run the servos up to time ``t`` (s)."""

    def positions(self) -> np.ndarray:
        """(6,) present positions, steps (float; a servo read rounds them)."""

    def torque(self) -> np.ndarray:
        """(6,) bool, torque enable register."""

    def loads(self) -> np.ndarray:
        """(6,) present load, +-1000 (``ReadLoad``)."""


class KinematicServos:
    """Ideal servos: each runs its own trapezoid to its goal with the commanded ``spd``
    (0 = ``max_speed``) and ``acc`` (0 = no ramp), re-planned from its current velocity whenever a
    new goal arrives, and stops exactly at the goal. No position-loop lag, no gravity, no load.
    The motion is solved piecewise in closed form (cheap for any time step).

    ``positions0``: (6,) start positions (steps); ``t0``: start time (s).
    """

    def __init__(self, positions0: Sequence[float], t0: float = 0.0, *, max_speed: float = ST3235_MAX_SPEED,
                 max_accel: float = math.inf) -> None:
        self.t = float(t0)
        # plain lists: six scalars per call, where numpy's per-element overhead would dominate
        self._pos = [float(p) for p in positions0]
        self._goal = list(self._pos)
        self._vel = [0.0] * N_JOINTS
        self._spd = [0.0] * N_JOINTS
        self._acc = [0.0] * N_JOINTS
        self._on = [True] * N_JOINTS
        self.max_speed = float(max_speed)
        self.max_accel = float(max_accel)

    # read-only views for tests and the firmware model
    pos = property(lambda self: np.array(self._pos))
    goal = property(lambda self: np.array(self._goal))
    vel = property(lambda self: np.array(self._vel))
    spd = property(lambda self: np.array(self._spd))
    acc = property(lambda self: np.array(self._acc))

    # ------------------------------------------------------------------ ServoModel
    def command(self, joints: Sequence[int], goal: Sequence[float], spd: Sequence[float], acc: Sequence[float]) -> None:
        """See ``ServoModel.command``."""
        for j, g, s, a in zip(joints, goal, spd, acc):
            self._goal[j] = servo_goal(g)
            self._spd[j] = float(s)
            self._acc[j] = float(a)
            self._on[j] = True

    def set_torque(self, on: bool, joints: Sequence[int] | None = None) -> None:
        """See ``ServoModel.set_torque``."""
        for j in (range(N_JOINTS) if joints is None else joints):
            self._on[j] = bool(on)
            self._vel[j] = 0.0

    def place(self, joints: Sequence[int], positions: Sequence[float]) -> None:
        """An outside force (a hand) moved these servos while limp: they stand at ``positions`` (steps), at rest."""
        for j, p in zip(joints, positions):
            self._pos[j] = float(p)
            self._vel[j] = 0.0

    def advance(self, t: float) -> None:
        """See ``ServoModel.advance``: each servo's trapezoid, solved in closed form."""
        dt = t - self.t
        if dt <= 0:
            return
        pos, vel, goal = self._pos, self._vel, self._goal
        for j in range(N_JOINTS):
            if not self._on[j] or (pos[j] == goal[j] and vel[j] == 0.0):
                continue
            spd, acc = self._spd[j], self._acc[j]
            vcap = min(spd, self.max_speed) if spd > 0 else self.max_speed
            a = acc * ACC_UNIT if acc > 0 else self.max_accel
            pos[j], vel[j] = _trapezoid(pos[j], vel[j], goal[j], vcap, a, dt)
        self.t = float(t)

    def positions(self) -> np.ndarray:
        """See ``ServoModel.positions``."""
        return np.array(self._pos)

    def torque(self) -> np.ndarray:
        """See ``ServoModel.torque``."""
        return np.array(self._on)

    def loads(self) -> np.ndarray:
        """No load on ideal servos: zeros."""
        return np.zeros(N_JOINTS)


def _trapezoid(x: float, v: float, g: float, vcap: float, a: float, dt: float) -> tuple[float, float]:
    """One servo's position and velocity ``dt`` s later, moving to ``g`` with top speed ``vcap`` and
    acceleration ``a`` (inf: speed changes at once): accelerate (or slow down to ``vcap``), cruise,
    brake to stop exactly at the goal (braking harder than ``a`` when it is already too late)."""
    for _ in range(8):
        if dt <= 1e-12:
            break
        d = g - x
        if d == 0.0 and v == 0.0:
            break
        s = 1.0 if (d > 0 or (d == 0 and v < 0)) else -1.0
        dist, u = abs(d), v * s  # distance to go, speed toward the goal
        if math.isinf(a):
            step = min(vcap * dt, dist)
            x += s * step
            v = s * vcap if step < dist else 0.0
            break
        if u < 0:  # moving away: brake to a stop first
            tau = min(dt, -u / a)
            x += s * (u * tau + 0.5 * a * tau * tau)
            v = s * (u + a * tau)
            dt -= tau
            continue
        if u > 0 and u * u / (2 * a) >= dist:  # brake now, as hard as it takes to stop at the goal
            t_stop = 2 * dist / u
            if dt >= t_stop:
                x, v = g, 0.0
                break
            ab = u * u / (2 * dist)
            x += s * (u * dt - 0.5 * ab * dt * dt)
            v = s * (u - ab * dt)
            break
        if u > vcap:  # slow down to the top speed
            tau = min(dt, (u - vcap) / a)
            x += s * (u * tau - 0.5 * a * tau * tau)
            v = s * (u - a * tau)
            dt -= tau
            continue
        peak = math.sqrt((2 * a * dist + u * u) / 2)  # where accelerating meets braking
        if u < min(vcap, peak) - 1e-9:  # accelerate
            tau = min(dt, (min(vcap, peak) - u) / a)
            x += s * (u * tau + 0.5 * a * tau * tau)
            v = s * (u + a * tau)
            dt -= tau
            continue
        cruise = (dist - u * u / (2 * a)) / u if u > 0 else 0.0  # at top speed until the braking point
        tau = min(dt, max(cruise, 0.0))
        x += s * u * tau
        v = s * u
        dt -= tau
        if tau <= 1e-12:  # at the braking point: brake next
            ab = u * u / (2 * max(abs(g - x), 1e-12))
            t_stop = 2 * abs(g - x) / u
            if dt >= t_stop:
                x, v = g, 0.0
                break
            x += s * (u * dt - 0.5 * ab * dt * dt)
            v = s * (u - ab * dt)
            break
    return x, v
