"""Servo models: how a commanded goal becomes a joint torque.

A servo here is a DC motor behind a gearbox, run by a position loop that follows a speed/acceleration
profile. Per servo, at every physics step (``TIMESTEP`` of ``roarmctl.physics.mjcf``):

1. the profile moves the loop's reference toward the goal (``profile_step``: the servo's own
   trapezoid, speed ``spd`` in steps/s, acceleration ``acc`` in units of 100 steps/s^2, 0 = no limit);
2. the position loop sets the motor's duty cycle from the error: ``duty = clip(kp * (ref - pos),
   -limit, limit)``, zero inside the dead band (P only: the RoArm firmware writes P and I = 0);
3. the motor gives ``torque = n * stall * (duty - speed / no_load_speed)`` at the joint (``n``
   servos on one joint): full torque at stall, none at the no-load speed, the straight torque-speed
   line of a DC motor at a fixed supply voltage. The ``- speed / no_load_speed`` part is the motor's
   back-EMF braking; the physics applies it as the joint's viscous damping ``n * stall / no_load_speed``
   (integrated implicitly by MuJoCo), the duty part as an applied torque.

The numbers of the Feetech ST3235 (``ST3235``) and their sources are in ``roarmctl.device.st3235`` (the
schedule's sag compensation uses the same ones). What this module adds:

* the speed register (address 46) counts steps/s, "0 means the maximum speed"; the acceleration register
  (address 41) counts 100 steps/s^2, "0 means maximum acceleration"; the dead band (addresses 26/27) is
  1 step by default; the torque limit (address 48) caps the duty: Feetech's STS memory table
  (ftservo/ftservo-wiki docs/en/reference/parameter/memory-sts.md @ 9522ce1). The same table says that with
  the 0.0146 rpm unit "its precision is also 0.732 rpm" (50 steps/s): we read that as the profile's speed
  being a multiple of 50 steps/s (``speed_quantum``; our reading);
* **assumed**: no velocity feed-forward in the loop; the profile continues from its own reference when a
  new goal arrives (it does not restart from the measured position);
* **assumed**: the rotor's inertia seen at the output is ``MECH_TIME_CONSTANT * stall / no_load_speed``
  (a 10 ms mechanical time constant, typical of small DC motors: 6.2e-3 kg m^2 for the ST3235);
  no gearbox friction or backlash.

For robots without servo data, ``generic_spec`` builds the same model from the description's effort
and velocity limits (assumptions stated there), and ``Servos`` then follows the planned motion with
velocity feed-forward (an industrial drive's behaviour), not a streamed profile.

Units: steps, steps/s, steps/s^2 inside the profile and the loop (a servo's own), N m and rad/s at the
joint.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from roarmctl.device import st3235

ACC_UNIT = 100.0  # steps/s^2 per acceleration register count (Feetech STS memory table, address 41)
MECH_TIME_CONSTANT = 0.010  # s, assumed (see the module doc)


@dataclass(frozen=True)
class ServoSpec:
    """One servo type.

    ``stall_torque`` N m and ``no_load_speed`` rad/s at the supply voltage; ``steps_per_rad`` of the
    encoder; ``kp`` duty (1 = 100 %) per step of position error; ``deadband`` steps;
    ``speed_quantum`` steps/s (the profile's speed resolution; 0: exact); ``max_speed`` steps/s of
    the profile for ``spd = 0`` (inf: the motor's own limit); ``armature`` kg m^2 of rotor inertia
    at the output; ``feedforward``: the loop adds the reference speed's duty (generic drives only).
    """

    name: str
    stall_torque: float
    no_load_speed: float
    steps_per_rad: float = st3235.STEPS_PER_RAD
    kp: float = st3235.KP
    deadband: float = 1.0
    speed_quantum: float = 50.0
    max_speed: float = math.inf
    armature: float = 0.0
    feedforward: bool = False

    @property
    def damping(self) -> float:
        """Back-EMF braking of one servo at the joint, N m s/rad."""
        return self.stall_torque / self.no_load_speed


def _st3235() -> ServoSpec:
    stall, no_load = st3235.STALL_TORQUE, st3235.NO_LOAD_SPEED
    return ServoSpec("ST3235", stall, no_load, armature=MECH_TIME_CONSTANT * stall / no_load)


ST3235 = _st3235()


def generic_spec(name: str, effort: float, velocity: float, *, error_at_full: float = 0.05) -> ServoSpec:
    """A position servo for a joint with effort limit ``effort`` (N m) and velocity limit ``velocity``
    (rad/s). **Assumed**: stall torque = the effort limit, no-load speed twice the velocity limit,
    full torque at ``error_at_full`` rad of error, a 10 ms mechanical time constant, velocity and torque
    feed-forward (the planned motion's inverse dynamics, as an industrial drive's model-based control),
    no dead band; positions in rad (``steps_per_rad`` 1)."""
    no_load = 2.0 * velocity
    return ServoSpec(f"generic {effort:g} N m", float(effort), float(no_load), steps_per_rad=1.0, kp=1.0 / error_at_full,
                     deadband=0.0, speed_quantum=0.0, armature=MECH_TIME_CONSTANT * effort / no_load, feedforward=True)


def with_limit(spec: ServoSpec, **changes: Any) -> ServoSpec:
    """A copy of ``spec`` with some fields changed (for tests and studies)."""
    return replace(spec, **changes)


def quantise_speed(spd: float, quantum: float) -> float:
    """A speed register (steps/s) as the servo runs it: a multiple of ``quantum`` (0: exact), at least one
    quantum when non-zero (0 stays 0: maximum speed)."""
    if spd <= 0:
        return 0.0
    if quantum <= 0:
        return spd
    return max(round(spd / quantum) * quantum, quantum)


def profile_step(pos: float, vel: float, goal: float, vmax: float, amax: float, dt: float) -> tuple[float, float]:
    """One step ``dt`` (s) of a servo's trapezoid toward ``goal``: speed at most ``vmax`` (inf: none),
    acceleration at most ``amax`` (inf: none, the speed jumps), stopping exactly at the goal; a new goal
    is taken from the current position and speed. Steps, steps/s, steps/s^2 (plain floats: a servo bank
    has a handful of channels and this runs every physics step)."""
    d = goal - pos
    if d == 0.0:
        return pos, (0.0 if abs(vel) < 1e-9 else vel)
    sign = 1.0 if d > 0 else -1.0
    if amax == math.inf:
        v = sign * min(vmax, abs(d) / dt)  # no ramp: the speed jumps, never past the goal
    else:
        vdes = sign * min(vmax, math.sqrt(2.0 * amax * abs(d)))  # fastest speed that can still stop at the goal
        lim = amax * dt
        v = vel + min(max(vdes - vel, -lim), lim)
    new = pos + v * dt
    if (goal - new) * sign < 0 and v * sign > 0:  # crossed the goal within the step
        return goal, 0.0
    return new, v


class ServoBank:
    """The servos of one robot: channel k drives joint ``joint[k]`` (an index into the robot's ``q``)
    with ``count[k]`` servos of ``spec[k]``; servo steps = ``zero[k] + sign[k] * steps_per_rad * q``.

    State per channel (servo units, plain lists): goal, speed and acceleration registers, the profile's
    reference and speed, torque on/off, torque limit (0..1 of full duty) and the last duty.
    """

    def __init__(self, joint: npt.ArrayLike, spec: list[ServoSpec], count: Iterable[float], sign: Iterable[float],
                 zero: Iterable[float], torque_limit: Iterable[float] | None = None) -> None:
        self.joint = np.asarray(joint, dtype=int)
        self.spec = list(spec)
        n = len(self.spec)
        self.count = [float(c) for c in count]
        self.sign = [float(v) for v in sign]
        self.zero = [float(v) for v in zero]
        self.limit = [1.0] * n if torque_limit is None else [float(v) for v in torque_limit]
        self.goal = [0.0] * n
        self.spd = [0.0] * n
        self.acc = [0.0] * n
        self.ref = [0.0] * n
        self.ref_vel = [0.0] * n
        self.enabled = [True] * n
        self.duty = [0.0] * n
        self._vmax = [math.inf] * n
        self._amax = [math.inf] * n
        # per channel: steps per joint unit with the sign, and the torque per unit of duty at the joint
        self._ks = [s.steps_per_rad * g for s, g in zip(self.spec, self.sign)]
        self._tau = [g * c * s.stall_torque for s, g, c in zip(self.spec, self.sign, self.count)]
        self._ff = [0.0] * n  # feed-forward duty (generic drives)

    @property
    def n(self) -> int:
        """Number of channels."""
        return len(self.spec)

    def steps(self, q: npt.ArrayLike) -> np.ndarray:
        """Servo positions (n,) steps of joint values ``q`` (dof,) rad."""
        q = np.asarray(q, dtype=float)
        return np.array([z + k * q[j] for z, k, j in zip(self.zero, self._ks, self.joint)])

    def joint_value(self, steps: Iterable[float]) -> np.ndarray:
        """Joint values (n,) rad of servo positions (n,) steps."""
        return np.array([(float(p) - z) / k for p, z, k in zip(steps, self.zero, self._ks)])

    def joint_damping(self) -> np.ndarray:
        """(n,) back-EMF damping at each channel's joint, N m s/rad (0 while torque is off)."""
        return np.array([c * s.damping if on else 0.0 for c, s, on in zip(self.count, self.spec, self.enabled)])

    def armature(self) -> np.ndarray:
        """(n,) rotor inertia the servos add at each channel's joint, kg m^2."""
        return np.array([c * s.armature for c, s in zip(self.count, self.spec)])

    def reset(self, q: npt.ArrayLike) -> None:
        """Torque on, everything at rest at ``q``: goal and reference = the present position."""
        p = self.steps(q).tolist()
        n = self.n
        self.goal, self.ref = list(p), list(p)
        self.ref_vel, self.spd, self.acc, self.duty = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
        self.enabled = [True] * n
        self._limits()

    def command(self, channels: Sequence[int], goal: Sequence[float], spd: Sequence[float],
                acc: Sequence[float]) -> None:
        """Write goal (steps), speed register (steps/s) and acceleration register (100 steps/s^2) of
        ``channels``; a servo whose torque was off is switched on from where it stands (``set_torque``)."""
        for c, g, s, a in zip(channels, goal, spd, acc):
            self.goal[c], self.spd[c], self.acc[c] = float(g), float(s), float(a)
        self._limits()

    def set_torque(self, on: bool, channels: Iterable[int], q: npt.ArrayLike) -> None:
        """Torque enable of ``channels``; switched on, the profile starts at the present position."""
        p = self.steps(q)
        for c in channels:
            if on and not self.enabled[c]:
                self.ref[c], self.ref_vel[c] = float(p[c]), 0.0
            self.enabled[c] = bool(on)
            if not on:
                self.duty[c] = 0.0

    def _limits(self) -> None:
        for c, s in enumerate(self.spec):
            v = quantise_speed(self.spd[c], s.speed_quantum)
            self._vmax[c] = v if v > 0 else s.max_speed
            self._amax[c] = self.acc[c] * ACC_UNIT if self.acc[c] > 0 else math.inf

    def follow(self, q_ref: Sequence[float] | np.ndarray, qd_ref: Sequence[float] | np.ndarray,
               tau_ref: Sequence[float] | np.ndarray | None = None) -> None:
        """Generic drives: the reference is the planned motion itself (positions (dof,) rad, speeds rad/s) and,
        with ``tau_ref`` (dof,) N m, the torque it needs (fed forward)."""
        for c, j in enumerate(self.joint):
            self.ref[c] = self.zero[c] + self._ks[c] * float(q_ref[j])
            self.ref_vel[c] = self._ks[c] * float(qd_ref[j])
            self.goal[c] = self.ref[c]
            self._ff[c] = 0.0 if tau_ref is None else float(tau_ref[j]) / (self.sign[c] * self.count[c] * self.spec[c].stall_torque)

    def torques(self, q: list[float], dt: float, profile: bool = True) -> list[float]:
        """Advance the profiles by ``dt`` (s) and return the duty torque (n,) N m at each channel's joint
        (``q``: the robot's joint values as a list; the back-EMF part is the joint damping)."""
        out = [0.0] * self.n
        for c, spec in enumerate(self.spec):
            if not self.enabled[c]:
                self.duty[c] = 0.0
                continue
            if profile:
                self.ref[c], self.ref_vel[c] = profile_step(self.ref[c], self.ref_vel[c], self.goal[c],
                                                            self._vmax[c], self._amax[c], dt)
            err = self.ref[c] - (self.zero[c] + self._ks[c] * q[self.joint[c]])
            if abs(err) <= spec.deadband:
                err = 0.0
            duty = spec.kp * err
            if spec.feedforward:
                duty += self.ref_vel[c] / (spec.steps_per_rad * spec.no_load_speed) + self._ff[c]
            lim = self.limit[c]
            duty = lim if duty > lim else (-lim if duty < -lim else duty)
            self.duty[c] = duty
            out[c] = self._tau[c] * duty
        return out

    def loads(self) -> np.ndarray:
        """Present load (n,) as the servo reports it: the duty in 0.1 % (+-1000)."""
        return np.round(np.array(self.duty) * 1000.0)
