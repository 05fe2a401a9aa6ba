"""The firmware frame: one transform between plan coordinates (m, z = 0 on the desk) and the RoArm
firmware's / roarm-sdk's (mm, origin at shoulder height), checked against the firmware's own FK
formula and the simulator's T:1051 x/y/z."""

import json
import math

import numpy as np
import pytest

from roarmctl.device.protocol import encode, parse_feedback
from roarmctl.device.simulator import Firmware, SimConfig, firmware_fk
from roarmctl.robot.frames import device_point, from_frame, get_frame, to_frame
from roarmctl.robot.ik import solve_ik_frame
from roarmctl.robot.loader import load_robot

R = load_robot("roarm_m3_pro")
FW = get_frame(R, "firmware")


def _workspace(n: int, seed: int = 3) -> np.ndarray:
    arm = R.arm_indices
    rng = np.random.default_rng(seed)
    return R.full_q(rng.uniform(R.lower[arm], R.upper[arm], size=(n, len(arm))))


def test_transform_round_trips_and_home_is_shoulder_height_apart():
    p = np.array([[0.25, -0.15, 0.02], [0.0, 0.0, 0.0]])
    assert from_frame(FW, to_frame(FW, p)) == pytest.approx(p)
    # the desk under the base is 122 mm below the firmware's origin
    assert to_frame(FW, [0, 0, 0]) == pytest.approx([0, 0, -122.059])
    home = R.full_q(R.named_poses["home"])
    world_mm = R.kin.fk(home)[:3, 3] * 1000
    fw = to_frame(FW, device_point(R, FW, home))
    assert world_mm[2] - fw[2] == pytest.approx(120.6, abs=1.0)  # the "about 120 mm in z"


def test_matches_the_firmware_fk_formula_everywhere_in_the_workspace():
    q = _workspace(5000)
    ours = to_frame(FW, device_point(R, FW, q))
    theirs = np.array([firmware_fk(*row[:4])[:3] for row in q])
    err = np.linalg.norm(ours - theirs, axis=1)
    assert err.max() < 3.0
    assert np.median(err) < 0.5  # the firmware's own end point, not hand_tcp (2-3 mm away)


@pytest.mark.slow  # the firmware model moved through the workspace
def test_matches_the_simulators_t1051_within_3_mm():
    f = Firmware(SimConfig(info_print=0), t0=0.0)
    t = 0.0
    for q in _workspace(40, seed=11):
        wire = {"base": q[0], "shoulder": q[1], "elbow": q[2], "wrist": q[3], "roll": q[4], "hand": math.pi - q[5],
                "spd": 0, "acc": 0, "T": 102}
        f.receive(encode(wire), t)
        f.advance(t + 2.5)
        f.pop_output(t + 2.5)
        f.receive(b'{"T":105}\n', t + 2.5)
        f.advance(t + 2.6)
        fb = [parse_feedback(x) for x in f.pop_output(t + 2.6).split(b"\r\n") if x][-1]
        t += 2.6
        # the commanded pose (servo quantisation: 1 count = 1.5 mrad) and the measured joints
        measured = np.array([fb.joints[k] for k in ("base", "shoulder", "elbow", "wrist", "roll")])
        for qq in (q, R.full_q(measured)):
            ours = to_frame(FW, device_point(R, FW, qq))
            assert np.linalg.norm(ours - np.array(fb.xyz)) < 3.0, (q, fb.xyz, ours)


def test_ik_in_the_firmware_frame_hits_the_firmware_end_point():
    for target in ([346.16, 0.0, 223.13], [250.0, 120.0, -60.0], [180.0, -200.0, 40.0]):
        for q in solve_ik_frame(R, FW, target, all_solutions=True):
            b, s, e, w = q[:4]
            assert firmware_fk(b, s, e, w)[:3] == pytest.approx(target, abs=0.3)
            assert to_frame(FW, device_point(R, FW, q)) == pytest.approx(target, abs=1e-3)


def test_kin_cli_frame_firmware(capsys):
    from roarmctl.cli import main

    def run(*args):
        with pytest.raises(SystemExit) as e:
            main(list(args))
        out = capsys.readouterr().out
        return e.value.code, out

    code, out = run("kin", "fk", "roarm_m3_pro", "0", "0", "1.5708", "0", "0", "--frame", "firmware", "--json")
    assert code == 0
    d = json.loads(out)
    assert d["unit"] == "mm" and d["position"] == pytest.approx([346.16, 0, 223.13], abs=0.2)
    code, out = run("kin", "ik", "roarm_m3_pro", "--xyz", "300", "50", "-80", "--frame", "firmware", "--json")
    assert code == 0
    q = json.loads(out)["solutions"][0]
    assert firmware_fk(*q[:4])[:3] == pytest.approx([300, 50, -80], abs=0.3)
    code, _ = run("kin", "fk", "roarm_m3_pro", "0", "0", "1.5708", "0", "0", "--frame", "nosuch")
    assert code == 2
