"""Collision meshes (issue 8, item 1): loaded with trimesh, checked in FCL as convex hulls (default)
or as triangles (``mesh_collision: exact``); every bad mesh input is exit 2 naming file and link."""

from __future__ import annotations

import re
from pathlib import Path

import fcl
import numpy as np
import pytest
import trimesh
import yaml
from clirun import roarmctl

from roarmctl.errors import DescriptionError
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.loader import bundled_dir, load_robot
from roarmctl.robot.model import transform

LINK3_BOXES = re.compile(r'(<link name="link3">(?:(?!</link>).)*?)((?:<collision(?:(?!</link>).)*?</collision>\s*)+)(</link>)', re.S)


def l_shape() -> trimesh.Trimesh:
    """A non-convex L in link3's frame, 0.12 m along -y (the forearm) with a foot along +x."""
    bar = trimesh.creation.box((0.02, 0.12, 0.02), transform((0, -0.06, 0)))
    foot = trimesh.creation.box((0.08, 0.02, 0.02), transform((0.03, -0.11, 0)))
    return trimesh.util.concatenate([bar, foot])


def mesh_robot(tmp_path: Path, mesh_xml: str, side_extra: dict | None = None, mesh: trimesh.Trimesh | None = None) -> Path:
    """The bundled M3 with link3's collision boxes replaced by ``mesh_xml``; returns the sidecar."""
    (tmp_path / "meshes").mkdir(exist_ok=True)
    (mesh if mesh is not None else l_shape()).export(tmp_path / "meshes" / "forearm.stl")
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    urdf, n = LINK3_BOXES.subn(lambda m: m.group(1) + f"<collision>{mesh_xml}</collision>" + m.group(3), urdf)
    assert n == 1
    (tmp_path / "urdf").mkdir(exist_ok=True)
    (tmp_path / "urdf" / "arm.urdf").write_text(urdf)
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    side["urdf"] = "urdf/arm.urdf"
    side.update(side_extra or {})
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    return tmp_path / "arm.yaml"


def world_vertices(robot, q, shape) -> np.ndarray:
    frame = robot.kin.link_frames(robot.full_q(q))[robot.kin.link_index[shape.link]] @ shape.origin
    return shape.mesh.vertices @ frame[:3, :3].T + frame[:3, 3]


Q = np.array([0.0, 0.3, 1.2, 0.0, 0.0])


def probe_at(point, size=0.01) -> Scene:
    return Scene([SceneItem("probe", "obstacle", "box", transform(point), size=(size,) * 3)])


def test_mesh_link_hits_a_probe_box_the_boxes_would_not_see(tmp_path):
    robot = load_robot(str(mesh_robot(tmp_path, '<geometry><mesh filename="../meshes/forearm.stl"/></geometry>')))
    shapes = [s for s in robot.collision if s.link == "link3"]
    assert [s.kind for s in shapes] == ["mesh"]
    # the tip of the L's foot, in the world: found by trimesh's own vertices, not by our hull
    frame = robot.kin.link_frames(robot.full_q(Q))[robot.kin.link_index["link3"]]
    tip = frame[:3, :3] @ np.array([0.068, -0.11, 0.0]) + frame[:3, 3]
    hit = CollisionChecker(robot, probe_at(tip), padding=0.0)
    assert not hit.is_valid(Q)
    assert "link3 hits obstacle 'probe'" in hit.explain(Q)
    # the bundled box model has no box there: it plans straight through this probe
    boxed = CollisionChecker(load_robot("roarm_m3_pro"), probe_at(tip), padding=0.0)
    assert boxed.is_valid(Q)
    # 15 mm beyond the foot's end along link3's x: clear, and hit again once padding covers the gap
    far = frame[:3, :3] @ np.array([0.09, -0.11, 0.0]) + frame[:3, 3]
    assert CollisionChecker(robot, probe_at(far), padding=0.0).is_valid(Q)
    assert not CollisionChecker(robot, probe_at(far), padding=0.02).is_valid(Q)


def test_hull_contains_every_mesh_vertex(tmp_path):
    src = l_shape()
    robot = load_robot(str(mesh_robot(tmp_path, '<geometry><mesh filename="../meshes/forearm.stl"/></geometry>')))
    (shape,) = [s for s in robot.collision if s.link == "link3"]
    hull = fcl.CollisionObject(fcl.Convex(shape.mesh.vertices, len(shape.mesh.faces),
                                          np.hstack([np.full((len(shape.mesh.faces), 1), 3), shape.mesh.faces]).ravel()))
    local = src.vertices - (shape.origin[:3, 3])  # link3's frame has no rotation for this element
    assert len(shape.mesh.vertices) < len(src.vertices) + 1
    for v in local:  # FCL itself says each original vertex is in the hull (a 1 um ball touches it)
        ball = fcl.CollisionObject(fcl.Sphere(1e-6), fcl.Transform(np.eye(3), np.asarray(v, dtype=float)))
        assert fcl.collide(hull, ball)
    # and by plane tests on the faces
    v, f = shape.mesh.vertices, shape.mesh.faces
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    off = np.einsum("ij,ij->i", n, v[f[:, 0]])
    assert np.all(local @ n.T - off <= 1e-9)


def test_exact_mesh_sees_the_notch_the_hull_fills(tmp_path):
    side = mesh_robot(tmp_path, '<geometry><mesh filename="../meshes/forearm.stl"/></geometry>',
                      {"mesh_collision": {"link3": "exact"}})
    exact = load_robot(str(side))
    convex = load_robot(str(mesh_robot(tmp_path / "c", '<geometry><mesh filename="../meshes/forearm.stl"/></geometry>')
                        if (tmp_path / "c").mkdir() is None else None))
    frame = exact.kin.link_frames(exact.full_q(Q))[exact.kin.link_index["link3"]]
    notch = frame[:3, :3] @ np.array([0.04, -0.06, 0.0]) + frame[:3, 3]  # inside the hull, outside the L
    assert not CollisionChecker(convex, probe_at(notch), padding=0.0).is_valid(Q)
    assert CollisionChecker(exact, probe_at(notch), padding=0.0).is_valid(Q)
    tip = frame[:3, :3] @ np.array([0.068, -0.11, 0.0]) + frame[:3, 3]
    assert not CollisionChecker(exact, probe_at(tip), padding=0.0).is_valid(Q)


def test_scale_and_package_paths(tmp_path):
    big = l_shape()
    big.apply_scale(1000.0)  # millimetres in the file
    side = mesh_robot(tmp_path, '<geometry><mesh filename="package://armpkg/meshes/forearm.stl" scale="0.001 0.001 0.001"/></geometry>',
                      {"packages": {"armpkg": "."}}, mesh=big)
    robot = load_robot(str(side))
    (shape,) = [s for s in robot.collision if s.link == "link3"]
    assert np.allclose(shape.mesh.half_extents, [0.04, 0.06, 0.01], atol=1e-9)
    # the same through --package-path on the command line
    data = yaml.safe_load(side.read_text())
    del data["packages"]
    side.write_text(yaml.safe_dump(data))
    proc = roarmctl("--package-path", f"armpkg={tmp_path}", "kin", "fk", str(side), "0", "0", "0", "0", "0", "--json")
    assert proc.returncode == 0, proc.stderr


@pytest.mark.parametrize("xml, extra, needle", [
    ('<geometry><mesh filename="../meshes/nothere.stl"/></geometry>', None, r"link 'link3' collision\[0\] mesh filename: file '.*nothere.stl' not found"),
    ('<geometry><mesh filename="../meshes/garbage.stl"/></geometry>', None, r"link 'link3' collision\[0\] mesh filename: .*garbage.stl.* (contains no triangles|as a mesh)"),
    ('<geometry><mesh filename="package://nopkg/forearm.stl"/></geometry>', None, r"link 'link3' collision\[0\] mesh filename: package 'nopkg'"),
    ('<geometry><mesh filename="../meshes/forearm.stl" scale="1 0 1"/></geometry>', None, r"link 'link3' collision\[0\] mesh scale"),
    ('<geometry><mesh/></geometry>', None, r"link 'link3' collision\[0\] mesh: missing attribute 'filename'"),
    ('<geometry><cone radius="1"/></geometry>', None, r"link 'link3' collision\[0\]: geometry <cone> is not supported"),
    ('<geometry><cylinder radius="0.01"/></geometry>', None, r"link 'link3' collision\[0\] cylinder.*length.*missing"),
    ('<geometry><sphere radius="-1"/></geometry>', None, r"link 'link3' collision\[0\] sphere radius: .*positive"),
    ('<geometry><mesh filename="../meshes/forearm.stl"/></geometry>', {"mesh_collision": "wobbly"}, r"arm.yaml: mesh_collision: 'wobbly'"),
    ('<geometry><mesh filename="../meshes/forearm.stl"/></geometry>', {"packages": {"p": "no/such/dir"}}, r"arm.yaml: packages.p: folder 'no/such/dir' not found"),
])
def test_bad_mesh_input_is_exit_2_naming_file_and_field(tmp_path, xml, extra, needle):
    side = mesh_robot(tmp_path, xml, extra)
    (tmp_path / "meshes" / "garbage.stl").write_bytes(b"solid x\nthis is not an stl\n")
    with pytest.raises(DescriptionError, match=needle):
        load_robot(str(side))
    proc = roarmctl("kin", "fk", str(side), "0", "0", "0", "0", "0")
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and re.search(needle, proc.stderr.replace("\n", " ")), proc.stderr


@pytest.mark.parametrize("ext", ["stl", "obj", "dae"])
def test_mesh_formats_give_the_same_hull(tmp_path, ext):
    """STL, OBJ and COLLADA files of the same L load to the same hull (bounding box, vertex set)."""
    src = l_shape()
    src.export(tmp_path / f"l.{ext}")
    side = mesh_robot(tmp_path, f'<geometry><mesh filename="../l.{ext}"/></geometry>')
    (shape,) = [s for s in load_robot(str(side)).collision if s.link == "link3"]
    assert np.allclose(shape.mesh.half_extents, [0.04, 0.06, 0.01], atol=1e-6)
    assert np.allclose(shape.origin[:3, 3], [0.03, -0.06, 0.0], atol=1e-6)
    hull = trimesh.convex.convex_hull(src)
    got = {tuple(np.round(v + shape.origin[:3, 3], 6)) for v in shape.mesh.vertices}
    assert got == {tuple(np.round(v, 6)) for v in hull.vertices}


def test_flat_mesh_has_no_hull_and_says_so(tmp_path):
    flat = trimesh.Trimesh(vertices=[[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0.05, 0.05, 0]], faces=[[0, 1, 2], [1, 3, 2]])
    side = mesh_robot(tmp_path, '<geometry><mesh filename="../meshes/forearm.stl"/></geometry>', mesh=flat)
    with pytest.raises(DescriptionError, match=r"link 'link3' collision\[0\] mesh '.*forearm.stl': no convex hull"):
        load_robot(str(side))
    # as exact triangles the same flat mesh is fine
    data = yaml.safe_load(side.read_text())
    data["mesh_collision"] = "exact"
    side.write_text(yaml.safe_dump(data))
    (shape,) = [s for s in load_robot(str(side)).collision if s.link == "link3"]
    assert shape.mesh.exact and len(shape.mesh.faces) == 2
