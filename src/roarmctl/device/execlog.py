"""The execution log (``roarmctl.execlog/1``): one module owns its form, its writer and its reader.

``execute`` (``roarmctl.device.streamer``), ``teach`` (``roarmctl.device.teach``, the raw feedback stream) and
``simulate`` (``roarmctl.physics.report``, the run file) each build an ``ExecLog`` and write it with ``write_log``;
``export``, ``visualize-path`` and the validation of a run read it with ``read_log`` / ``parse_log``, which check
every field they use (times, numbers, sizes) so a hostile file is refused with exit 2 and one line naming the field.

A log is a JSON object: ``format``, ``port``, ``firmware``, ``robot`` (a name), ``device`` (what the arm said it
was, or null), ``speed_scale`` in (0, 1], ``t0_monotonic`` (s), what the writer records of its run (``details``:
the streamer's summary and tracking, teach's waypoints, the physics report), ``sent`` (``{"t", "cmd", ...}``, every
command sent) and ``received`` (``{"t", "line", "feedback"?, "read_t"?, ...}``, every line read); times ``t`` in s
after ``t0_monotonic``. A robot not bundled is carried as ``robot_description`` (``roarmctl.robot.bundle``).

A run of a trajectory (``execute``, ``simulate``) carries it whole as ``trajectory``: the document of the trajectory
that ran (``roarmctl.trajectory/1`` without its ``robot_description``, which is the log's), so the log alone is the
run with its scene, targets and marks. A copy, not a path and digest: the trajectory that ran is not always a file
(``execute --from-current`` plans its first motion again from the arm's pose; ``execute`` takes a plan file), a
path goes stale when files move, and a reader would otherwise open a file that a log names. A log of an older
roarmctl has none: its readers take the trajectory from the user (``-t``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roarmctl.checks import Checker, HugeNumber
from roarmctl.errors import TrajectoryFileError
from roarmctl.fileio import atomic_write_json
from roarmctl.formats import MAX_DURATION, MAX_POINTS, MIN_SPEED_SCALE, read_document

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory

FORMAT = "roarmctl.execlog/1"
MAX_LOG_ENTRIES = 10 * MAX_POINTS  # commands sent and lines received
MAX_LOG_TIME = 2 * MAX_DURATION + 600.0  # s, |t| of any entry: the slowest run of the longest trajectory, and its start
MAX_NAME = 255  # characters of the robot's name

CHECK = Checker(TrajectoryFileError, json=True, bound=math.inf, max_name=MAX_NAME)


@dataclass
class ExecLog:
    """One run's log as its writer builds it; ``to_dict`` is the document ``write_log`` writes.

    ``sent``/``received``: the entries (times ``t`` in s after ``t0_monotonic``); ``details``: the fields this
    kind of run records besides, in the order written; ``kind``: None for ``execute`` and ``simulate`` (whose
    logs look alike), ``"teach"`` for the raw feedback stream of a teach session."""

    robot: str
    port: str | None
    firmware: str | None
    speed_scale: float
    t0_monotonic: float
    sent: list[dict[str, Any]]
    received: list[dict[str, Any]]
    device: dict[str, Any] | None = None
    kind: str | None = None
    robot_description: dict[str, Any] | None = None
    details: dict[str, Any] = field(default_factory=dict)
    #: the trajectory that ran (``trajectory_document``), None for a run of no trajectory (teach)
    trajectory: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``roarmctl.execlog/1`` document (plain JSON values)."""
        head: dict[str, Any] = {"format": FORMAT}
        if self.kind is not None:
            head["kind"] = self.kind
        head |= {"port": self.port, "firmware": self.firmware, "robot": self.robot, "device": self.device}
        if self.robot_description is not None:  # a robot not bundled, carried (roarmctl.robot.bundle)
            head["robot_description"] = self.robot_description
        head |= {"speed_scale": self.speed_scale, "t0_monotonic": self.t0_monotonic}
        body = self.details | ({"trajectory": self.trajectory} if self.trajectory is not None else {})
        return head | body | {"sent": self.sent, "received": self.received}


def trajectory_document(traj: Trajectory) -> dict[str, Any]:
    """The document a log carries of the trajectory that ran: its file's, without the ``robot_description`` (the
    log carries the run's robot once, at its top)."""
    doc = traj.to_dict()
    doc.pop("robot_description", None)
    return doc


def carried_trajectory(log: dict[str, Any], where: str = "execution log") -> Trajectory | None:
    """The trajectory a log carries (``trajectory``), checked in form by the one trajectory reader
    (``roarmctl.motion.validate.parse_document``: its bounds on size and values), with the log's robot description;
    None for a log without one (teach, or an older roarmctl's). A damaged one raises ``TrajectoryFileError`` naming
    the log's field."""
    doc = log.get("trajectory")
    if doc is None:
        return None
    from roarmctl.motion.validate import parse_document

    CHECK.mapping(doc, where, "trajectory")
    traj = parse_document(doc, f"{where}: trajectory")
    traj.robot_description = log.get("robot_description")
    return traj


def write_log(path: str | Path, log: ExecLog | dict[str, Any]) -> Path:
    """Write an execution log atomically (compact JSON)."""
    doc = log.to_dict() if isinstance(log, ExecLog) else log
    return atomic_write_json(path, doc, indent=None)


def is_log(data: Any) -> bool:
    """Whether a parsed JSON document says it is an execution log."""
    return isinstance(data, dict) and data.get("format") == FORMAT


def read_log(path: str | Path) -> dict[str, Any]:
    """An execution log file, read within ``roarmctl.formats.MAX_FILE_BYTES`` and checked by ``parse_log``."""
    return parse_log(read_document(path), str(path))


def parse_log(data: Any, where: str = "execution log") -> dict[str, Any]:
    """An execution log checked in the fields its readers use: ``robot``, ``speed_scale`` in
    [``MIN_SPEED_SCALE``, 1], ``sent`` and ``received`` lists of at most ``MAX_LOG_ENTRIES`` entries whose ``t`` (s)
    are finite, within +-``MAX_LOG_TIME`` and never decreasing (a received entry's ``read_t``, when there, finite
    and not after its ``t``), commands and feedback as objects of finite numbers. Returns ``data``; raises
    ``TrajectoryFileError`` naming the field."""
    CHECK.mapping(data, where, "log")
    if data.get("format") != FORMAT:
        CHECK.fail(where, "format", f"expected '{FORMAT}', got {CHECK.kind(data.get('format'))}")
    CHECK.name(data.get("robot"), where, "robot")
    if data.get("speed_scale") is not None:
        CHECK.number(data["speed_scale"], where, "speed_scale", lo=MIN_SPEED_SCALE, hi=1.0)
    for key in ("sent", "received"):
        entries = data.get(key)
        if not isinstance(entries, list) or len(entries) > MAX_LOG_ENTRIES:
            CHECK.fail(where, key, f"expected a list of at most {MAX_LOG_ENTRIES} entries, got {CHECK.kind(entries)}")
        last = -math.inf
        inner = "cmd" if key == "sent" else "feedback"
        for i, e in enumerate(entries):
            f = f"{key}[{i}]"
            CHECK.mapping(e, where, f)
            t = CHECK.number(e.get("t"), where, f"{f}.t", lo=-MAX_LOG_TIME, hi=MAX_LOG_TIME)
            if t < last:
                CHECK.fail(where, f"{f}.t", f"{t:g} s is before the entry before it ({last:g} s)", "entries are in time order")
            last = t
            if key == "received" and e.get("read_t") is not None:  # when the servos were read: before the line arrived
                CHECK.number(e["read_t"], where, f"{f}.read_t", lo=-MAX_LOG_TIME, hi=t)
            body = e.get(inner)
            if body is None and key == "received":
                continue
            CHECK.mapping(body, where, f"{f}.{inner}")
            for k, v in body.items():
                if isinstance(v, (int, float, HugeNumber)) and not isinstance(v, bool):
                    CHECK.number(v, where, f"{f}.{inner}.{k}", lo=-1e6, hi=1e6)
    return data
