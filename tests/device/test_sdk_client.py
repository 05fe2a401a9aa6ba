"""Waveshare's own roarm_sdk drives the simulator like the real arm: proof that the simulator speaks
the firmware's protocol (the SDK's spacing, its framing on '}\\r\\n', its gripper convention)."""

import math
import time

import pytest

from roarmctl.device.simulator import PtySimulator, SimConfig

pytestmark = pytest.mark.slow  # real time: the SDK drives the simulated arm

roarm_mod = pytest.importorskip("roarm_sdk.roarm")

COUNT = 2 * math.pi / 4096


@pytest.fixture
def arm():
    with PtySimulator(SimConfig(), process=True) as sim:  # factory InfoPrint 2: the SDK copes with the stream
        client = roarm_mod.roarm(roarm_type="roarm_m3", port=sim.path, baudrate=115200)
        try:
            yield client, sim
        finally:
            client.disconnect()


def test_sdk_feedback_at_boot_pose(arm):
    client, _ = arm
    fb = client.feedback_get()
    assert isinstance(fb, list) and len(fb) == 10  # x y z tit b s e t r g
    x, _y, z, _tit, b, s, e, t, r, g = fb
    assert (x, z) == pytest.approx((346.16, 223.13), abs=1.5)
    assert e == pytest.approx(math.pi / 2, abs=1e-5)
    assert g == pytest.approx(0.0, abs=1e-5)  # SDK: pi - hand; boot hand = pi (closed)
    for v in (b, s, t, r):
        assert abs(v) <= COUNT + 1e-6  # the 2047 middle reads one count off


def test_sdk_joint_commands_move_the_simulated_arm(arm):
    client, sim = arm
    client.echo_set(0)
    target = [0.4, -0.3, 1.2, 0.5, -0.6, 1.0]  # URDF convention; the SDK sends hand = pi - 1.0
    client.joints_radian_ctrl(radians=list(target), speed=2000, acc=0)
    got = _until(client.joints_radian_get, lambda q: q == pytest.approx(target, abs=2 * COUNT))
    assert got == pytest.approx(target, abs=2 * COUNT)
    # single-joint command (T:101): wrist to -0.2
    client.joint_radian_ctrl(joint=4, radian=-0.2, speed=1500, acc=0)
    got = _until(client.joints_radian_get, lambda q: q[3] == pytest.approx(-0.2, abs=2 * COUNT))
    assert got[3] == pytest.approx(-0.2, abs=2 * COUNT)
    # the simulator saw the SDK's own (spaced) JSON and executed it
    codes = [c["T"] for _, c in sim.received()]
    assert 102 in codes and 101 in codes and 605 in codes


def _until(read, done, timeout: float = 60.0):
    """``read()`` again until ``done(value)`` (the servos arrive on the simulator's clock, however busy the machine);
    the last value. ``timeout`` (s, wall) only detects a hang."""
    end = time.monotonic() + timeout
    value = read()
    while not done(value) and time.monotonic() < end:
        time.sleep(0.05)
        value = read()
    return value


def _settle(client, want, index, tol, timeout=60.0):
    """Poll the SDK's own feedback until ``value[index]`` is within ``tol`` of ``want`` (or time out)."""
    end = time.monotonic() + timeout
    got = None
    while time.monotonic() < end:
        got = client.feedback_get()
        if isinstance(got, list) and all(abs(got[i] - w) <= tol for i, w in zip(index, want)):
            return got
        time.sleep(0.1)
    return got


def test_every_sdk_call_the_readme_lists(arm):
    """The SDK calls named in docs/guide.md, each against what the simulated servos did."""
    client, sim = arm
    client.echo_set(0)  # T:605
    client.led_ctrl(led=128)  # T:114: accepted, nothing moves
    client.dynamic_adaptation_set(mode=0, torques=[500] * 6)  # T:112: accepted, nothing moves
    # joints_angle_ctrl: T:122 in degrees; the SDK turns speed (steps/s) into deg/s, the firmware back
    client.joints_angle_ctrl(angles=[20, -10, 80, 15, -30, 40], speed=1200, acc=0)
    st = _until(sim.state, lambda st: st["move_spd"] == 1200)
    assert st["spd"][0] == 1200 and st["move_spd"] == 1200  # persistent, as the firmware's moveSpd
    got = _settle(client, [math.radians(v) for v in (20, -10, 80, 15, -30, 40)], range(4, 10), 2 * COUNT)
    assert client.joints_angle_get() == pytest.approx([20, -10, 80, 15, -30, 40], abs=math.degrees(2 * COUNT))
    # joint_angle_ctrl: T:121, one joint in degrees
    client.joint_angle_ctrl(joint=1, angle=-25, speed=1500, acc=0)
    got = _settle(client, [math.radians(-25)], [4], 2 * COUNT)
    assert got[4] == pytest.approx(math.radians(-25), abs=2 * COUNT)
    # gripper_angle_ctrl / gripper_radian_ctrl (T:121 / T:101 on joint 6), read back in the SDK's convention
    client.gripper_angle_ctrl(angle=30, speed=1500, acc=0)
    _settle(client, [math.radians(30)], [9], 2 * COUNT)
    assert client.gripper_angle_get() == pytest.approx(30, abs=math.degrees(2 * COUNT))
    client.gripper_radian_ctrl(radian=0.9, speed=1500, acc=0)
    _settle(client, [0.9], [9], 2 * COUNT)
    assert client.gripper_radian_get() == pytest.approx(0.9, abs=2 * COUNT)
    # pose_ctrl: T:1041 (mm, deg); pose_get reads x y z tit + roll, gripper back
    client.pose_ctrl(pose=[300, 40, 120, 10, 0, 20])
    got = _settle(client, [300, 40, 120], [0, 1, 2], 1.5)
    x, y, z, tit, _roll, grip = client.pose_get()
    assert (x, y, z) == pytest.approx((300, 40, 120), abs=1.5)
    assert tit == pytest.approx(10, abs=0.3) and grip == pytest.approx(20, abs=0.3)
    # torque_set: T:210 off, the arm goes limp (the SDK then waits for feedback), on again
    client.torque_set(cmd=0)
    assert not any(_until(lambda: sim.state()["torque"], lambda t: not any(t)))
    client.torque_set(cmd=1)
    assert all(_until(lambda: sim.state()["torque"], all))
    # move_init: a T:102 to the SDK's home pose at speed 100
    client.move_init()
    st = _until(sim.state, lambda st: st["spd"][2] == 100)
    assert st["spd"][2] == 100 and st["move_spd"] == 0  # a T:102 zeroes the shared moveSpd
    codes = {c["T"] for _, c in sim.received()}
    assert {605, 114, 112, 122, 121, 101, 1041, 105, 210, 102} <= codes
