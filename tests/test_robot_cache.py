"""``load_robot`` keeps what it loaded, and hands it out again only while every file the load read is unchanged.

A long-lived process (a notebook, a Python user of ``roarmctl.api``) that edits a description between two loads
must get the edited robot: the URDF, a xacro include, the SRDF, a mesh, the sidecar. A copy of the published
OpenManipulator-X (tests/data/arms) is edited in place; the values asserted are the ones written into the files.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from roarmctl.errors import DescriptionError
from roarmctl.robot import xacro_input
from roarmctl.robot.loader import load_robot
from roarmctl.robot.model import Robot

ARM = Path(__file__).parent / "data" / "arms" / "open_manipulator_x"
TOP_XACRO = "open_manipulator_description/urdf/open_manipulator_x/open_manipulator_x.urdf.xacro"
ARM_XACRO = "open_manipulator_description/urdf/open_manipulator_x/open_manipulator_x_arm.urdf.xacro"  # an include
SRDF = "open_manipulator_moveit_config/config/open_manipulator_x/open_manipulator_x.srdf"
MESHES = "open_manipulator_description/meshes/open_manipulator_x"
UR5E = Path(__file__).parent / "data" / "arms" / "ur5e"


@pytest.fixture
def arm(tmp_path: Path) -> Path:
    """The sidecar of a private copy of the OpenManipulator-X description."""
    shutil.copytree(ARM, tmp_path / "arm")
    return tmp_path / "arm" / "robot.yaml"


def _edit(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert text.count(old) == 1, f"{old!r} not once in {path}"
    path.write_text(text.replace(old, new))


def _upper(robot: Robot, joint: str) -> float:
    return float(robot.upper[robot.joint_names.index(joint)])


def test_unchanged_files_give_the_same_robot(arm: Path) -> None:
    first = load_robot(str(arm))
    assert load_robot(str(arm)) is first


def test_an_included_xacro_file_edited_is_seen(arm: Path) -> None:
    first = load_robot(str(arm))
    assert _upper(first, "joint3") == pytest.approx(1.4)  # as published
    _edit(arm.parent / ARM_XACRO, 'lower="${-1.5}" upper="${1.4}"', 'lower="${-1.5}" upper="${1.25}"')
    second = load_robot(str(arm))
    assert second is not first
    assert _upper(second, "joint3") == pytest.approx(1.25)
    assert load_robot(str(arm)) is second  # and kept again


@pytest.mark.slow
def test_the_top_xacro_file_edited_is_seen(arm: Path) -> None:
    first = load_robot(str(arm))
    _edit(arm.parent / TOP_XACRO, '<robot name="open_manipulator_x"', '<robot name="edited_arm"')
    assert first.name != "edited_arm"
    assert load_robot(str(arm)).name == "edited_arm"


def test_the_srdf_edited_is_seen(arm: Path) -> None:
    first = load_robot(str(arm))
    assert first.named_poses["home"][2] == pytest.approx(0.7)
    _edit(arm.parent / SRDF, '<joint name="joint3" value="0.7"/>', '<joint name="joint3" value="0.55"/>')
    assert load_robot(str(arm)).named_poses["home"][2] == pytest.approx(0.55)


def test_the_sidecar_edited_is_seen(arm: Path) -> None:
    load_robot(str(arm))
    _edit(arm, "tool: {xyz: [0.012, 0, 0]}", "tool: {xyz: [0.012, 0, 0]}\nname: renamed")
    assert load_robot(str(arm)).name == "renamed"


def test_a_mesh_replaced_is_seen(arm: Path) -> None:
    def mesh_of(robot: Robot, link: str) -> np.ndarray:
        shape = next(s for s in robot.collision if s.link == link and s.kind == "mesh")
        assert shape.mesh is not None
        return np.asarray(shape.mesh.vertices)

    first = load_robot(str(arm))
    assert mesh_of(first, "link3").shape != mesh_of(first, "link2").shape  # two different meshes as published
    shutil.copyfile(arm.parent / MESHES / "link2.stl", arm.parent / MESHES / "link3.stl")
    second = load_robot(str(arm))
    # link3's collision shape is now made from link2's mesh (same scale, both convex): the same hull
    np.testing.assert_array_equal(mesh_of(second, "link3"), mesh_of(second, "link2"))


def test_a_file_removed_is_not_served_from_the_store(arm: Path) -> None:
    load_robot(str(arm))
    (arm.parent / ARM_XACRO).unlink()
    with pytest.raises(DescriptionError, match=r"xacro include: file .* not found"):
        load_robot(str(arm))


@pytest.mark.slow
def test_a_relative_name_is_read_in_the_current_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name in ("a", "b"):
        shutil.copytree(ARM, tmp_path / name)
    _edit(tmp_path / "b" / ARM_XACRO, 'lower="${-1.5}" upper="${1.4}"', 'lower="${-1.5}" upper="${1.25}"')
    monkeypatch.chdir(tmp_path / "a")
    assert _upper(load_robot("robot.yaml"), "joint3") == pytest.approx(1.4)
    monkeypatch.chdir(tmp_path / "b")
    assert _upper(load_robot("robot.yaml"), "joint3") == pytest.approx(1.25)


@pytest.mark.slow
@pytest.mark.parametrize("trusted", [False, True])
def test_a_yaml_file_xacro_loads_edited_is_seen(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, trusted: bool) -> None:
    """UR's xacro reads its limits with xacro.load_yaml: by roarmctl's reader, or by xacro itself when trusted."""
    monkeypatch.setattr(xacro_input, "TRUST_ALL", trusted)
    shutil.copytree(UR5E, tmp_path / "ur5e")
    spec = str(tmp_path / "ur5e" / "robot.yaml")
    assert _upper(load_robot(spec), "shoulder_lift_joint") == pytest.approx(2 * math.pi)  # 360 deg, as published
    limits = tmp_path / "ur5e" / "config" / "ur5e" / "joint_limits.yaml"
    text = limits.read_text()
    at = text.index("shoulder_lift_joint:")
    head, tail = text[:at], text[at:]
    limits.write_text(head + tail.replace("max_position: !degrees  360.0", "max_position: !degrees  300.0", 1))
    assert _upper(load_robot(spec), "shoulder_lift_joint") == pytest.approx(math.radians(300))


# make_bundle (what a plan for a description carries) is kept the same way: each edit above reaches the next bundle
@pytest.mark.parametrize("edit", ["include", "srdf", "mesh", "sidecar"])
def test_a_bundle_is_made_again_when_a_file_it_read_changed(arm: Path, edit: str) -> None:
    from roarmctl.robot.bundle import make_bundle

    first = make_bundle(str(arm))
    assert first is not None
    again = make_bundle(str(arm))
    assert again == first and again is not first  # kept, handed out as a copy: a caller's change stays its own
    again["files"].clear()
    assert make_bundle(str(arm)) == first
    if edit == "include":
        _edit(arm.parent / ARM_XACRO, 'lower="${-1.5}" upper="${1.4}"', 'lower="${-1.5}" upper="${1.25}"')
        seen = 'upper="1.25"'
    elif edit == "srdf":
        _edit(arm.parent / SRDF, '<joint name="joint3" value="0.7"/>', '<joint name="joint3" value="0.55"/>')
        seen = 'value="0.55"'
    elif edit == "mesh":
        shutil.copyfile(arm.parent / MESHES / "link2.stl", arm.parent / MESHES / "link3.stl")
        seen = ""
    else:
        _edit(arm, "tool: {xyz: [0.012, 0, 0]}", "tool: {xyz: [0.012, 0, 0]}\nname: renamed")
        seen = "name: renamed"
    second = make_bundle(str(arm))
    assert second is not None and second != first
    text = "".join(v for v in second["files"].values() if isinstance(v, str))
    assert seen in text
    if edit == "mesh":  # the two meshes' bytes are now the same file's
        meshes = [v["base64"] for k, v in second["files"].items() if k.startswith("meshes/")]
        assert len(set(meshes)) < len(meshes)
