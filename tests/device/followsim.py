"""Helpers for the follow tests on the simulated arms: a policy process's JSON lines over a pipe on a real-time
schedule, a simulated leader's guide, and the checks of what the follower's firmware really ran."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from typing import Any

import numpy as np

from roarmctl.device.follow import FollowConfig
from roarmctl.device.follow_guard import GuardLimits
from roarmctl.device.follow_session import Followed, LeaderSpec, follow_live, leader_tracking
from roarmctl.device.follow_sources import StreamSource
from roarmctl.device.guide import Guide
from roarmctl.device.protocol import WireMap
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")
WM = WireMap(ROBOT)
HOME = np.array([0.0, 0.0, 1.5708, 0.0, 0.0, 0.0])
_pose = np.eye(4)
_pose[:3, 3] = (0.35, 0.0, 0.1)
TABLE = SceneItem("table", "obstacle", "box", _pose, size=(0.3, 0.4, 0.2))  # top at z = 0.2 m in front of the arm
CHECKER = CollisionChecker(ROBOT, Scene([TABLE]), singularity_margin=0.02)


POLICY = """
import json, sys, time
lines = json.loads(sys.argv[1])
t0 = time.monotonic()
for t, text in lines:
    time.sleep(max(0.0, t0 + t - time.monotonic()))
    try:
        sys.stdout.write(text + "\\n")
        sys.stdout.flush()
    except BrokenPipeError:
        break
"""


class Policy:
    """A policy process: writes ``lines`` (``(t, obj)``: s after its start, the JSON object or a raw str) to its
    stdout on a real-time schedule; the follower reads its end of the pipe. It starts before the arm is ready (as a
    real one would: its first lines wait in the pipe)."""

    def __init__(self, lines: list[tuple[float, Any]]) -> None:
        self.lines = [(t, obj if isinstance(obj, str) else json.dumps(obj)) for t, obj in lines]
        self.proc: subprocess.Popen[bytes] | None = None

    def source(self) -> StreamSource:
        self.proc = subprocess.Popen([sys.executable, "-c", POLICY, json.dumps(self.lines)], stdout=subprocess.PIPE)
        assert self.proc.stdout is not None
        return StreamSource(ROBOT, self.proc.stdout.fileno(), "policy")

    def stop(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait(5)
            if self.proc.stdout is not None:
                self.proc.stdout.close()


def policy_line(t: float, q: np.ndarray) -> tuple[float, dict]:
    return t, {"t": t, "joints": [float(v) for v in q[:5]], "gripper": float(q[5])}


def ramp(t0: float, a, b, n: int, hz: float = 10.0) -> list[tuple[float, dict]]:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return [policy_line(t0 + k / hz, a + (b - a) * (k + 1) / n) for k in range(n)]


def run(*, policy: Policy | None = None, leader: LeaderSpec | None = None, **kw: Any) -> tuple[Followed, BaseException | None]:
    """Follow on the simulated arm; (what was recorded, the exception raised or None)."""
    duration = kw.pop("duration", None)
    cfg = FollowConfig(guard=GuardLimits(**kw), first_frame=10.0, duration=duration)
    try:
        src = policy.source() if policy is not None else None
        return follow_live(ROBOT, CHECKER, sim=True, source=src, leader=leader, config=cfg), None
    except Exception as exc:  # noqa: BLE001 - the tests look at it
        return exc.followed, exc  # type: ignore[attr-defined]
    finally:
        if policy is not None:
            policy.stop()


def commanded(done: Followed) -> tuple[np.ndarray, np.ndarray]:
    """(times s, (N, dof) rad) of the T:102 goals the follower's simulated firmware ran (its own record)."""
    assert done.executed is not None
    rows = [(t, c) for _, t, c in done.executed if c.get("T") == 102]
    return np.array([t for t, _ in rows]), np.array([WM.from_wire({f: c[f] for f in WM.field_names}) for _, c in rows])


def assert_nothing_unsafe_ran(done: Followed, rate: float = 50.0) -> np.ndarray:
    """Every goal the firmware ran: within limits (4-decimal wire), clear of the table, the arm and the singularity
    margin, and no step between two goals beyond what the joint velocity limits allow in one set-point interval."""
    _, q = commanded(done)
    assert len(q) >= 1
    lo, hi = ROBOT.lower - 1e-4, ROBOT.upper + 1e-4
    assert np.all((q >= lo) & (q <= hi))
    assert CHECKER.validity_batch(q[:, :5], gripper=q[:, 5]).all()
    steps = np.abs(np.diff(q, axis=0))
    assert np.all(steps <= ROBOT.velocity_limits / rate + 2e-4), steps.max(axis=0)
    return q


def guide(ts: list[float], qs: list[np.ndarray]) -> Guide:
    return Guide(np.array(ts, dtype=float), np.array(qs, dtype=float))


def swing(duration: float = 6.0, hz: float = 0.25) -> Guide:
    """A hand that keeps the leader moving: every joint on slow cosines from rest at HOME (every frame differs)."""
    ts = np.arange(0.1, duration, 0.1)
    def c(t: float, f: float) -> float:  # from rest: 0 .. 1 .. 0 with zero speed at the start
        return 0.5 * (1 - math.cos(2 * math.pi * f * t))

    qs = [HOME + [0.5 * c(t, hz), 0.15 * c(t, hz / 2), -0.1 * c(t, hz), 0.3 * c(t, hz), 0.2 * c(t, hz / 2),
                  0.4 * c(t, hz)] for t in ts]
    return guide(list(ts), qs)


def tracking(done: Followed) -> dict[str, float]:
    """The follower's true joints against the leader's (``follow_session.leader_tracking``)."""
    return leader_tracking(done.recording, done.leader_recording)
