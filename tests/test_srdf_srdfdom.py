"""SRDF read as srdfdom reads it (issue 33, item 1).

srdfdom (moveit/srdfdom, ``src/model.cpp``) walks each kind of element it knows and skips, with a logged
message, one it cannot use: an element inside a ``<group>`` other than joint, link, chain and group (a
``<passive_joint>`` written there is never seen), a joint or link the URDF lacks (in a group, a chain, a
``passive_joint``, a ``disable_collisions`` pair, a ``group_state``), an unknown top-level element. MoveIt then
loads the robot. roarmctl does the same: each such element, put anywhere in a working SRDF, leaves the robot
exactly as without it, and a note names it. (srdfdom is not on PyPI: the cases are read off its source;
how it reads a ``group_state`` value is C++'s stream extraction, run here by a C++ compiler.)
"""

from __future__ import annotations

import itertools
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.errors import DescriptionError
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.robot.srdf import srdfdom_values

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
    ("top", '<disable_default_collisions link="nolink"/>', "disable_default_collisions: 'nolink' is not a link"),
    ("top", '<enable_collisions link1="link1" link2="nolink"/>', "enable_collisions link2: 'nolink' is not a link"),
    ("in_state", '<joint name="link4_to_link5"/>', "joint 'link4_to_link5': no value: skipped"),
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


# ----------------------------------------------------------------------------- group_state values
#: srdfdom's loop over a group_state joint's value (src/model.cpp, loadGroupStates), one value text a line; the C++
#: library's ``operator>>`` is the reference for what it stores ("abc" stores 0: the stream fails).
ORACLE = r"""
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
int main() {
  std::string line;
  while (std::getline(std::cin, line)) {
    std::istringstream ss(line);
    while (ss.good() && !ss.eof()) {
      double val = 0;
      ss >> val >> std::ws;
      std::printf("%.17g ", val);
    }
    std::printf("\n");
  }
}
"""


@pytest.fixture(scope="module")
def oracle(tmp_path_factory):
    cxx = shutil.which("g++") or shutil.which("c++")
    if cxx is None:
        pytest.skip("no C++ compiler")
    d = tmp_path_factory.mktemp("oracle")
    (d / "o.cpp").write_text(ORACLE)
    subprocess.run([cxx, "-O1", "-o", str(d / "o"), str(d / "o.cpp")], check=True, timeout=120)

    def run(texts: list[str]) -> list[list[float]]:
        out = subprocess.run([str(d / "o")], input="\n".join(texts) + "\n", capture_output=True, text=True,
                             check=True, timeout=60).stdout
        return [[float(v) for v in line.split()] for line in out.splitlines()]

    return run


NAMED = ["1.5", "abc", "1.5abc", " 2 ", "1 2", "nan", "inf", "-inf", "1e999", "-1e999", "1e-999", "1e-310", "1e",
         "0x10", ".5", "+3", "-", "1,5", "1.5.", "3e-2", "e5", "1e+", "${pi/2}", "1E2", "infinity", "-.5e1x", "--1",
         "1.5\t2", "1.5e3.2", "0.7853981633974483"]


@pytest.mark.slow
@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.text(alphabet="0123456789+-.eE x\t", min_size=1, max_size=12).filter(lambda s: s.strip(" \t")),
                min_size=20, max_size=20))
def test_a_value_is_read_as_srdfdoms_cxx_stream_reads_it(oracle, texts):
    """The class of value texts (digits, signs, points, exponents, spaces, junk), against the C++ library running
    srdfdom's own loop: the same numbers, in the same count (a blank text is left out: C++ leaves it undefined)."""
    texts = NAMED + texts
    for text, theirs in zip(texts, oracle(texts), strict=True):
        assert srdfdom_values(text) == theirs, text


def test_a_value_srdfdom_reads_as_one_number_is_that_number_with_a_note(tmp_path):
    pose = POSE.replace('value="0.2"', 'value="abc"').replace('value="0.30000000000000004"', 'value="nan"')
    assert pose.count('"abc"') == 1 and pose.count('"nan"') == 1
    robot = load(tmp_path, pose=pose)
    assert np.allclose(robot.named_poses["home"][:5], [0, 0.1, 0, 0, 0.4])  # both read as 0, as srdfdom stores them
    assert any("value 'abc' is not a number: read as 0, as srdfdom reads it" in n for n in robot.notes), robot.notes
    assert any("value 'nan' is not a number: read as 0" in n for n in robot.notes)


@pytest.mark.parametrize("value, said", [("1.5abc", "1.5, 0"), ("", "no number"), ("0.1 0.2", "0.1, 0.2")])
def test_a_value_srdfdom_reads_as_no_or_several_numbers_leaves_the_state_out(tmp_path, value, said):
    """MoveIt leaves a joint whose value count does not match out of the state; roarmctl's named poses give every arm
    joint, so the state is left out with notes, and the robot loads as MoveIt loads it."""
    robot = load(tmp_path, pose=POSE.replace('value="0.2"', f'value="{value}"'))
    assert "home" not in robot.named_poses
    assert any(f"read by srdfdom as {said}, not one number" in n for n in robot.notes), robot.notes
    assert any("group_state 'home' left out: no value for link2_to_link3" in n for n in robot.notes)


# ----------------------------------------------------------------------------- disable_default_collisions
def _expected_pairs(base, links: list[str], no_default: list[str], enabled: set[frozenset]) -> set[frozenset]:
    """The allowed pairs by srdfdom's model (model.h: links "disabled by default (and only selectively enabled)",
    enabled pairs "re-enable collision after having disabled it via a default"), derived pair by pair, on top of
    the robot's pairs without them (the SRDF's disable_collisions, the adjacent and gripper pairs)."""
    out = set(base.allowed_collisions)
    for a, b in itertools.combinations(links, 2):
        if (a in no_default or b in no_default) and frozenset((a, b)) not in enabled:
            out.add(frozenset((a, b)))
    return out


@pytest.mark.parametrize("seed", range(6))
def test_disable_default_collisions_allows_a_links_pairs_but_the_enabled_ones(tmp_path, seed):
    (tmp_path / "with").mkdir()
    base = load(tmp_path)
    links = list(base.link_names)
    rng = np.random.default_rng(seed)
    no_default = [str(x) for x in rng.choice(links, size=1 + seed % 3, replace=False)]
    candidates = [frozenset((a, b)) for a in no_default for b in links if a != b]
    enabled = {candidates[int(k)] for k in rng.choice(len(candidates), size=min(3, len(candidates)), replace=False)}
    top = "".join(f'<disable_default_collisions link="{n}"/>' for n in no_default) + "".join(
        '<enable_collisions link1="{}" link2="{}" reason="x"/>'.format(*sorted(p)) for p in enabled)
    robot = load(tmp_path / "with", top=top)
    assert robot.allowed_collisions == _expected_pairs(base, links, no_default, enabled - base.allowed_collisions)
    assert any(f"disable_default_collisions '{no_default[0]}'" in n for n in robot.notes), robot.notes
    assert summary(robot)[:2] == summary(base)[:2] and robot.named_poses.keys() == base.named_poses.keys()


@pytest.mark.parametrize("value", ["9", "1e999", "-7.5"])
def test_a_state_outside_the_limits_is_left_out_not_refused(tmp_path, value):
    """srdfdom stores any number (1e999: the largest double) and MoveIt loads the robot with such a state; roarmctl's
    named poses lie within the limits, so the state is left out with a note naming the joint, its value and limits.
    The same pose written in the sidecar is still refused: the user's own file says something impossible."""
    robot = load(tmp_path, pose=POSE.replace('value="0.2"', f'value="{value}"'))
    assert "home" not in robot.named_poses
    assert any("group_state 'home' left out: link2_to_link3 = " in n and "outside its limits" in n for n in robot.notes)
    side = yaml.safe_load((tmp_path / "arm.yaml").read_text())
    side["named_poses"] = {"bad": [0, 0, float(value) if value != "1e999" else 9.0, 0, 0]}
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    with pytest.raises(DescriptionError, match=r"named_poses.bad: link2_to_link3 = .* is outside its limits"):
        load_robot(str(tmp_path / "arm.yaml"))
