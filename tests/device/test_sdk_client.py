"""Waveshare's own roarm_sdk drives the simulator like the real arm: proof that the simulator speaks
the firmware's protocol (the SDK's spacing, its framing on '}\\r\\n', its gripper convention)."""

import math
import time

import pytest

from roarmctl.device.simulator import PtySimulator, SimConfig

roarm_mod = pytest.importorskip("roarm_sdk.roarm")

COUNT = 2 * math.pi / 4096


@pytest.fixture
def arm():
    with PtySimulator(SimConfig()) as sim:  # factory InfoPrint 2: the SDK copes with the stream
        client = roarm_mod.roarm(roarm_type="roarm_m3", port=sim.path, baudrate=115200)
        try:
            yield client, sim
        finally:
            client.disconnect()


def test_sdk_feedback_at_boot_pose(arm):
    client, _ = arm
    fb = client.feedback_get()
    assert isinstance(fb, list) and len(fb) == 10  # x y z tit b s e t r g
    x, y, z, tit, b, s, e, t, r, g = fb
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
    time.sleep(0.6)
    got = client.joints_radian_get()
    assert got == pytest.approx(target, abs=2 * COUNT)
    # single-joint command (T:101): wrist to -0.2
    client.joint_radian_ctrl(joint=4, radian=-0.2, speed=1500, acc=0)
    time.sleep(0.5)
    assert client.joints_radian_get()[3] == pytest.approx(-0.2, abs=2 * COUNT)
    # the simulator saw the SDK's own (spaced) JSON and executed it
    codes = [c["T"] for _, c in sim.firmware.received]
    assert 102 in codes and 101 in codes and 605 in codes
