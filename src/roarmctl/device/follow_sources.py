"""Where a follower's targets come from: JSON lines (a policy process writing to stdin or to a local socket) or a
leader arm (its feedback frames, read as ``teach`` reads them, with its torque off).

A recorded episode (:class:`ReplaySource`: a LeRobot dataset's ``action`` column, read by the CLI) is played back
on this host's clock.

A JSON line is one object ``{"t": s, "joints": [rad x arm joints], "gripper": rad}``: ``t`` on the source's own
clock (increasing), the arm joints and the gripper in the robot description's convention (URDF radians, as plans
and ``kin`` use them); ``gripper`` may be left out (the last one stays). A line that is not such an object is a
refused frame (it counts toward the guard's run); ``NaN`` and ``Infinity`` are read as numbers so that the guard
refuses them by name. Lines are bounded (``MAX_LINE`` bytes), and so is what one poll reads.

The leader arm (:class:`LeaderSource`) is a :class:`~roarmctl.device.teach.TeachSession` on its own port: torque
off after two agreeing frames, every frame through the one feedback validator (a failed read's +pi, a NaN, a value
faster than a hand, a torque or supply fault are refused there and count here), torque on at its measured pose when
following ends. Its gripper is mapped from the leader's closed..open range onto the follower's.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import socket
import stat
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.device.feedback import FeedbackRefused
from roarmctl.device.follow import SourceEnded
from roarmctl.device.follow_guard import SourceLost, Target
from roarmctl.device.protocol import LineBuffer
from roarmctl.errors import DeviceError, InputError

if TYPE_CHECKING:
    from roarmctl.device.teach import TeachSession
    from roarmctl.robot.model import Robot

MAX_LINE = 65536  # bytes of one JSON line
MAX_READ = 1 << 20  # bytes read in one poll
KEYS = {"t", "joints", "gripper"}


class JsonLines:
    """Targets from JSON lines for ``robot``; ``feed(data, now)`` parses bytes as they come."""

    def __init__(self, robot: Robot, name: str) -> None:
        self.robot = robot
        self.name = name
        self.lines = LineBuffer(MAX_LINE)
        self.arm = list(robot.arm_indices)
        self.grip = robot.joint_index(robot.gripper.joint) if robot.gripper is not None else None
        self.gripper: float | None = None  # the last gripper value given
        self._refused: list[tuple[float, str]] = []
        self.count = 0

    def feed(self, data: bytes, now: float) -> list[Target]:
        """The targets of the complete lines in ``data`` (malformed ones go to ``refusals``)."""
        out = []
        for raw in self.lines.feed(data):
            if not raw.strip():
                continue
            self.count += 1
            tg = self.parse(raw, now)
            if isinstance(tg, str):
                self._refused.append((now, f"line {self.count}: {tg}"))
            else:
                out.append(tg)
        return out

    def parse(self, raw: bytes, now: float) -> Target | str:
        """One line -> a Target, or why it is not one."""
        try:
            obj = json.loads(raw.decode("utf-8"), parse_constant=float)
        except (UnicodeDecodeError, ValueError, RecursionError):
            return "not a JSON object"
        if not isinstance(obj, dict):
            return "not a JSON object"
        if not {"t", "joints"} <= set(obj) or set(obj) - KEYS:
            extra = sorted(set(obj) - KEYS)
            return f"unknown key {extra[0]!r}" if extra else "expected {\"t\": s, \"joints\": [rad, ...], \"gripper\": rad}"
        t = _number(obj["t"])
        joints = obj["joints"]
        n = len(self.arm)
        if t is None:
            return f"t is {obj['t']!r}, not a number of seconds"
        if not isinstance(joints, list) or len(joints) != n or any(_number(v) is None for v in joints):
            return f"joints must be a list of {n} numbers (rad)"
        q = np.zeros(self.robot.dof)
        q[self.arm] = [_number(v) for v in joints]
        if self.grip is not None:
            if "gripper" in obj:
                g = _number(obj["gripper"])
                if g is None:
                    return f"gripper is {obj['gripper']!r}, not a number (rad)"
                self.gripper = g
            if self.gripper is None:
                return "the first line needs 'gripper' (rad)"
            q[self.grip] = self.gripper
        return Target(t, q, now)

    def refusals(self) -> list[tuple[float, str]]:
        """See ``Source.refusals``."""
        out, self._refused = self._refused, []
        return out


def _number(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


def _fed(parser: JsonLines, read: Callable[[], bytes], now: float, what: str) -> list[Target]:
    """The targets of what ``read()`` has for a JSON-lines source now (none while nothing waits); its end raises
    ``SourceEnded``, a read error ``SourceLost`` naming ``what``."""
    try:
        data = read()
    except (BlockingIOError, InterruptedError):
        return []
    except OSError as exc:
        raise SourceLost(f"source lost: {what} ({exc})") from None
    if not data:
        raise SourceEnded
    return parser.feed(data, now)


class StreamSource:
    """JSON lines from an open file descriptor (stdin, a pipe): read without waiting; end of file ends the source."""

    def __init__(self, robot: Robot, fd: int, name: str = "stdin") -> None:
        self.fd = fd
        self.name = name
        self.parser = JsonLines(robot, name)
        self._blocking = os.get_blocking(fd)
        os.set_blocking(fd, False)

    def poll(self, now: float) -> list[Target]:
        """See ``Source.poll``."""
        return _fed(self.parser, lambda: os.read(self.fd, MAX_READ), now, f"cannot read {self.name}")

    def refusals(self) -> list[tuple[float, str]]:
        """See ``Source.refusals``."""
        return self.parser.refusals()

    def close(self) -> None:
        """Give the descriptor its blocking mode back."""
        with contextlib.suppress(OSError):
            os.set_blocking(self.fd, self._blocking)


class SocketSource:
    """JSON lines from the one process that connects to the Unix socket ``path`` (created here, removed at close;
    an existing file is refused). Its disconnection ends the source."""

    def __init__(self, robot: Robot, path: str | Path) -> None:
        self.path = Path(path)
        self.name = f"socket {self.path}"
        if self.path.exists() or self.path.is_symlink():
            raise InputError(f"{self.path}: the file exists", "give a new path (roarmctl creates the socket)", option="socket")
        self.parser = JsonLines(robot, self.name)
        self.server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self.server.bind(str(self.path))
        except OSError as exc:
            self.server.close()
            raise InputError(f"{self.path}: cannot create it ({exc.strerror or exc})", option="socket") from None
        self._inode = self.path.stat().st_ino
        self.server.listen(1)
        self.server.setblocking(False)
        self.conn: socket.socket | None = None

    def poll(self, now: float) -> list[Target]:
        """See ``Source.poll``."""
        if self.conn is None:
            try:
                self.conn, _ = self.server.accept()
            except (BlockingIOError, InterruptedError):
                return []
            self.conn.setblocking(False)
        conn = self.conn
        return _fed(self.parser, lambda: conn.recv(MAX_READ), now, self.name)

    def refusals(self) -> list[tuple[float, str]]:
        """See ``Source.refusals``."""
        return self.parser.refusals()

    def close(self) -> None:
        """Close the connection and the socket; remove the socket file this source made (and only that)."""
        for s in (self.conn, self.server):
            if s is not None:
                with contextlib.suppress(OSError):
                    s.close()
        with contextlib.suppress(OSError):
            st = self.path.lstat()
            if stat.S_ISSOCK(st.st_mode) and st.st_ino == self._inode:
                self.path.unlink()


class ReplaySource:
    """Recorded targets played back on this host's clock: ``times`` (F,) s increasing, ``targets`` (F, dof) rad in
    the robot's joint order (a dataset episode's ``action`` column); frame k is due ``times[k] - times[0]`` s after
    the first poll. The end of the frames ends the source."""

    def __init__(self, times: np.ndarray, targets: np.ndarray, name: str) -> None:
        self.times = np.asarray(times, dtype=float)
        self.targets = np.asarray(targets, dtype=float)
        if self.times.ndim != 1 or self.targets.shape[:1] != self.times.shape or len(self.times) == 0:
            raise InputError(f"{name}: expected (F,) times and (F, dof) targets, got {self.times.shape} and "
                             f"{self.targets.shape}")
        self.name = name
        self.k = 0
        self.t0: float | None = None

    def poll(self, now: float) -> list[Target]:
        """See ``Source.poll``."""
        if self.t0 is None:
            self.t0 = now
        if self.k >= len(self.times):
            raise SourceEnded
        due = self.times[0] + (now - self.t0)
        out = []
        while self.k < len(self.times) and self.times[self.k] <= due:
            out.append(Target(float(self.times[self.k]), self.targets[self.k].copy(), now))
            self.k += 1
        return out

    def refusals(self) -> list[tuple[float, str]]:
        """See ``Source.refusals`` (none: the frames are numbers already)."""
        return []

    def close(self) -> None:
        """Nothing to give back."""


class LeaderSource:
    """A leader arm's feedback frames as targets for the follower ``robot``: ``session`` is a started
    :class:`TeachSession` (torque off) on the leader's link; the gripper maps from ``session.robot``'s range."""

    def __init__(self, session: TeachSession, robot: Robot) -> None:
        self.session = session
        self.robot = robot
        self.name = f"leader {session.link.port}"
        self._refused_seen = session.validator.refused
        self._line_seen: Any = session.link.received[-1] if session.link.received else None
        self._last = session.last
        self._refused: list[tuple[float, str]] = []
        lead = session.robot
        if lead.arm_dof != robot.arm_dof:
            raise InputError(f"the leader ({lead.name}) has {lead.arm_dof} arm joints, the follower ({robot.name}) "
                             f"{robot.arm_dof}", "follow with a leader of the same kind")

    def map(self, q_leader: np.ndarray) -> np.ndarray:
        """The leader's joints (its dof,) -> the follower's (dof,): arm joints as they are, the gripper's
        closed..open fraction onto the follower's closed..open."""
        lead, fol = self.session.robot, self.robot
        q = np.zeros(fol.dof)
        q[fol.arm_indices] = np.asarray(q_leader)[lead.arm_indices]
        if fol.gripper is not None:
            g = fol.joint_index(fol.gripper.joint)
            if lead.gripper is None:
                q[g] = fol.gripper.open
            else:
                lg = float(q_leader[lead.joint_index(lead.gripper.joint)])
                span = lead.gripper.open - lead.gripper.closed
                frac = (lg - lead.gripper.closed) / span if span else 0.0
                q[g] = fol.gripper.closed + frac * (fol.gripper.open - fol.gripper.closed) if math.isfinite(frac) else lg
        return q

    def poll(self, now: float) -> list[Target]:
        """See ``Source.poll``: the newest accepted leader frame, if a new one came."""
        s = self.session
        try:
            s.pump()
        except FeedbackRefused as exc:
            raise SourceLost(f"leader: {exc.message}", "the follower holds; check the leader's power and cable") from None
        except DeviceError as exc:
            raise SourceLost(f"leader: {exc.message}", exc.hint) from None
        # a line that starts as a feedback frame but does not parse (a NaN, a cut line) never reaches the validator
        rec = s.link.received
        lines = []
        for r in reversed(rec):  # back to the last line seen (the session trims the front of the list)
            if r is self._line_seen:
                break
            lines.append(r)
        for r in reversed(lines):
            if r.feedback is None and r.line.startswith('{"T":1051'):
                self._refused.append((r.t, f"leader frame: not a valid feedback frame: {r.line[:60]!r}"))
        if rec:
            self._line_seen = rec[-1]
        v = s.validator
        if v.refused > self._refused_seen:
            new = list(v.refusals)[-(v.refused - self._refused_seen):]
            self._refused += [(r.t, f"leader frame: {r.reason}") for r in new]
            self._refused_seen = v.refused
        if s.last is None or s.last is self._last:
            return []
        self._last = s.last
        # dated by when the leader's servos were read: at most a round trip after the question it answers (a host
        # that reads the answer late, on a loaded machine, would otherwise crowd two frames' motion into a short time)
        t = s.last.t
        info = s.link.info
        if s.asked_at is not None and info is not None:
            t = min(t, s.asked_at + info.rtt)
        return [Target(t, self.map(s.last.q), t)]

    def refusals(self) -> list[tuple[float, str]]:
        """See ``Source.refusals``."""
        out, self._refused = self._refused, []
        return out

    def close(self) -> None:
        """Torque on at the leader's measured pose (it does not move), then close its port."""
        try:
            self.session.hold_here()
        finally:
            self.session.link.close()
