"""Padding that fits the geometry (issue 22, item 2): a padded mesh holds every point within the padding
and little more (checked with FCL's distance, an independent measure), a part thinner than twice the
padding is named in a warning with the fix, and a link's own padding from the sidecar is used."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from roarmctl.robot.loader import load_robot
from roarmctl.robot.meshes import MeshGeometry, convex_hull
from roarmctl.robot.padding import thickness, thin_parts

CORPUS = Path(__file__).parent / "data" / "arms"


def _hull_mesh(points: np.ndarray) -> MeshGeometry:
    v, f = convex_hull(points, "test")
    centre = (v.min(axis=0) + v.max(axis=0)) / 2
    return MeshGeometry(v - centre, f, False, "test")


def _inside(v: np.ndarray, f: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Points inside the convex polytope (v, f) by its outward face planes (qhull's, independent of roarmctl)."""
    from scipy.spatial import ConvexHull

    eq = ConvexHull(v).equations
    return np.all(pts @ eq[:, :3].T + eq[:, 3] <= 1e-12, axis=1)


@pytest.mark.parametrize("shape", ["plate", "blob", "needle"])
def test_padded_hull_holds_the_padding_and_little_more(shape):
    rng = np.random.default_rng({"plate": 1, "blob": 2, "needle": 3}[shape])
    scale = {"plate": [0.04, 0.012, 0.003], "blob": [0.05, 0.04, 0.03], "needle": [0.06, 0.004, 0.004]}[shape]
    mesh = _hull_mesh(rng.uniform(-0.5, 0.5, (60, 3)) * scale)
    grow = 0.005
    v, f = mesh.grown(grow)
    # no vertex of the padded shape is farther than 1.071 x the padding from the part: its distance to the
    # nearest vertex of the part (at least the distance to the part) says so
    near = np.min(np.linalg.norm(v[:, None, :] - mesh.vertices[None, :, :], axis=2), axis=1)
    assert near.max() <= 1.071 * grow
    # every point at the padding's distance from the part (from its vertices, and from points on its faces
    # along their normals) lies inside the padded shape
    dirs = rng.normal(size=(2000, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    at_vertices = mesh.vertices[rng.integers(0, len(mesh.vertices), 2000)] + 0.999 * grow * dirs
    tri = mesh.vertices[mesh.faces]
    w = rng.dirichlet([1, 1, 1], len(tri))
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    on_faces = np.einsum("ij,ijk->ik", w, tri) + 0.999 * grow * n
    assert np.all(_inside(v, f, at_vertices)) and np.all(_inside(v, f, on_faces))


def test_moving_vertices_along_their_normals_overshoots_on_a_thin_finger():
    """Why the padding changed: the old vertex-normal push (kept for exact meshes) moves a thin plate's
    corners out by up to 5 x the padding; the padded hull stays within 1.071 x."""
    rng = np.random.default_rng(1)
    mesh = _hull_mesh(rng.uniform(-0.5, 0.5, (60, 3)) * [0.04, 0.012, 0.003])
    old = np.linalg.norm(mesh.grown_vertices(0.005) - mesh.vertices, axis=1)
    assert old.max() > 2 * 0.005


def _finger_arm(tmp_path: Path, side_extra: dict | None = None) -> Path:
    """A one-joint arm whose finger is a published-style plate mesh 40 x 10 x 3 mm (an STL)."""
    trimesh.creation.box([0.04, 0.01, 0.003]).export(tmp_path / "finger.stl")
    (tmp_path / "arm.urdf").write_text("""<robot name="finger_arm">
      <link name="base"><collision><geometry><box size="0.05 0.05 0.05"/></geometry></collision></link>
      <link name="finger"><collision><origin xyz="0.05 0 0"/><geometry><mesh filename="finger.stl"/></geometry></collision></link>
      <joint name="j" type="revolute"><parent link="base"/><child link="finger"/><origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
        <limit lower="-2" upper="2" effort="1" velocity="1"/></joint></robot>""")
    side = {"urdf": "arm.urdf", "limits": {"acceleration": [2.0], "jerk": [20.0]}, **(side_extra or {})}
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    return tmp_path / "arm.yaml"


def test_a_finger_mesh_with_5_mm_padding_gets_the_warning(tmp_path):
    robot = load_robot(str(_finger_arm(tmp_path)))
    finger = next(s for s in robot.collision if s.link == "finger")
    assert thickness(finger) == pytest.approx(0.003, abs=1e-9)
    warning = thin_parts(robot, 0.005)
    assert warning is not None and "finger (3.0 mm thick, padded 5 mm)" in warning and "padding: {finger:" in warning
    assert "base" not in warning
    assert thin_parts(robot, 0.001) is None  # 1 mm is less than half of 3 mm


def test_a_links_own_padding_is_used_by_the_checker_and_silences_the_warning(tmp_path):
    """A probe 3 mm above the finger plate: with the plan's 5 mm padding the state is invalid; with the
    finger's own 1 mm (sidecar) it is valid, and nothing is said."""
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene, SceneItem

    probe = Scene([SceneItem.box("probe", (0.01, 0.01, 0.01), (0.05, 0.0, 0.1 + 0.0015 + 0.003 + 0.005))])
    plain = load_robot(str(_finger_arm(tmp_path / "a" if (tmp_path / "a").mkdir() is None else tmp_path)))
    assert not CollisionChecker(plain, probe, padding=0.005).is_valid(np.array([0.0]))
    (tmp_path / "b").mkdir()
    own = load_robot(str(_finger_arm(tmp_path / "b", {"padding": {"finger": 0.001}})))
    assert own.padding == {"finger": 0.001}
    assert CollisionChecker(own, probe, padding=0.005).is_valid(np.array([0.0]))
    assert thin_parts(own, 0.005) is None


def test_published_thin_part_is_named():
    """The WidowX-250s's gripper prop (a 5 mm thick servo horn, Interbotix's mesh) gets the warning at the
    plans' 5 mm padding; its 16 mm fingers do not."""
    robot = load_robot(str(CORPUS / "wx250s" / "robot.yaml"))
    warning = thin_parts(robot, 0.005)
    assert warning is not None and "wx250s/gripper_prop_link (5.0 mm thick" in warning
    assert "left_finger_link" not in warning
