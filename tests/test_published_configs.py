"""Published robot configurations load as they are (issue 22, item 1): SRDF passive joints, mimic fingers in
the gripper group, a sidecar gripper over the SRDF's, movable joints nothing drives, fixed-joint limits,
links without <inertial>, SRDF written as xacro, and the limits a description lacks said once.

The robot here is a small arm built in the test (so every expected value is derived by hand); the
published arms themselves are in tests/test_arm_corpus.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from clirun import roarmctl

from roarmctl.errors import DescriptionError
from roarmctl.robot.loader import load_robot

# A 2-joint arm (yaw, pitch) with a parallel gripper in the style of Kinova's and xArm's: one driven finger
# joint, the other finger mimicking it with a multiplier, a free-spinning 'spinner' the sidecar does not list,
# a fixed joint carrying <limit lower="0" upper="0"> (Kinova's end_effector joint), and links without <inertial>.
URDF = """<robot name="gripper_arm">
  <link name="base"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.1 0.1 0.05"/></geometry></collision></link>
  <link name="upper"><inertial><mass value="0.5"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0.15 0 0"/><geometry><box size="0.3 0.04 0.04"/></geometry></collision></link>
  <link name="hand"><collision><geometry><box size="0.02 0.06 0.02"/></geometry></collision></link>
  <link name="spinner"/>
  <link name="tcp"/>
  <link name="left"><collision><origin xyz="0.02 0 0"/><geometry><box size="0.04 0.005 0.01"/></geometry></collision></link>
  <link name="right"><collision><origin xyz="0.02 0 0"/><geometry><box size="0.04 0.005 0.01"/></geometry></collision></link>
  <joint name="yaw" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="5" velocity="1.5"/></joint>
  <joint name="pitch" type="revolute"><parent link="upper"/><child link="hand"/><origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="5" velocity="1.5"/></joint>
  <joint name="spin" type="continuous"><parent link="hand"/><child link="spinner"/><origin xyz="0 0 0.05"/><axis xyz="1 0 0"/>
    <limit effort="1" velocity="3"/></joint>
  <joint name="tcp_joint" type="fixed"><parent link="hand"/><child link="tcp"/><origin xyz="0.06 0 0"/>
    <limit effort="0" lower="0" upper="0" velocity="0"/></joint>
  <joint name="finger" type="revolute"><parent link="hand"/><child link="left"/><origin xyz="0.01 0.02 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.8" effort="1" velocity="1"/></joint>
  <joint name="finger_mirror" type="revolute"><parent link="hand"/><child link="right"/><origin xyz="0.01 -0.02 0"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="0.5" effort="1" velocity="1"/><mimic joint="finger" multiplier="-0.676" offset="0.149"/></joint>
</robot>"""

# What the MoveIt Setup Assistant writes for such an arm: a gripper group with both finger joints (one of
# them mimicking), the mimicking one marked passive, states 'open' and 'close'.
SRDF = """<robot name="gripper_arm">
  <group name="arm"><chain base_link="base" tip_link="tcp"/></group>
  <group name="hand"><joint name="finger"/><joint name="finger_mirror"/></group>
  <group_state name="ready" group="arm"><joint name="yaw" value="0.1"/><joint name="pitch" value="0.5"/></group_state>
  <group_state name="open" group="hand"><joint name="finger" value="0.7"/><joint name="finger_mirror" value="-0.324"/></group_state>
  <group_state name="close" group="hand"><joint name="finger" value="0.05"/><joint name="finger_mirror" value="0.115"/></group_state>
  <end_effector name="ee" parent_link="tcp" group="hand"/>
  <passive_joint name="finger_mirror"/>
  <disable_collisions link1="base" link2="upper" reason="Adjacent"/>
</robot>"""

LIMITS = {"joint_limits": {
    "yaw": {"has_acceleration_limits": True, "max_acceleration": 3.0},
    "finger_mirror": {"has_velocity_limits": True, "max_velocity": 2.0}}}  # a mimic joint's entry: read, not used


def write(tmp_path: Path, side: dict | None = None, srdf: str = SRDF, srdf_name: str = "arm.srdf") -> Path:
    (tmp_path / "arm.urdf").write_text(URDF)
    (tmp_path / srdf_name).write_text(srdf)
    (tmp_path / "joint_limits.yaml").write_text(yaml.safe_dump(LIMITS))
    data = {"urdf": "arm.urdf", "srdf": srdf_name, "joint_limits": "joint_limits.yaml", **(side or {})}
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(data))
    return tmp_path / "arm.yaml"


def test_passive_and_mimic_fingers_leave_one_gripper_joint(tmp_path):
    r = load_robot(str(write(tmp_path)))
    # the spinner is in no SRDF group: held still, like MoveIt leaves it; the mimic finger follows 'finger'
    assert r.joint_names == ["yaw", "pitch", "finger"]
    assert (r.gripper.joint, r.gripper.open, r.gripper.closed) == ("finger", 0.7, 0.05)
    assert r.tcp_link == "tcp"
    np.testing.assert_allclose(r.named_poses["ready"], [0.1, 0.5, 0.05])
    assert r.acceleration_limits[0] == 3.0
    assert any("spin at 0 rad" in n for n in r.notes)


def test_the_mimic_finger_follows_with_its_multiplier_and_offset(tmp_path):
    """The right finger's frame is turned by -0.676 q + 0.149 about z relative to the hand (by hand)."""
    r = load_robot(str(write(tmp_path)))
    for q in (0.0, 0.4, 0.8):
        f = r.kin.link_frames(np.array([0.3, -0.2, q]))
        rel = np.linalg.inv(f[r.kin.link_index["hand"]]) @ f[r.kin.link_index["right"]]
        a = -0.676 * q + 0.149
        np.testing.assert_allclose(rel[:3, :3], [[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]], atol=1e-12)
        np.testing.assert_allclose(rel[:3, 3], [0.01, -0.02, 0], atol=1e-12)


def test_a_sidecar_gripper_wins_over_the_srdf_group(tmp_path):
    r = load_robot(str(write(tmp_path, {"gripper": {"joint": "finger", "open": 0.6, "closed": 0.0}})))
    assert (r.gripper.open, r.gripper.closed) == (0.6, 0.0)
    # a gripper group that drives two joints is no error when the sidecar names the gripper
    two = SRDF.replace('<passive_joint name="finger_mirror"/>', "").replace(
        '<group name="hand">', '<group name="hand"><joint name="spin"/>')
    side = write(tmp_path, {"gripper": {"joint": "finger", "open": 0.6, "closed": 0.0}, "joints": ["yaw", "pitch", "finger"]},
                 srdf=two)
    assert load_robot(str(side)).gripper.joint == "finger"


def test_a_movable_joint_not_listed_is_held_at_rest_and_moves_nothing(tmp_path):
    """joints: without 'spin' (a continuous joint): the robot loads (it crashed with "'spin' is not in
    list"), 'spin' is fixed at 0 (its limits allow it), and the spinner link sits where the URDF
    puts it at 0: 0.05 m above the hand."""
    r = load_robot(str(write(tmp_path, {"joints": ["yaw", "pitch", "finger"]})))
    assert "spin" not in r.joint_names
    f = r.kin.link_frames(np.array([0.0, 0.0, 0.0]))
    np.testing.assert_allclose(f[r.kin.link_index["spinner"]][:3, 3], [0.3, 0, 0.15], atol=1e-12)
    proc = roarmctl("kin", "fk", str(tmp_path / "arm.yaml"), "0", "0", "0")
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("spin at 0 rad") == 1  # said once


def test_fixed_joint_limits_are_ignored_and_links_without_inertial_are_massless(tmp_path):
    from roarmctl.robot.dynamics import gravity_vector

    r = load_robot(str(write(tmp_path)))
    assert r.inertials["hand"].mass == 0.0
    massless = next(n for n in r.notes if "no <inertial>" in n)
    assert "hand" in massless and "left" in massless and "tcp" not in massless  # tcp has no body: not said
    # gravity on the pitch joint: only 'upper' (0.5 kg) has mass, its COM on the yaw axis... of the
    # pitch joint's load nothing remains (hand and fingers are massless): torque 0
    assert gravity_vector(r, np.array([0.0, 0.3, 0.0]))[1] == pytest.approx(0.0, abs=1e-12)


def test_srdf_written_as_xacro_is_expanded_with_the_sidecar_arguments(tmp_path):
    srdf = SRDF.replace('<robot name="gripper_arm">', '<robot name="gripper_arm" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                        '<xacro:arg name="ready_yaw" default="0.1"/>').replace(
        '<joint name="yaw" value="0.1"/>', '<joint name="yaw" value="$(arg ready_yaw)"/>')
    r = load_robot(str(write(tmp_path, {"xacro_args": {"ready_yaw": 0.25}}, srdf=srdf, srdf_name="arm.srdf.xacro")))
    np.testing.assert_allclose(r.named_poses["ready"], [0.25, 0.5, 0.05])


def test_defaults_the_description_lacks_are_listed_with_units_by_joint_type(tmp_path):
    r = load_robot(str(write(tmp_path)))
    # acceleration: yaw from joint_limits.yaml; pitch and finger have none; velocity all from the URDF
    assert r.defaults == {"acceleration": ["pitch", "finger"], "jerk": ["yaw", "pitch", "finger"]}
    note = r.notes[-1]
    assert "acceleration 2 rad/s^2 for pitch, finger" in note and "velocity" not in note
    r2 = load_robot(str(write(tmp_path, {"limits": {"acceleration": [3, 3, 3], "jerk": [30, 30, 30]}})))
    assert r2.defaults == {} and not any("defaults used" in n for n in r2.notes)


def test_an_unknown_srdf_element_and_a_foreign_group_state_are_notes_not_errors(tmp_path):
    srdf = SRDF.replace("</robot>", '<link_sphere_approximation link="base"/><group name="other"><joint name="spin"/></group>'
                                    '<group_state name="twirl" group="other"><joint name="spin" value="1"/></group_state></robot>')
    r = load_robot(str(write(tmp_path, srdf=srdf)))
    assert any("<link_sphere_approximation> not used" in n for n in r.notes)
    assert any("group_state 'twirl' of group 'other' not used" in n for n in r.notes)


def test_a_floating_virtual_joint_is_still_refused(tmp_path):
    srdf = SRDF.replace("</robot>", '<virtual_joint name="v" type="floating" parent_frame="world" child_link="base"/></robot>')
    with pytest.raises(DescriptionError, match="virtual_joint 'v': type 'floating' is not supported"):
        load_robot(str(write(tmp_path, srdf=srdf)))


def test_links_through_a_link_without_geometry_are_adjacent(tmp_path):
    """Franka's link7 and hand are joined through link8, which has no collision geometry: MoveIt Setup
    Assistant counts them adjacent (not checked against each other); so does the loader. 'hand' and
    'upper' (joined by 'pitch') are adjacent anyway; 'base' and 'hand' are not."""
    r = load_robot(str(write(tmp_path)))
    assert frozenset(("hand", "upper")) in r.allowed_collisions
    assert frozenset(("base", "hand")) not in r.allowed_collisions
    assert frozenset(("left", "right")) in r.allowed_collisions  # the gripper's own parts


def test_gripper_parts_against_the_arm_are_still_checked(tmp_path):
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene

    r = load_robot(str(write(tmp_path)))
    assert frozenset(("left", "upper")) not in r.allowed_collisions
    checker = CollisionChecker(r, Scene([]), padding=0.0)
    assert checker.is_valid(np.array([0.0, 0.0]))


def test_a_mimic_joints_own_limits_bound_its_leader(tmp_path):
    """The right finger (-0.676 q + 0.149) may not go below -0.3 rad: the driven finger then stops at
    (0.149 + 0.3) / 0.676 = 0.66420 rad instead of its own 0.8 (by hand), and the loader says so."""
    side = write(tmp_path, {"gripper": {"joint": "finger", "open": 0.6, "closed": 0.05}})
    (tmp_path / "arm.urdf").write_text(URDF.replace('<limit lower="-1" upper="0.5"', '<limit lower="-0.3" upper="0.5"'))
    r = load_robot(str(side))
    i = r.joint_index("finger")
    assert r.lower[i] == 0.0 and r.upper[i] == pytest.approx((0.149 + 0.3) / 0.676, abs=1e-12)
    assert any("'finger' limited to [0, 0.664201]" in n for n in r.notes)


def test_a_tcp_moved_by_a_finger_that_mimics_the_gripper_is_refused(tmp_path):
    """A mimic joint of the arm is a share of its leader's Jacobian column (tests/test_urdf_differential.py, the IRB
    5400's wrist); one that follows the gripper joint would make the gripper a column of the arm: refused, naming it."""
    with pytest.raises(DescriptionError, match=r"tcp_link: 'right' is moved by 'finger_mirror', which mimics the "
                                               r"gripper joint 'finger'"):
        load_robot(str(write(tmp_path, {"tcp_link": "right"})))
