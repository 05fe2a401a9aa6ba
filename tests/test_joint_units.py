"""Units by joint type (issue 22, item 3): a prismatic joint (the WidowX-250s's finger, Interbotix's
published description) is in metres in ``kin`` input and output with or without ``--deg``, in its JSON
units, the plan's peak table, the CSV columns and the drawing's axes; angles without ``--deg`` that look
like degrees and ``kin`` inputs outside the limits are warned about."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from roarmctl.cli import run as run_cli  # noqa: E402
from roarmctl.robot.loader import load_robot  # noqa: E402

WX = str(Path(__file__).parent / "data" / "arms" / "wx250s" / "robot.yaml")
Q_RAD = [0.1, -0.2, 0.3, 0.0, 0.4, 0.0, 0.02]  # six angles (rad), the finger 0.02 m


def fk(capsys, *args: str) -> tuple[dict, str]:
    capsys.readouterr()
    assert run_cli(["kin", "fk", WX, *args, "--json"]) == 0
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err


def test_deg_turns_angles_into_degrees_and_leaves_metres_alone(capsys):
    rad, _ = fk(capsys, *map(str, Q_RAD))
    deg_in = [f"{np.degrees(v):.12g}" for v in Q_RAD[:6]] + ["0.02"]
    deg, _ = fk(capsys, *deg_in, "--deg")
    np.testing.assert_allclose(deg["position"], rad["position"], atol=1e-12)  # the same pose
    assert deg["q_units"] == ["deg"] * 6 + ["m"] and rad["q_units"] == ["rad"] * 6 + ["m"]
    assert deg["q"][6] == pytest.approx(0.02) and deg["q"][2] == pytest.approx(np.degrees(0.3))


def test_angles_that_look_like_degrees_and_values_outside_the_limits_are_warned_about(capsys):
    _, err = fk(capsys, "0", "0", "90", "0", "0", "0", "0.02")
    assert "90 look like degrees" in err and "pass --deg" in err
    assert "elbow = 90 rad" in err  # and outside the elbow's limits
    _, err = fk(capsys, *map(str, Q_RAD[:6]), "0.05")
    assert "left_finger = 0.05 m (limits [0.015, 0.037])" in err and "look like degrees" not in err
    _, err = fk(capsys, *map(str, Q_RAD))
    assert "warning" not in err


def test_ik_prints_the_finger_in_metres_with_deg(capsys):
    capsys.readouterr()
    assert run_cli(["kin", "ik", WX, "--xyz", "0.3", "0.0", "0.1", "--pitch", "90", "--deg", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    robot = load_robot(WX)
    assert out["units"][-1] == "m"
    finger = out["solutions"][0][-1]
    assert robot.lower[-1] <= finger <= robot.upper[-1]  # metres, not 0.86 "degrees" of 0.015 m


@pytest.fixture(scope="module")
def wx_traj(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("units") / "wx.traj.json"
    assert run_cli(["plan", str(Path(WX).parent / "plan.yaml"), "-o", str(out), "--json"]) == 0
    return out


@pytest.mark.slow
def test_peaks_csv_and_drawing_use_the_finger_units(wx_traj, tmp_path):
    from roarmctl.motion.report import motion_peaks
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.viz.data import path_data, robot_for
    from roarmctl.viz.path_figure import render_path

    traj = load_trajectory(wx_traj)
    robot = load_robot(WX)
    units = motion_peaks(traj, robot)["units"]
    assert units["jerk"][-1] == "m/s^3" and units["torque"][-1] == "N" and units["torque"][0] == "N m"
    out = tmp_path / "wx.csv"
    assert run_cli(["export", str(wx_traj), "-o", str(out)]) == 0
    rows = list(csv.DictReader(io.StringIO(out.read_text())))
    assert "left_finger_m" in rows[0] and "left_finger_m_s" in rows[0] and "waist_rad" in rows[0]
    np.testing.assert_allclose([float(r["left_finger_m"]) for r in rows], traj.positions[:, -1], atol=1e-8)
    fig = render_path(path_data(traj, robot_for(traj)), view="iso", size=(12, 8))
    by_gid = {a.get_gid(): a for a in fig.findobj(lambda a: bool(a.get_gid()))}
    assert "(m)" in by_gid["q:left_finger"].axes.get_ylabel()
    assert "(rad)" in by_gid["q:waist"].axes.get_ylabel()
    assert "(m/s)" in by_gid["v:left_finger"].axes.get_ylabel()


@pytest.mark.parametrize("spec", ["roarm_m3_pro", WX])
def test_joint_unit_follows_the_prismatic_mask(spec):
    # joint_unit looks up one joint's kind; the mask (its other users) and the unit must agree on every joint
    robot = load_robot(spec)
    mask = robot.prismatic
    assert mask.any() == (spec == WX)  # the WidowX's finger is prismatic, the RoArm has none
    for i in range(robot.dof):
        metres = bool(mask[i])
        assert robot.joint_unit(i) == ("m" if metres else "rad")
        assert robot.joint_unit(i, 2, deg=True) == ("m/s^2" if metres else "deg/s^2")
        assert robot.joint_unit(i, kind="effort") == ("N" if metres else "N m")
