"""The simulator's hand (``--guide``): while torque is off the servos follow a script; torque back on,
they stand where the hand left them. Firmware model alone, explicit times (deterministic)."""

import math
import subprocess
import sys

import numpy as np
import pytest

from roarmctl.device.firmware import Firmware
from roarmctl.device.fwmath import position_to_rad, urdf_from_firmware
from roarmctl.device.guide import Guide, guided_servos, load_guide, urdf_to_steps
from roarmctl.device.protocol import encode, parse_feedback
from roarmctl.device.sim_config import SimConfig
from roarmctl.errors import InputError

Q_A = [0.3, 0.2, 1.2, 0.4, 0.1, 0.5]  # URDF: 5 joints + gripper
Q_B = [-0.4, 0.5, 0.9, 0.2, -0.2, 0.1]


def guided(guide: Guide, **kw) -> Firmware:
    return Firmware(SimConfig(info_print=0, **kw), t0=0.0, servos=guided_servos(guide)())


def read(f: Firmware, t: float) -> np.ndarray:
    """URDF joints from a T:105 answer at ``t``."""
    f.receive(b'{"T":105}\n', t)
    f.advance(t + 0.05)
    lines = [parse_feedback(x) for x in f.pop_output(t + 0.05).split(b"\r\n") if x]
    fb = [x for x in lines if x][-1]
    return urdf_from_firmware([fb.joints[k] for k in ("base", "shoulder", "elbow", "wrist", "roll", "hand")])


def test_steps_invert_the_firmware_conversion():
    q = np.array(Q_A)
    back = urdf_from_firmware([position_to_rad(j, p) for j, p in enumerate(urdf_to_steps(q))])
    assert back == pytest.approx(q, abs=1e-12)


def test_torque_off_the_hand_moves_the_arm_linearly_from_where_it_stood():
    g = Guide(np.array([1.0, 2.0]), np.array([Q_A, Q_B]))
    f = guided(g)
    start = read(f, 0.0)
    f.receive(encode({"T": 210, "cmd": 0}), 0.2)
    f.advance(3.5)
    t_off = next(t for _, t, c in f.executed if c.get("T") == 210)
    t, q, torque = f.recording()
    after = t > t_off
    assert not torque[after].any() and torque[t < t_off].all()
    # the true positions: linear from the pose at torque-off to A (1 s), to B (2 s), then B
    ts, qs = np.array([0.0, 1.0, 2.0]), np.array([start, Q_A, Q_B])
    expected = np.array([[np.interp(x - t_off, ts, qs[:, j]) for j in range(6)] for x in t[after]])
    assert np.abs(q[after] - expected).max() < 1e-9
    assert t[after][-1] - t_off > 3.0
    assert read(f, 3.5) == pytest.approx(Q_B, abs=2e-3)  # and the feedback says so (one count of rounding)


def test_torque_on_the_servos_hold_where_the_hand_left_them_after_a_position_write():
    g = Guide(np.array([0.5]), np.array([Q_A]))
    f = guided(g)
    f.receive(encode({"T": 210, "cmd": 0}), 0.0)
    f.advance(1.0)
    here = read(f, 1.0)
    wire = dict(zip(("base", "shoulder", "elbow", "wrist", "roll"), here[:5])) | {"hand": math.pi - here[5]}
    f.receive(encode({"T": 102, **wire, "spd": 0, "acc": 0}), 1.1)  # targets = measured pose (torque on)
    f.receive(encode({"T": 210, "cmd": 1}), 1.12)
    f.advance(1.2)
    assert f.servos.torque().all()
    t, q, _ = f.recording()
    after = q[t >= 1.1]
    assert np.abs(after - here).max() < 2e-3  # no jump: it holds where the hand left it
    assert read(f, 3.0) == pytest.approx(here, abs=2e-3)


def test_torque_on_alone_drives_to_the_goal_kept_while_limp():
    """Why teach writes the measured pose first: torque on by itself returns to the old goal (a jump)."""
    g = Guide(np.array([0.5]), np.array([Q_A]))
    f = guided(g)
    before = read(f, 0.0)
    f.receive(encode({"T": 210, "cmd": 0}), 0.1)
    f.advance(1.0)
    f.receive(encode({"T": 210, "cmd": 1}), 1.0)
    f.advance(3.0)
    assert read(f, 3.0) == pytest.approx(before, abs=2e-3)


def test_guide_file_is_checked(tmp_path):
    p = tmp_path / "g.yaml"
    p.write_text("- {t: 1.0, joints: [0.3, 0.2, 1.2, 0.4, 0.1], gripper: 0.5}\n- {t: 2, joints: [0, 0, 1, 0, 0]}\n")
    g = load_guide(p)
    assert g.t.tolist() == [1.0, 2.0] and g.q[1, 5] == 0.5
    for bad, word in [("- {t: 1, joints: [0, 0, 1, 0, 0], gripper: 0.5}\n- {t: 1, joints: [0, 0, 1, 0, 0]}\n", "after"),
                      ("- {t: 1, joints: [0, 0, 1, 0], gripper: 0.5}\n", "5 joint"),
                      ("- {t: 1, joints: [0, 0, 90, 0, 0], gripper: 0.5}\n", "radians"),
                      ("- {t: 1, joints: [0, 0, 1, 0, 0]}\n", "gripper"),
                      ("{t: 1}\n", "list")]:
        p.write_text(bad)
        with pytest.raises(InputError, match=word):
            load_guide(p)


@pytest.mark.slow
def test_sim_device_guide_option_refuses_physics_servos(tmp_path):
    p = tmp_path / "g.yaml"
    p.write_text("- {t: 1.0, joints: [0.3, 0.2, 1.2, 0.4, 0.1], gripper: 0.5}\n")
    r = subprocess.run([sys.executable, "-m", "roarmctl", "sim-device", "--guide", str(p), "--servos", "physics"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "ideal" in r.stderr


@pytest.mark.slow
def test_sim_device_guide_moves_the_served_arm_while_torque_is_off(tmp_path):
    """`sim-device --guide` end to end: a client switches torque off, and the feedback follows the script."""
    import signal
    import time

    from roarmctl.device.feedback import FeedbackValidator, read_valid
    from roarmctl.device.link import Link
    from roarmctl.robot.loader import load_robot

    p = tmp_path / "g.yaml"
    p.write_text("- {t: 0.5, joints: [0.3, 0.2, 1.2, 0.4, 0.1], gripper: 0.5}\n")
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "sim-device", "--guide", str(p), "--no-boot"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        path = proc.stdout.readline().strip()
        robot = load_robot("roarm_m3_pro")
        link = Link(path)
        link.require_torque = False
        with link:
            link.connect()
            link.send({"T": 210, "cmd": 0})
            check = FeedbackValidator(robot, firmware=link.firmware, expect_torque=None)
            end = time.monotonic() + 60  # a hang detector: the script's 0.5 s run on the simulator's clock
            q = read_valid(link, check).q
            while time.monotonic() < end and not np.allclose(q, Q_A, atol=2e-3):
                q = read_valid(link, check).q
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=30)
    assert q == pytest.approx(Q_A, abs=2e-3)
