"""Robot descriptions: the bundled ones load as documented; broken ones give a DescriptionError naming the field."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import yaml
from clirun import roarmctl

from roarmctl.errors import DescriptionError, InputError
from roarmctl.robot.loader import bundled_dir, bundled_robots, load_robot

GOOD_DH = {
    "format": "roarmctl.robot/1",
    "name": "two_link",
    "convention": "standard",
    "dh": [
        {"name": "j1", "a": 0.5, "alpha": 0, "d": 0, "lower": -3, "upper": 3},
        {"name": "j2", "a": 0.4, "alpha": 0, "d": 0, "lower": -3, "upper": 3},
    ],
    "inertials": [{"link": "link1", "mass": 1.0}, {"link": "link2", "mass": 1.0}],
}


def _write_dh(tmp_path: Path, mutate) -> Path:
    data = copy.deepcopy(GOOD_DH)
    mutate(data)
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _set(path: list, value):
    def mutate(d):
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return mutate


def _pop(path: list):
    def mutate(d):
        node = d
        for k in path[:-1]:
            node = node[k]
        node.pop(path[-1])
    return mutate


def test_bundled_robots_load():
    assert set(bundled_robots()) >= {"roarm_m3_pro", "ur10", "planar_2r", "scara_2r"}
    r = load_robot("roarm_m3_pro")
    assert r.dof == 6 and r.arm_dof == 5 and r.tcp_link == "hand_tcp"
    assert r.gripper.joint == "link5_to_gripper_link" and (r.gripper.open, r.gripper.closed) == (1.5, 0.0)
    assert np.allclose(r.named_poses["home"], [0, 0, 1.5708, 0, 0, 0])
    assert [w.field for w in r.wire] == ["base", "shoulder", "elbow", "wrist", "roll", "hand"]
    assert r.wire[-1].to_wire(0.0) == pytest.approx(np.pi)  # hand = pi - q_gripper
    assert np.all(r.velocity_limits > 0) and np.all(r.acceleration_limits > 0)
    assert sum(i.mass for i in r.inertials.values()) == pytest.approx(0.4493225, abs=1e-7)  # sum of the <mass> values in Waveshare's roarm_m3.xacro
    u = load_robot("ur10")
    assert u.dof == 6 and np.allclose(u.upper, 2 * np.pi)


def test_good_dh_loads(tmp_path):
    r = load_robot(str(_write_dh(tmp_path, lambda d: None)))
    assert r.joint_names == ["j1", "j2"]
    assert np.allclose(r.kin.fk([0, 0])[:3, 3], [0.9, 0, 0])


@pytest.mark.parametrize("mutate, needle", [
    (_pop(["dh", 0, "a"]), "dh[0].a"),
    (_set(["dh", 1, "alpha"], "ninety"), "dh[1].alpha"),
    (_set(["dh", 0, "d"], True), "dh[0].d"),
    (_pop(["dh", 0, "lower"]), "dh[0].lower"),
    (_set(["dh", 0, "lower"], 4), "dh[0]: lower must be below upper"),
    (_set(["dh", 0, "bogus"], 1), "bogus"),
    (_set(["dh", 0, "type"], "spherical"), "dh[0].type"),
    (_set(["dh"], "not a table"), "dh:"),
    (_set(["convention"], "craig"), "convention"),
    (_pop(["convention"]), "convention"),
    (_pop(["dh"]), "'dh'"),
    (_set(["format"], "something/2"), "format"),
    (_set(["length_unit"], "cm"), "length_unit"),
    (_set(["angle_unit"], "grad"), "angle_unit"),
    (_set(["limits"], {"velocity": {"j3": 1.0}}), "unknown joint 'j3'"),
    (_set(["limits"], {"velocity": [1.0]}), "limits.velocity"),
    (_set(["limits"], {"acceleration": {"j1": -1.0}}), "limits.acceleration.j1"),
    (_set(["limits"], {"velocity": [1.0, 0.0]}), "limits.velocity.j2"),
    (_set(["gripper"], {"joint": "j9", "open": 1, "closed": 0}), "gripper.joint"),
    (_set(["named_poses"], {"home": [0.0]}), "named_poses.home"),
    (_set(["tool"], {"xyz": [0, 0]}), "tool.xyz"),
    (_set(["tool"], [0, 0, 0.1]), "tool"),
    (_set(["base"], {"xyz": "up"}), "base.xyz"),
    (_set(["inertials", 0, "mass"], "heavy"), "inertials[0].mass"),
    (_set(["inertials", 0, "mass"], -1.0), "inertials[0].mass"),
    (_set(["inertials", 0, "com"], [0, 0]), "inertials[0].com"),
    (_set(["inertials", 0, "link"], "link7"), "inertials[0].link"),
])
def test_bad_dh_names_the_field(tmp_path, mutate, needle):
    path = _write_dh(tmp_path, mutate)
    with pytest.raises(DescriptionError) as ei:
        load_robot(str(path))
    assert needle in str(ei.value)
    assert str(path) in str(ei.value)  # names the file too
    assert "\n" not in str(ei.value)


def test_not_yaml_gives_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("format: roarmctl.robot/1\ndh:\n  - [unclosed\n")
    with pytest.raises(DescriptionError) as ei:
        load_robot(str(path))
    assert "not valid YAML" in str(ei.value) and "broken.yaml:" in str(ei.value)


def test_unknown_robot_is_input_error():
    with pytest.raises(InputError) as ei:
        load_robot("no_such_robot_xyz")
    assert "roarm_m3_pro" in (ei.value.hint or "")


# ------------------------------------------------------------------------------- URDF + sidecar
URDF = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
SIDE = (bundled_dir() / "roarm_m3_pro.yaml").read_text()


def _write_urdf(tmp_path: Path, urdf: str = URDF, side: str = SIDE) -> Path:
    (tmp_path / "arm.urdf").write_text(urdf)
    path = tmp_path / "arm.yaml"
    path.write_text(side.replace("urdf: roarm_m3_pro.urdf", "urdf: arm.urdf"))
    return path


def test_urdf_copy_loads_like_bundled(tmp_path):
    r = load_robot(str(_write_urdf(tmp_path)))
    b = load_robot("roarm_m3_pro")
    q = np.array([0.3, 0.4, 1.0, 0.5, 0.2, 0.7])
    assert np.allclose(r.kin.fk(q), b.kin.fk(q))


def test_bare_urdf_loads(tmp_path):
    (tmp_path / "bare.urdf").write_text(URDF)
    r = load_robot(str(tmp_path / "bare.urdf"))
    assert r.dof == 6 and r.gripper is None


@pytest.mark.parametrize("urdf_edit, side_edit, needle", [
    (("</robot>", ""), None, "not valid XML"),
    (('xyz="0 0 0.051959"', 'xyz="0 0 abc"'), None, "origin xyz"),
    (('type="revolute"', 'type="planar"'), None, "type 'planar'"),
    (('lower="-3.13"', 'lower="x"'), None, "limit lower"),
    (('<mass value="0.2562183"/>', '<mass value="heavy"/>'), None, "mass value"),
    (('<parent link="base_link"/><child link="link1"/>', '<parent link="base_link"/>'), None, "<child link"),
    (None, ("joints: [base_link_to_link1", "joints: [nope"), "joints: 'nope'"),
    (None, ("tcp_link: hand_tcp", "tcp_link: hand"), "tcp_link: 'hand'"),
    (None, ("velocity:     {base_link_to_link1", "velocity:     {base_link_to_linkX"), "unknown joint 'base_link_to_linkX'"),
    (None, ("{joint: base_link_to_link1,    field: base", "{joint: foo,    field: base"), "wire[0].joint"),
    (None, ("open: 1.5", "open: wide"), "gripper.open"),
    (None, ("urdf: arm.urdf", "urdf: missing.urdf"), "urdf: file 'missing.urdf' not found"),
])
def test_bad_urdf_or_sidecar_names_the_field(tmp_path, urdf_edit, side_edit, needle):
    urdf = URDF.replace(*urdf_edit, 1) if urdf_edit else URDF
    side = SIDE.replace("urdf: roarm_m3_pro.urdf", "urdf: arm.urdf")
    if side_edit:
        assert side_edit[0] in side
        side = side.replace(*side_edit, 1)
    with pytest.raises(DescriptionError) as ei:
        load_robot(str(_write_urdf(tmp_path, urdf, side)))
    assert needle in str(ei.value)


# ------------------------------------------------------------------------------- through the CLI
def test_bad_description_through_cli_exit_2_one_line(tmp_path):
    path = _write_dh(tmp_path, _set(["convention"], "craig"))
    proc = roarmctl("kin", "fk", str(path), "0", "0")
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "convention" in lines[0] and lines[0].startswith("error:")
    assert "Traceback" not in proc.stderr
