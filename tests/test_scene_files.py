"""Scene items from files: meshes (convex pieces or exact triangles) and point clouds (occupied cells, FCL octree).

Independent references: the cells a point falls in are worked out by hand (floor(p / r)); a mesh or cloud of a
box is checked against the same box as an FCL primitive; the planner's path is re-checked by a checker whose
scene holds only boxes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import fcl
import numpy as np
import pytest
from clirun import roarmctl

from roarmctl.errors import InputError, PlanFileError
from roarmctl.motion.collision import CollisionChecker, densify
from roarmctl.motion.geometry import item_parts
from roarmctl.motion.ompl_planner import plan_joint_path
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]
TABLE = SceneItem.box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
WALL_SIZE, WALL_XYZ = (0.04, 0.10, 0.15), (0.28, 0.0, 0.075)
# The arm reaches into the wall's place at base angle 0 (TCP at about (0.28, 0, 0.08)); from -0.6 to +0.6 rad
# about the base the straight joint path sweeps through the wall.
Q_MID = np.array([0.0, 0.4, 2.5, -0.7, 0.0])
Q_START, Q_GOAL = Q_MID + [-0.6, 0, 0, 0, 0], Q_MID + [0.6, 0, 0, 0, 0]


@pytest.fixture(scope="module")
def robot():
    return load_robot("roarm_m3_pro")


def _box_mesh_file(folder: Path, size, suffix=".stl") -> Path:
    import trimesh

    path = folder / f"wall{suffix}"
    trimesh.creation.box(extents=size).export(path)
    return path


def _box_points(size, step: float) -> np.ndarray:
    """Points filling a box of ``size`` (m) centred on the origin, ``step`` apart, the faces included."""
    axes = [np.linspace(-s / 2, s / 2, int(round(s / step)) + 1) for s in size]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _hits(item: SceneItem, point) -> bool:
    """FCL alone: does a sphere of 0.1 mm at ``point`` (world, m) touch any part of ``item``?"""
    probe = fcl.CollisionObject(fcl.Sphere(1e-4), fcl.Transform(np.asarray(point, dtype=float)))
    return any(fcl.collide(p.obj, probe) for p in item_parts(item))


# ---------------------------------------------------------------------------- point clouds
@pytest.mark.parametrize("rpy", [(0.0, 0.0, 0.0), (0.3, -0.2, 1.1)])
def test_a_point_inside_an_occupied_cell_collides_and_one_a_resolution_away_does_not(rpy):
    r = 0.01
    points = np.array([[0.0123, 0.0456, 0.0789], [-0.2, 0.1, 0.05], [0.3, -0.3, -0.01]])
    item = SceneItem.from_points("scan", points, r, xyz=(0.1, -0.2, 0.3), rpy=rpy)
    cells = np.floor(points / r).astype(int)  # by hand: the cell each point falls in
    assert sorted(map(tuple, item.cloud.cells.tolist())) == sorted(map(tuple, cells.tolist()))
    pose = item.pose
    for c in cells:
        centre = (c + 0.5) * r
        assert _hits(item, pose[:3, :3] @ centre + pose[:3, 3])
        for axis in range(3):
            for sign in (-1, 1):
                away = centre + sign * r * np.eye(3)[axis]  # the neighbouring cell's centre: empty
                assert not _hits(item, pose[:3, :3] @ away + pose[:3, 3])
        inside = c * r + np.array([0.05, 0.95, 0.5]) * r  # anywhere inside the cell, not only its centre
        assert _hits(item, pose[:3, :3] @ inside + pose[:3, 3])


@pytest.mark.slow  # CPU: a 100,000-point cloud read and split
def test_a_large_cloud_is_split_into_blocks_whose_boxes_hold_their_cells():
    rng = np.random.default_rng(4)
    points = rng.uniform([-0.4, -0.3, 0.0], [0.4, 0.3, 0.2], (20000, 3))
    item = SceneItem.from_points("scan", points, 0.01, xyz=(0.1, 0.0, 0.0), rpy=(0.0, 0.0, 0.4))
    parts = item_parts(item)
    assert len(parts) > 10
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    world = (item.cloud.cells[:, None, :] + corners[None]) * 0.01  # every cell corner, item frame
    world = world.reshape(-1, 3) @ item.pose[:3, :3].T + item.pose[:3, 3]
    held = np.zeros(len(world), dtype=bool)
    for p in parts:  # every corner lies in some part's box (the pre-filter's promise)
        local = (world - p.centre) @ p.rot
        held |= np.all(np.abs(local) <= p.half + 1e-12, axis=1)
    assert held.all()


@pytest.mark.parametrize("suffix", [".npy", ".ply", ".pcd"])
def test_cloud_files_give_the_cells_of_their_points(tmp_path, suffix):
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.1, 0.1, (500, 3))
    path = tmp_path / f"scan{suffix}"
    if suffix == ".npy":
        np.save(path, points)
    elif suffix == ".ply":
        import trimesh

        trimesh.PointCloud(points).export(path)
    else:
        from pypcd4 import PointCloud

        PointCloud.from_xyz_points(points.astype(np.float32)).save(path)
    item = SceneItem.cloud_file("scan", path, 0.02)
    expected = np.unique(np.floor(points.astype(np.float32 if suffix != ".npy" else float) / 0.02).astype(int), axis=0)
    assert np.array_equal(item.cloud.cells, expected)


def test_bad_cloud_files_are_input_errors(tmp_path):
    (tmp_path / "a.npy").write_bytes(b"not numpy")
    with pytest.raises(InputError, match="cannot read"):
        SceneItem.cloud_file("scan", tmp_path / "a.npy", 0.01)
    np.save(tmp_path / "b.npy", np.zeros((4, 2)))
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        SceneItem.cloud_file("scan", tmp_path / "b.npy", 0.01)
    with pytest.raises(InputError, match="not found"):
        SceneItem.cloud_file("scan", tmp_path / "missing.pcd", 0.01)
    (tmp_path / "dir.npy").mkdir()
    os.mkfifo(tmp_path / "fifo.pcd")  # never opened for a blocking read: refused at once
    for name in ("dir.npy", "fifo.pcd"):
        with pytest.raises(InputError, match="not a regular file"):
            SceneItem.cloud_file("scan", tmp_path / name, 0.01)


# ---------------------------------------------------------------------------- meshes
def test_a_mesh_of_two_boxes_is_two_convex_pieces_and_the_gap_between_stays_free(tmp_path):
    import trimesh

    a = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    b.apply_translation((0.3, 0.0, 0.0))
    path = tmp_path / "two.obj"
    trimesh.util.concatenate([a, b]).export(path)
    item = SceneItem.mesh_file("two", path, xyz=(0.0, 0.0, 0.5))
    assert len(item.mesh.pieces) == 2
    assert _hits(item, (0.0, 0.0, 0.5)) and _hits(item, (0.3, 0.0, 0.5))
    assert not _hits(item, (0.15, 0.0, 0.5))  # one hull of both would fill the gap
    exact = SceneItem.mesh_file("two", path, xyz=(0.0, 0.0, 0.5), exact=True)
    assert len(exact.mesh.pieces) == 1 and not _hits(exact, (0.15, 0.0, 0.5))


def test_a_mesh_in_millimetres_with_a_scale(tmp_path):
    path = _box_mesh_file(tmp_path, (40.0, 100.0, 150.0))
    item = SceneItem.mesh_file("wall", path, WALL_XYZ, scale=0.001)
    lo, hi = item.aabb()
    assert np.allclose(lo, np.subtract(WALL_XYZ, np.divide(WALL_SIZE, 2)))
    assert np.allclose(hi, np.add(WALL_XYZ, np.divide(WALL_SIZE, 2)))


# ---------------------------------------------------------------------------- planning around them
def _wall_items(tmp_path: Path) -> dict[str, SceneItem]:
    mesh = SceneItem.mesh_file("wall", _box_mesh_file(tmp_path, WALL_SIZE), WALL_XYZ)
    cloud = SceneItem.from_points("wall", _box_points(WALL_SIZE, 0.004), 0.005, xyz=WALL_XYZ)
    return {"mesh": mesh, "cloud": cloud}


@pytest.mark.parametrize("kind", ["mesh", "cloud"])
def test_a_mesh_and_a_cloud_block_the_straight_path_and_the_planner_goes_around(robot, tmp_path, kind):
    item = _wall_items(tmp_path)[kind]
    checker = CollisionChecker(robot, Scene([TABLE, item]))
    free = CollisionChecker(robot, Scene([TABLE]))
    assert free.segment_valid(Q_START, Q_GOAL)  # without the wall the straight motion is fine
    assert not checker.segment_valid(Q_START, Q_GOAL)
    assert "wall" in checker.explain(Q_MID)
    path = plan_joint_path(checker, Q_START, Q_GOAL, seed=1, time_budget=20.0)
    assert len(path) > 2
    # from the start to the goal: a path that stops short (or begins elsewhere) does not go around the wall
    assert np.allclose(path[0], Q_START, rtol=0, atol=1e-12) and np.allclose(path[-1], Q_GOAL, rtol=0, atol=1e-12), \
        (path[0], path[-1])
    # the same solid as a plain FCL box (a cloud's cells reach out to whole cells: the box grown to them)
    lo, hi = item.aabb()
    box = CollisionChecker(robot, Scene([TABLE, SceneItem.box("wall", hi - lo, (lo + hi) / 2)]))
    assert box.first_invalid(densify(path, 0.002)) is None


@pytest.mark.slow  # plans around a mesh and a point cloud, then draws it: CPU-heavy
def test_a_plan_file_with_a_mesh_and_a_cloud_plans_and_draws(tmp_path):
    import yaml

    plan = yaml.safe_load((ROOT / "plans" / "obstacle.yaml").read_text())
    _box_mesh_file(tmp_path, (40.0, 100.0, 150.0))
    np.save(tmp_path / "post.npy", _box_points((0.03, 0.03, 0.12), 0.004) + [0.30, -0.28, 0.06])
    plan["scene"]["obstacles"] = [
        {"name": "wall", "shape": "mesh", "file": "wall.stl", "scale": 0.001, "xyz": list(WALL_XYZ)},
        {"name": "post", "shape": "cloud", "file": "post.npy", "resolution": 0.005, "xyz": [0, 0, 0]},
    ]
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(plan))
    out = tmp_path / "p.traj.json"
    run = roarmctl("plan", str(tmp_path / "p.yaml"), "-o", str(out), "--json")
    assert run.returncode == 0, run.stderr
    scene = {i["name"]: i for i in json.loads(out.read_text())["scene"]["items"]}
    assert scene["wall"]["shape"] == "mesh" and scene["post"]["shape"] == "cloud"
    assert scene["post"]["resolution"] == 0.005 and len(scene["post"]["cells"]) > 50
    png = tmp_path / "p.png"
    run = roarmctl("visualize-path", str(out), "-o", str(png))
    assert run.returncode == 0, run.stderr
    assert png.stat().st_size > 10_000
    # what the picture draws of them, against the files they came from: the wall's faces span the STL's box
    # (40 x 100 x 150 mm, scaled to m, at its xyz), the post's marks are its occupied cells, inside the points' box
    from roarmctl.api import load_trajectory
    from roarmctl.viz.data import path_data
    from roarmctl.viz.path_figure import render_path
    from roarmctl.viz.shapes import item_faces

    traj = load_trajectory(out)
    fig = render_path(path_data(traj, load_robot(traj.robot)), size=(8, 6))
    drawn = {a.get_gid(): a for a in fig.findobj(lambda a: (a.get_gid() or "").startswith("scene:"))}
    assert {"scene:wall", "scene:post"} <= set(drawn)
    wall = np.vstack(item_faces(scene["wall"], 0))  # the faces handed to the wall's collection
    assert np.allclose(wall.min(axis=0), np.subtract(WALL_XYZ, np.divide(WALL_SIZE, 2)), atol=1e-6)
    assert np.allclose(wall.max(axis=0), np.add(WALL_XYZ, np.divide(WALL_SIZE, 2)), atol=1e-6)
    marks = item_faces(scene["post"], 1)[0]  # the cell centres scattered
    assert len(marks) == len(scene["post"]["cells"]) == len(drawn["scene:post"].get_offsets())
    lo, hi = np.array([0.285, -0.295, 0.0]), np.array([0.315, -0.265, 0.12])
    assert np.allclose(marks.min(axis=0), lo, atol=0.005) and np.allclose(marks.max(axis=0), hi, atol=0.005)
    run = roarmctl("export", str(out), "-o", str(tmp_path / "p.mcap"))
    assert run.returncode == 0, run.stderr
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    with open(tmp_path / "p.mcap", "rb") as f:
        scene = next(store.deserialize_cdr(m.data, "visualization_msgs/msg/MarkerArray")
                     for _, c, m in make_reader(f).iter_messages(topics=["/scene"]))
    kinds = {mk.text: mk for mk in scene.markers}
    assert kinds["wall"].type == 11 and len(kinds["wall"].points) % 3 == 0  # TRIANGLE_LIST
    assert kinds["post"].type == 6 and kinds["post"].scale.x == 0.005  # CUBE_LIST, one cube per cell
    assert len(kinds["post"].points) == len(json.loads(out.read_text())["scene"]["items"][2]["cells"])


@pytest.mark.parametrize("item, message", [
    ({"name": "w", "shape": "mesh", "file": "../outside.stl", "xyz": [0, 0, 0]}, "outside the plan's folder"),
    ({"name": "w", "shape": "mesh", "file": "missing.stl", "xyz": [0, 0, 0]}, "not found"),
    ({"name": "w", "shape": "cloud", "file": "c.npy", "xyz": [0, 0, 0]}, "needs 'resolution'"),
    ({"name": "w", "shape": "mesh", "file": "c.npy", "resolution": 0.01, "xyz": [0, 0, 0]}, "does not apply"),
])
def test_mesh_and_cloud_mistakes_exit_2_naming_the_line(tmp_path, item, message):
    import yaml

    plan = yaml.safe_load((ROOT / "plans" / "obstacle.yaml").read_text())
    plan["scene"]["obstacles"] = [item]
    (tmp_path / "plans").mkdir()
    path = tmp_path / "plans" / "p.yaml"
    path.write_text(yaml.safe_dump(plan, default_flow_style=False))
    run = roarmctl("plan", str(path), "-o", str(tmp_path / "x.json"))
    assert run.returncode == 2, run.stderr
    assert message in run.stderr and "p.yaml:" in run.stderr and "Traceback" not in run.stderr


def test_a_mesh_cannot_be_an_object():
    with pytest.raises(InputError, match="cannot be an object"):
        SceneItem.from_mesh("m", np.eye(3), [[0, 1, 2]], exact=True, role="object")
    from roarmctl.plan.schema import load_plan

    with pytest.raises(PlanFileError, match="not one of box, cylinder, sphere"):
        load_plan({"robot": "roarm_m3_pro", "objects": [{"name": "m", "shape": "mesh", "file": "x.stl", "xyz": [0, 0, 0]}],
                   "tasks": [{"wait": 1}]})
