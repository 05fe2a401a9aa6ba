"""A hand for the simulated arm: while a servo's torque is off, its position follows a script.

``roarmctl sim-device --guide FILE`` and ``roarmctl teach --sim --guide FILE`` read FILE, a YAML list of
``{t: s, joints: [rad, ...], gripper: rad}``: ``t`` counts from the moment torque went off, ``joints``
are the arm's joint values and ``gripper`` the gripper joint's, all in the robot description's
convention (URDF radians, as plans and ``kin`` use them). Between entries the hand moves linearly; it
starts where the arm stood when torque went off (so the first entry should come some time after 0 s)
and stays at the last entry. Each time torque goes off the script starts again.

What a limp RoArm does, from Waveshare's RoArm-M3 example firmware (public copy
github.com/jhacksman/RoArm-M3, 0.84 build, ``RoArm-M3_module.h``): ``{"T":210,"cmd":0}`` calls
``servoTorqueCtrl(254, 0)``, a broadcast torque-disable (lines 116-121); a limp servo keeps reporting
its position, so the feedback follows the hand. A position write switches a limp servo's torque on
(Feetech STS), and torque on drives each servo to the goal it last had. :class:`GuidedServos` wraps any
:class:`~roarmctl.device.servos.ServoModel` that can be ``place``d (the kinematic servos): when a
servo takes torque again it stands where the hand left it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roarmctl.device.fwmath import INIT_RAD, command_to_goal
from roarmctl.device.servos import N_JOINTS, ST3235_MAX_SPEED, KinematicServos, ServoModel
from roarmctl.errors import InputError
from roarmctl.validation import load_yaml

MAX_ENTRIES = 10_000
MAX_SECONDS = 3600.0
ARM_JOINTS = 5  # the RoArm-M3's arm joints before the gripper (base, shoulder, elbow, wrist, roll)


@dataclass(frozen=True)
class Guide:
    """The script: ``t`` (N,) s from torque-off, increasing; ``q`` (N, 6) URDF radians (5 arm joints + gripper)."""

    t: np.ndarray
    q: np.ndarray

    @property
    def duration(self) -> float:
        """Time of the last entry (s)."""
        return float(self.t[-1])


def load_guide(path: str | Path) -> Guide:
    """Read and check a guide file (bounded YAML reader). Raises InputError (exit 2) naming the entry."""
    raw = load_yaml(path, InputError, what=None)
    name = str(path)
    if not isinstance(raw, list) or not raw:
        raise InputError(f"{name}: expected a list of {{t: seconds, joints: [rad x {ARM_JOINTS}], gripper: rad}}")
    if len(raw) > MAX_ENTRIES:
        raise InputError(f"{name}: {len(raw)} entries, more than {MAX_ENTRIES}")
    ts: list[float] = []
    qs: list[list[float]] = []
    line_of = getattr(raw, "line_of", lambda i: 0)
    for i, entry in enumerate(raw):
        where = f"{name}:{line_of(i)}: entry {i + 1}"
        if not isinstance(entry, dict) or set(entry) - {"t", "joints", "gripper"} or not {"t", "joints"} <= set(entry):
            raise InputError(f"{where}: expected {{t: seconds, joints: [rad x {ARM_JOINTS}], gripper: rad}}")
        t = _number(entry["t"], f"{where}.t")
        if not 0.0 <= t <= MAX_SECONDS:
            raise InputError(f"{where}.t: {t:g} s is outside 0..{MAX_SECONDS:g} s")
        if ts and t <= ts[-1]:
            raise InputError(f"{where}.t: {t:g} s does not come after {ts[-1]:g} s", "times must increase")
        joints = entry["joints"]
        if not isinstance(joints, list) or len(joints) != ARM_JOINTS:
            raise InputError(f"{where}.joints: expected a list of {ARM_JOINTS} joint values (rad)")
        q = [_number(v, f"{where}.joints[{k}]") for k, v in enumerate(joints)]
        grip = _number(entry["gripper"], f"{where}.gripper") if "gripper" in entry else (qs[-1][-1] if qs else None)
        if grip is None:
            raise InputError(f"{where}: the first entry needs 'gripper' (rad)")
        if any(abs(v) > 2 * math.pi for v in (*q, grip)):
            raise InputError(f"{where}: joint values are radians (|value| <= 2 pi)", "convert degrees with math.radians")
        ts.append(t)
        qs.append([*q, grip])
    return Guide(np.array(ts), np.array(qs))


def _number(v: object, where: str) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise InputError(f"{where}: expected a number, got {v!r}")
    return float(v)


def urdf_to_steps(q6: Sequence[float]) -> np.ndarray:
    """(6,) URDF radians of the M3 (gripper q = pi - hand) -> present servo positions (steps, float):
    the exact inverse of the firmware's ``calculateRadByFeedback`` (``fwmath.position_to_rad``), no clamps:
    a hand is not bound by the firmware's command clamps."""
    b, s, e, t, r, g = (float(v) for v in q6)
    hand = math.pi - g
    k = 4096 / (2 * math.pi)
    return np.array([(math.pi - b) * k, (s + math.pi) * k, (e + math.pi / 2) * k, (t + math.pi) * k,
                     (math.pi - r) * k, hand * k])


class GuidedServos:
    """A :class:`ServoModel` whose limp servos follow a :class:`Guide` (see the module docstring).

    ``inner``: the servos when they have torque; it must have ``place(joints, positions)``.
    """

    def __init__(self, inner: ServoModel, guide: Guide) -> None:
        if not hasattr(inner, "place"):
            raise InputError("needs servos that a hand can move (the ideal ones)", option="guide")
        self.inner = inner
        self.guide = guide
        self.t = 0.0
        self._t_off: float | None = None
        self._start = np.asarray(inner.positions(), dtype=float)
        self._limp = ~np.asarray(inner.torque(), dtype=bool)
        self._steps = np.array([urdf_to_steps(q) for q in guide.q])  # (N, 6) steps
        if self._limp.any():  # started limp: the hand starts now
            self._t_off = 0.0

    # ------------------------------------------------------------------ the hand
    def hand(self, t: float) -> np.ndarray:
        """(6,) positions (steps) the hand holds the servos at, at time ``t`` (s, the firmware's clock)."""
        tau = t - (self._t_off if self._t_off is not None else t)
        ts = np.concatenate([[0.0], self.guide.t]) if self.guide.t[0] > 0 else self.guide.t
        ps = np.vstack([self._start, self._steps]) if self.guide.t[0] > 0 else self._steps
        return np.array([np.interp(tau, ts, ps[:, j]) for j in range(N_JOINTS)])

    def _limp_positions(self) -> np.ndarray:
        pos = np.asarray(self.inner.positions(), dtype=float).copy()
        if self._limp.any():
            pos[self._limp] = self.hand(self.t)[self._limp]
        return pos

    def _take_torque(self, joints: Iterable[int]) -> None:
        """Joints that get torque again stand where the hand left them."""
        joints = [j for j in joints if self._limp[j]]
        if not joints:
            return
        here = self._limp_positions()
        self.inner.place(joints, [float(here[j]) for j in joints])
        self._limp[joints] = False

    # ------------------------------------------------------------------ ServoModel
    def command(self, joints: Sequence[int], goal: Sequence[float], spd: Sequence[float], acc: Sequence[float]) -> None:
        """A position write: a limp servo takes torque where the hand left it, then drives to the goal."""
        self._take_torque(list(joints))
        self.inner.command(joints, goal, spd, acc)

    def set_torque(self, on: bool, joints: Sequence[int] | None = None) -> None:
        """Torque on: the servo stands where the hand left it (then drives to its kept goal). Off: the hand
        takes the servos from where they stand, and its script starts again."""
        js = list(range(N_JOINTS)) if joints is None else list(joints)
        if on:
            self._take_torque(js)
        else:
            was = self._limp.copy()
            self._start = self._limp_positions()
            self._limp[js] = True
            if not was[js].all():
                self._t_off = self.t
        self.inner.set_torque(on, joints)

    def advance(self, t: float) -> None:
        """Run the servos with torque up to ``t``; the limp ones are where the hand is."""
        self.inner.advance(t)
        self.t = max(self.t, float(t))

    def positions(self) -> np.ndarray:
        """See ``ServoModel.positions``."""
        return self._limp_positions()

    def torque(self) -> np.ndarray:
        """See ``ServoModel.torque``."""
        return np.asarray(self.inner.torque())

    def loads(self) -> np.ndarray:
        """See ``ServoModel.loads``."""
        return np.asarray(self.inner.loads())


def guided_servos(guide: Guide, max_speed: float | None = None) -> Callable[[], GuidedServos]:
    """A zero-argument factory (for ``PtySimulator(servos=...)``, also in its own process) of the ideal
    kinematic servos, started as the firmware's default ones, with ``guide``'s hand on the limp ones."""
    def make() -> GuidedServos:
        start = [float(command_to_goal(j, INIT_RAD[j])) for j in range(N_JOINTS)]
        return GuidedServos(KinematicServos(start, max_speed=max_speed or ST3235_MAX_SPEED), guide)

    return make
