"""The guard of a live source: every joint target a leader arm or a policy sends is judged here before it can
move the arm, and a source that goes wrong ends the following.

Why it exists: on the stock RoArm-M3 firmware a follower swung 180 degrees when its leader's servos lost power
(a failed servo read keeps its previous value, 0 steps until a read succeeded, which converts to +pi on base and
roll: ``getFeedback`` in Waveshare's ``RoArm-M3_module.h``, lines 71-96 of the 0.84 example firmware in the public
copy github.com/jhacksman/RoArm-M3, whose ``docs/FIRMWARE-SAFETY-FIX.md`` tells of the swing), and LeRobot's
followers only clip each step's relative target (``max_relative_target``).

A target (:class:`Target`: the source's own time stamp and a joint vector) is accepted only when, in this order:

1. it is fresh: its stamp comes after the last frame's (a repeat or an older frame is *stale*), it was not
   delivered later than ``max_lag`` beyond the quickest delivery seen (the source's clock against this host's),
   and its values are not bit-for-bit those of the frames of the last ``frozen_after`` s (a frozen source:
   a failed read repeats the previous value);
2. every value is a finite number, within the joint's limits (a value at most ``limit_tolerance`` beyond a limit is
   taken as the limit: a leader's reading of a joint at its limit can round past it by a servo step);
3. the step from the last accepted target is within the budget: per joint, at most ``max_velocity x dt`` and
   at most ``max_acceleration x dt^2`` away from where the last velocity would have taken it (``dt``: the
   source's time between the two, at most this host's plus ``max_lag``, so a stamp cannot buy a larger step while
   frames that queued up in a pipe still pass; a value that jumped by pi and stayed needs pi / 2 rad/s = 1.6 s of
   refusals before it fits a RoArm joint's budget, far more than ``max_refusals`` frames of any source);
4. the target, and the straight joint-space segment to it from the last accepted one (every ``resolution``
   rad), is clear of the scene and of the arm itself and outside the singularity margin (the planner's own
   ``CollisionChecker``);
5. what the caller adds (``extra``): the follower checks the jerk-limited motion it will really command.

A refused target is not sent; the arm goes on to (and stays at) the last accepted one. ``max_refusals`` refused
targets in a row, or no frame for ``timeout`` s, raise :class:`SourceLost` (a ``DeviceError``: exit 4): the
caller holds the arm.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.checks import Bound, check_options
from roarmctl.errors import DeviceError
from roarmctl.motion.collision import interpolate

if TYPE_CHECKING:
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.robot.model import Robot

KINDS = ("source", "stale", "frozen", "not_finite", "joint_limit", "step", "collision", "singularity", "motion")


class SourceLost(DeviceError):
    """The source is lost (silent beyond the timeout) or refused too often in a row (exit 4); the arm must hold."""


#: GuardLimits' bounds (``roarmctl.checks.check_options``): times in s, angles in rad.
GUARD_BOUNDS = {
    "velocity_scale": Bound(0.0, 1.0, strict_lo=True),  # share of the joint velocity limits
    "acceleration_scale": Bound(0.0, 1.0, strict_lo=True),
    "step_tolerance": Bound(0.0, 0.5),
    "start_tolerance": Bound(0.0, math.pi),
    "timeout": Bound(0.0, 60.0, strict_lo=True),
    "max_lag": Bound(0.0, 60.0, strict_lo=True),
    "frozen_after": Bound(0.0, 3600.0),  # 0: never
    "max_refusals": Bound(1, 1000, whole=True),
    "resolution": Bound(0.0, 0.1, strict_lo=True),
    "limit_tolerance": Bound(0.0, 0.1),
}


@dataclass(frozen=True)
class GuardLimits:
    """The guard's options, each checked on creation (``GUARD_BOUNDS``). Times in s, angles in rad.

    ``velocity_scale``/``acceleration_scale``: the share of the robot's joint velocity and acceleration limits
    a step may use; ``step_tolerance``: rad added to every step bound (the source's own jitter);
    ``start_tolerance``: how far the first target may be from the measured pose, per joint; ``timeout``: silence
    that loses the source; ``max_lag``: delivery later than the quickest seen that makes a frame stale;
    ``frozen_after``: identical frames for this long make the source frozen (0: never); ``max_refusals``: refused
    targets in a row that end the following; ``resolution``: rad between the states checked along a segment;
    ``limit_tolerance``: rad beyond a joint limit that is taken as the limit.
    """

    velocity_scale: float = 1.0
    acceleration_scale: float = 1.0
    step_tolerance: float = 0.02
    start_tolerance: float = 0.15
    timeout: float = 0.5
    max_lag: float = 0.25
    frozen_after: float = 2.0
    max_refusals: int = 5
    resolution: float = 0.01
    limit_tolerance: float = 0.005

    def __post_init__(self) -> None:
        check_options(self, GUARD_BOUNDS)


@dataclass(frozen=True)
class Target:
    """One frame of a source: ``t`` s on the source's own clock, ``q`` (dof,) rad in the robot description's
    convention (gripper included), ``received`` s on this host's clock."""

    t: float
    q: np.ndarray
    received: float


@dataclass(frozen=True)
class Verdict:
    """The guard's answer: ``kind`` "ok" or one of ``KINDS``, and the one-line reason ("" when accepted)."""

    kind: str
    reason: str = ""

    @property
    def accepted(self) -> bool:
        """Whether the target may be followed."""
        return self.kind == "ok"


class Guard:
    """Judge the targets of one source for ``robot`` with ``checker`` (its scene, padding and singularity margin).

    ``start``: (dof,) the arm's measured pose; the first target must be within ``start_tolerance`` of it.
    Counts (``accepted``, ``refused``, by kind) and the last refusals are kept for the log.
    """

    def __init__(self, robot: Robot, checker: CollisionChecker, limits: GuardLimits | None = None, *,
                 start: np.ndarray, keep: int = 1000) -> None:
        self.robot = robot
        self.checker = checker
        self.lim = limits or GuardLimits()
        self.vmax = robot.velocity_limits * self.lim.velocity_scale
        self.amax = robot.acceleration_limits * self.lim.acceleration_scale
        self.lower, self.upper = robot.lower, robot.upper
        self.arm = np.asarray(robot.arm_indices)
        self.grip = robot.joint_index(robot.gripper.joint) if robot.gripper is not None else None
        self.last_q = np.asarray(start, dtype=float).copy()  # the last accepted target (the measured pose at first)
        self.last_t: float | None = None  # its source time
        self.last_at: float | None = None  # its host time
        self.velocity = np.zeros(robot.dof)  # rad/s between the last two accepted targets
        self.seen_t: float | None = None  # the last frame's source time (any frame)
        self.heard: float | None = None  # the last frame's host time (any frame)
        self.quickest: float | None = None  # least (received - t) seen: the source's clock against ours
        self.same_q: np.ndarray | None = None
        self.same_since: float | None = None  # source time since which every frame had the values same_q
        self.run = 0
        self.accepted = 0
        self.refused = 0
        self.by_kind: dict[str, int] = {}
        self.refusals: deque[dict[str, Any]] = deque(maxlen=keep)

    # ------------------------------------------------------------------ judging
    def check(self, target: Target, extra: Callable[[np.ndarray], Verdict | None] | None = None) -> Verdict:
        """Judge and count ``target``; on acceptance it becomes the last accepted one. ``extra(q)`` is asked last
        (None or an accepted verdict: fine). Raises SourceLost on the ``max_refusals``-th refusal in a row."""
        verdict = self._fresh(target)
        if verdict is None:
            verdict = self._values(target.q)
        if verdict is None:
            target = Target(target.t, np.clip(target.q, self.lower, self.upper), target.received)
        if verdict is None:
            verdict = self._step(target)
        if verdict is None:
            verdict = self._clear(target.q)
        if verdict is None and extra is not None:
            verdict = extra(target.q)
        if verdict is None or verdict.accepted:
            return self._accept(target)
        return self._refuse(target, verdict)

    def _fresh(self, tg: Target) -> Verdict | None:
        seen, self.seen_t, self.heard = self.seen_t, tg.t, tg.received
        if not math.isfinite(tg.t):
            return Verdict("stale", f"the frame's time stamp is {tg.t!r}, not a number of seconds")
        if seen is not None and tg.t <= seen:
            self.seen_t = seen
            return Verdict("stale", f"stale frame: stamped {tg.t:.3f} s, not after the previous frame's {seen:.3f} s")
        offset = tg.received - tg.t
        self.quickest = offset if self.quickest is None else min(self.quickest, offset)
        if offset - self.quickest > self.lim.max_lag:
            return Verdict("stale", f"stale frame: delivered {offset - self.quickest:.3f} s later than the source's "
                                    f"quickest (more than {self.lim.max_lag:g} s)")
        q = np.asarray(tg.q, dtype=float)
        if self.same_q is not None and q.shape == self.same_q.shape and np.array_equal(q, self.same_q):
            assert self.same_since is not None
            if self.lim.frozen_after > 0 and tg.t - self.same_since > self.lim.frozen_after:
                return Verdict("frozen", f"frozen source: the same values for {tg.t - self.same_since:.2f} s "
                                         f"(more than {self.lim.frozen_after:g} s; a failed read repeats its last value)")
        else:
            self.same_q, self.same_since = q.copy(), tg.t
        return None

    def _values(self, q: np.ndarray) -> Verdict | None:
        names = self.robot.joint_names
        if q.shape != (self.robot.dof,):
            return Verdict("not_finite", f"the target has {q.size} values, the robot {self.robot.dof} joints")
        bad = np.flatnonzero(~np.isfinite(q))
        if bad.size:
            return Verdict("not_finite", f"{names[bad[0]]} is {q[bad[0]]!r}, not a finite number")
        tol = self.lim.limit_tolerance + 1e-9
        out = np.flatnonzero((q < self.lower - tol) | (q > self.upper + tol))
        if out.size:
            j = int(out[0])
            return Verdict("joint_limit", f"joint limit: {names[j]} = {q[j]:.4f} rad is outside "
                                          f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")
        return None

    def _step(self, tg: Target) -> Verdict | None:
        names, tol = self.robot.joint_names, self.lim.step_tolerance
        d = tg.q - self.last_q
        if self.last_t is None or self.last_at is None:
            far = np.flatnonzero(np.abs(d) > self.lim.start_tolerance)
            if far.size:
                j = int(far[0])
                return Verdict("step", f"the first target is {abs(d[j]):.3f} rad from the arm on {names[j]} (more than "
                                       f"{self.lim.start_tolerance:g}): start the source where the arm stands")
            return None
        dt = self._dt(tg.t, tg.received)
        over_v = np.abs(d) - (self.vmax * dt + tol)
        over_a = np.abs(d - self.velocity * dt) - (self.amax * dt * dt + tol)
        for over, what, bound in ((over_v, "velocity", self.vmax), (over_a, "acceleration", self.amax)):
            j = int(np.argmax(over))
            if over[j] > 0:
                unit = "rad/s" if what == "velocity" else "rad/s^2"
                return Verdict("step", f"{names[j]} steps {d[j]:+.3f} rad in {dt:.3f} s: beyond its {what} budget "
                                       f"({bound[j]:g} {unit})")
        return None

    def _clear(self, q: np.ndarray) -> Verdict | None:
        res = self.lim.resolution
        path = interpolate(self.last_q, q, res)
        grip = None if self.grip is None else path[:, self.grip]
        # the target itself first: a target in the table is refused as such, not at the segment's first touch
        bad = None if self.checker.first_invalid(path[-1:, self.arm], gripper=None if grip is None else grip[-1:]) is None \
            else len(path) - 1
        if bad is None:
            bad = self.checker.first_invalid(path[:, self.arm], gripper=grip)
        if bad is None:
            return None
        if self.grip is not None:
            self.checker.set_gripper(float(path[bad, self.grip]))
        why = self.checker.explain(path[bad, self.arm])
        kind = "singularity" if "singular" in why else "joint_limit" if why.startswith("joint limit") else "collision"
        where = "at the target" if bad == len(path) - 1 else f"{bad / (len(path) - 1):.0%} of the way to it"
        return Verdict(kind, f"{why} ({where})")

    def _dt(self, t_src: float, t_host: float) -> float:
        """s from the last accepted target to one at source time ``t_src`` that arrived at ``t_host``."""
        assert self.last_t is not None and self.last_at is not None
        return max(min(t_src - self.last_t, t_host - self.last_at + self.lim.max_lag), 1e-3)

    # ------------------------------------------------------------------ counting
    def _accept(self, tg: Target) -> Verdict:
        q = np.asarray(tg.q, dtype=float)
        if self.last_t is not None and self.last_at is not None:
            dt = self._dt(tg.t, tg.received)
            self.velocity = (q - self.last_q) / dt
        self.last_q, self.last_t, self.last_at = q.copy(), tg.t, tg.received
        self.accepted += 1
        self.run = 0
        return Verdict("ok")

    def _refuse(self, tg: Target, verdict: Verdict) -> Verdict:
        self.refused += 1
        self.run += 1
        self.by_kind[verdict.kind] = self.by_kind.get(verdict.kind, 0) + 1
        self.refusals.append({"t": tg.received, "kind": verdict.kind, "reason": verdict.reason})
        if self.run >= self.lim.max_refusals:
            raise SourceLost(f"{self.run} targets refused in a row: {verdict.reason}",
                             "the arm holds at the last accepted target; fix the source, then follow again")
        return verdict

    def refuse_frame(self, received: float, kind: str, reason: str) -> None:
        """Count a frame refused before it became a target (``received``: host time, s): a leader frame its
        validator refused, a line that is not a target. Raises SourceLost as ``check`` does."""
        self.heard = received
        self._refuse(Target(math.nan, np.zeros(0), received), Verdict(kind, reason))

    def check_silence(self, now: float) -> None:
        """Raise SourceLost when no frame came for ``timeout`` s (``now``: this host's clock, s; the silence
        counts from ``since`` until the first frame)."""
        if self.heard is not None and now - self.heard > self.lim.timeout:
            raise SourceLost(f"source lost: no frame for {now - self.heard:.2f} s (timeout {self.lim.timeout:g} s)",
                             "the arm holds at the last accepted target; check the source process or the leader's cable")

    def expect_from(self, now: float) -> None:
        """Start counting silence at ``now`` (before the first frame)."""
        if self.heard is None:
            self.heard = now

    def summary(self) -> dict[str, Any]:
        """Counts and the last refusals, for the log."""
        return {"accepted": self.accepted, "refused": self.refused, "by_kind": dict(self.by_kind),
                "refusals": list(self.refusals)[-20:]}
