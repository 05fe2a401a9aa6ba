"""The RoArm JSON-over-serial wire protocol (M3 firmware 0.84; the M2's T:102/T:1051 subset):
encoding, feedback parsing, units.

Host -> arm: one compact JSON object per line ending in ``\\n``. Arm -> host: lines ending in
``\\r\\n``; only ``"T":1051`` lines are feedback, everything else (boot text, echoes, warnings) is
ignored. Sources: Waveshare's RoArm-M3 example firmware 0.84 (RoArm-M3_example-250108: uart_ctrl.h
reads a line up to ``\n`` and drops what ``deserializeJson`` rejects; json_cmd.h lists the T codes;
RoArm-M3_module.h converts radians to servo steps and prints T:1051) and Waveshare's Python SDK
(waveshareteam/waveshare_roarm_sdk, roarm_sdk/common.py: ``hand = pi - q_gripper`` for the M3).

This module is pure (no I/O, no serial import): the link, the streamer, ``--output`` and the
simulator all share it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from roarmctl.errors import DescriptionError
from roarmctl.robot.model import WIRE_FIELDS

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

BAUDRATE = 115200
BYTES_PER_SECOND = BAUDRATE / 10.0  # 8N1: 10 bits per byte on the wire
STEPS_PER_REV = 4096
STEPS_PER_RAD = STEPS_PER_REV / (2.0 * math.pi)  # 651.9 servo steps per radian
MIDDLE = 2047
ACC_UNIT = 100.0  # the servo ACC register counts 100 steps/s^2
SPD_MAX_REGISTER = 4096
ACC_MAX_REGISTER = 254

#: T:102 joint fields of the M3 firmware, in the firmware's joint order (1..6 for T:101).
M3_FIELDS = WIRE_FIELDS
#: The matching T:1051 feedback keys.
M3_FEEDBACK_KEYS = ("b", "s", "e", "t", "r", "g")
#: T:102 joint fields of the RoArm-M2 firmware (waveshare_roarm_sdk roarm_sdk/common.py,
#: handle_m2_joints_radian) and its T:1051 keys, where ``t`` is the gripper.
M2_FIELDS = ("base", "shoulder", "elbow", "hand")
M2_FEEDBACK_KEYS = ("b", "s", "e", "t")
#: Protocol model -> (T:102 fields, T:1051 keys), chosen by the description's wire fields.
MODELS = {"m3": (M3_FIELDS, M3_FEEDBACK_KEYS), "m2": (M2_FIELDS, M2_FEEDBACK_KEYS)}
#: Strictly inside the firmware's clamps: base/roll +pi would map to servo step -1 (invalid), so
#: keep one count inside; the others are the 0.84 firmware's own clamps (``RoArmM3_*JointCtrlRad`` in
#: RoArm-M3_module.h: shoulder and wrist +-pi/2, elbow 512..3071 steps, hand 700..3396 steps).
SAFE_WIRE_RANGE = {
    "base": (-math.pi + 1.5 / STEPS_PER_RAD, math.pi - 1.5 / STEPS_PER_RAD),
    "shoulder": (-math.pi / 2, math.pi / 2),
    "elbow": ((512 - 1024) / STEPS_PER_RAD, (3071 - 1024) / STEPS_PER_RAD),
    "wrist": (-math.pi / 2, math.pi / 2),
    "roll": (-math.pi + 1.5 / STEPS_PER_RAD, math.pi - 1.5 / STEPS_PER_RAD),
    "hand": (700 / STEPS_PER_RAD, 3396 / STEPS_PER_RAD),
}


def encode(obj: dict[str, Any]) -> bytes:
    """One command line: compact JSON (so the newer firmware's ``"T":0`` fast path matches) + ``\\n``."""
    return (json.dumps(obj, separators=(",", ":"), allow_nan=False) + "\n").encode()


def r4(x: float) -> float:
    """Round to 4 decimals (0.1 mrad, well below one servo step of 1.5 mrad); no negative zero."""
    v = round(float(x), 4)
    return 0.0 if v == 0 else v


def steps_per_s(rad_per_s: float) -> float:
    """A joint speed in servo steps/s (4096 per turn) from rad/s."""
    return abs(rad_per_s) * STEPS_PER_RAD


def spd_register(rad_per_s: float, minimum: int = 1) -> int:
    """``spd`` for a joint speed (rad/s): steps/s rounded up; never 0 (0 means *maximum* speed)."""
    return int(min(SPD_MAX_REGISTER, max(minimum, math.ceil(steps_per_s(rad_per_s) - 1e-9))))


def acc_register(rad_per_s2: float, minimum: int = 1) -> int:
    """``acc`` for a joint acceleration (rad/s^2) in units of 100 steps/s^2, rounded up; never 0."""
    return int(min(ACC_MAX_REGISTER, max(minimum, math.ceil(abs(rad_per_s2) * STEPS_PER_RAD / ACC_UNIT - 1e-9))))


def joints_command(wire: dict[str, float], spd: int, acc: int, fields: tuple[str, ...] = M3_FIELDS) -> dict[str, Any]:
    """``T:102`` with every joint field of the model (missing keys would read as 0 on the arm) and
    explicit spd/acc. ``fields``: ``M3_FIELDS`` (six) or ``M2_FIELDS`` (four).

    ``wire`` maps field name -> firmware radians. Values are clamped to ``SAFE_WIRE_RANGE`` and
    rounded to 4 decimals.
    """
    missing = [f for f in fields if f not in wire]
    if missing:
        raise ValueError(f"T:102 needs every joint field; missing {missing}")
    cmd: dict[str, Any] = {"T": 102}
    for f in fields:
        lo, hi = SAFE_WIRE_RANGE[f]
        v = float(wire[f])
        if not math.isfinite(v):
            raise ValueError(f"T:102 {f}: value {v} is not finite")
        cmd[f] = r4(min(max(v, lo), hi))
    cmd["spd"] = int(spd)
    cmd["acc"] = int(acc)
    return cmd


def feedback_request() -> dict[str, Any]:
    """The ``T:105`` request for one ``T:1051`` feedback line."""
    return {"T": 105}


def quiet_command() -> dict[str, Any]:
    """InfoPrint 0: stop the echo and the unsolicited feedback stream."""
    return {"T": 605, "cmd": 0}


class WireMap:
    """Joint vector <-> firmware fields for one robot, from its description's ``wire`` list.

    ``q`` is (dof,) in ``robot.joint_names`` order (gripper last), radians, URDF convention.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        by_field = {w.field: w for w in robot.wire}
        self.model = next((m for m, (fields, _) in MODELS.items() if set(by_field) == set(fields)), None)
        if self.model is None:
            missing = [f for f in M3_FIELDS if f not in by_field]
            raise DescriptionError(
                f"robot '{robot.name}' has no RoArm wire mapping for {', '.join(missing) or 'these fields'}"
                f" (wire fields: {', '.join(by_field) or 'none'})",
                "only robots with a 'wire' section for base/shoulder/elbow/wrist/roll/hand (RoArm-M3) or "
                "base/shoulder/elbow/hand (RoArm-M2) can be executed",
            )
        self.field_names, self.feedback_keys = MODELS[self.model]
        self.fields = [by_field[f] for f in self.field_names]
        self.index = [robot.joint_index(w.joint) for w in self.fields]

    def to_wire(self, q: npt.ArrayLike) -> dict[str, float]:
        """Joint values (dof,) rad -> {device field: firmware radians}, clamped."""
        q = np.asarray(q, dtype=float)
        return {w.field: w.to_wire(float(q[i])) for w, i in zip(self.fields, self.index)}

    def to_wire_array(self, q: npt.ArrayLike) -> np.ndarray:
        """(N, dof) joint values -> (N, fields) firmware radians in ``field_names`` order, clamped."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.empty((q.shape[0], len(self.fields)))
        for k, (w, i) in enumerate(zip(self.fields, self.index)):
            out[:, k] = np.clip(w.offset + w.sign * q[:, i], w.lower, w.upper)
        return out

    def from_wire(self, values: dict[str, float] | Iterable[float]) -> np.ndarray:
        """Firmware radians (dict by field, or values in ``field_names`` order) -> (dof,) joint vector."""
        if isinstance(values, dict):
            vals = [float(values[f]) for f in self.field_names]
        else:
            vals = [float(v) for v in values]
        q = np.zeros(self.robot.dof)
        for w, i, v in zip(self.fields, self.index, vals):
            q[i] = w.from_wire(v)
        return q

    def command(self, q: npt.ArrayLike, spd: int, acc: int) -> dict[str, Any]:
        """The joints command (``T:102``) that drives the arm to ``q`` (dof,) rad with these ``spd``/``acc``."""
        return joints_command(self.to_wire(q), spd, acc, self.field_names)

    def hold(self, wire: dict[str, float], spd: int, acc: int) -> dict[str, Any]:
        """``T:102`` for firmware radians ``wire`` (by field) in this model's fields."""
        return joints_command(wire, spd, acc, self.field_names)


# ----------------------------------------------------------------------------- feedback
#: Longest line taken as feedback: a real 20260701 T:1051 line is about 324 bytes.
MAX_FEEDBACK_LINE = 2048
#: Largest magnitude a T:1051 number may have (x/y/z are mm within about 600, loads +-1000, v centivolts).
MAX_FEEDBACK_NUMBER = 1e5
_MAX_DIGITS = 15


@dataclass
class Feedback:
    """One parsed ``T:1051`` line. ``joints``: firmware radians by field name (``M3_FIELDS``;
    ``M2_FIELDS`` for M2 frames); ``xyz``: firmware FK end point in mm (origin at the shoulder-axis
    height); ``firmware``: see ``identify_firmware``; ``problems``: why a value could not be taken
    (a joint named there is missing from ``joints``)."""

    raw: dict[str, Any]
    joints: dict[str, float]
    xyz: tuple[float, float, float]
    firmware: str
    extra: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


class _Unsane(str):
    """A number token too long to be a sane value, kept as its text (never turned into a number;
    a log that records it stays valid JSON)."""

    def short(self) -> str:
        return f"{self[:12]}... ({len(self)} characters)" if len(self) > 16 else str(self)


def _bounded_int(text: str) -> Any:
    return _Unsane(text) if len(text.lstrip("-")) > _MAX_DIGITS else int(text)


def _bounded_float(text: str) -> Any:
    v = float(text) if len(text) <= 40 else math.inf
    return v if math.isfinite(v) else _Unsane(text)


def _no_constant(text: str) -> Any:
    return _Unsane(text)  # NaN, Infinity, -Infinity: not numbers here


def parse_json_line(line: bytes | str) -> dict[str, Any] | None:
    """A complete line -> JSON object, or None for anything else (boot text, partial, garbage, too long).

    Numbers are bounded while parsing: an integer of more than 15 digits, a float token over 40
    characters and NaN/Infinity become opaque values that no numeric check accepts.
    """
    if len(line) > MAX_FEEDBACK_LINE:
        return None
    if isinstance(line, bytes):
        try:
            line = line.decode("utf-8")
        except UnicodeDecodeError:
            return None
    line = line.strip()
    if not (line.startswith("{") and line.endswith("}")):
        return None
    try:
        obj = json.loads(line, parse_int=_bounded_int, parse_float=_bounded_float, parse_constant=_no_constant)
    except (ValueError, RecursionError):
        return None
    return obj if isinstance(obj, dict) else None


def identify_firmware(obj: dict[str, Any]) -> str:
    """Tell firmware builds apart by their T:1051 fields (``RoArmM3_infoFeedback`` in RoArm-M3_module.h
    lines 596-621 of the 0.84 build; the 20260701 build adds ``torswitch*`` and ``v``; the M2 keys
    from roarm_sdk/common.py).

    ``"m3-0.84"`` (b s e t r g, tit), ``"m3-2026"`` (adds torswitch* and v), ``"m2"`` (b s e t
    only, torB..), ``"unknown"`` otherwise.
    """
    keys = set(obj)
    if all(k in keys for k in M3_FEEDBACK_KEYS):
        if any(k.startswith("torswitch") for k in keys) or "v" in keys:
            return "m3-2026"
        return "m3-0.84"
    if all(k in keys for k in ("b", "s", "e", "t")) and ("torB" in keys or "r" not in keys):
        return "m2"
    return "unknown"


def number(v: Any) -> float | None:
    """A JSON value as a finite float of sane size (|v| <= MAX_FEEDBACK_NUMBER), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) and abs(v) <= MAX_FEEDBACK_NUMBER else None


_num = number


def describe(v: Any) -> str:
    """A short text of a bad value for an error message."""
    return v.short() if isinstance(v, _Unsane) else (f"{v!r}"[:20])


def parse_feedback_report(line: bytes | str | dict[str, Any]) -> Feedback | None:
    """A ``"T":1051`` line -> Feedback (with ``problems`` for values that are not finite numbers of
    sane size); None for any other line."""
    obj = line if isinstance(line, dict) else parse_json_line(line)
    if obj is None or obj.get("T") != 1051:
        return None
    fw = identify_firmware(obj)
    joints: dict[str, float] = {}
    problems: list[str] = []
    if fw.startswith("m3") or fw == "m2":
        fields, keys = MODELS["m2" if fw == "m2" else "m3"]
        for f, k in zip(fields, keys):
            v = number(obj.get(k))
            if v is None:
                problems.append(f"{f} read {describe(obj.get(k))}: not a finite number of sane size")
            else:
                joints[f] = v
    else:
        problems.append("a T:1051 line without the joint keys b s e t r g")
    x, y, z = (number(obj.get(k)) or 0.0 for k in ("x", "y", "z"))
    xyz = (x, y, z)
    used = set(M2_FEEDBACK_KEYS if fw == "m2" else M3_FEEDBACK_KEYS)
    extra = {k: v for k, v in obj.items() if k not in used | {"T", "x", "y", "z"}}
    return Feedback(raw=obj, joints=joints, xyz=xyz, firmware=fw, extra=extra, problems=problems)


def parse_feedback(line: bytes | str | dict[str, Any]) -> Feedback | None:
    """A ``"T":1051`` line whose joint values are all finite numbers of sane size -> Feedback; None
    for any other line (``parse_feedback_report`` says why)."""
    fb = parse_feedback_report(line)
    return fb if fb is not None and not fb.problems else None


class LineBuffer:
    """Bytes in, complete lines out (split on ``\\n``, ``\\r`` stripped). Overlong junk is dropped."""

    def __init__(self, max_line: int = 8192) -> None:
        self._buf = bytearray()
        self.max_line = max_line

    def feed(self, data: bytes) -> list[bytes]:
        """Add received bytes; return the lines now complete."""
        self._buf.extend(data)
        lines = []
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                break
            lines.append(bytes(self._buf[:i]).rstrip(b"\r"))
            del self._buf[: i + 1]
        if len(self._buf) > self.max_line:
            self._buf.clear()
        return lines

    def clear(self) -> None:
        """Forget a partial line."""
        self._buf.clear()


def wire_seconds(nbytes: int) -> float:
    """Time (s) ``nbytes`` take on the 115200 8N1 link."""
    return nbytes / BYTES_PER_SECOND


READ_BEFORE_PRINT = 0.004  # s: from the firmware's servo reads to the first byte of its T:1051 line (an estimate)


def feedback_read_time(t_received: float, line: str | bytes) -> float:
    """When the firmware read the servos for a feedback ``line`` received complete at ``t_received`` (s, same
    clock): the reply's wire time (the line and its ``\r\n``) and ``READ_BEFORE_PRINT`` earlier. (The streamer
    narrows this further with the time it asked, which a log does not keep.)"""
    return t_received - wire_seconds(len(line) + 2) - READ_BEFORE_PRINT


def frame_read_time(entry: dict[str, Any]) -> float:
    """When the firmware read the servos for one ``received`` entry of an execution log (s on the log's clock: the
    stream's time since its start, pauses included): the ``read_t`` the streamer logged for a frame it judged (an
    answer to a T:105 dated at most a round trip after the question: a busy host reads lines late, the firmware did
    not read the servos later), else, for a frame it did not judge or a log written before ``read_t``, arrival less
    the reply's wire time and the firmware's work (``feedback_read_time``), else the arrival ``t``.

    The one measured-frame time: the browser view (on the plan's time, ``schedule.plan_clock`` of it) and every
    export (bag, MCAP, CSV: on the log's clock) stamp a measured frame with it."""
    read_t, line = entry.get("read_t"), entry.get("line")
    if isinstance(read_t, (int, float)) and not isinstance(read_t, bool):
        return float(read_t)
    if isinstance(line, str):
        return feedback_read_time(float(entry["t"]), line)
    return float(entry["t"])
