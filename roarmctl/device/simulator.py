"""A model of the RoArm-M3 ESP32 firmware 0.84 as seen from its USB serial port.

What it reproduces, read from Waveshare's RoArm-M3 example firmware ([fw84] = RoArm-M3_example-250108,
"version 0.84": RoArm-M3_example.ino, RoArm-M3_module.h, RoArm-M3_config.h, json_cmd.h, uart_ctrl.h;
[fw26] = the newer RoArm-M3_example_20260701 build, which also calls itself 0.84):
- framing: JSON lines in (``\\n``), ``\\r\\n`` lines out; malformed lines are dropped silently;
  missing keys read as 0 (ArduinoJson null -> 0);
- the link's byte rate (115200 8N1 = 11520 B/s) in both directions: a line is executed when its
  last byte has arrived, and a reply reaches the host when its last byte has left;
- the main loop: every ``loop_period`` it executes every complete line, reads the servos, and with
  InfoPrint 2 prints feedback whenever the transmitter is idle;
- commands T:102, T:101, T:121/T:122 (degrees; ``spd``/``acc`` through ``calculatePosByDeg``,
  T:122 stores them as the shared ``moveSpd``/``moveAcc`` that T:1041 uses, T:102 zeroes them),
  T:104 (firmware IK, blocking cosine interpolation), T:1041 (one IK step), T:105, T:605, T:210,
  T:0 (0.84: torque off, *blocks 10 s*, torque on; scaled by ``time_factor``), T:999, T:100,
  T:111; everything else (LED, EEPROM writes, Wi-Fi, missions, ...) is accepted and ignored, as
  the firmware's ``jsonCmdReceiveHandler`` falls through its switch for codes it does not move on;
- the servos: 4096 steps/rev, the firmware's clamps and rad<->step conversions incl. the 2047
  middle (so 0 rad reads back one count off), base/roll inverted; each servo runs its own
  trapezoid with the command's ``spd`` (steps/s, 0 = ``max_speed``) and ``acc`` (100 steps/s^2,
  0 = no ramp), replanned from its current velocity whenever a new goal arrives, stopping at the
  goal (like Feetech STS servos);
- ``firmware="m3-2026"`` ([fw26]): one queued command per loop
  pass (queue of 50, ``{"error":"Queue full"}`` beyond), the ``"T":0`` byte match that flushes
  the queue without dropping torque, elbow lower clamp 0 rad, T:210 cmd 0 goes to rest first;
- feedback in the real ``T:1051`` format with x, y, z and tit from the firmware FK (``RoArmM3_computePosbyJointRad``,
  RoArm-M3_module.h, with the RoArm-M3_config.h link lengths);
  ``firmware="m3-2026"`` adds torswitch*/v, ``firmware="m2"`` answers like an M2 (b s e t, torB..).

It records the true servo positions over time (``recording()``: times and joint radians in the
URDF convention: identity for the arm, gripper q = pi - hand) so tests can compare executed motion
with the plan. Not modelled: servo PID lag, gravity, load, stale servo reads, Wi-Fi/ESP-NOW.

``Firmware`` is the pure model (explicit times, deterministic); ``PtySimulator`` runs it in a
thread behind a real pseudo-terminal so any program can open it like ``/dev/ttyUSB0``.
"""

from __future__ import annotations

import json
import math
import os
import select
import threading
import time
import tty
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from roarmctl.device.protocol import BYTES_PER_SECOND, MIDDLE

TWO_PI = 2.0 * math.pi
# Firmware IK/FK constants (RoArm-M3_config.h), mm.
L2A, L2B = 236.82, 30.00
L3A = 144.49
L4A, L4B = 171.67, 13.69
L2 = math.hypot(L2A, L2B)
T2 = math.atan2(L2B, L2A)
LE = math.hypot(L4A, L4B)
TE = math.atan2(L4B, L4A)

JOINTS = ("base", "shoulder", "elbow", "wrist", "roll", "hand")
# Boot state of the firmware (*_JOINT_RAD): elbow pi/2, gripper pi (closed).
INIT_RAD = (0.0, 0.0, math.pi / 2, 0.0, 0.0, math.pi)
BANNER = ("RoArm-M3 booting", "version: 0.84", "servo status: OK", "moveInit", "Boot done")


def steps(rad: float) -> int:
    """``calculatePosByRad``: round(rad / 2pi * 4096)."""
    return int(round(rad / TWO_PI * 4096))


def deg_register(value: float, u8: bool = False) -> float:
    """T:121/T:122 ``spd``/``acc``: ``calculatePosByDeg`` (round(deg / 360 * 4096)) written to the
    servo register; the acc register is one byte, so larger values wrap (json_cmd.h says "max: 22.5")."""
    v = int(round(abs(value) / 360.0 * 4096))
    return float(v & 0xFF) if u8 else float(min(v, 65535))


def command_to_goal(joint: int, rad: float, elbow_min_zero: bool = False) -> int:
    """Firmware joint command (rad) -> servo goal step, with the 0.84 clamps (``RoArmM3_*JointCtrlRad``, RoArm-M3_module.h)."""
    if joint == 0:  # base, inverted
        return MIDDLE - steps(min(max(rad, -math.pi), math.pi))
    if joint == 1:  # shoulder (driving servo 12; 13 mirrors it)
        return MIDDLE + steps(min(max(rad, -math.pi / 2), math.pi / 2))
    if joint == 2:  # elbow, clamped in steps ([fw26]: lower clamp 1024, i.e. 0 rad)
        return min(max(1024 + steps(rad), 1024 if elbow_min_zero else 512), 3071)
    if joint == 3:  # wrist
        return MIDDLE + steps(min(max(rad, -math.pi / 2), math.pi / 2))
    if joint == 4:  # roll, inverted
        return MIDDLE - steps(min(max(rad, -math.pi), math.pi))
    return min(max(steps(rad), 700), 3396)  # gripper, no offset


def position_to_rad(joint: int, p: float) -> float:
    """``calculateRadByFeedback``: servo position (steps) -> firmware radians."""
    a = p * TWO_PI / 4096
    return (math.pi - a, a - math.pi, a - math.pi / 2, a - math.pi, math.pi - a, a)[joint]


def firmware_fk(b: float, s: float, e: float, t: float) -> tuple[float, float, float, float]:
    """``RoArmM3_computePosbyJointRad``: x, y, z (mm, origin on the base axis at shoulder height), tit."""
    r = L2 * math.sin(s + T2) + L3A * math.sin(e + s) + LE * math.sin(e + s + t + TE)
    z = L2 * math.cos(s + T2) + L3A * math.cos(e + s) + LE * math.cos(e + s + t + TE)
    return r * math.cos(b), r * math.sin(b), z, e + s + t - math.pi / 2


def firmware_ik(x: float, y: float, z: float, pitch: float) -> tuple[float, float, float, float] | None:
    """Inverse of ``firmware_fk`` (elbow-up branch): b, s, e, t, or None when out of reach."""
    b = math.atan2(y, x) if (x or y) else 0.0
    r = math.hypot(x, y)
    phi = pitch + math.pi / 2  # = e + s + t
    rw, zw = r - LE * math.sin(phi + TE), z - LE * math.cos(phi + TE)
    c = (rw * rw + zw * zw - L2 * L2 - L3A * L3A) / (2 * L2 * L3A)
    if not -1.0 <= c <= 1.0:
        return None
    g = math.acos(c)
    alpha = math.atan2(rw, zw) - math.atan2(L3A * math.sin(g), L2 + L3A * math.cos(g))
    s = alpha - T2
    e = g + T2
    return b, s, e, phi - e - s


def urdf_from_firmware(rad6) -> np.ndarray:
    """Firmware radians (base..hand) -> URDF joint vector of the M3 (identity, gripper pi - hand)."""
    q = np.array(rad6, dtype=float)
    q[..., 5] = math.pi - q[..., 5]
    return q


@dataclass
class SimConfig:
    """Knobs of the model. Times in s, speeds in steps/s."""

    firmware: str = "m3-0.84"  # or "m3-2026", "m2"
    info_print: int = 2  # factory default (InfoPrint = 2 in RoArm-M3_example.ino): continuous feedback
    loop_period: float = 0.004  # main loop: serial + 6 servo reads
    max_speed: float = 3072.0  # spd = 0: ST3235 no-load speed, steps/s
    max_accel: float = math.inf  # acc = 0: no ramp
    time_factor: float = 1.0  # scales the firmware's blocking delays (T:0's 10 s, T:111)
    boot: bool = False  # print the boot banner and do the boot move when started
    byte_rate: float = BYTES_PER_SECOND
    silent: bool = False  # a device that never says anything (wrong baud, dead firmware)
    deaf: bool = False  # a device whose input is lost (it keeps streaming with InfoPrint 2)
    record_limit: int = 2_000_000


class Firmware:
    """The pure model: feed bytes with their time, advance to a time, collect output lines.

    All times are on one clock (s, e.g. ``time.monotonic()``) supplied by the caller.
    """

    def __init__(self, config: SimConfig | None = None, t0: float = 0.0) -> None:
        self.cfg = config or SimConfig()
        self.info_print = self.cfg.info_print
        self.now = t0
        n = 6
        self.pos = np.array([float(command_to_goal(j, INIT_RAD[j])) for j in range(n)])
        self.goal = self.pos.copy()
        self.vel = np.zeros(n)
        self.spd = np.full(n, 600.0)
        self.acc = np.full(n, 20.0)
        self.torque = True
        self.stop_flag = False
        # The firmware's shared moveSpd/moveAcc arrays (init 0/20): T:1041 moves with them, T:122
        # sets them (persistently), T:102 resets them to 0 after its own move.
        self.move_spd = 0.0
        self.move_acc = 20.0
        self._rx_free = t0  # when the receiver finishes the last byte it got
        self._rx_line = bytearray()
        self._rx_lines: deque[tuple[float, bytes]] = deque()
        self._queue: deque[bytes] = deque()  # [fw26] command queue
        self._tx_free = t0
        self.out: deque[tuple[float, bytes]] = deque()  # (time the last byte leaves, line)
        self._busy_until = t0
        self._blocking: Callable[[float], None] | None = None  # runs each step while busy
        self._after_block: Callable[[], None] | None = None
        self._next_tick = t0
        self._fb_pos = self.pos.copy()  # last servo read of the main loop
        self.rec_t: deque[float] = deque(maxlen=self.cfg.record_limit)
        self.rec_q: deque[np.ndarray] = deque(maxlen=self.cfg.record_limit)
        self.rec_torque: deque[bool] = deque(maxlen=self.cfg.record_limit)
        self.received: list[tuple[float, dict]] = []  # executed commands (time, parsed)
        self.lock = threading.Lock()
        if self.cfg.boot:
            self._boot()
        self._record()

    # ------------------------------------------------------------------ link
    def receive(self, data: bytes, t: float) -> None:
        """Bytes that reached the UART at ``t``; each byte takes 1/byte_rate on the wire."""
        if self.cfg.deaf:
            return
        dt = 1.0 / self.cfg.byte_rate
        start = max(t, self._rx_free)
        for k, b in enumerate(data):
            if b == 0x0A:
                self._rx_lines.append((start + (k + 1) * dt, bytes(self._rx_line)))
                self._rx_line.clear()
            elif len(self._rx_line) < 4096:
                self._rx_line.append(b)
        self._rx_free = start + len(data) * dt

    def println(self, text: str, t: float) -> None:
        """``Serial.println``: queue ``text\\r\\n``; it leaves the wire at the byte rate."""
        if self.cfg.silent:
            return
        data = text.encode() + b"\r\n"
        done = max(t, self._tx_free) + len(data) / self.cfg.byte_rate
        self._tx_free = done
        self.out.append((done, data))

    def pop_output(self, t: float) -> bytes:
        """Bytes whose transmission has completed by ``t``."""
        chunks = []
        while self.out and self.out[0][0] <= t:
            chunks.append(self.out.popleft()[1])
        return b"".join(chunks)

    def next_event(self) -> float:
        """Earliest time something happens (a loop tick or an output line completing)."""
        t = self._next_tick
        if self.out:
            t = min(t, self.out[0][0])
        return t

    # ------------------------------------------------------------------ time
    def advance(self, t: float) -> None:
        """Run the model up to time ``t``: servo motion and every main-loop tick on the way."""
        while self._next_tick <= t:
            tick = self._next_tick
            self._move_servos(tick)
            self._loop(tick)
            self._next_tick = tick + self.cfg.loop_period
        self._move_servos(t)

    def _move_servos(self, t: float, max_dt: float = 0.001) -> None:
        while self.now < t - 1e-12:
            dt = min(max_dt, t - self.now)
            if self._blocking is not None:
                self._blocking(self.now + dt)
            if self.torque:
                self._servo_step(dt)
            self.now += dt

    def _servo_step(self, dt: float) -> None:
        d = self.goal - self.pos
        vcap = np.where(self.spd > 0, np.minimum(self.spd, self.cfg.max_speed), self.cfg.max_speed)
        a = np.where(self.acc > 0, self.acc * 100.0, self.cfg.max_accel)
        sign = np.sign(d)
        with np.errstate(invalid="ignore"):
            brake = np.sqrt(2.0 * a * np.abs(d))  # fastest speed that can still stop at the goal
        vdes = sign * np.minimum(vcap, np.where(np.isfinite(a), brake, np.inf))
        finite = np.isfinite(a)
        dv = np.clip(vdes - self.vel, -np.where(finite, a, 0) * dt, np.where(finite, a, 0) * dt)
        v = np.where(finite, self.vel + dv, vdes)
        # no ramp: never overshoot within the step
        v = np.where(finite, v, sign * np.minimum(np.abs(v), np.abs(d) / dt))
        new = self.pos + v * dt
        crossed = (d != 0) & (np.sign(self.goal - new) != sign) & (np.sign(v) == sign)
        new = np.where(crossed, self.goal, new)
        v = np.where(crossed | ((d == 0) & (np.abs(self.vel) < 1e-9)), 0.0, v)
        self.pos, self.vel = new, v

    def _record(self) -> None:
        with self.lock:
            self.rec_t.append(self.now)
            self.rec_q.append(urdf_from_firmware([position_to_rad(j, self.pos[j]) for j in range(6)]))
            self.rec_torque.append(self.torque)

    def _loop(self, t: float) -> None:
        """One iteration of ``loop()``: serial commands, servo reads, InfoPrint 2 feedback."""
        if t >= self._busy_until and self._blocking is not None:
            self._blocking = None
            after, self._after_block = self._after_block, None
            if after:
                after()
        if self.cfg.firmware == "m3-2026":
            self._loop_queued(t)
        elif t >= self._busy_until:
            while self._rx_lines and self._rx_lines[0][0] <= t and t >= self._busy_until:
                _, line = self._rx_lines.popleft()
                self._execute(line, t)
        self._fb_pos = np.round(self.pos)
        if self.info_print == 2 and t >= self._busy_until and self._tx_free <= t:
            self.println(self._feedback_line(), t)
        self._record()

    def _loop_queued(self, t: float) -> None:
        """[fw26]: a serial task queues lines (50 deep, overflow dropped with an error line); a line
        with the bytes ``"T":0`` flushes the queue at once; ``loop()`` runs one command per pass."""
        while self._rx_lines and self._rx_lines[0][0] <= t:
            _, line = self._rx_lines.popleft()
            if b'"T":0' in line and b'"T":0' + line.split(b'"T":0', 1)[1][:1] in (b'"T":0,', b'"T":0}'):
                self._queue.clear()
                self.stop_flag = True
                continue
            if len(self._queue) >= 50:
                self.println('{"error":"Queue full"}', t)
                continue
            self._queue.append(line[:255])
        if t >= self._busy_until and self._queue:
            self._execute(self._queue.popleft(), t)

    # ------------------------------------------------------------------ commands
    def _execute(self, line: bytes, t: float) -> None:
        try:
            text = line.decode("utf-8").strip()
            cmd = json.loads(text)
        except (UnicodeDecodeError, json.JSONDecodeError):
            return  # the firmware drops malformed lines without a word
        if not isinstance(cmd, dict) or len(text) > 255:
            return
        if self.info_print == 1:
            self.println(text, t)
        self.received.append((t, cmd))

        def num(key: str) -> float:
            v = cmd.get(key, 0)
            return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else 0.0

        code = int(num("T"))
        if code == 102:
            if self.cfg.firmware == "m2":
                rads = [num("base"), num("shoulder"), num("elbow"), self._rad(3), self._rad(4), num("hand")]
            else:
                rads = [num(k) for k in JOINTS]
            self._set_goals(range(6), rads, num("spd"), num("acc"))
            self.move_spd, self.move_acc = 0.0, 0.0
        elif code == 122 and self.cfg.firmware != "m2":
            rads = [math.radians(num(k)) for k in ("b", "s", "e", "t", "r", "h")]
            self.move_spd, self.move_acc = deg_register(num("spd")), deg_register(num("acc"), u8=True)
            self._set_goals(range(6), rads, self.move_spd, self.move_acc)
        elif code == 121:
            j = int(num("joint")) - 1
            if 0 <= j < 6:
                self._set_goals([j], [math.radians(num("angle"))], deg_register(num("spd")), deg_register(num("acc"), u8=True))
        elif code == 101:
            j = int(num("joint")) - 1
            if 0 <= j < 6:
                self._set_goals([j], [num("rad")], num("spd"), num("acc"))
        elif code == 104 or code == 1041:
            self._cartesian(num("x"), num("y"), num("z"), num("t"), num("r"), num("g"), num("spd"), t, code == 104)
        elif code == 105:
            self.println(self._feedback_line(), t)
        elif code == 605:
            self.info_print = int(num("cmd"))
        elif code == 210:
            if self.cfg.firmware == "m3-2026" and not num("cmd"):  # rest pose first, then release
                self._set_goals(range(6), list(INIT_RAD[:5]) + [self._rad(5)], 600, 20)
                self._block(t, self._eta(), after=lambda: self._set_torque(False))
            else:
                self._set_torque(bool(num("cmd")))
        elif code == 0 and self.cfg.firmware == "m3-2026":
            self.stop_flag = True  # no torque change on the newer build
        elif code == 0:
            self.stop_flag = True
            self._set_torque(False)
            self._block(t, 10.0 * self.cfg.time_factor, after=lambda: self._set_torque(True))
        elif code == 999:
            self.stop_flag = False
        elif code == 100:
            self._set_goals(range(6), list(INIT_RAD[:5]) + [self._rad(5)], 600, 20)
            self._block(t, self._eta())
        elif code == 111:
            self._block(t, num("cmd") / 1000.0 * self.cfg.time_factor)

    def _rad(self, j: int) -> float:
        return position_to_rad(j, self.pos[j])

    def _set_goals(self, joints, rads, spd: float, acc: float) -> None:
        new_fw = self.cfg.firmware == "m3-2026"
        for j, r in zip(joints, rads):
            self.goal[j] = command_to_goal(j, r, new_fw)
            self.spd[j] = max(0.0, min(spd, 65535.0))
            self.acc[j] = max(0.0, min(acc, 255.0))

    def _set_torque(self, on: bool) -> None:
        if on and not self.torque:
            self.goal = np.round(self.pos)  # enabling torque holds where the arm is
            self.vel[:] = 0.0
        if not on:
            self.vel[:] = 0.0
        self.torque = on

    def _block(self, t: float, duration: float, after: Callable[[], None] | None = None,
               during: Callable[[float], None] | None = None) -> None:
        self._busy_until = t + max(0.0, duration)
        self._blocking = during or (lambda _t: None)
        self._after_block = after

    def _eta(self) -> float:
        v = np.where(self.spd > 0, np.minimum(self.spd, self.cfg.max_speed), self.cfg.max_speed)
        return float(np.max(np.abs(self.goal - self.pos) / v)) + 0.05

    def _cartesian(self, x, y, z, pitch, roll, g, spd, t, interpolate: bool) -> None:
        """T:104 (blocking cosine interpolation in joint space, simplified) and T:1041 (one step)."""
        sol = firmware_ik(x, y, z, pitch)
        if sol is None:
            return
        target = [*sol, roll, g]
        if not interpolate:
            self._set_goals(range(6), target, self.move_spd, self.move_acc)
            return
        start = [self._rad(j) for j in range(6)]
        dist = math.dist(firmware_fk(*start[:4])[:3], (x, y, z))
        duration = max(0.2, dist / max(1e-3, spd if spd > 0 else 0.25) / 1000.0)
        t_start = t

        def during(now: float) -> None:
            u = min(1.0, (now - t_start) / duration)
            w = 0.5 - 0.5 * math.cos(math.pi * u)
            self._set_goals(range(6), [a + (b - a) * w for a, b in zip(start, target)], 0, 0)

        self._block(t, duration, during=during)

    def _boot(self) -> None:
        for text in BANNER:
            self.println(text, self.now)
        self._set_goals(range(6), INIT_RAD, 600, 20)
        self._block(self.now, 0.5 * self.cfg.time_factor)

    # ------------------------------------------------------------------ feedback
    def feedback(self) -> dict:
        """The T:1051 object the firmware would print now (from the main loop's last servo read)."""
        rad = [position_to_rad(j, float(self._fb_pos[j])) for j in range(6)]
        b, s, e, t, r, g = rad
        x, y, z, tit = firmware_fk(b, s, e, t)
        f6 = lambda v: round(v, 6)  # noqa: E731
        f2 = lambda v: round(v, 2)  # noqa: E731
        if self.cfg.firmware == "m2":
            return {"T": 1051, "x": f2(x), "y": f2(y), "z": f2(z), "b": f6(b), "s": f6(s), "e": f6(e), "t": f6(g),
                    "torB": 0, "torS": 0, "torE": 0, "torH": 0}
        obj = {"T": 1051, "x": f2(x), "y": f2(y), "z": f2(z), "tit": f6(tit), "b": f6(b), "s": f6(s), "e": f6(e),
               "t": f6(t), "r": f6(r), "g": f6(g), "tB": 0, "tS": 0, "tE": 0, "tT": 0, "tR": 0, "tG": 0}
        if self.cfg.firmware == "m3-2026":
            on = int(self.torque)
            obj |= {f"torswitch{k}": on for k in "BSETRG"} | {"v": 1200}
        return obj

    def _feedback_line(self) -> str:
        return json.dumps(self.feedback(), separators=(",", ":"))

    # ------------------------------------------------------------------ record
    def recording(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,), joint radians (N, 6) in the URDF convention, torque on (N,))."""
        with self.lock:
            return np.array(self.rec_t), np.array(self.rec_q), np.array(self.rec_torque, dtype=bool)


class PtySimulator:
    """Serve a ``Firmware`` on a pseudo-terminal in a background thread.

    ``path`` is the slave device to open (like ``/dev/ttyUSB0``). ``clock`` must be monotonic; the
    recording and the firmware share it. Use as a context manager or call ``start``/``stop``.
    """

    def __init__(self, config: SimConfig | None = None, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.config = config or SimConfig()
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        tty.setraw(self.master)
        self.path = os.ttyname(self.slave)
        os.set_blocking(self.master, False)
        self.firmware = Firmware(self.config, t0=clock())
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="roarm-sim", daemon=True)
        self.error: BaseException | None = None

    def start(self) -> PtySimulator:
        """Start serving the pseudo-terminal in a background thread; return self."""
        self._thread.start()
        return self

    def __enter__(self) -> PtySimulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self) -> None:
        """Stop the thread and close the pseudo-terminal."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass

    def disconnect(self) -> None:
        """Simulate the cable being pulled: close the pty so the host's reads and writes fail."""
        self.stop()

    def recording(self):
        """The firmware's record of servo positions over time (see ``Firmware.recording``)."""
        return self.firmware.recording()

    def _run(self) -> None:
        fw = self.firmware
        try:
            while not self._stop.is_set():
                now = self.clock()
                timeout = max(0.0, min(fw.next_event() - now, 0.05))
                ready, _, _ = select.select([self.master], [], [], timeout)
                now = self.clock()
                if ready:
                    try:
                        data = os.read(self.master, 4096)
                    except OSError:
                        data = b""
                    if data:
                        fw.receive(data, now)
                fw.advance(now)
                out = fw.pop_output(now)
                if out:
                    self._write(out)
        except BaseException as exc:  # noqa: BLE001 - surfaced to tests through .error
            self.error = exc

    def _write(self, data: bytes) -> None:
        try:
            os.write(self.master, data)
        except OSError:
            pass  # nobody reads and the buffer is full (or closed): lost, like bytes on an open UART
