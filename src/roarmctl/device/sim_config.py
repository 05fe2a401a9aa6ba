"""The simulated RoArm-M3 firmware's knobs: its builds, the faults it can rehearse (``SimConfig``, which
``roarmctl sim-device`` exposes as options, and ``Bogus`` feedback values), the texts it prints, and the time one
loop pass takes. ``roarmctl.device.firmware`` is the model they configure; the firmware references ([fw84],
[fw26], file letters and line numbers) are listed there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from roarmctl.device.protocol import BYTES_PER_SECOND, MIDDLE
from roarmctl.device.servos import ST3235_MAX_SPEED

BUILDS = ("m3-0.84", "m3-2026", "m2")
ROM_TEXT = ("ets Jul 29 2019 12:21:46", "", "rst:0x1 (POWERON_RESET),boot:0x13 (SPI_FAST_FLASH_BOOT)",
            "configsip: 0, SPIWP:0xee", "mode:DIO, clock div:1", "load:0x3fff0030,len:1344", "entry 0x400805e4")
MAC = "2C:BC:BB:4D:C1:6C"
LOW_VOLTAGE = ("Low operating voltage detected. The servo cannot operate properly. UI controls have been disabled. "
               "Please use the device's operating voltage for power supply.")
HIGH_VOLTAGE = "Servo input voltage is too high. Please verify that the power supply voltage is within the specified operating range."
REST_STEPS = (MIDDLE, MIDDLE - 1024, MIDDLE + 1024, MIDDLE, MIDDLE, MIDDLE)  # [fw26] Move_to_location()
MOTION_CODES = (101, 102, 104, 1041, 106, 121, 122)
SERVO_IDS = (11, 12, 14, 15, 16, 17)  # the servo read for each joint (C:69-75)


@dataclass(frozen=True)
class Bogus:
    """A hostile feedback value: ``key`` of T:1051 printed as the raw JSON text ``value`` in ``frames``
    frames (0: every frame) from the first frame after ``after`` executed motion commands."""

    key: str
    value: str
    after: int = 0
    frames: int = 1


@dataclass
class SimConfig:
    """Knobs of the model. Times in s, speeds in steps/s, voltage in V. The fault fields are what
    ``roarmctl sim-device`` exposes as options."""

    firmware: str = "m3-0.84"  # or "m3-2026", "m2"
    info_print: int = 2  # factory default (C:9): continuous feedback
    boot: bool = False  # run setup() at start: ROM text, silence, boot moves, boot mission
    time_factor: float = 1.0  # scales the firmware's delays (boot, T:0's 10 s, T:111)
    byte_rate: float = BYTES_PER_SECOND
    max_speed: float = ST3235_MAX_SPEED  # the default kinematic servos' spd = 0 speed
    max_accel: float = math.inf
    read_time: float = 0.0005  # one servo's FeedBack + ReadMode on the 1 Mbit/s bus (about 45 bytes)
    read_timeout: float = 0.100  # a failed read waits SCServo's IOTimeOut
    pass_overhead: float | None = None  # other work per pass: 0.84 0.3 ms; 2026 2 ms (INA219, OLED, web socket)
    loop_period: float = 0.0  # extra time per pass (a slow loop, for tests)
    tx_fifo: int = 128  # bytes Serial.println hands over without waiting
    rx_buffer: int = 384  # 256-byte receive buffer + 128-byte FIFO
    silent: bool = False  # nothing ever comes out (wrong baud, dead firmware)
    deaf: bool = False  # nothing ever gets in
    fail_reads: dict[str, float] = field(default_factory=dict)  # joint -> probability that a read fails
    unpowered: bool = False  # servo supply off: every read fails, INA219 reads 0 V
    voltage: float = 12.0  # supply voltage (V)
    torque_off: bool = False  # servos start limp
    esp_now_leader: bool = False  # a leader arm nearby broadcasts its pose (this arm starts as follower)
    leader_pose: tuple[float, ...] = (0.6, 0.2, 1.3, 0.3, 0.0, 3.0)  # firmware radians the leader sends
    bogus: tuple[Bogus, ...] = ()
    mute_after: int | None = None  # stop printing anything after this many motion commands
    faults_from: float = 0.0  # s after the start before fail_reads, unpowered, bogus and mute apply (a leader sends no motions)
    stuck: tuple[str, ...] = ()  # joints whose servo cannot move (blocked): their goal writes have no effect
    boot_mission: tuple[str, ...] = ()  # JSON lines of the flash mission "boot"
    seed: int = 0
    record_limit: int = 2_000_000


def own_pass(firmware: str, read_time: float = SimConfig.read_time) -> float:
    """The model's own loop pass (s) of ``firmware`` without feedback printing: six servo reads and the other work
    (``pass_overhead``); ``loop_period`` adds to it. A pass of ``T`` s is ``loop_period = T - own_pass(...)``."""
    queued = firmware == "m3-2026"
    return 6 * read_time * (1.3 if queued else 1.0) + (0.002 if queued else 0.0003)
