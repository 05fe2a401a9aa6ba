"""Jerk-limited following: Ruckig's online trajectory generation from the state last commanded to the newest
accepted target, sampled once per set-point, so that a 10 Hz source does not make a 10 Hz staircase.

The motion's clock runs only when a set-point is sent (a firmware that is behind makes it wait, as the plan's clock
waits in ``roarmctl.device.streamer``), so the set-points sent are exactly the motion's samples ``dt`` apart and
the servos, which run straight from one goal to the next, move on the chords between them. :meth:`Smoother.check`
therefore checks those samples and the chords between them (every ``resolution`` rad) before a motion is taken:
within every joint's limits, clear of the scene and the arm itself, outside the singularity margin. A motion that
fails is not taken; the one in progress (checked when it was taken, to its end) goes on.

Ruckig (Berscheid and Kroeger, "Jerk-limited Real-time Trajectory Generation with Arbitrary Target States", RSS
2021; pypi ``ruckig``) gives the time-optimal motion within per-joint velocity, acceleration and jerk limits from any
state (position, velocity, acceleration) to a target at rest.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.follow_guard import Verdict
from roarmctl.errors import InputError
from roarmctl.motion.collision import densify

if TYPE_CHECKING:
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.robot.model import Robot

MAX_SAMPLES = 20_000  # set-points of one motion at most (400 s at 50 Hz): a longer one is refused


class Motion:
    """One jerk-limited motion: ``samples`` (K, dof) rad, the set-points at ``dt``, 2 ``dt``, ... after its
    start (the last one is the target), and their velocities and accelerations (K, dof)."""

    def __init__(self, samples: np.ndarray, velocities: np.ndarray, accelerations: np.ndarray) -> None:
        self.samples = samples
        self.velocities = velocities
        self.accelerations = accelerations


class Smoother:
    """Ruckig toward the newest target for ``robot`` (all its joints, gripper included), one set-point every
    ``dt`` s, within ``velocity_scale`` / ``acceleration_scale`` of the robot's limits and its jerk limits.

    ``start`` (dof,) rad: where the arm stands (at rest). ``position`` is the last set-point taken by
    :meth:`step`; ``velocity``/``acceleration`` its state.
    """

    def __init__(self, robot: Robot, start: np.ndarray, dt: float, *, velocity_scale: float = 1.0,
                 acceleration_scale: float = 1.0) -> None:
        from ruckig import InputParameter, Ruckig, Trajectory

        self.robot = robot
        self.dt = float(dt)
        n = robot.dof
        self._otg, self._inp, self._traj = Ruckig(n), InputParameter(n), Trajectory(n)
        self._inp.max_velocity = list(robot.velocity_limits * velocity_scale)
        self._inp.max_acceleration = list(robot.acceleration_limits * acceleration_scale)
        if robot.jerk_limits is None:  # every loaded robot has them (the loader fills them in)
            raise InputError(f"robot '{robot.name}' has no jerk limits: following needs them")
        self._inp.max_jerk = list(robot.jerk_limits)
        self.position = np.asarray(start, dtype=float).copy()
        self.velocity = np.zeros(n)
        self.acceleration = np.zeros(n)
        self.motion: Motion | None = None
        self.k = 0  # samples of ``motion`` taken
        self.computed = 0  # motions computed (the bench's count)

    def plan(self, target: np.ndarray) -> Motion | str:
        """The motion from the current state to ``target`` (dof,) rad, arriving at rest, or why there is none.

        (Passing a moving source's targets at its estimated speed was tried: with a leader's frames arriving 25-45 ms
        apart the speed estimate is noisy, and the lag to the leader grew from 0.11 to 0.17 s, tests/device/followsim.)
        """
        from ruckig import Result, RuckigError

        inp = self._inp
        n = len(self.position)
        inp.current_position = list(self.position)
        inp.current_velocity = list(self.velocity)
        inp.current_acceleration = list(self.acceleration)
        inp.target_position = list(np.asarray(target, dtype=float))
        inp.target_velocity = [0.0] * n
        inp.target_acceleration = [0.0] * n
        self.computed += 1
        try:
            result = self._otg.calculate(inp, self._traj)
        except RuckigError as exc:
            return f"no jerk-limited motion to it ({exc})"
        if result not in (Result.Working, Result.Finished):
            return f"no jerk-limited motion to it (ruckig: {result.name})"
        duration = float(self._traj.duration)
        k = max(1, math.ceil(duration / self.dt - 1e-9))
        if k > MAX_SAMPLES:
            return f"the motion to it takes {duration:.1f} s, more than {MAX_SAMPLES * self.dt:g} s"
        states = [self._traj.at_time(min(i * self.dt, duration)) for i in range(1, k + 1)]
        pos = np.array([s[0] for s in states])
        pos[-1] = target  # at rest there, exactly
        return Motion(pos, np.array([s[1] for s in states]), np.array([s[2] for s in states]))

    def check(self, motion: Motion, checker: CollisionChecker, resolution: float = 0.01) -> Verdict | None:
        """None when every set-point of ``motion`` is within the joint limits and it and the chords between
        them (from the current set-point on) are clear; else the refusal ("motion")."""
        robot = self.robot
        lo, hi = robot.lower - 1e-9, robot.upper + 1e-9
        out = np.flatnonzero(np.any((motion.samples < lo) | (motion.samples > hi), axis=0))
        if out.size:
            name = robot.joint_names[int(out[0])]
            return Verdict("motion", f"the jerk-limited motion to it overshoots {name}'s limits")
        path = densify(np.vstack([self.position, motion.samples]), resolution)
        arm = robot.arm_indices
        g = robot.joint_index(robot.gripper.joint) if robot.gripper is not None else None
        bad = checker.first_invalid(path[:, arm], gripper=None if g is None else path[:, g])
        if bad is None:
            return None
        if g is not None:
            checker.set_gripper(float(path[bad, g]))
        return Verdict("motion", f"the jerk-limited motion to it: {checker.explain(path[bad, arm])}")

    def take(self, motion: Motion) -> None:
        """Follow ``motion`` from the next set-point on."""
        self.motion, self.k = motion, 0

    @property
    def moving(self) -> bool:
        """Whether set-points of the current motion are still to be taken."""
        return self.motion is not None and self.k < len(self.motion.samples)

    def step(self) -> np.ndarray:
        """The next set-point (dof,) rad (the last one again at rest)."""
        m = self.motion
        if m is not None and self.k < len(m.samples):
            self.position = m.samples[self.k].copy()
            self.velocity = m.velocities[self.k].copy()
            self.acceleration = m.accelerations[self.k].copy()
            self.k += 1
            if self.k == len(m.samples):
                self.velocity[:] = 0.0
                self.acceleration[:] = 0.0
        return self.position

    def state(self) -> dict[str, Any]:
        """The state for the log."""
        return {"position": [round(float(v), 6) for v in self.position], "motions": self.computed}
