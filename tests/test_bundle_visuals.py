"""The arm as it looks (issue 33, item 3): a carried description (``robot_description``) keeps the visual meshes,
within a byte budget, so pictures of a trajectory draw the robot's visuals, not only its collision shapes."""

from __future__ import annotations

import numpy as np
import trimesh
import yaml

from roarmctl.robot import bundle
from roarmctl.robot.bundle import load_bundle, make_bundle
from roarmctl.robot.visuals import visual_shapes

URDF = """<robot name="r">
  <link name="base"/>
  <link name="l1">
    <visual><geometry><mesh filename="look.stl"/></geometry><material name="m"><color rgba="1 0 0 1"/></material></visual>
    <visual><geometry><mesh filename="not_shipped.stl"/></geometry></visual>
    <collision><geometry><box size="0.05 0.05 0.2"/></geometry></collision>
  </link>
  <link name="l2"><collision><geometry><box size="0.05 0.05 0.1"/></geometry></collision></link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 0 0.2"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""


def description(tmp_path):
    look = trimesh.creation.icosphere(subdivisions=2, radius=0.04)
    (tmp_path / "look.stl").write_bytes(look.export(file_type="stl"))
    (tmp_path / "arm.urdf").write_text(URDF)
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump({"format": "roarmctl.robot/1", "urdf": "arm.urdf"}))
    return tmp_path / "arm.yaml", look


def test_the_carried_robot_keeps_its_visual_meshes(tmp_path):
    side, look = description(tmp_path)
    doc = make_bundle(str(side))
    (tmp_path / "look.stl").unlink()  # the carried robot reads nothing beside it
    robot = load_bundle(doc, "t.traj.json")
    shapes, _ = visual_shapes(robot)
    assert len(shapes) == 1 and shapes[0].shape.link == "l1" and shapes[0].rgba == (1.0, 0.0, 0.0, 1.0)
    mesh = shapes[0].shape.mesh
    assert len(mesh.faces) == len(look.faces)  # the triangles themselves, not a hull of them
    assert np.allclose(np.ptp(mesh.vertices, axis=0), np.ptp(look.vertices, axis=0), atol=1e-6)
    assert "not_shipped" not in doc["files"]["robot.urdf"]  # a visual whose file is missing is left out


def test_visual_meshes_over_the_budget_are_left_out(tmp_path, monkeypatch):
    side, _ = description(tmp_path)
    monkeypatch.setattr(bundle, "VISUAL_BYTES", 100)
    doc = make_bundle(str(side))
    assert not [f for f in doc["files"] if f.startswith("meshes/")]
    shapes, _ = visual_shapes(load_bundle(doc, "t.traj.json"))
    assert shapes == []
