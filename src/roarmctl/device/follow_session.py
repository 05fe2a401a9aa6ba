"""One following session from start to end, for the CLI (``roarmctl follow``) and the API alike: open the
follower (a port, or the firmware simulator on a pty), connect, start the source (a leader arm, also simulated, or
JSON lines), follow, hold if anything went wrong, give the leader its torque back, close, write the log.

What the simulators recorded (the follower's commands as its firmware ran them, both arms' true servo positions)
is returned for tests and benches (:class:`Followed`).
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.follow import FollowConfig, Follower, FollowResult, Source
from roarmctl.device.follow_guard import SourceLost
from roarmctl.device.follow_sources import LeaderSource
from roarmctl.device.guide import guided_servos
from roarmctl.device.link import Link
from roarmctl.device.protocol import WireMap
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.device.teach import Judge, TeachSession
from roarmctl.errors import DeviceError, InputError, RoarmError
from roarmctl.fileio import atomic_write_json

if TYPE_CHECKING:
    from roarmctl.device.guide import Guide
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.robot.model import Robot


@dataclass(frozen=True)
class LeaderSpec:
    """A leader arm: on ``port``, or simulated (``port`` None) with a ``guide`` hand script and ``faults`` (fields
    of the simulator's ``SimConfig``: fault injection); ``robot`` its description (default: the follower's)."""

    port: str | None = None
    guide: Guide | None = None
    robot: Robot | None = None
    faults: dict[str, Any] | None = None


@dataclass
class Followed:
    """A session's result, where it ran, and what the simulators recorded (None on real arms): ``executed``
    (the follower firmware's commands: (line complete, ran, command)), ``recording`` (follower) and
    ``leader_recording`` (times s, joints (N, 6) rad URDF, torque) on the monotonic clock."""

    result: FollowResult
    port: str
    executed: list[tuple[float, float, dict[str, Any]]] | None = None
    recording: Any = None
    leader_recording: Any = None


@contextlib.contextmanager
def _nothing() -> Iterator[None]:
    yield


def follow_live(robot: Robot, checker: CollisionChecker, *, port: str | None = None, sim: bool = False,
                source: Source | None = None, leader: LeaderSpec | None = None, config: FollowConfig | None = None,
                on_event: Callable[[str], None] | None = None, log_path: str | Path | None = None,
                shield: Callable[[], contextlib.AbstractContextManager[Any]] = _nothing,
                on_tick: Callable[[], None] | None = None) -> Followed:
    """Follow ``source`` (JSON lines, see ``roarmctl.device.follow_sources``) or ``leader`` with the arm on ``port``
    or the simulator (``sim``). Raises what :meth:`Follower.run` raises (after the hold), with the result as the
    exception's ``result`` and the :class:`Followed` as its ``followed``; the log goes to ``log_path`` on every way out once the follower's port opened.
    ``shield``: a context manager that keeps signals out of the cleanup (the CLI's); ``on_tick``: called once a pass
    of the follower's loop (``Follower``; the CLI checks for a stop there)."""
    if (port is None) == (not sim):
        raise InputError("follow: give exactly one of a port or the simulator")
    if (source is None) == (leader is None):
        raise InputError("follow: give exactly one source (JSON lines or a leader arm)")
    sims: list[PtySimulator] = []
    followed: Followed | None = None
    link: Link | None = None
    follower: Follower | None = None
    try:
        if sim:
            sims.append(PtySimulator(SimConfig(), process=True).start())
            port = sims[0].path
        assert port is not None
        link = Link(str(port))
        link.expect = WireMap(robot).model or "m3"
        link.open()
        link.connect()
        if leader is not None:  # its torque goes off (a hand moves it) once the follower is ready
            try:
                source = _leader_source(leader, robot, sims)
            except DeviceError as exc:  # a leader that cannot start is a lost source; the follower has not moved
                raise SourceLost(f"leader: {exc.message}", exc.hint) from None
        assert source is not None
        follower = Follower(link, robot, checker, source, config, on_event=on_event,
                            extra_lateness=sims[0].recent_lateness if sim else None, on_tick=on_tick)
        result = follower.run()
        followed = Followed(result, str(port))
    except RoarmError as exc:
        res = getattr(exc, "result", None)
        if res is None and follower is not None:
            res = FollowResult("failed", exc.message, follower.log("failed", exc.message))
            exc.result = res  # type: ignore[attr-defined]
        followed = Followed(res, str(port)) if res is not None else None
        exc.followed = followed  # type: ignore[attr-defined]  # filled with the simulators' records below
        raise
    finally:
        with shield():
            if source is not None:
                source.close()
            if link is not None:
                link.close()
            for k, s in enumerate(sims):
                if followed is not None:
                    if k == 0 and sim:
                        followed.executed, followed.recording = s.executed(), s.recording()
                    else:
                        followed.leader_recording = s.recording()
                s.stop()
            if log_path is not None and followed is not None and link is not None and link.ser is not None:
                try:
                    atomic_write_json(log_path, followed.result.log, indent=None)
                except (OSError, InputError) as exc:
                    warnings.warn(f"could not write the follow log {log_path}: {exc}", RuntimeWarning, stacklevel=2)
    return followed


def _leader_source(spec: LeaderSpec, robot: Robot, sims: list[PtySimulator]) -> Source:
    """Open, connect and start the leader (torque off) as a source."""
    lead_robot = spec.robot or robot
    port = spec.port
    if port is None:
        if spec.guide is None:
            raise InputError("a simulated leader needs a guide (the hand's script)")
        sims.append(PtySimulator(SimConfig(**(spec.faults or {})), servos=guided_servos(spec.guide), process=True).start())
        port = sims[-1].path
    link = Link(port)
    link.expect = WireMap(lead_robot).model or "m3"
    link.require_torque = False
    try:
        link.open()
        link.connect()
        session = TeachSession(link, lead_robot, Judge(lead_robot, 0.0))
        session.start()
    except BaseException:
        link.close()
        raise
    return LeaderSource(session, robot)


def leader_tracking(follower: Any, leader: Any, lags: np.ndarray | None = None) -> dict[str, float]:
    """How closely the follower followed the leader, from the two simulators' recordings ((times s, joints (N, 6)
    rad, torque), one monotonic clock): the lag (s, of ``lags``, default 0-1 s by 5 ms) that fits best (least squares
    over the arm joints), and at that lag the RMS and max over the follower's motion of the largest arm-joint error
    (rad)."""
    tf, qf, _ = follower
    tl, ql, _ = leader
    lags = np.arange(0.0, 1.0, 0.005) if lags is None else lags
    arm = qf.shape[1] - 1  # the RoArm's recordings: the arm joints, then the gripper
    moving = np.flatnonzero(np.linalg.norm(np.diff(qf[:, :arm], axis=0), axis=1) > 1e-6)
    if not len(moving):
        return {"latency_s": math.nan, "rms_rad": math.nan, "max_rad": math.nan}
    sel = slice(int(moving[0]), int(moving[-1]) + 1)
    t, q = tf[sel], qf[sel, :arm]
    best, fit = None, math.inf
    for lag in lags:  # the lag: least squares over every arm joint (a joint's constant offset does not hide it)
        ref = np.column_stack([np.interp(t - lag, tl, ql[:, j]) for j in range(arm)])
        sq = float(np.mean((q - ref) ** 2))
        if sq < fit:
            fit, best = sq, (float(lag), np.max(np.abs(q - ref), axis=1))
    assert best is not None
    lag, err = best
    return {"latency_s": lag, "rms_rad": float(np.sqrt(np.mean(err ** 2))), "max_rad": float(err.max())}
