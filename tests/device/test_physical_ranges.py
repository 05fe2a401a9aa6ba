"""The simulated arm stays inside every physical range: its joints' ends (the MJCF's ranges from the description),
one turn of each servo (0-4095 steps: Feetech's angle-limit registers and encoder), the firmware's goal clamps, the
table under it. Driven as issue 35 saw it leave them: a port opened with pyserial's defaults and one T:102, then
Waveshare's roarm-sdk ``joints_angle_ctrl(angles=[30, 0, 90, 0, 0, 45], speed=1000, acc=100)`` (which sends a T:122
with the gripper at 180 - 45 deg and acc 100 / 254 / 100 * 180 deg/s^2); before, the physics gripper swung to -54
deg, past its end at 0."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from simwait import run_on, until

from roarmctl.device.firmware import Firmware
from roarmctl.device.fwmath import position_to_rad
from roarmctl.device.servos import KinematicServos
from roarmctl.device.sim_config import SimConfig
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")
FIRST = b'{"T":102,"base":0,"shoulder":0,"elbow":1.57,"wrist":0,"roll":0,"hand":3.14,"spd":0,"acc":10}\n'
SDK_T122 = b'{"T":122,"b":30,"s":0,"e":90,"t":0,"r":0,"h":135,"spd":87.890625,"acc":0.7086614173228346}\n'
LIMITS = np.array([(j.lower, j.upper) for j in ROBOT.joints if j.kind != "fixed" and j.mimic is None])


def within_the_arm(q: np.ndarray, slack: float = 0.02) -> bool:
    """Every recorded joint value (N, 6) within the description's limits (rad; MuJoCo's soft limits give a little)."""
    return bool(np.all(q >= LIMITS[:, 0] - slack) and np.all(q <= LIMITS[:, 1] + slack))


def physics_firmware() -> Firmware:
    from roarmctl.physics.servo_backend import for_firmware

    return Firmware(SimConfig(info_print=0), t0=0.0, servos=for_firmware(ROBOT)())


@pytest.mark.slow
@pytest.mark.parametrize("lines", [[FIRST, SDK_T122], [b'{"T":122,"h":135}\n'],
                                   [b'{"T":102,"base":9,"shoulder":-9,"elbow":9,"wrist":9,"roll":-9,"hand":-9,"spd":0,'
                                    b'"acc":0}\n']], ids=["sdk-sequence", "t122-hand-alone", "every-field-far-out"])
def test_the_physics_arm_stays_within_its_joints_ends_one_servo_turn_and_the_firmware_clamps(lines):
    fw = physics_firmware()
    fw.advance(0.3)
    for k, line in enumerate(lines):
        fw.receive(line, 0.3 + 0.2 * k)
    for t in np.arange(0.4, 6.0, 0.05):
        fw.advance(float(t))
        p = fw.servos.positions()
        assert np.all((p >= 0) & (p <= 4095)), p  # one turn of each servo
    _ts, q, _ = fw.recording()
    assert within_the_arm(q), np.degrees(q[np.argmax(np.abs(q).max(axis=1))])
    # the firmware's own reading of it: every joint within its range as the firmware converts it
    rad = [position_to_rad(j, float(fw.read_pos[j])) for j in range(6)]
    assert all(abs(r) <= math.pi + 1e-9 for r in rad)


def test_the_mjcf_gives_every_joint_the_descriptions_range():
    from roarmctl.motion.scene import Scene
    from roarmctl.physics.mjcf import build_document

    xml = build_document(ROBOT, Scene([])).xml
    joints = {j.get("name"): j for j in ET.fromstring(xml).iter("joint")}
    moving = [j for j in ROBOT.joints if j.kind != "fixed"]
    assert moving and all(any(name.endswith(j.name) for name in joints) for j in moving)
    for j in moving:
        el = next(v for name, v in joints.items() if name.endswith(j.name))
        lo, hi = (float(x) for x in el.get("range").split())
        assert (lo, hi) == pytest.approx((j.lower, j.upper), abs=1e-12)


def test_a_servo_takes_goals_within_one_turn_and_reads_one_turn():
    from roarmctl.device.servos import servo_reading

    servos = KinematicServos([2047.0] * 6, 0.0)
    servos.command([0, 1], [5000.0, -300.0], [0.0, 0.0], [0.0, 0.0])
    servos.advance(5.0)
    assert servos.positions()[0] == 4095.0 and servos.positions()[1] == 0.0
    assert servo_reading(4096.0 + 10.0) == 10.0 and servo_reading(-1.0) == 4095.0


@pytest.mark.slow
def test_waveshares_sdk_sequence_leaves_no_physical_range_on_sim_device():
    """The issue's sequence on the simulated arm over a real pseudo-terminal, booting as sim-device does."""
    import threading

    import serial

    roarm_mod = pytest.importorskip("roarm_sdk.roarm")
    from roarmctl.device.simulator import PtySimulator
    from roarmctl.physics.servo_backend import roarm_m3_pro

    with PtySimulator(SimConfig(boot=True), servos=roarm_m3_pro, process=True) as sim:
        s = serial.Serial(sim.path)  # pyserial's defaults
        s.write(FIRST)
        s.close()
        arm = roarm_mod.roarm(roarm_type="roarm_m3", port=sim.path, baudrate=115200)
        th = threading.Thread(target=lambda: arm.joints_angle_ctrl(angles=[30, 0, 90, 0, 0, 45], speed=1000, acc=100),
                              daemon=True)
        th.start()
        # the move run (after the set-up, about 6 s), then 3 s of the firmware's clock (30 degrees at 1000 steps/s: 0.35 s)
        until(sim, lambda st: any(c.get("T") == 122 for _, c in sim.received()))
        run_on(sim, 3.0)
        _ts, q, _ = sim.recording()
        codes = [c.get("T") for _, c in sim.received()]
    assert 122 in codes
    assert within_the_arm(q), np.degrees(q[np.argmax(np.abs(q).max(axis=1))])
    assert q[-1][0] == pytest.approx(math.radians(30), abs=0.02)  # and it got where it was sent
