"""The RoArm-M3 ESP32 firmware as a pure model: bytes in at their times, lines out at theirs.

Read from Waveshare's RoArm-M3 example firmware (public copies in github.com/jhacksman/RoArm-M3):
[fw84] = build 0.84 / 250108, ``leader_follower_mode/firmware/esp32/RoArm-M3_example-250108/
RoArm-M3_example/`` (line numbers below are of that copy: ``.ino`` I, ``uart_ctrl.h`` U,
``RoArm-M3_module.h`` M, ``RoArm-M3_config.h`` C, ``esp_now_ctrl.h`` E, ``RoArm-M3_advance.h`` A);
[fw26] = build 20260701, ``deployments/2026-09-08-m3-pro/vendor/RoArm-M3_example/`` at af66158
(functions named, that copy has no stable line numbers here).

What one pass of ``loop()`` does and costs (I:156-183; [fw26] ``loop()`` in its .ino):
- [fw84] ``serialCtrl()`` reads every byte waiting and runs every complete line at once (U:384-407),
  echoing it first when InfoPrint is 1 (U:396-398); [fw26] a FreeRTOS task on core 0 reads the
  UART and queues lines (``serialTask``/``serialCtrl`` in uart_ctrl.h: 50 lines of 256 bytes,
  ``{"error":"Queue full"}`` beyond; a line containing the bytes ``"T":0`` flushes the queue and
  sets StopFlag without being queued, ``"T":999`` clears it), and ``loop()`` runs ONE queued line
  per pass;
- ``RoArmM3_getPosByServoFeedback()`` reads six servos over the 1 Mbit/s bus (M:574-592), each a
  ``FeedBack`` and a ``ReadMode`` transaction (M:71-96; [fw26] also reads the torque-enable byte);
  a read that fails keeps the old position (0 before any success: base and roll then read +pi,
  M:90-95) after waiting the SCServo library's ``IOTimeOut`` of 100 ms;
- [fw26] ``Stall_detection()`` prints a warning line every pass while the INA219 supply voltage is
  outside 6.00-12.90 V (``Protective_voltage(_min)``);
- with InfoPrint 2 (the factory default, C:9) ``RoArmM3_infoFeedback()`` prints a T:1051 line every
  pass (I:174-176). ``Serial.println`` returns once the line fits the UART's 128-byte hardware FIFO
  (Arduino-ESP32's Serial has no transmit ring buffer by default, and ESP-IDF's
  ``uart_write_bytes`` then blocks until the data is in the FIFO): a 230-byte line holds each pass
  for about 9 ms, so the loop runs at the wire's pace while it streams feedback.

Commands: T:102/101 (joint radians), T:121/122 (degrees; spd/acc through ``calculatePosByDeg``,
T:122 sets the shared moveSpd/moveAcc that T:1041 uses, T:102 zeroes them: M:764-779), T:104
(firmware IK, blocking cosine interpolation), T:1041, T:105 (one more read pass, then a line),
T:605 InfoPrint (A:352-361), T:210 torque ([fw84] broadcast enable, M:119-121; [fw26] cmd 0 first
folds the arm to its rest pose, ``Move_to_location()``, then releases), T:0 ([fw84] torque off,
``delay(10000)``, torque on: M:132-136; [fw26] only the StopFlag), T:999, T:100, T:111, T:301
(ESP-NOW mode: 3 = follower, the default, C:16; a leader's broadcast drives this arm at spd 0,
E:115-143). Every other code is accepted and ignored, as the dispatcher falls through for codes it
does not move on.

Start-up (``setup()``, I:48-153): ROM boot text, ``delay(1200)`` of silence (I:53), 0.5 s more
(I:81), the servo check's line (M:167-181), ``RoArmM3_moveInit()`` moving every joint to its middle
at speed 600 / acc 20 with its waits (M:196-242), Wi-Fi/web/ESP-NOW set-up, the MAC address line
(E:36-47), the flash mission ``boot`` (aborted when serial input is waiting: A:8-15), and [fw84]
the Cartesian move to the init pose (I:152). Input that arrives meanwhile waits in the 256-byte
receive buffer and the 128-byte FIFO; more is lost.

The servos are a :class:`~roarmctl.device.servos.ServoModel` (default: ideal kinematic servos).
Faults for rehearsal are fields of :class:`~roarmctl.device.sim_config.SimConfig`. ``Firmware`` is
deterministic: all times are given by the caller; ``roarmctl.device.simulator`` runs it behind a pseudo-terminal.
"""

from __future__ import annotations

import json
import math
import random
import threading
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from roarmctl.device.espnow import boot_mission_listing
from roarmctl.device.fwmath import (
    INIT_RAD,
    command_to_goal,
    deg_register,
    firmware_fk,
    firmware_ik,
    position_to_rad,
    urdf_from_firmware,
)
from roarmctl.device.protocol import MIDDLE
from roarmctl.device.servos import JOINTS, KinematicServos, ServoModel
from roarmctl.device.sim_config import (
    BUILDS,
    HIGH_VOLTAGE,
    LOW_VOLTAGE,
    MAC,
    MOTION_CODES,
    REST_STEPS,
    ROM_TEXT,
    SERVO_IDS,
    SimConfig,
)


def _num_text(v: float) -> str:
    """A double as ArduinoJson prints it in T:1051: up to 9 decimals, about 10 significant digits
    (a real line: ``"x":402.6030162,"b":3.138524692,"e":0.003067962``)."""
    v = round(float(v), 9)
    if v == 0:
        return "0"
    return f"{v:.10g}"


class Firmware:
    """The pure model. Feed bytes with ``receive(data, t)``, run it with ``advance(t)``, collect
    complete output lines with ``pop_output(t)``; times are one clock (s) chosen by the caller."""

    def __init__(self, config: SimConfig | None = None, t0: float = 0.0, servos: ServoModel | None = None) -> None:
        self.cfg = cfg = config or SimConfig()
        if cfg.firmware not in BUILDS:
            raise ValueError(f"unknown firmware build {cfg.firmware!r}; one of {BUILDS}")
        self.queued_build = cfg.firmware == "m3-2026"
        self.now = t0
        self.t_start = t0
        start = [float(command_to_goal(j, INIT_RAD[j])) for j in range(6)]
        self.servos: ServoModel = servos if servos is not None else KinematicServos(
            start, t0, max_speed=cfg.max_speed, max_accel=cfg.max_accel)
        self.servos.advance(t0)
        if cfg.torque_off:
            self.servos.set_torque(False)
        self.info_print = cfg.info_print
        self.esp_now_mode = 3
        self.stop_flag = False
        self.move_spd, self.move_acc = 0.0, 20.0
        self.read_pos = np.round(self.servos.positions())  # servoFeedback[].pos
        for name, p in cfg.fail_reads.items():
            if p >= 1.0:  # never read since power-up: the struct's zero (M:23, M:90-95)
                self.read_pos[JOINTS.index(name)] = 0.0
        self.read_torque = self.servos.torque().astype(int)
        self.read_load = np.zeros(6)
        self.overhead = cfg.pass_overhead if cfg.pass_overhead is not None else (0.002 if self.queued_build else 0.0003)
        self.rng = random.Random(cfg.seed)
        # link
        self._rx_free = t0
        self._rx_partial = bytearray()
        self._rx_lines: deque[tuple[float, bytes]] = deque()
        self._rx_dropped = 0
        self._queue: deque[tuple[float, bytes]] = deque()  # [fw26] the command queue: (line complete, line)
        self._tx_free = t0
        self.out: deque[tuple[float, bytes]] = deque()  # (time its last byte leaves, line)
        # loop
        self._next_pass = t0
        self._busy_until = t0
        self._blocking: Callable[[float], None] | None = None
        self._after_block: Callable[[], None] | None = None
        self._serial_task_from = t0  # [fw26] the serial task exists from the end of setup()
        self.motion_count = 0
        self._bogus_left = {i: (b.frames if b.frames > 0 else -1) for i, b in enumerate(cfg.bogus)}  # -1: no end
        self._leader_next = t0
        self.boot_mission_aborted: bool | None = None
        self.booting_until = t0
        # what happened (for tests and benches)
        self.received: list[tuple[float, dict]] = []  # executed commands (time executed, parsed)
        self.executed: list[tuple[float, float, dict]] = []  # (line complete at the UART, executed, parsed)
        self.passes: deque[float] = deque(maxlen=10_000)  # pass durations (s)
        self.rec_t: deque[float] = deque(maxlen=cfg.record_limit)
        self.rec_q: deque[np.ndarray] = deque(maxlen=cfg.record_limit)
        self.rec_torque: deque[bool] = deque(maxlen=cfg.record_limit)
        self.lock = threading.Lock()
        if cfg.boot:
            self._boot(t0)
        self._record(t0)

    # ------------------------------------------------------------------ link
    def receive(self, data: bytes, t: float) -> None:
        """Bytes that reached the UART at ``t``; each takes 1/byte_rate on the wire."""
        if self.cfg.deaf:
            return
        dt = 1.0 / self.cfg.byte_rate
        start = max(t, self._rx_free)
        for k, b in enumerate(data):
            if b == 0x0A:
                self._rx_lines.append((start + (k + 1) * dt, bytes(self._rx_partial)))
                self._rx_partial.clear()
            elif len(self._rx_partial) < 4096:
                self._rx_partial.append(b)
        self._rx_free = start + len(data) * dt

    def muted(self) -> bool:
        """Whether the mute fault has silenced the output (after ``mute_after`` motion commands)."""
        return self.cfg.mute_after is not None and self.motion_count >= self.cfg.mute_after and self.faulty()

    def faulty(self) -> bool:
        """Whether the faults apply yet (``faults_from`` s after the start)."""
        return self.now - self.t_start >= self.cfg.faults_from

    def println(self, text: str, t: float) -> float:
        """``Serial.println`` at ``t``: queue ``text\\r\\n`` for the wire; return when the call returns
        (once at most ``tx_fifo`` bytes of it are still waiting)."""
        if self.cfg.silent or self.muted():
            return t
        data = text.encode() + b"\r\n"
        done = max(t, self._tx_free) + len(data) / self.cfg.byte_rate
        self._tx_free = done
        self.out.append((done, data))
        return max(t, done - self.cfg.tx_fifo / self.cfg.byte_rate)

    def pop_output(self, t: float) -> bytes:
        """Bytes whose transmission has completed by ``t``."""
        chunks = []
        while self.out and self.out[0][0] <= t:
            chunks.append(self.out.popleft()[1])
        return b"".join(chunks)

    def next_event(self) -> float:
        """Earliest time something happens (a loop pass starts or an output line completes)."""
        t = self._next_pass
        if self.out:
            t = min(t, self.out[0][0])
        return t

    # ------------------------------------------------------------------ time
    def advance(self, t: float) -> None:
        """Run the model up to time ``t``: every loop pass that starts by then."""
        while self._next_pass <= t:
            s = self._next_pass
            self._step_to(s)
            if s < self._busy_until:  # inside a blocking command or setup()
                self._record(s)
                self._next_pass = min(self._busy_until, s + 0.002)
                continue
            if self._blocking is not None:
                self._end_block(s)
            self._take_lines(s)
            end = self._pass(s)
            self.passes.append(end - s)
            self._next_pass = max(end, s + 1e-5)
        self._step_to(t)

    def _step_to(self, t: float) -> None:
        """Servos (and a blocking command's own stepping) up to ``t``."""
        if t <= self.now:
            return
        if self._blocking is not None:
            u = self.now
            while u < t:
                u = min(t, u + 0.002)
                self.servos.advance(u)
                self._blocking(u)
        else:
            self.servos.advance(t)
        self.now = t

    def _record(self, t: float) -> None:
        pos = self.servos.positions()
        with self.lock:
            self.rec_t.append(t)
            self.rec_q.append(urdf_from_firmware([position_to_rad(j, pos[j]) for j in range(6)]))
            self.rec_torque.append(bool(self.servos.torque().all()))

    # ------------------------------------------------------------------ input side
    def _take_lines(self, s: float) -> None:
        """Lines complete by ``s``. Bytes nobody read (setup, a blocking command, a slow pass) wait
        in the receive buffer; what does not fit is lost (the newest bytes). [fw26] the serial task
        then queues each line (or flushes the queue)."""
        waiting, kept = 0, deque[tuple[float, bytes]]()
        while self._rx_lines and self._rx_lines[0][0] <= s:
            t_line, line = self._rx_lines.popleft()
            waiting += len(line) + 1
            if waiting > self.cfg.rx_buffer and (not self.queued_build or t_line < self._serial_task_from):
                self._rx_dropped += 1
                continue
            kept.append((t_line, line))
        if not self.queued_build:
            self._rx_lines.extendleft(reversed(kept))
            return
        for t_line, line in kept:
            if b'"T":0' in line:
                self._queue.clear()
                self.stop_flag = True
            elif b'"T":999' in line:
                self.stop_flag = False
            elif len(self._queue) >= 50:
                self.println('{"error":"Queue full"}', max(t_line, s))
            else:
                self._queue.append((t_line, line[:255]))

    # ------------------------------------------------------------------ one pass of loop()
    def _pass(self, s: float) -> float:
        c = s
        if self.queued_build:
            if self._queue:
                t_line, line = self._queue.popleft()
                c = self._handle(line, t_line, c)
                c += 0.0003  # the web socket copy of jsonInfoHttp after each command
        else:
            while self._rx_lines and self._rx_lines[0][0] <= c and c >= self._busy_until:
                t_line, line = self._rx_lines.popleft()
                c = self._handle(line, t_line, c, echo=True)
        if c < self._busy_until:  # a blocking command: the rest of the pass runs after it
            return min(self._busy_until, c + 0.002)
        c = self._read_servos(c)
        if self.queued_build:
            v = self._voltage_cv()
            if v <= 600:
                c = self.println(LOW_VOLTAGE, c)
            elif v >= 1290:
                c = self.println(HIGH_VOLTAGE, c)
        c += self.overhead + self.cfg.loop_period
        self._esp_now(c)
        if self.info_print == 2:
            c = self._print_feedback(c)
        self._step_to(c)
        self._record(c)
        return c

    def _read_servos(self, c: float) -> float:
        """``RoArmM3_getPosByServoFeedback``: one read per joint, in order; a failed one costs the
        library's timeout and keeps the old position ([fw26]: torque flag and current read 0)."""
        per = self.cfg.read_time * (1.3 if self.queued_build else 1.0)
        cfg = self.cfg
        faulty = self.faulty()
        fails = [faulty and (cfg.unpowered or (cfg.fail_reads.get(name, 0.0) > 0 and self.rng.random() < cfg.fail_reads[name]))
                 for name in JOINTS]
        if not any(fails):  # six reads in a row: sampled together at the middle of the block
            self._step_to(c + 3 * per)
            self.read_pos[:] = np.round(self.servos.positions())
            self.read_torque[:] = self.servos.torque()
            self.read_load[:] = self.servos.loads()
            return c + 6 * per
        for j, fail in enumerate(fails):
            if fail:
                c += cfg.read_timeout
                self.read_torque[j] = 0
                if self.info_print == 1:  # M:92-93
                    c = self.println(f"Servo ID:{SERVO_IDS[j]} status: failed.", c)
                continue
            self._step_to(c + per / 2)
            self.read_pos[j] = round(float(self.servos.positions()[j]))
            self.read_torque[j] = int(self.servos.torque()[j])
            self.read_load[j] = float(self.servos.loads()[j])
            c += per
        return c

    def _voltage_cv(self) -> int:
        return 0 if self.cfg.unpowered and self.faulty() else int(self.cfg.voltage * 100)

    def _esp_now(self, t: float) -> None:
        """A leader nearby broadcasts its joints every 50 ms; a follower (mode 3) obeys at spd 0, acc 0."""
        if not self.cfg.esp_now_leader or self.esp_now_mode != 3:
            return
        while self._leader_next <= t:
            self._step_to(max(self.now, self._leader_next))
            self._set_goals(range(6), list(self.cfg.leader_pose), 0, 0)
            self._leader_next += 0.05

    # ------------------------------------------------------------------ output side
    def feedback(self) -> dict:
        """The T:1051 object the firmware would print now (from the last servo read)."""
        return json.loads(self._feedback_line(apply_bogus=False))

    def _feedback_line(self, apply_bogus: bool = True) -> str:
        rad = [position_to_rad(j, float(self.read_pos[j])) for j in range(6)]
        b, s, e, t, r, g = rad
        x, y, z, tit = firmware_fk(b, s, e, t)
        ld = [int(round(v)) for v in self.read_load]
        if self.cfg.firmware == "m2":
            items: list[tuple[str, Any]] = [("T", 1051), ("x", x), ("y", y), ("z", z), ("b", b), ("s", s), ("e", e),
                                            ("t", g), ("torB", ld[0]), ("torS", ld[1]), ("torE", ld[2]), ("torH", ld[5])]
        else:
            items = [("T", 1051), ("x", x), ("y", y), ("z", z), ("tit", tit), ("b", b), ("s", s), ("e", e), ("t", t),
                     ("r", r), ("g", g), ("tB", ld[0]), ("tS", ld[1]), ("tE", ld[2]), ("tT", ld[3]), ("tR", ld[4]),
                     ("tG", ld[5])]
            if self.queued_build:
                items += [(f"torswitch{k}", int(self.read_torque[j])) for j, k in enumerate("BSETRG")]
                items += [("v", self._voltage_cv())]
        text = {k: (str(v) if isinstance(v, int) else _num_text(v)) for k, v in items}
        if apply_bogus and self.faulty():
            for i, bog in enumerate(self.cfg.bogus):
                if self.motion_count >= bog.after and self._bogus_left[i] != 0 and bog.key in text:
                    text[bog.key] = bog.value
                    if self._bogus_left[i] > 0:
                        self._bogus_left[i] -= 1
        return "{" + ",".join(f'"{k}":{v}' for k, v in text.items()) + "}"

    def _print_feedback(self, c: float) -> float:
        if self.muted():
            return c
        if self.queued_build:
            c += 0.0008  # inaDataUpdate(): the INA219 over I2C
        return self.println(self._feedback_line(), c)

    # ------------------------------------------------------------------ commands
    def _handle(self, line: bytes, t_line: float, c: float, echo: bool = False) -> float:
        """Run one command line at ``c``; return when the loop may continue."""
        try:
            text = line.decode("utf-8").strip()
            cmd = json.loads(text)
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError):
            return c  # the firmware drops malformed lines without a word
        if not isinstance(cmd, dict) or len(text) > 255:
            return c
        if echo and self.info_print == 1:
            c = self.println(text, c)
        self._step_to(c)
        self.received.append((c, cmd))
        self.executed.append((t_line, c, cmd))

        def num(key: str) -> float:
            v = cmd.get(key, 0)
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                return 0.0
            try:
                f = float(v)
            except OverflowError:
                return 0.0
            return f if math.isfinite(f) else 0.0

        code = int(num("T")) if abs(num("T")) < 1e9 else -1
        if code in MOTION_CODES:
            self.motion_count += 1
        if code == 102:
            if self.cfg.firmware == "m2":
                rads = [num("base"), num("shoulder"), num("elbow"), self._rad(3), self._rad(4), num("hand")]
            else:
                rads = [num(k) for k in JOINTS]
            self._set_goals(range(6), rads, num("spd"), num("acc"))
            self.move_spd, self.move_acc = 0.0, 0.0
            c += 0.00015  # SyncWritePosEx: 7 servos, about 90 bytes at 1 Mbit/s
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
            c += 0.0001
        elif code == 106:
            self._set_goals([5], [num("cmd")], num("spd"), num("acc"))
        elif code in (104, 1041):
            self._cartesian(num("x"), num("y"), num("z"), num("t"), num("r"), num("g"), num("spd"), c, code == 104)
        elif code == 105:
            c = self._read_servos(c)
            c = self.println(self._feedback_line(), c + (0.0008 if self.queued_build else 0.0))
        elif code == 605:
            if int(num("cmd")) in (0, 1, 2):
                self.info_print = int(num("cmd"))
        elif code == 301:
            if int(num("mode")) in (0, 1, 2, 3):
                self.esp_now_mode = int(num("mode"))
        elif code == 602:  # CMD_BOOT_MISSION_INFO: missionContent("boot")
            c = self._list_boot_mission(c)
        elif code == 210:
            if self.queued_build and not num("cmd"):  # Move_to_location(), then release
                self._set_goals_steps(range(6), REST_STEPS, 600, 20)
                self._block(c, self._eta() + 2.4 * self.cfg.time_factor, after=lambda: self.servos.set_torque(False))
            else:
                self.servos.set_torque(bool(num("cmd")))
        elif code == 0:
            self.stop_flag = True
            if not self.queued_build:  # [fw84]: torque off, 10 s, torque on (M:132-136)
                self.servos.set_torque(False)
                self._block(c, 10.0 * self.cfg.time_factor, after=lambda: self.servos.set_torque(True))
        elif code == 999:
            self.stop_flag = False
        elif code == 100:
            self._set_goals_steps(range(6), (MIDDLE,) * 6, 600, 20)
            self._block(c, self._eta())
        elif code == 111:
            self._block(c, num("cmd") / 1000.0 * self.cfg.time_factor)
        return c

    def _rad(self, j: int) -> float:
        return position_to_rad(j, float(self.read_pos[j]))

    def _set_goals(self, joints: Sequence[int], rads: Sequence[float], spd: float, acc: float) -> None:
        goals = [command_to_goal(j, r, self.queued_build) for j, r in zip(joints, rads)]
        self._set_goals_steps(joints, goals, spd, acc)

    def _set_goals_steps(self, joints: Sequence[int], goals: Sequence[float], spd: float, acc: float) -> None:
        stuck = [JOINTS.index(name) for name in self.cfg.stuck]
        pairs = [(j, g) for j, g in zip(joints, goals) if j not in stuck]
        joints, goals = [j for j, _ in pairs], [g for _, g in pairs]
        s = float(max(0.0, min(spd, 65535.0)))
        a = float(max(0.0, min(acc, 255.0)))
        self.servos.command(joints, [float(g) for g in goals], [s] * len(joints), [a] * len(joints))

    def _block(self, t: float, duration: float, after: Callable[[], None] | None = None,
               during: Callable[[float], None] | None = None) -> None:
        self._busy_until = t + max(0.0, duration)
        self._blocking = during or (lambda _t: None)
        self._after_block = after

    def _end_block(self, t: float) -> None:
        self._blocking = None
        after, self._after_block = self._after_block, None
        if after:
            after()

    def _eta(self) -> float:
        goal = np.array(getattr(self.servos, "goal", self.servos.positions()), dtype=float)
        return float(np.max(np.abs(goal - self.servos.positions()) / 600.0)) + 0.05

    def _cartesian(self, x: float, y: float, z: float, pitch: float, roll: float, g: float, spd: float, t: float,
                   interpolate: bool) -> None:
        """T:104 (blocking cosine interpolation, here in joint space; [fw26] StopFlag ends it) and T:1041."""
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

        def during(now: float) -> None:
            if self.stop_flag and self.queued_build:
                self._busy_until = now
                return
            u = min(1.0, (now - t) / duration)
            w = 0.5 - 0.5 * math.cos(math.pi * u)
            self._set_goals(range(6), [a + (b - a) * w for a, b in zip(start, target)], 0, 0)

        self._block(t, duration, during=during)

    # ------------------------------------------------------------------ setup()
    def _boot(self, t0: float) -> None:
        """setup(): ROM text, 1.7 s of silence, the servo check, the boot moves, the MAC line, the
        boot mission (aborted if input is waiting), [fw84] the move to the init pose."""
        k = self.cfg.time_factor
        for text in ROM_TEXT:
            self.println(text, t0)
        t = t0 + 1.7 * k
        self.println("Bus servos status check: failed." if self.cfg.unpowered else "All bus servos status checked.", t)
        events: list[tuple[float, Callable[[], object]]] = []
        moves = t + 0.05 * k
        events.append((moves, lambda: self._set_goals_steps(range(6), (MIDDLE,) * 6, 600, 20)))
        t_moved = moves + 2.2 * k + 1.5 * k  # waitMove2Goal x2, delay(1200), delay(1000)
        t_mac = t_moved + 0.6 * k  # torque limits, Wi-Fi, web server, ESP-NOW
        self.booting_until = t_mac + 0.3 * k
        events.append((t_mac, lambda: self.println(MAC, t_mac)))
        events.append((t_mac + 0.05 * k, self._boot_mission))
        if not self.queued_build:
            events.append((t_mac + 0.1 * k, lambda: self._set_goals(range(6), list(INIT_RAD), 0, 0)))
        pending = sorted(events, key=lambda e: e[0])

        def during(now: float) -> None:
            while pending and pending[0][0] <= now:
                pending.pop(0)[1]()

        self._block(t0, self.booting_until - t0, during=during)
        self._serial_task_from = self.booting_until

    def _list_boot_mission(self, c: float) -> float:
        for text in boot_mission_listing(self.cfg.boot_mission):
            c = self.println(text, c)
        return c

    def _boot_mission(self) -> None:
        self._list_boot_mission(self.now)  # missionPlay lists the mission before it plays it (A:253-254)
        waiting = bool(self._rx_lines) or bool(self._rx_partial)
        self.boot_mission_aborted = waiting and bool(self.cfg.boot_mission)
        if waiting:
            return
        for line in self.cfg.boot_mission:
            self._handle(line.encode(), self.now, self.now)

    # ------------------------------------------------------------------ record
    def recording(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (N,), joint radians (N, 6) in the URDF convention, torque on (N,))."""
        with self.lock:
            return np.array(self.rec_t), np.array(self.rec_q), np.array(self.rec_torque, dtype=bool)
