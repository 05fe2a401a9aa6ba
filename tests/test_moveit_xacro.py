"""xacro, SRDF and joint_limits.yaml input (issue 8, item 2): what they set, and bad input as exit 2."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from clirun import roarmctl

from roarmctl.errors import DescriptionError
from roarmctl.robot.loader import bundled_dir, load_robot

SRDF = """<robot name="arm">
  <group name="arm"><chain base_link="base_link" tip_link="hand_tcp"/></group>
  <group name="gripper"><link name="gripper_link"/></group>
  <group_state name="tucked" group="arm">
    <joint name="base_link_to_link1" value="0.1"/><joint name="link1_to_link2" value="0"/>
    <joint name="link2_to_link3" value="2.0"/><joint name="link3_to_link4" value="0"/><joint name="link4_to_link5" value="0"/>
  </group_state>
  <group_state name="open" group="gripper"><joint name="link5_to_gripper_link" value="1.2"/></group_state>
  <group_state name="close" group="gripper"><joint name="link5_to_gripper_link" value="0.1"/></group_state>
  <disable_collisions link1="link1" link2="link4" reason="Never"/>
  %s
</robot>"""

LIMITS = {"default_velocity_scaling_factor": 0.5, "joint_limits": {
    "base_link_to_link1": {"has_velocity_limits": True, "max_velocity": 0.7, "has_acceleration_limits": True, "max_acceleration": 1.1},
    "link1_to_link2": {"has_velocity_limits": False, "max_velocity": 0, "has_position_limits": True, "min_position": -1.0, "max_position": 1.0}}}


def setup(tmp_path: Path, srdf_extra: str = "", limits=None, side_extra=None) -> Path:
    (tmp_path / "arm.srdf").write_text(SRDF % srdf_extra)
    (tmp_path / "joint_limits.yaml").write_text(yaml.safe_dump(limits if limits is not None else LIMITS))
    side = {"format": "roarmctl.robot/1", "urdf": str(bundled_dir() / "roarm_m3_pro.urdf"), "srdf": "arm.srdf",
            "joint_limits": "joint_limits.yaml", "ik": "roarm5"}
    side.update(side_extra or {})
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    return tmp_path / "arm.yaml"


def test_srdf_and_joint_limits_fill_the_description(tmp_path):
    r = load_robot(str(setup(tmp_path)))
    assert r.tcp_link == "hand_tcp"
    assert (r.gripper.joint, r.gripper.open, r.gripper.closed) == ("link5_to_gripper_link", 1.2, 0.1)
    assert np.allclose(r.named_poses["tucked"], [0.1, 0, 2.0, 0, 0, 0.1])
    assert frozenset(("link1", "link4")) in r.allowed_collisions
    assert r.velocity_limits[0] == 0.7 and r.acceleration_limits[0] == 1.1
    assert r.velocity_limits[1] == 1.0  # has_velocity_limits false: the URDF's 0 means unset -> default
    assert (r.lower[1], r.upper[1]) == (-1.0, 1.0)


def test_xacro_input_expands_arguments(tmp_path):
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    urdf = urdf.replace('<robot name="roarm_m3_pro">', '<robot name="roarm_m3_pro" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                        '<xacro:arg name="base_height" default="0.0701"/>')
    urdf = urdf.replace('<origin xyz="0 0 0.0701" rpy="0 0 0"/>', '<origin xyz="0 0 $(arg base_height)" rpy="0 0 0"/>')
    (tmp_path / "arm.urdf.xacro").write_text(urdf)
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    side.update(urdf="arm.urdf.xacro", xacro_args={"base_height": 0.2})
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    r, m3 = load_robot(str(tmp_path / "arm.yaml")), load_robot("roarm_m3_pro")
    q = m3.full_q(m3.named_poses["home"])
    assert np.allclose(r.kin.fk(q)[:3, 3] - m3.kin.fk(q)[:3, 3], [0, 0, 0.2 - 0.0701], atol=1e-12)


@pytest.mark.parametrize("srdf_extra, limits, side_extra, needle", [
    ('<virtual_joint name="v" type="floating" parent_frame="world" child_link="base_link"/>', None, None,
     r"arm.srdf: virtual_joint 'v': type 'floating' is not supported"),
    ("", {"joint_limits": {"nojoint": {}}}, None, r"joint_limits.yaml: joint_limits.nojoint: not a joint"),
    ("", None, {"gripper_group": "arm"}, r"arm.srdf: gripper group 'arm' drives 5 joints"),
    ("", {"joint_limits": {"link1_to_link2": {"has_velocity_limits": True, "max_velocity": "fast"}}}, None,
     r"joint_limits.link1_to_link2.max_velocity: expected a number"),
    ("", {"joint_limits": {"link1_to_link2": {"max_speed": 1}}}, None, r"joint_limits.link1_to_link2: unknown key"),
    ("", None, {"srdf": "missing.srdf"}, r"arm.yaml: srdf: file '.*missing.srdf' not found"),
])
def test_bad_moveit_input_is_exit_2_naming_file_and_field(tmp_path, srdf_extra, limits, side_extra, needle):
    side = setup(tmp_path, srdf_extra, limits, side_extra)
    with pytest.raises(DescriptionError, match=needle):
        load_robot(str(side))
    proc = roarmctl("kin", "fk", str(side), "0", "0", "0", "0", "0")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr


@pytest.mark.parametrize("body, needle", [
    ('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><xacro:undefined_macro/></robot>', r"bad.xacro: xacro: "),
    ('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="${1/0}"/></robot>', r"bad.xacro: xacro: "),
    ('<robot name="r"><link name="a"', r"bad.xacro: xacro: "),
])
def test_bad_xacro_is_exit_2_naming_the_file(tmp_path, body, needle):
    (tmp_path / "bad.xacro").write_text(body)
    with pytest.raises(DescriptionError, match=needle):
        load_robot(str(tmp_path / "bad.xacro"))
    proc = roarmctl("kin", "fk", str(tmp_path / "bad.xacro"), "0")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "bad.xacro" in proc.stderr


def test_xacro_find_uses_the_packages_map(tmp_path):
    pkg = tmp_path / "armpkg"
    pkg.mkdir()
    (pkg / "parts.xacro").write_text('<robot xmlns:xacro="http://www.ros.org/wiki/xacro"><link name="extra"/></robot>')
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text().replace(
        '<robot name="roarm_m3_pro">', '<robot name="roarm_m3_pro" xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:include filename="$(find armpkg)/parts.xacro"/>'
        '<joint name="extra_joint" type="fixed"><parent link="link5"/><child link="extra"/></joint>')
    (tmp_path / "arm.xacro").write_text(urdf)
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    side.update(urdf="arm.xacro", packages={"armpkg": "armpkg"})
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    assert "extra" in load_robot(str(tmp_path / "arm.yaml")).link_names
    del side["packages"]
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    from roarmctl.robot import loader

    loader._CACHE.clear()
    with pytest.raises(DescriptionError, match=r"arm.xacro: xacro include: \$\(find armpkg\): package 'armpkg' is unknown"):
        load_robot(str(tmp_path / "arm.yaml"))


JOINT_LIST_SRDF = """<robot name="arm">
  <group name="arm">%s</group>
  <group name="hand"><joint name="link5_to_gripper_link"/></group>
  <group name="arm_and_hand"><group name="arm"/><group name="hand"/></group>
  <group_state name="ready" group="arm_and_hand">
    <joint name="base_link_to_link1" value="0.2"/><joint name="link1_to_link2" value="0.1"/>
    <joint name="link2_to_link3" value="1.9"/><joint name="link3_to_link4" value="0.3"/><joint name="link4_to_link5" value="0"/>
    <joint name="link5_to_gripper_link" value="0.7"/>
  </group_state>
  <end_effector name="ee" parent_link="hand_tcp" group="arm"/>
</robot>"""


def test_srdf_with_an_arm_group_of_joints_and_a_composite_state(tmp_path):
    """An SRDF in the style of Franka's in example-robot-data: the arm group lists joints (no chain),
    the end effector names the TCP link (and, unusually, the arm group), a pose is given for a group
    made of the arm and hand groups. With ``gripper_group: hand`` it loads: TCP from the end effector,
    the pose with its gripper value."""
    joints = "".join(f'<joint name="{n}"/>' for n in ("base_link_to_link1", "link1_to_link2", "link2_to_link3",
                                                       "link3_to_link4", "link4_to_link5"))
    (tmp_path / "arm.srdf").write_text(JOINT_LIST_SRDF % joints)
    side = {"format": "roarmctl.robot/1", "urdf": str(bundled_dir() / "roarm_m3_pro.urdf"), "srdf": "arm.srdf",
            "ik": "roarm5", "gripper_group": "hand", "gripper": {"joint": "link5_to_gripper_link", "open": 1.2, "closed": 0.0}}
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    r = load_robot(str(tmp_path / "arm.yaml"))
    assert r.tcp_link == "hand_tcp"
    assert np.allclose(r.named_poses["ready"], [0.2, 0.1, 1.9, 0.3, 0, 0.7])


def _ros2_parameter_file(limits: dict, prefix: str = "$(var tf_prefix)") -> str:
    """``limits`` in a ROS 2 parameter file's layout, as MoveIt 2 launch files load it (the AR4's)."""
    joints = {prefix + name: spec for name, spec in limits["joint_limits"].items()}
    return yaml.safe_dump({"/**/move_group": {"ros__parameters": {"robot_description_planning": {
        "joint_limits": joints, "cartesian_limits": {"max_trans_vel": 0.05}}}}})


@pytest.mark.parametrize("prefix, args", [("$(var tf_prefix)", {"tf_prefix": ""}), ("$(var p)", {"p": ""}), ("", None)])
def test_a_ros2_parameter_file_reads_as_the_moveit1_layout(tmp_path, prefix, args):
    """The same limits in MoveIt 2's launch-file layout (NODE.ros__parameters.robot_description_planning, keys with
    ``$(var NAME)`` that the launch replaces by its argument: here from xacro_args) give the same robot."""
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    plain = load_robot(str(setup(tmp_path / "one")))
    side = setup(tmp_path / "two", side_extra={"xacro_args": args} if args is not None else None)
    (tmp_path / "two" / "joint_limits.yaml").write_text(_ros2_parameter_file(LIMITS, prefix))
    r = load_robot(str(side))
    for key in ("velocity_limits", "acceleration_limits", "lower", "upper"):
        assert np.array_equal(getattr(r, key), getattr(plain, key)), key
    assert any("cartesian_limits not used" in n for n in r.notes), r.notes


@pytest.mark.parametrize("text, args, needle", [
    ("$(var tf_prefix)base_link_to_link1: {}", None, r"'\$\(var tf_prefix\)' has no value"),
    ("$(var tf_prefix)base_link_to_link1: {}", {"other": 1}, r"give it in the sidecar's xacro_args"),
    ("$(env HOME)base_link_to_link1: {}", {"tf_prefix": ""}, r"only \$\(var NAME\) is read"),
    ("$(find-pkg-share x)base_link_to_link1: {}", {"tf_prefix": ""}, r"only \$\(var NAME\) is read"),
])
def test_a_launch_substitution_without_a_value_is_refused(tmp_path, text, args, needle):
    side = setup(tmp_path, side_extra={"xacro_args": args} if args is not None else None)
    (tmp_path / "joint_limits.yaml").write_text("/**/move_group:\n  ros__parameters:\n    robot_description_planning:\n"
                                               "      joint_limits:\n        " + text + "\n")
    with pytest.raises(DescriptionError, match=needle):
        load_robot(str(side))


@pytest.mark.parametrize("acc, dec, expected, noted", [(1.1, -0.5, 0.5, True), (1.1, -2.0, 1.1, False), (None, -0.4, 0.4, False)])
def test_the_smaller_of_acceleration_and_deceleration_is_the_limit(tmp_path, acc, dec, expected, noted):
    """MoveIt 2's ``max_deceleration`` (negative): roarmctl's timing brakes as it speeds up, so the acceleration
    limit is the smaller magnitude, said when the deceleration is the smaller."""
    spec = {"has_deceleration_limits": True, "max_deceleration": dec}
    if acc is not None:
        spec.update(has_acceleration_limits=True, max_acceleration=acc)
    r = load_robot(str(setup(tmp_path, limits={"joint_limits": {"base_link_to_link1": spec}})))
    assert r.acceleration_limits[0] == expected
    assert any("max_deceleration" in n for n in r.notes) == noted


def test_the_ar4s_published_joint_limits_are_read():
    """The AR4's published joint_limits.yaml (a ROS 2 parameter file with $(var tf_prefix) keys): its comments say
    60 deg/s and 30 deg/s^2 for every arm joint, 0.05 m/s and 0.1 m/s^2 for the jaw."""
    r = load_robot(str(Path(__file__).parent / "data" / "arms" / "ar4" / "robot.yaml"))
    arm = r.arm_indices
    assert np.allclose(r.velocity_limits[arm], np.radians(60), rtol=1e-4)
    assert np.allclose(r.acceleration_limits[arm], np.radians(30), rtol=1e-4)
    g = r.joint_index(r.gripper.joint)
    assert (r.velocity_limits[g], r.acceleration_limits[g]) == (0.05, 0.1)
