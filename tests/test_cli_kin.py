"""`roarmctl kin fk/ik/jacobian/dynamics` through the real entry point: JSON keys, values, units, exit codes."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from clirun import roarmctl as run

from roarmctl.robot.loader import load_robot


def run_json(*args: str) -> dict:
    proc = run(*args, "--json")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("\n") == 1  # one JSON object, nothing else
    return json.loads(proc.stdout)


def test_fk_json_keys_and_values():
    out = run_json("kin", "fk", "roarm_m3_pro", "0", "0", str(math.pi / 2), "0", "0")
    assert {"position", "rotation", "rpy"} <= set(out)
    assert np.allclose(out["position"], [0.343668, 0, 0.343728], atol=2e-6)
    assert np.allclose(out["rotation"], np.eye(3), atol=1e-5)
    assert np.allclose(out["rpy"], 0, atol=1e-5)


def test_fk_deg_round_trip():
    rad = run_json("kin", "fk", "ur10", *[str(math.radians(v)) for v in (30, 45, 26, 50, 60, 80)])
    deg = run_json("kin", "fk", "ur10", "30", "45", "26", "50", "60", "80", "--deg")
    assert np.allclose(rad["position"], deg["position"], atol=1e-12)
    assert np.allclose(np.radians(deg["rpy"]), rad["rpy"], atol=1e-12)
    assert np.allclose(deg["q"], [30, 45, 26, 50, 60, 80])
    assert np.allclose(np.array(deg["position"]) * 1000, [519.9835444, 57.7255263, 1110.6969610], atol=1e-4)


def test_ik_json_solutions_verified_by_fk():
    robot = load_robot("roarm_m3_pro")
    out = run_json("kin", "ik", "roarm_m3_pro", "--xyz", "0.25", "-0.1", "0.05", "--pitch", str(math.pi / 2), "--all")
    assert out["solutions"]
    for q, err in zip(out["solutions"], out["position_errors"]):
        assert len(q) == 6
        t = robot.kin.fk(np.array(q))
        assert np.linalg.norm(t[:3, 3] - [0.25, -0.1, 0.05]) <= 1e-6 and err <= 1e-6
        assert t[2, 0] == pytest.approx(-1.0, abs=1e-5)  # pointing straight down


def test_ik_deg_round_trip_through_fk():
    out = run_json("kin", "ik", "roarm_m3_pro", "--xyz", "0.2", "0.1", "0.15", "--pitch", "60", "--roll", "30", "--deg")
    q = out["solutions"][0]
    assert q[4] == pytest.approx(30.0)  # roll comes back in degrees
    fk = run_json("kin", "fk", "roarm_m3_pro", *map(str, q), "--deg")
    assert np.allclose(fk["position"], [0.2, 0.1, 0.15], atol=1e-6)


def test_ik_ur10_all_eight():
    t = load_robot("ur10").kin.fk(np.radians([30, 45, 26, 50, 60, 80]))
    from roarmctl.robot.model import rpy_from_matrix

    rpy = rpy_from_matrix(t[:3, :3])
    out = run_json("kin", "ik", "ur10", "--xyz", *(repr(float(v)) for v in t[:3, 3]), "--rpy", *(repr(float(v)) for v in rpy), "--all")
    assert len(out["solutions"]) == 8
    assert max(out["orientation_errors"]) < 1e-6


def test_ik_ref_sorts_and_keeps_gripper():
    out = run_json("kin", "ik", "roarm_m3_pro", "--xyz", "0.25", "0", "0.1", "--pitch", "1.2", "--ref", "0,0.3,1.5,0.8,0,1.1")
    assert out["solutions"][0][5] == pytest.approx(1.1)


@pytest.mark.parametrize("args, reason", [
    (["roarm_m3_pro", "--xyz", "0.9", "0", "0.1"], "out_of_reach"),
    (["roarm_m3_pro", "--xyz", "0.08", "0", "0.05", "--pitch", "0"], "joint_limit"),
    (["roarm_m3_pro", "--xyz", "0.3", "0", "0.2", "--rpy", "0", "0", "90", "--deg"], "orientation"),
    (["scara_2r", "--xyz", "0.9", "0", "0"], "out_of_reach"),
])
def test_ik_unreachable_exit_3_one_line(args, reason):
    proc = run("kin", "ik", *args, "--json")
    assert proc.returncode == 3
    out = json.loads(proc.stdout)  # --json: a failure is a JSON object too
    assert out["ok"] is False and out["exit_code"] == 3 and reason in out["error"]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and reason in lines[0] and "Traceback" not in proc.stderr


def test_ik_bad_usage_exit_2():
    assert run("kin", "ik", "roarm_m3_pro", "--xyz", "0.3", "0", "0.2", "--pitch", "1", "--rpy", "0", "0", "0").returncode == 2
    assert run("kin", "ik", "roarm_m2_s", "--xyz", "0.2", "0", "0.1", "--pitch", "1").returncode == 2  # position-only IK
    # a pitch the 2-joint SCARA cannot hold is infeasible (3), not ignored; the position alone needs the
    # elbow at 131.8 deg (cos = (0.3^2 - 0.4^2 - 0.3^2) / (2 0.4 0.3)), beyond its 130 deg limit
    r = run("kin", "ik", "scara_2r", "--xyz", "0.3", "0", "0", "--pitch", "1")
    assert r.returncode == 3 and "joint_limit" in r.stderr
    assert run("kin", "ik", "roarm_m3_pro", "--xyz", "0.3", "0").returncode == 2


def test_ik_table_output():
    proc = run("kin", "ik", "roarm_m3_pro", "--xyz", "0.25", "0", "0.05", "--pitch", "90", "--deg")
    assert proc.returncode == 0 and "solution" in proc.stdout and "base_link_to_link1" in proc.stdout


def test_jacobian_json_scara_singular():
    out = run_json("kin", "jacobian", "scara_2r", "0", "0")
    assert {"jacobian", "manipulability", "singular_values", "ellipsoid_radii", "singularity"} <= set(out)
    assert np.array(out["jacobian"]).shape == (6, 2)
    assert np.allclose(out["ellipsoid_radii"], [0.761577, 0], atol=1e-6)
    assert out["singularity"] == "elbow_stretched"


def test_jacobian_json_roarm():
    out = run_json("kin", "jacobian", "roarm_m3_pro", "0", "0.2", "1.2", "0.3", "0", "--deg")
    assert np.array(out["jacobian"]).shape == (6, 5)
    assert out["singularity"] is None or isinstance(out["singularity"], str)


def test_dynamics_json_matches_seed001():
    out = run_json("kin", "dynamics", "planar_2r", "--q", f"{math.pi / 4} {math.pi / 3}", "--qd", "1,-0.5", "--qdd", "0 0")
    assert {"tau", "mass_matrix", "gravity"} <= set(out)
    assert np.allclose(out["mass_matrix"], [[4, 1.5], [1.5, 1]], atol=1e-12)
    assert np.allclose(out["gravity"], [11.33442, -2.539015], atol=1e-5)
    assert np.allclose(out["tau"], [11.33442 + 0.649519, -2.539015 + 0.866025], atol=1e-5)


def test_dynamics_takes_joint_values_like_fk():
    """``kin dynamics ROBOT Q...`` (negative values too) gives what ``--q`` gives; both at once is exit 2.
    Hand-derived: the double pendulum at q = (-pi/4, pi/3) at rest holds
    G1 = (m1 + m2) g l1 cos q1 + m2 g l2 cos(q1 + q2), G2 = m2 g l2 cos(q1 + q2) (l = 1 m, m = 1 kg)."""
    q1, q2 = -math.pi / 4, math.pi / 3
    pos = run_json("kin", "dynamics", "planar_2r", f"{q1}", f"{q2}")
    opt = run_json("kin", "dynamics", "planar_2r", "--q", f"{q1} {q2}")
    assert np.allclose(pos["tau"], opt["tau"], atol=1e-12)
    g = 9.81
    assert np.allclose(pos["gravity"], [2 * g * math.cos(q1) + g * math.cos(q1 + q2), g * math.cos(q1 + q2)], atol=1e-9)
    both = run("kin", "dynamics", "planar_2r", "0", "0", "--q", "0 0")
    assert both.returncode == 2 and "once" in both.stderr


def test_dynamics_deg():
    rad = run_json("kin", "dynamics", "planar_2r", "--q", f"{math.pi / 4},{math.pi / 3}", "--qdd", "1 2")
    deg = run_json("kin", "dynamics", "planar_2r", "--q", "45 60", "--qdd", f"{math.degrees(1)} {math.degrees(2)}", "--deg")
    assert np.allclose(rad["tau"], deg["tau"], atol=1e-9)  # torques stay N m
    assert np.allclose(deg["q"], [45, 60])


def test_dynamics_errors_exit_2():
    proc = run("kin", "dynamics", "scara_2r", "--q", "0 0")
    assert proc.returncode == 2 and "inertial" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert run("kin", "dynamics", "planar_2r", "--q", "0 x").returncode == 2
    assert run("kin", "dynamics", "planar_2r", "--q", "0 0 0").returncode == 2


def test_negative_joint_values_are_values_not_options():
    out = run_json("kin", "fk", "roarm_m3_pro", "0", "-0.5", "1", "-0.2", "0")
    assert np.allclose(out["q"][:5], [0, -0.5, 1, -0.2, 0])
    out = run_json("kin", "jacobian", "planar_2r", "-1", "-0.5")
    assert np.array(out["jacobian"]).shape == (6, 2)
    out = run_json("kin", "dynamics", "planar_2r", "--q", "-0.5 1", "--qd", "-1,-1")
    assert len(out["tau"]) == 2


def test_joint_values_typed_as_a_list_are_the_same_values():
    """'[0, -0.5, 1, -0.2, 0]' (a list as YAML or Python writes it) and '0,-0.5,...' give the same FK as five
    separate arguments; a word among them is one line naming it, exit 2."""
    apart = run_json("kin", "fk", "roarm_m3_pro", "0", "-0.5", "1", "-0.2", "0")
    for typed in ("[0, -0.5, 1, -0.2, 0]", "[0,-0.5,1,-0.2,0]", "0,-0.5,1,-0.2,0"):
        out = run_json("kin", "fk", "roarm_m3_pro", typed)
        assert out["q"] == apart["q"] and out["position"] == apart["position"], typed
    proc = run("kin", "fk", "roarm_m3_pro", "[0, x, 1, -0.2, 0]")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "'x' is not a number" in proc.stderr


@pytest.mark.parametrize("args", [
    ("fk", "roarm_m3_pro", "0", "0", "nan", "0", "0"),                 # was exit 0 with a NaN pose
    ("fk", "roarm_m3_pro", "0", "0", "inf", "0", "0"),
    ("jacobian", "ur10", "0", "0", "0", "0", "-inf", "0"),
    ("dynamics", "planar_2r", "--q", "0 0", "--qd", "nan 0"),
    ("ik", "roarm_m3_pro", "--xyz", "0.25", "0", "0.05", "--pitch", "inf"),  # was exit 1, a bug report
    ("ik", "roarm_m3_pro", "--xyz", "0.25", "0", "0.05", "--pitch", "1.5", "--roll", "nan"),
    ("ik", "ur10", "--xyz", "0.5", "0.2", "0.5", "--pitch", "nan"),
    ("ik", "roarm_m3_pro", "--xyz", "0.25", "0", "0.05", "--ref", "0 0 nan 0 0"),
])
def test_non_finite_numbers_exit_2_one_line(args):
    proc = run("kin", *args)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "finite" in lines[0] and "Traceback" not in proc.stderr


def test_library_ik_refuses_non_finite_angles():
    from roarmctl.errors import InputError
    from roarmctl.robot.ik import solve_ik

    robot = load_robot("roarm_m3_pro")
    for kw in ({"pitch": float("inf")}, {"pitch": 1.0, "roll": float("nan")}):
        with pytest.raises(InputError, match="finite"):
            solve_ik(robot, [0.25, 0, 0.05], **kw)


def test_names_with_brackets_in_a_description_are_printed_as_they_are(tmp_path):
    """A joint or robot named with '[/]' (any text a description may hold) was read as rich markup: robots show,
    kin jacobian and kin dynamics ended as internal errors (MarkupError, exit 1)."""
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "src" / "roarmctl" / "robots" / "planar_2r.yaml"
    text = src.read_text().replace("name: joint1,", 'name: "jo[/]int1",').replace("name: planar_2r", 'name: "pl[/]anar"')
    assert "jo[/]int1" in text and "pl[/]anar" in text
    desc = tmp_path / "p2r.yaml"
    desc.write_text(text)
    for args in (("robots", "show", str(desc)), ("kin", "jacobian", str(desc), "0.1", "0.2"),
                 ("kin", "dynamics", str(desc), "0", "0"), ("kin", "fk", str(desc), "0", "0")):
        proc = run(*args)
        assert proc.returncode == 0 and "[/]" in proc.stdout, proc.stderr


@pytest.mark.parametrize("spec", ["missing.yaml", "arms/missing.urdf", "sub/dir/robot"])
def test_a_missing_description_path_is_named_as_a_missing_file(spec):
    """A path that is not there said "unknown robot 'missing.yaml' (...; or give a path to a .yaml or .urdf file)":
    the fix it offered is what the user had done."""
    proc = run("kin", "fk", spec, "0", "0")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and f"no such description file '{spec}'" in lines[0], proc.stderr
    assert "unknown robot" not in lines[0]
    assert "unknown robot 'roarm_m9'" in run("kin", "fk", "roarm_m9", "0", "0").stderr  # a name stays a name
