"""The Feetech ST3235 servo of the RoArm, in numbers, each with its source.

Used by the physics servo model (``roarmctl.physics.servo``) and by the schedule's sag compensation
(``roarmctl.device.sag``): one place for the figures both rely on.

* Stall torque 30 kg cm = 2.94 N m at 12 V: Feetech's ST-3235-C001 page (github.com/ftservo/ftservo-wiki,
  docs/en/products/models/st-3235-c001/main.md @ 9340fa0, "Stall torque 30 kg·cm@12V").
* No-load speed 0.222 s per 60 deg at 12 V = 4.72 rad/s: Waveshare's ST3235 page (as quoted in
  github.com/jhacksman/RoArm-M3 research/hardware/servos/ST3235_Metal_Shell_Servo.md).
* 4096 steps per turn: RoArm-M3_config.h ARM_SERVO_POS_RANGE (Waveshare RoArm-M3 example firmware 0.84).
* Position loop P = 16, I = 0, written to every servo at boot: ``RoArmM3_resetPID``, RoArm-M3_module.h
  lines 976-983 of that firmware.
* Loop stiffness, **calibrated** on the one public measurement we found: an STS3215 (same family, same
  30 kg cm stall) held 1.5 kg on a 10 cm lever at 45 deg (1.04 N m, 35 % of stall) 20-30 steps off its
  goal (TheRobotStudio/SO-ARM100 issue #134, "Positional Error Under Load") with the factory P = 32
  (huggingface/lerobot src/lerobot/robots/so100_follower/so100_follower.py @ 973b2f2: "Default is 32"):
  ``KP_PER_P`` = 0.354 / 25 / 32 of full duty per step per unit of P. **Assumed**: the duty is
  proportional to P.
* Two servos on the shoulder (IDs 12 and 13, RoArm-M3_config.h; the M2 has the same pair); the
  gripper's torque limited to 30 % at boot (``RoArmM3_handTorqueCtrl(300)``, RoArm-M3_example.ino).
"""

from __future__ import annotations

import math

KGCM = 0.0980665  # N m per kg cm
STALL_TORQUE = 30.0 * KGCM  # N m at 12 V
NO_LOAD_SPEED = math.radians(60.0) / 0.222  # rad/s at 12 V
STEPS_PER_RAD = 4096 / (2 * math.pi)
KP_PER_P = (1.04 / 2.94) / 25.0 / 32.0  # duty per step per unit of the P register (calibrated, see above)
FIRMWARE_P = 16
KP = FIRMWARE_P * KP_PER_P  # duty per step of position error, as the RoArm's firmware sets the loop
#: Time (s) a joint lags a goal moving at constant speed: the P loop needs ``speed / no_load`` of full duty,
#: i.e. ``speed / (no_load * kp * steps per rad)`` of error (no velocity feed-forward; 46 ms for P = 16).
LOOP_LAG = 1.0 / (NO_LOAD_SPEED * KP * STEPS_PER_RAD)
#: Servos per firmware joint field (the shoulder's two: IDs 12 and 13).
SERVOS_PER_FIELD = {"shoulder": 2}
#: Torque limit per field at boot, 0..1 (the gripper at 300 of 1000; the others at 1000).
TORQUE_LIMIT = {"hand": 0.3}


#: What the model's servo stiffness rests on, in one sentence (the run's ``model.notes``, ``simulate --help``)
STIFFNESS_NOTE = ("servo stiffness: the ST3235's position loop at the firmware's P = 16, its duty per step of error "
                  "calibrated on a sister servo (an STS3215 holding 1.04 N m 20-30 steps off its goal at P = 32) and "
                  "assumed proportional to P: 13.6 N m/rad per servo; bench/bench_physics.py --stiffness shows 0.5x and 2x")


def stiffness(field: str) -> float:
    """Steady torque (N m) that holds the joint of firmware field ``field`` one radian off its goal:
    ``n * stall * kp * steps per rad`` (13.6 N m/rad for one servo, 27.1 for the shoulder's two)."""
    return SERVOS_PER_FIELD.get(field, 1) * STALL_TORQUE * KP * STEPS_PER_RAD
