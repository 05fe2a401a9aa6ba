"""SRDF read as srdfdom reads it (issue 33, item 1).

srdfdom (moveit/srdfdom, ``src/model.cpp``) walks each kind of element it knows and skips, with a logged
message, one it cannot use: an element inside a ``<group>`` other than joint, link, chain and group (a
``<passive_joint>`` written there is never seen), a joint or link the URDF lacks (in a group, a chain, a
``passive_joint``, a ``disable_collisions`` pair, a ``group_state``), an unknown top-level element. MoveIt then
loads the robot. roarmctl does the same: each such element, put anywhere in a working SRDF, leaves the robot
exactly as without it, and a note names it. (srdfdom is not on PyPI: the cases are read off its source.)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from roarmctl.robot.loader import bundled_dir, load_robot

ARM = ("base_link_to_link1", "link1_to_link2", "link2_to_link3", "link3_to_link4", "link4_to_link5")
SRDF = """<robot name="arm">
  <group name="arm">{in_arm}<chain base_link="base_link" tip_link="hand_tcp"/></group>
  <group name="gripper">{in_gripper}<joint name="link5_to_gripper_link"/></group>
  <group_state name="home" group="arm">{in_state}{pose}</group_state>
  <group_state name="open" group="gripper"><joint name="link5_to_gripper_link" value="1.2"/></group_state>
  <group_state name="close" group="gripper"><joint name="link5_to_gripper_link" value="0.1"/></group_state>
  <disable_collisions link1="link1" link2="link4" reason="Never"/>
  {top}
</robot>"""
POSE = "".join(f'<joint name="{n}" value="{0.1 * k}"/>' for k, n in enumerate(ARM))

#: (where, element, what the note says): what srdfdom skips.
SKIPPED = [
    ("in_arm", '<passive_joint name="link4_to_link5"/>', "<passive_joint> not read inside a group"),
    ("in_gripper", '<passive_joint name="link5_to_gripper_link"/>', "<passive_joint> not read inside a group"),
    ("in_arm", '<end_effector name="e" group="gripper" parent_link="hand_tcp"/>', "<end_effector> not read inside a group"),
    ("in_arm", '<joint name="no_such_joint"/>', "group 'arm' joint: 'no_such_joint' is not a joint"),
    ("in_gripper", '<link name="no_such_link"/>', "group 'gripper' link: 'no_such_link' is not a link"),
    ("in_gripper", '<chain base_link="link1" tip_link="nowhere"/>', "chain tip_link: 'nowhere' is not a link"),
    ("in_state", '<joint name="ghost" value="1"/>', "group_state 'home' joint: 'ghost' is not a joint"),
    ("top", '<passive_joint name="ghost"/>', "passive_joint: 'ghost' is not a joint"),
    ("top", '<disable_collisions link1="link1" link2="nolink" reason="Never"/>', "disable_collisions link2: 'nolink'"),
    ("top", '<link_sphere_approximation link="link1"/>', "<link_sphere_approximation> not used"),
    ("top", '<some_future_element/>', "<some_future_element> not used"),
    ("top", '<group name="other"><chain base_link="nowhere" tip_link="hand_tcp"/></group>',
     "group 'other' chain base_link: 'nowhere' is not a link"),
]


def load(tmp_path: Path, **parts: str):
    fields = {"in_arm": "", "in_gripper": "", "in_state": "", "top": "", "pose": POSE, **parts}
    (tmp_path / "arm.srdf").write_text(SRDF.format(**fields))
    side = {"format": "roarmctl.robot/1", "urdf": str(bundled_dir() / "roarm_m3_pro.urdf"), "srdf": "arm.srdf",
            "ik": "roarm5"}
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    return load_robot(str(tmp_path / "arm.yaml"))


def summary(robot) -> tuple:
    return (robot.tcp_link, robot.joint_names, sorted(map(sorted, robot.allowed_collisions)),
            {k: np.round(v, 12).tolist() for k, v in robot.named_poses.items()},
            (robot.gripper.joint, robot.gripper.open, robot.gripper.closed), robot.held_joints)


@pytest.mark.parametrize("where, element, said", SKIPPED, ids=[f"{w}:{e.split()[0][1:]}" for w, e, _ in SKIPPED])
def test_what_srdfdom_skips_is_skipped_with_a_note(tmp_path, where, element, said):
    (tmp_path / "with").mkdir()
    base = load(tmp_path)
    robot = load(tmp_path / "with", **{where: element})
    assert summary(robot) == summary(base)
    assert any(said in n for n in robot.notes), robot.notes
    assert not any(said in n for n in base.notes)


def test_the_baseline_reads_the_arm_the_gripper_and_the_pose(tmp_path):
    robot = load(tmp_path)
    assert robot.tcp_link == "hand_tcp" and frozenset(("link1", "link4")) in robot.allowed_collisions
    assert (robot.gripper.joint, robot.gripper.open, robot.gripper.closed) == ("link5_to_gripper_link", 1.2, 0.1)
    assert np.allclose(robot.named_poses["home"][:5], [0, 0.1, 0.2, 0.3, 0.4])
