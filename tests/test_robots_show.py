"""``roarmctl robots show ARM`` (issue 33, item 4): every value with where it came from, checked against the files
read here independently, and every sidecar key documented in docs/reference.md."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from clirun import roarmctl

from roarmctl.robot.provenance import summary
from roarmctl.robot.validate import COMMON_KEYS, DH_KEYS, NESTED_KEYS, URDF_KEYS

ROOT = Path(__file__).resolve().parents[1]

ARMS = Path(__file__).parent / "data" / "arms"
REFERENCE = Path(__file__).parents[1] / "docs" / "reference.md"


def test_joint_limits_yaml_values_are_named_as_such():
    info = summary(str(ARMS / "irb2400" / "robot.yaml"))
    published = yaml.safe_load((ARMS / "irb2400" / "abb_irb2400_moveit_config" / "config" / "joint_limits.yaml").read_text())
    for j in info["joints"]:
        spec = published["joint_limits"].get(j["name"], {})
        if spec.get("has_velocity_limits"):
            assert j["velocity_source"] == "joint_limits.yaml" and j["velocity"] == spec["max_velocity"]
        if spec.get("has_acceleration_limits"):
            assert j["acceleration_source"] == "joint_limits.yaml" and j["acceleration"] == spec["max_acceleration"]
        assert j["unit"] == "rad" and j["velocity_unit"] == "rad/s"
    assert info["tcp"]["source"] == "SRDF" and info["named_poses"]["all-zeros"]["source"] == "SRDF"


@pytest.mark.slow
def test_sidecar_srdf_urdf_and_defaults_are_told_apart():
    info = summary(str(ARMS / "ar4" / "robot.yaml"))
    joints = {j["name"]: j for j in info["joints"]}
    assert joints["joint_1"]["effort"] is None and joints["joint_1"]["effort_source"] == "none given"  # effort="-1"
    # its published joint_limits.yaml (a ROS 2 parameter file) gives velocity and acceleration; Kinova's Gen3 has
    # none: its velocity is the URDF's and its acceleration roarmctl's default
    assert joints["joint_1"]["acceleration_source"] == joints["joint_1"]["velocity_source"] == "joint_limits.yaml"
    gen3 = {j["name"]: j for j in summary(str(ARMS / "gen3" / "robot.yaml"))["joints"]}
    assert gen3["joint_1"]["acceleration_source"] == "roarmctl default"
    assert gen3["joint_1"]["velocity_source"] == "URDF"
    assert joints["gripper_jaw1_joint"]["unit"] == "m" and joints["gripper_jaw1_joint"]["type"] == "prismatic"
    assert info["gripper"]["source"] == "SRDF" and info["gripper"]["joint"] == "gripper_jaw1_joint"
    assert info["tcp"] == {"link": "gripper_base_link", "source": "sidecar",
                           "tool": {"xyz": [0, -0.06, 0], "rpy": [0, 0, -1.5707963]}}
    sources = {tuple(p["links"]): p["source"] for p in info["allowed_collisions"]}
    assert sources[("link_2", "link_4")] == "sidecar" and sources[("link_1", "link_3")] == "SRDF"
    assert sources[("link_1", "link_2")] == "adjacent (always allowed)"
    assert info["groups"] == {"arm_group": "ar_manipulator", "gripper_group": "ar_gripper"}
    assert info["meshes"]["collision"] == 10 and info["meshes"]["visual_elements"] >= 10
    assert any("<passive_joint> not read inside a group" in n for n in info["notes"])


def test_the_cli_prints_the_same_and_refuses_a_bad_name():
    proc = roarmctl("robots", "show", "roarm_m3_pro", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["ok"] is True and out["joints"] == summary("roarm_m3_pro")["joints"]
    text = roarmctl("robots", "show", str(ARMS / "irb2400" / "robot.yaml"))
    assert text.returncode == 0 and "TCP: tool0 [SRDF]" in text.stdout and "collision pairs disabled:" in text.stdout
    bad = roarmctl("robots", "show", "no_such_robot")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert json.loads(roarmctl("robots", "--json").stdout)["ok"] is True  # the list stays where it was


@pytest.mark.parametrize("key", sorted(set(COMMON_KEYS + URDF_KEYS + DH_KEYS) | {k for v in NESTED_KEYS.values() for k in v}))
def test_every_sidecar_key_is_documented(key):
    assert f"`{key}" in REFERENCE.read_text() or f" {key}" in REFERENCE.read_text(), key


def test_a_description_folder_is_refused_naming_the_files_it_holds(tmp_path):
    """A user names the folder of a published arm (as the corpus keeps them): one line, exit 2, naming the files
    in it that could be meant; a plan naming a folder gets no names of what is there (its folder is not the user's
    choice)."""
    r = roarmctl("robots", "show", str(ROOT / "tests" / "data" / "arms" / "ur5e"))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert "is a folder" in r.stderr and "plan.yaml, robot.yaml" in r.stderr
    (tmp_path / "arm").mkdir()
    (tmp_path / "arm" / "secret.yaml").write_text("x: 1\n")
    from roarmctl.errors import InputError
    from roarmctl.robot.loader import load_robot

    with pytest.raises(InputError, match="is a folder") as err:
        load_robot(str(tmp_path / "arm"), confine=True)
    assert "secret" not in str(err.value) and "secret" not in (err.value.hint or "")
