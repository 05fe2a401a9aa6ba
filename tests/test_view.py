"""The browser view (``roarmctl view``, ``visualize-path -o NAME.html``): its numbers checked against
independent computations, and the page itself in a real browser (the system's Chromium driven by
Playwright, see tests/browser.py): each bundled plan's page loads offline with no console error, and the
TCP drawn on screen at the grasp lies where FK puts it.

Without Chromium (a developer's machine) the browser tests skip and say how to install it; under CI
(``CI`` set, as ``.ci/run`` runs) a missing Chromium is a failure, never a skip.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import browser as br
import numpy as np
import pytest
from clirun import planned_and_run_on_sim, roarmctl, virtual_simulator

from roarmctl.cli import run as run_cli

ROOT = Path(__file__).resolve().parents[1]
# the bundled plans (datagen templates live in plans/datagen/: a plan file plus a datagen: block is no plan by itself)
PLANS = sorted((ROOT / "plans").glob("*.yaml"))
# one xdist worker runs this module: one browser and one planning of the bundled plans for all its tests
pytestmark = pytest.mark.xdist_group("browser-view")

MAX_PAGE = 5_000_000  # bytes: the limit for a bundled plan's page
PIXELS = 3.0  # how far the drawn TCP may lie from its FK projection


# ------------------------------------------------------------------------------------------- fixtures
class _Planned(dict):
    """A bundled plan planned the first time a test reads it (name -> (trajectory file, Trajectory)), then kept:
    ``make test-fast``'s few tests here read pick_place only (planning all six took 1.2 s of CPU for them)."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.folder = folder

    def __missing__(self, name: str) -> tuple[Path, object]:
        from roarmctl.motion.pipeline import plan_file

        (plan,) = [p for p in PLANS if p.stem == name]
        traj = plan_file(plan, seed=None).trajectory
        f = self.folder / f"{name}.traj.json"
        traj.save(f)
        self[name] = (f, traj)
        return self[name]


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """Each bundled plan planned once, when first read (``_Planned``): name -> (trajectory file, Trajectory)."""
    return _Planned(tmp_path_factory.mktemp("view_plans"))


@pytest.fixture(scope="module")
def chromium():
    """One headless Chromium for the module (the system's; skipped only where it is absent and CI is not)."""
    if br.chromium_path() is None:
        msg = "Chromium not found: install it with 'make browser' (apt-get install chromium) or set ROARMCTL_CHROMIUM"
        if os.environ.get("CI"):
            pytest.fail(msg + " (CI must run the browser tests)")
        pytest.skip(msg)
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = br.launch(p)
        yield b
        b.close()


def write_html(tmp_path: Path, source: Path, *extra: str, name: str = "view.html") -> tuple[int, Path]:
    out = tmp_path / name
    return run_cli(["visualize-path", str(source), "-o", str(out), *extra]), out


def sample_at(traj, t: float) -> int:
    """Index of the trajectory sample at time ``t`` (the page's samples are a subset of the file's)."""
    i = int(np.argmin(np.abs(np.asarray(traj.times) - t)))
    assert abs(traj.times[i] - t) < 1e-5
    return i


# ------------------------------------------------------------------------------------------- numbers
def _point_box_distance(p: np.ndarray, pose: np.ndarray, size) -> float:
    """Distance (m) from point ``p`` to a box of full ``size`` at ``pose`` (0 inside): closed form."""
    local = pose[:3, :3].T @ (p - pose[:3, 3])
    d = np.maximum(np.abs(local) - np.asarray(size) / 2, 0.0)
    return float(np.linalg.norm(d))


def test_clearance_of_a_sphere_is_the_closed_form_distance_to_the_nearest_box():
    """FCL's clearance against a ball beside the arm equals the point-to-box distance minus the radius,
    taken over every collision box of the arm (all the M3's shapes are boxes), at several poses."""
    from roarmctl.motion.clearance import clearance
    from roarmctl.motion.scene import SceneItem
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    qs = np.array([robot.full_q(robot.named_poses[n]) for n in ("home", "observe", "ready")])
    r = 0.02
    balls = [np.array([0.30, 0.05, 0.20]), np.array([0.05, -0.18, 0.12]), np.array([0.20, 0.20, 0.30])]
    for centre in balls:
        item = SceneItem.sphere("ball", r, centre)
        c = clearance(robot, [item], qs)
        frames = robot.kin.link_frames(qs)
        for i in range(len(qs)):
            expect = min(_point_box_distance(centre, frames[i, robot.kin.link_index[s.link]] @ s.origin, s.size)
                         for s in robot.collision) - r
            assert c.distance[i] == pytest.approx(max(expect, 0.0), abs=1e-6)
            assert c.item[i] == 0


def test_every_items_distance_and_the_closest_points_are_the_closed_form():
    """Two balls beside the arm at three poses: the page's distance of *each* item (not only the nearest) is the
    closed-form point-to-box distance minus the radius over every collision box, and each item's closest-point pair
    drawn in 3D spans that item's distance, ends on its ball's surface and starts on the surface of an arm box."""
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.loader import load_robot
    from roarmctl.viz.web.document import view_document

    robot = load_robot("roarm_m3_pro")
    qs = np.array([robot.full_q(robot.named_poses[n]) for n in ("home", "observe", "ready")])
    balls = [("near", np.array([0.30, 0.05, 0.20]), 0.02), ("far", np.array([0.05, -0.25, 0.12]), 0.03)]
    scene = {"items": [{"name": n, "role": "obstacle", "shape": "sphere", "radius": r, "xyz": c.tolist(), "rpy": [0, 0, 0]}
                       for n, c, r in balls]}
    traj = Trajectory(robot.name, list(robot.joint_names), np.array([0.0, 1.0, 2.0]), qs, 0 * qs, 0 * qs, scene=scene)
    doc = view_document(traj, robot)
    n = doc["n"]
    each = _decode(doc["item_clearance"]).reshape(n, 2)
    pts = _decode(doc["item_points"]).reshape(n, 2, 2, 3)
    frames = robot.kin.link_frames(qs)
    for i in range(n):
        boxes = [(frames[i, robot.kin.link_index[s.link]] @ s.origin, s.size) for s in robot.collision]
        expect = [max(min(_point_box_distance(c, *box) for box in boxes) - r, 0.0) for _, c, r in balls]
        assert each[i] == pytest.approx(expect, abs=2e-6)
        assert min(expect) > 0  # nothing touches: every item has its pair
        for k, (_, c, r) in enumerate(balls):
            assert np.linalg.norm(pts[i, k, 0] - pts[i, k, 1]) == pytest.approx(expect[k], abs=2e-6)
            assert np.linalg.norm(pts[i, k, 1] - c) == pytest.approx(r, abs=2e-6)
            assert min(_point_box_distance(pts[i, k, 0], *box) for box in boxes) < 2e-6


def test_primitives_are_wound_outward_with_the_same_triangles():
    """The page draws convex primitives without back faces, so each triangle must face out: over random boxes,
    cylinders and spheres every normal of ``outward``'s triangles points away from the centre, and the triangles
    are the shape's own (the same corners, only some in the other order). The document marks them closed, a mesh
    not (it may be concave)."""
    from roarmctl.viz.shapes import item_faces, outward, triangles
    from roarmctl.viz.web.document import view_document

    rng = np.random.default_rng(7)
    for _ in range(20):
        size = rng.uniform(0.005, 0.8, 3)
        for item in ({"shape": "box", "size": size.tolist()}, {"shape": "cylinder", "radius": size[0], "length": size[1]},
                     {"shape": "sphere", "radius": size[2]}):
            tris = triangles(item_faces(item, local=True))
            out = outward(tris)
            normal = np.cross(out[:, 1] - out[:, 0], out[:, 2] - out[:, 0])
            assert np.all(np.einsum("ij,ij->i", normal, out.mean(axis=1)) > 0), item
            assert np.allclose(np.sort(out, axis=1), np.sort(tris, axis=1))
    import trimesh

    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    tm = trimesh.creation.box((0.05, 0.05, 0.05))
    scene = {"items": [{"name": "b", "role": "obstacle", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [0.3, 0, 0.1], "rpy": [0, 0, 0]},
                       {"name": "m", "role": "obstacle", "shape": "mesh", "xyz": [0.3, 0.2, 0.1], "rpy": [0, 0, 0],
                        "pieces": [{"vertices": tm.vertices.tolist(), "faces": tm.faces.tolist()}]}]}
    q = robot.full_q(robot.named_poses["home"])[None]
    doc = view_document(Trajectory(robot.name, list(robot.joint_names), np.array([0.0]), q, 0 * q, 0 * q, scene=scene), robot)
    assert [it["closed"] for it in doc["items"]] == [True, False]
    assert all(link["closed"] for link in doc["links"] if link["collision"])  # the M3's shapes are boxes


def test_clearance_to_a_mesh_and_a_cloud_agrees_with_the_same_box():
    """The same 6 x 4 x 10 cm block as a box, as a (rotated, offset) mesh, and as a point cloud of 5 mm cells:
    the arm's clearance to the mesh is the box's; to the cloud within a cell's half-diagonal of it."""
    import trimesh

    from roarmctl.motion.clearance import clearance
    from roarmctl.motion.scene import SceneItem
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    qs = np.array([robot.full_q(robot.named_poses[n]) for n in ("home", "observe", "ready")])
    centre, size = np.array([0.30, -0.08, 0.10]), np.array([0.06, 0.04, 0.10])
    box = SceneItem.box("block", size, centre)
    tm = trimesh.creation.box(size)
    mesh = SceneItem.from_mesh("block", tm.vertices @ np.diag([1, 1, 1]), tm.faces, xyz=centre)
    r = 0.005
    grid = np.stack(np.meshgrid(*[np.arange(-h + r / 2, h, r) for h in size / 2], indexing="ij"), -1).reshape(-1, 3)
    cloud = SceneItem.from_points("block", grid, r, xyz=centre)
    d_box = clearance(robot, [box], qs).distance
    assert np.all(d_box > 0.01)
    assert np.allclose(clearance(robot, [mesh], qs).distance, d_box, atol=1e-6)
    d_cloud = clearance(robot, [cloud], qs).distance
    assert np.all(np.abs(d_cloud - d_box) <= r * np.sqrt(3) / 2 + 1e-6), (d_cloud, d_box)
    # all three at once, each item's own distance (the cloud's many blocks searched per item): the same numbers
    moved = [SceneItem.box("b", size, centre + [0, 0.3, 0]), cloud, SceneItem.from_mesh("m", tm.vertices, tm.faces, xyz=centre - [0, 0.3, 0])]
    each = clearance(robot, moved, qs, per_item=True).item_distance
    for k, it in enumerate(moved):
        assert np.allclose(each[:, k], clearance(robot, [it], qs).distance, atol=1e-9)


def test_clearance_rules_base_on_the_table_and_a_carried_object():
    """The base standing on the table is not a clearance of 0 (the checker's base_links rule); an object carried
    at a sample is measured against the other items, and the arm is not measured against it."""
    from roarmctl.motion.clearance import clearance
    from roarmctl.motion.scene import SceneItem
    from roarmctl.robot.loader import load_robot

    robot = load_robot("roarm_m3_pro")
    q = robot.full_q(robot.named_poses["home"])[None]
    tcp = robot.kin.fk(q)[0]
    table = SceneItem.box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
    c = clearance(robot, [table], q)
    frames = robot.kin.link_frames(q)[0]
    corners = np.array([[sx, sy, sz, 2.0] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) / 2
    lowest = min(float(((frames[robot.kin.link_index[s.link]] @ s.origin) @ (corners * [*s.size, 1]).T)[2].min())
                 for s in robot.collision if s.link not in robot.base_links)  # the lowest corner above the table top
    assert c.distance[0] == pytest.approx(lowest, abs=1e-6)
    cube = SceneItem.box("cube", (0.04, 0.04, 0.04), tcp[:3, 3] - [0, 0, 0.03], role="object")  # in the jaws
    held = clearance(robot, [table, cube], q, carried=np.array([[False, True]]))
    assert held.parts[-1] == "cube"
    cube_bottom = tcp[2, 3] - 0.03 - 0.02
    assert held.distance[0] == pytest.approx(min(cube_bottom, c.distance[0]), abs=1e-6)


@pytest.mark.slow
def test_document_carries_the_object_with_the_hand_and_keeps_the_marks(planned):
    """pick_place: the cube's pose follows the TCP rigidly from grasp to release and ends at the plan's place
    target; events and blends sit at their sample times; every page array has one entry per sample."""
    import base64

    from roarmctl.viz.web.document import view_document

    f, traj = planned["pick_place"]
    doc = view_document(traj, name=f.name)
    n = doc["n"]
    dec = lambda k: np.frombuffer(base64.b64decode(doc[k]), dtype="<f4")  # noqa: E731
    times = dec("times")
    assert n == len(traj.times) and np.allclose(times, traj.times, atol=1e-5)
    for key, width in (("q", len(traj.joint_names)), ("tcp", 3), ("speed", 1), ("sigma_min", 1), ("clearance", 1)):
        assert dec(key).size == n * width, key
    assert len(doc["segment"]) == len(doc["nearest_item"]) == n
    cube = next(it for it in doc["items"] if it["name"] == "cube")
    track = np.frombuffer(base64.b64decode(cube["track"]), dtype="<f4").reshape(n, 3, 4)
    grasp, release = (next(e for e in doc["events"] if e["kind"] == k) for k in ("grasp", "release"))
    assert np.allclose(track[release["index"], :, 3], [0.25, 0.15, 0.02], atol=0.002)  # plans/pick_place.yaml: place xyz
    assert np.allclose(track[grasp["index"], :, 3], [0.25, -0.15, 0.02], atol=1e-6)  # still where it stood
    from roarmctl.robot.loader import load_robot

    fk = load_robot(traj.robot).kin.fk(traj.positions)
    rel = [np.linalg.inv(fk[k]) @ np.vstack([track[k], [0, 0, 0, 1]]) for k in (grasp["index"] + 1, release["index"])]
    assert np.allclose(rel[0], rel[1], atol=1e-5)  # rigid in the hand
    for e in doc["events"]:
        assert times[e["index"]] == pytest.approx(traj.times[sample_at(traj, e["time"])], abs=1e-5)
    assert [b["time"] for b in doc["blends"]] == pytest.approx(traj.blends)


@pytest.mark.slow
def test_long_motion_is_thinned_but_keeps_its_marks(planned):
    from roarmctl.viz.web.document import view_document

    _, traj = planned["multi_object"]
    doc = view_document(traj, max_samples=300)
    assert doc["n"] <= 300 + len(traj.events) + len(traj.blends) + 1
    import base64

    times = np.frombuffer(base64.b64decode(doc["times"]), dtype="<f4")
    assert times[0] == 0.0 and times[-1] == pytest.approx(traj.duration, abs=1e-5)
    for e in doc["events"]:
        assert times[e["index"]] == pytest.approx(traj.times[np.searchsorted(traj.times, e["time"] - 1e-9)], abs=1e-5)


def test_a_robot_without_collision_geometry_is_drawn_as_its_stick_arm():
    """A DH arm has no shapes: the page still draws it, joint origin to joint origin, ending at the TCP (FK)."""
    import base64

    import viz_fixtures

    from roarmctl.viz.data import robot_for
    from roarmctl.viz.web.document import view_document

    traj = viz_fixtures.planar_trajectory()
    robot = robot_for(traj)
    doc = view_document(traj)
    assert doc["links"] == [] and doc["bones"]
    pts = np.frombuffer(base64.b64decode(doc["bone_points"]), dtype="<f4").reshape(doc["n"], -1, 3)
    end = pts[:, doc["bones"][-1][1]]
    assert np.allclose(end, robot.kin.fk(traj.positions)[:, :3, 3], atol=1e-6)
    assert np.allclose(pts[:, doc["bones"][0][0]], 0.0, atol=1e-7)  # the base stays at the origin


def visual_robot(tmp_path: Path) -> Path:
    """The bundled M3 with visuals: link3 an L-shaped STL in orange (inline colour), base_link a box in a named
    material, and one visual whose mesh file is missing. Returns the sidecar."""
    import trimesh
    import yaml

    from roarmctl.robot.loader import bundled_dir
    from roarmctl.robot.model import transform

    bar = trimesh.creation.box((0.02, 0.12, 0.02), transform((0, -0.06, 0)))
    foot = trimesh.creation.box((0.08, 0.02, 0.02), transform((0.03, -0.11, 0)))
    trimesh.util.concatenate([bar, foot]).export(tmp_path / "forearm.stl")
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    urdf = urdf.replace('<link name="link3">', '<link name="link3"><visual><origin xyz="0 0 0.01"/><geometry>'
                        '<mesh filename="forearm.stl"/></geometry><material name="o"><color rgba="1 0.5 0 1"/></material>'
                        '</visual><visual><geometry><mesh filename="missing.stl"/></geometry></visual>', 1)
    urdf = urdf.replace('<link name="base_link">', '<link name="base_link"><visual><geometry><box size="0.1 0.1 0.02"/>'
                        '</geometry><material name="teal"/></visual>', 1)
    urdf = urdf.replace("</robot>", '<material name="teal"><color rgba="0 0.5 0.5 1"/></material></robot>')
    (tmp_path / "arm.urdf").write_text(urdf)
    side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
    side["urdf"] = "arm.urdf"
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    return tmp_path / "arm.yaml"


def visual_document(tmp_path: Path) -> dict:
    """The view document of the visual robot at home (three samples)."""
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.loader import load_robot
    from roarmctl.viz.web.document import view_document

    robot = load_robot(str(visual_robot(tmp_path)))
    q = np.tile(robot.full_q(robot.named_poses["home"]), (3, 1))
    traj = Trajectory(str(tmp_path / "arm.yaml"), list(robot.joint_names), np.array([0.0, 0.1, 0.2]), q,
                      np.zeros_like(q), np.zeros_like(q))
    return view_document(traj, robot)


def test_visual_meshes_are_drawn_where_the_description_has_them(tmp_path):
    """Visuals are read only when drawn; a mesh keeps its triangles (placed where the file puts them), colours
    come inline or by name, a missing visual file is left out and said; the planning geometry is unchanged."""
    import base64

    import trimesh

    from roarmctl.robot.loader import load_robot
    from roarmctl.robot.visuals import visual_shapes

    robot = load_robot(str(visual_robot(tmp_path)))
    bundled = load_robot("roarm_m3_pro")
    assert [(c.link, c.kind, c.size) for c in robot.collision] == [(c.link, c.kind, c.size) for c in bundled.collision]
    visuals, notes = visual_shapes(robot)
    assert [(v.shape.link, v.shape.kind) for v in visuals] == [("base_link", "box"), ("link3", "mesh")]
    assert visuals[0].rgba == (0.0, 0.5, 0.5, 1.0) and visuals[1].rgba == (1.0, 0.5, 0.0, 1.0)
    assert len(notes) == 1 and "missing.stl" in notes[0] and "link3" in notes[0]
    src = trimesh.load_mesh(tmp_path / "forearm.stl")
    mesh = visuals[1].shape
    assert len(mesh.mesh.faces) == len(src.faces)  # every triangle, not a hull
    placed = mesh.mesh.vertices @ mesh.origin[:3, :3].T + mesh.origin[:3, 3]
    uniq = lambda v: np.unique(np.round(v, 9), axis=0)  # noqa: E731  (an STL repeats each corner per face)
    assert np.allclose(uniq(placed), uniq(src.vertices + [0, 0, 0.01]), atol=1e-9)

    doc = visual_document(tmp_path)
    link3 = next(link for link in doc["links"] if link["name"] == "link3")
    (part,) = link3["visual"]
    assert part["color"] == "#ff8000"
    assert np.frombuffer(base64.b64decode(part["triangles"]), dtype="<f4").size == len(src.faces) * 9
    assert any("missing.stl" in n for n in doc["notes"])


def test_page_with_visual_meshes_shows_them(chromium, tmp_path):
    from roarmctl.viz.web.page import write_page

    out = write_page(visual_document(tmp_path), tmp_path / "visual.html")
    page, watch = br.open_page(chromium, out.as_uri())

    def orange() -> int:  # pixels of the orange forearm (shaded: red high, green about half of it, no blue)
        c = page.evaluate("window.roarmView.state().canvas")
        shot = br.screenshot(page).astype(int)[int(c["top"]):int(c["top"] + c["height"]), int(c["left"]):int(c["left"] + c["width"])]
        return int(((shot[..., 0] > 120) & (np.abs(shot[..., 1] * 2 - shot[..., 0]) < 40) & (shot[..., 2] < 40)).sum())

    try:
        assert watch.errors == [] and page.is_visible("#visual-toggle")
        assert "drawn from its collision shapes" not in page.inner_text("#notes")
        assert orange() > 200
        page.uncheck("#show-visual")
        assert orange() < 30  # the world axes' x axis (three.js draws it red to orange) is a line a pixel wide
    finally:
        page.close()


def test_large_visual_meshes_are_decimated_to_the_budget(tmp_path, monkeypatch):
    """Visual meshes over the pictures' budget are decimated (fast-simplification) so that all fit, each by the same
    factor; the result stays on the surface it draws (two spheres: every vertex within 1 % of the radius, the
    volume within 2 % of 4/3 pi r^3), the same input gives the same triangles, and a note says how many went."""
    import trimesh

    from roarmctl.robot import visuals as vis
    from roarmctl.robot.loader import load_robot

    monkeypatch.setattr(vis, "MAX_TRIANGLES", 20_000)
    radius = 0.03
    trimesh.creation.icosphere(subdivisions=5, radius=radius).export(tmp_path / "ball.stl")  # 20,480 triangles
    side = visual_robot(tmp_path)
    urdf = (tmp_path / "arm.urdf").read_text()
    ball = '<visual><geometry><mesh filename="ball.stl"/></geometry></visual>'
    (tmp_path / "arm.urdf").write_text(urdf.replace('<link name="link2">', f'<link name="link2">{ball}{ball}', 1))
    robot = load_robot(str(side))
    shapes, notes = vis.visual_shapes(robot)
    balls = [v.shape.mesh for v in shapes if v.shape.link == "link2"]
    assert len(balls) == 2 and all(len(b.faces) < 20_480 for b in balls)
    assert sum(len(v.shape.mesh.faces) for v in shapes if v.shape.kind == "mesh") <= 20_000
    for b in balls:
        r = np.linalg.norm(b.vertices, axis=1)
        assert np.all(np.abs(r - radius) < 0.01 * radius)
        volume = trimesh.Trimesh(b.vertices, b.faces).volume
        assert abs(volume - 4 / 3 * np.pi * radius ** 3) < 0.02 * 4 / 3 * np.pi * radius ** 3
    (said,) = [n for n in notes if "decimated" in n]
    assert "from 40,984 to" in said and "at most 20,000" in said  # 2 x 20,480 + the forearm's 24
    again, _ = vis.visual_shapes(load_robot(str(side)))
    assert all(np.array_equal(a.shape.mesh.vertices, b.shape.mesh.vertices) for a, b in zip(shapes, again)
               if a.shape.kind == "mesh")


@pytest.mark.slow
def test_a_robot_without_visuals_is_said_to_be_drawn_from_its_collision_shapes(planned):
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot
    from roarmctl.viz.web.document import view_document

    traj = load_trajectory(planned["pick_place"][0])
    doc = view_document(traj, load_robot(traj.robot))
    assert doc["notes"][0] == "drawn from its collision shapes: its description has no visual meshes"
    assert not any(link["visual"] for link in doc["links"])


@pytest.mark.slow
def test_page_is_one_file_with_no_outside_reference(planned, tmp_path):
    code, out = write_html(tmp_path, planned["pick_place"][0])
    assert code == 0
    text = out.read_text(encoding="utf-8")
    assert len(text.encode()) <= MAX_PAGE
    assert "default-src 'none'" in text  # the page may fetch nothing
    assert not re.search(r"<(script|link|img|iframe)[^>]+(src|href)=", text)
    data = re.search(r'<script id="roarm-view-data" type="application/json">(.*?)</script>', text, re.S).group(1)
    assert "<" not in data and json.loads(data)["format"] == "roarmctl.view/1"
    from importlib import resources

    three = resources.files("jupyter_threejs_sage").joinpath("static", "r130", "three.min.js").read_text()
    assert three in text  # the installed three.js, inlined as it is


# ------------------------------------------------------------------------------------------- in the browser
def check_grasp(page, traj, robot) -> None:
    """Click the grasp mark on the timeline; the TCP dot on screen must lie where FK of that sample projects."""
    page.click(".tick.event[data-kind=grasp]")
    st = page.evaluate("window.roarmView.state()")
    grasp = next(e for e in traj.events if e.kind == "grasp")
    i = sample_at(traj, st["time"])
    assert i == int(np.searchsorted(traj.times, grasp.time - 1e-9))  # the view jumped to the grasp sample
    fk = robot.kin.fk(traj.positions[i])[:3, 3]
    expect = br.project(st, fk)
    drawn, count = br.tcp_dot(br.screenshot(page), st["canvas"])
    assert count >= 20, "the TCP dot is not on screen"
    assert np.linalg.norm(drawn - expect) <= PIXELS, (drawn, expect)
    shown = page.inner_text("#r-time")
    assert f"{traj.times[i]:.3f} s" in shown


@pytest.mark.slow
@pytest.mark.parametrize("plan", [p.stem for p in PLANS])
def test_each_bundled_plan_page_loads_offline_and_draws_the_tcp_at_fk(chromium, planned, tmp_path, plan):
    from roarmctl.robot.loader import load_robot

    f, traj = planned[plan]
    code, out = write_html(tmp_path, f)
    assert code == 0 and out.stat().st_size <= MAX_PAGE
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        assert watch.errors == [] and watch.remote() == []
        assert page.locator("#joints tbody tr").count() == len(traj.joint_names)
        check_grasp(page, traj, load_robot(traj.robot))
        assert watch.errors == []
    finally:
        page.close()


def test_timeline_plays_scrubs_and_screenshot(chromium, planned, tmp_path):
    """Play moves the cursor forward at the chosen speed, the slider scrubs, and a screenshot shows the arm,
    the coloured path and the TCP dot (the one in the docs is made the same way by bench/bench_view.py).
    The page's clock is Playwright's (performance.now and requestAnimationFrame): how far 1.2 s of play at
    2x goes is then a number, not a race with a busy machine (on the wall clock, a late click once found the
    playback past the end)."""
    f, _traj = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        page.clock.install(time=0)
        page.clock.pause_at(1_000_000)  # ms; from here the page's time moves only when the test moves it
        page.select_option("#rate", "2")
        page.click("#play")
        page.clock.run_for(1200)  # ms of the page's time: 2.4 s of the trajectory at 2x
        page.click("#play")  # pause
        st = page.evaluate("window.roarmView.state()")
        assert not st["playing"]
        # where play stopped: the sample at 2.4 s (the page's samples are the file's, thinned on long motions; an
        # animation frame is 16 ms of page time, 32 ms of trajectory)
        assert abs(st["time"] - 2.4) < 0.05, st["time"]
        page.locator("#scrub").fill("100")
        assert page.evaluate("window.roarmView.state().index") == 100
        page.keyboard.press("ArrowRight")
        assert page.evaluate("window.roarmView.state().index") == 101
        shot = br.screenshot(page)
        shot_file = tmp_path / "view.png"
        page.screenshot(path=str(shot_file))
        assert shot_file.stat().st_size > 20_000
        st = page.evaluate("window.roarmView.state()")
        assert br.tcp_dot(shot, st["canvas"])[1] >= 20
        # the path's speed colours are on screen (viridis: dark blue to yellow)
        c = st["canvas"]
        sub = shot[int(c["top"]):int(c["top"] + c["height"]), int(c["left"]):int(c["left"] + c["width"])].astype(int)
        yellowish = (sub[..., 0] > 150) & (sub[..., 1] > 180) & (sub[..., 2] < 90)
        assert yellowish.sum() > 30
        assert watch.errors == []
    finally:
        page.close()


@pytest.fixture(scope="module")
def far_plan(tmp_path_factory):
    p = tmp_path_factory.mktemp("far") / "far.yaml"
    p.write_text((ROOT / "plans" / "pick_place.yaml").read_text().replace("xyz: [0.25, 0.15, 0.02]", "xyz: [0.75, 0.15, 0.02]"))
    return p


def test_failing_plan_page_shows_the_path_to_the_failure_and_marks_the_target(chromium, far_plan, tmp_path, capsys):
    code, out = write_html(tmp_path, far_plan)
    err = capsys.readouterr().err
    assert code == 3 and "unreachable" in err and str(out) in err
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        assert watch.errors == []
        data = page.evaluate("window.roarmView.data.failure")
        assert data["label"].startswith("task 2") and data["target"][0] == pytest.approx(0.75, abs=0.07)
        labels = page.locator(".label").all_inner_texts()
        assert any(t.startswith("failed: task 2") for t in labels)
        assert "PLANNING FAILED at task 2" in page.inner_text("#title")
        assert page.locator(".tick.event[data-kind=grasp]").count() == 1  # the pick was planned
    finally:
        page.close()


def test_text_from_a_file_is_shown_as_text_never_run(chromium, planned, tmp_path):
    """A scene item or event label holding markup is displayed literally; nothing in it runs."""
    f, _ = planned["pick_place"]
    doc = json.loads(f.read_text())
    evil = '<img src=x onerror="window.pwned=1"></script><script>window.pwned=2</script>'
    for item in doc["scene"]["items"]:
        if item["name"] == "cube":
            item["name"] = evil
    for e in doc["events"]:
        e["label"] = evil
    bad = tmp_path / "evil.traj.json"
    bad.write_text(json.dumps(doc))
    code, out = write_html(tmp_path, bad)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        assert page.evaluate("window.pwned === undefined")
        assert evil in page.locator(".label").all_inner_texts()
        assert watch.errors == [] and watch.remote() == []
    finally:
        page.close()


@pytest.mark.slow
def test_view_serves_the_page_on_loopback_until_ctrl_c(chromium, planned, tmp_path):
    """`roarmctl view` prints its URL (127.0.0.1, a free port), serves the same page visualize-path writes,
    answers nothing else, and Ctrl-C, its normal end, is no error: exit 0 and how to open the page again."""
    f, _ = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "view", str(f)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"http://127\.0\.0\.1:(\d+)/\?token=[\w-]{32,}", line)  # the token: tests/test_view_server.py
        assert m, line
        url = m.group(0)
        with urllib.request.urlopen(url, timeout=30) as r:
            assert r.status == 200 and r.read() == out.read_bytes()
        with pytest.raises(urllib.error.HTTPError) as e:
            urllib.request.urlopen(url.replace("/?", "/etc/passwd?"), timeout=30)
        assert e.value.code == 404
        page, watch = br.open_page(chromium, url)
        try:
            assert watch.errors == [] and page.evaluate("window.roarmView.data.n") > 100
        finally:
            page.close()
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            rest, err = proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise
    assert proc.returncode == 0 and "error" not in err and "interrupted" not in err, err
    assert f"open it again with: roarmctl view {f}" in rest.replace("\n", " ")


def test_view_rejects_a_port_in_use(planned, capsys):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert run_cli(["view", str(planned["pick_place"][0]), "--port", str(port)]) == 2
    assert "already in use" in capsys.readouterr().err


@pytest.mark.slow
def test_execution_log_shows_the_measured_arm_as_a_ghost(chromium, planned, tmp_path):
    """A run on the simulated arm: the page's measured-vs-commanded TCP distance agrees with the tracking error
    the streamer measured during the run (a separate computation), and the ghost is drawn and named."""
    import base64

    traj_file, log = planned_and_run_on_sim(tmp_path, "robot: roarm_m3_pro\nstart: home\nscene:\n  table: {shape: box, "
                                            "size: [0.8, 0.6, 0.02], xyz: [0.15, 0, -0.01]}\ntasks:\n  - move: {xyz: [0.25, 0.10, 0.08]}\n")
    from roarmctl.viz.web.sources import load_view_source, source_document

    doc = source_document(load_view_source(log, traj_file))
    assert doc["ghost"]["label"] == "measured" and doc["items"][0]["name"] == "table"
    dec = lambda a: np.frombuffer(base64.b64decode(a), dtype="<f4")  # noqa: E731
    times, ghost_tcp, error = dec(doc["times"]), dec(doc["ghost"]["tcp"]).reshape(-1, 3), dec(doc["ghost"]["error"])
    run = json.loads(log.read_text())
    # a feedback line describes the servos as read before its bytes crossed the wire (115200 baud 8N1: 11520 B/s)
    # and about 4 ms of firmware work earlier, and an answer to a T:105 at most a round trip after the question: the
    # log's read_t where the stream judged it (a busy host reads lines late; dated by their arrival, the page's error
    # was once 4.9 mm RMS off the streamer's in a run under load)
    fb = [(r.get("read_t", r["t"] - (len(r["line"]) + 2) / 11520 - 0.004), r["tcp_world_m"]) for r in run["received"]
          if "tcp_world_m" in r]
    from roarmctl.device.schedule import plan_clock

    # where the plan waited for a busy host (the log's paused), the page shows the measured arm on the plan's time
    t = plan_clock(np.array([a for a, _ in fb]), run["paused"])
    keep = np.concatenate([[True], np.diff(t) > 0])  # a pause's frames stand at its start
    t, world = t[keep], np.array([b for _, b in fb])[keep]
    inside = (times > t[0]) & (times < t[-1])
    assert inside.sum() > 20
    logged = np.column_stack([np.interp(times[inside], t, world[:, k]) for k in range(3)])
    assert np.abs(ghost_tcp[inside] - logged).max() < 0.001  # m: the measured TCP the streamer logged
    # the streamer's own tracking error (its time base: when the servos were read) is of the same size
    tracked = np.array([e["error_m"] for e in run["tracking"]])
    assert abs(np.sqrt(np.mean(error[inside] ** 2)) - np.sqrt(np.mean(tracked ** 2))) < 0.003
    code, out = write_html(tmp_path, log, name="run.html")  # no -t: the log carries its trajectory and its table
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        assert watch.errors == []
        assert page.is_visible("#ghost-toggle") and "mm" in page.inner_text("#r-ghost")
        assert "table" in page.inner_text("#item-clearance") and "give" not in page.inner_text("#notes")
        assert "drawn from its collision shapes: its description has no visual meshes" in page.inner_text("#notes")
    finally:
        page.close()


def _decode(a: str) -> np.ndarray:
    import base64

    return np.frombuffer(base64.b64decode(a), dtype="<f4")


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.asarray(a, dtype=float) ** 2)))


@pytest.fixture(scope="module")
def pick_place_run(planned, tmp_path_factory):
    """plans/pick_place.yaml run on the simulated arm (``execute --sim``, its physics servos, on a virtual clock:
    ``clirun.virtual_simulator``; the same run on a busy or an idle machine): (trajectory, log)."""
    d = tmp_path_factory.mktemp("pick_place_run")
    f, _ = planned["pick_place"]
    log = d / "pick_place.exec.json"
    with virtual_simulator():
        done = roarmctl("execute", str(f), "--sim", "--yes", "--log", str(log))
    assert done.returncode == 0, done.stderr
    return f, log


def _older_log(log: Path, tmp_path: Path) -> Path:
    """A copy of ``log`` as a roarmctl before logs carried their trajectory wrote it (no ``trajectory``)."""
    data = json.loads(log.read_text())
    del data["trajectory"]
    old = tmp_path / f"older-{log.name}"
    old.write_text(json.dumps(data))
    return old


@pytest.mark.slow
def test_a_run_carries_its_trajectory_and_is_shown_whole_without_t(pick_place_run, tmp_path):
    """A log of `execute` carries the trajectory it ran: viewed alone, its page is the page made with -t and the
    trajectory file (scene, targets, marks, the commanded arm, the tracking against the plan), number for number;
    visualize-path RUN -o NAME.html draws the cube and the grasp with no -t."""
    from roarmctl.viz.web.sources import load_view_source, source_document

    traj_file, log = pick_place_run
    carried = source_document(load_view_source(log))
    given = source_document(load_view_source(log, traj_file))
    assert carried == given
    assert [it["name"] for it in carried["items"]] == ["table", "cube"] and carried["targets"]
    assert carried["ghost"]["error_source"] == "plan"
    code, out = write_html(tmp_path, log, name="run.html")
    assert code == 0
    text = out.read_text()
    assert '"name":"cube"' in text and '"kind":"grasp"' in text


@pytest.mark.slow
def test_a_damaged_carried_trajectory_is_refused_naming_the_field(pick_place_run, tmp_path, capsys):
    """A log whose carried trajectory is damaged (a time that goes back) is refused with exit 2 and one line naming
    the log's field; no page is written."""
    _, log = pick_place_run
    data = json.loads(log.read_text())
    data["trajectory"]["points"][3]["time_from_start"] = -1.0
    bad = tmp_path / "bad.exec.json"
    bad.write_text(json.dumps(data))
    code, out = write_html(tmp_path, bad, name="bad.html")
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert "trajectory" in err and "points[3]" in err and "Traceback" not in err


@pytest.mark.slow
def test_a_run_viewed_without_its_trajectory_agrees_with_the_cli(pick_place_run, tmp_path):
    """A log that carries no trajectory (an older roarmctl's) viewed alone: its tracking figures are the run's (the
    CLI's summary, and those of the page made with -t), not the distance to commands drawn when their lines were
    sent (they aim ~80 ms ahead on the plan: 10x too high); the commanded TCP speed stays at the plan's peak (a
    tick's T:102 and gripper T:101 are one command, not a jump in 0.1 ms); the note names an option visualize-path
    has, and with it the page has the scene and the marks."""
    from roarmctl.viz.web.sources import load_view_source, source_document

    traj_file, log = pick_place_run
    log = _older_log(log, tmp_path)
    run = json.loads(log.read_text())
    alone = source_document(load_view_source(log))
    whole = source_document(load_view_source(log, traj_file))
    inside = lambda d: (_decode(d["times"]) > 0.1) & (_decode(d["times"]) < d["duration"] - 0.1)  # noqa: E731
    err_alone = _decode(alone["ghost"]["error"])[inside(alone)]
    err_whole = _decode(whole["ghost"]["error"])[inside(whole)]
    # the page draws the run's own errors: at each frame, between the two feedback samples around it (float32)
    from roarmctl.device.schedule import plan_clock

    rows_t = plan_clock(np.array([r["t"] for r in run["tracking"]]), run.get("paused", []) or [])
    rows_e = np.array([r["error_m"] for r in run["tracking"]])
    t_alone = _decode(alone["times"])[inside(alone)]
    right = np.clip(np.searchsorted(rows_t, t_alone), 1, len(rows_t) - 1)
    lo = np.minimum(rows_e[right - 1], rows_e[right]) - 1e-6
    hi = np.maximum(rows_e[right - 1], rows_e[right]) + 1e-6
    assert np.all((err_alone >= lo) & (err_alone <= hi))
    # so its RMS is the run's, up to the resampling: the page's frames are evenly spaced in time, the feedback frames
    # are not when the host is busy (0.75 mm apart at 5.4 mm RMS in a loaded CI run), never the 10x of drawing the
    # commands when their lines were sent
    summary_rms = run["summary"]["tracking_mm"]["rms"]
    assert abs(_rms(err_alone) * 1000 - summary_rms) < max(0.5, 0.2 * summary_rms)
    # the page's own comparison with the plan (-t) against the streamer's (which widens its window by the lateness it
    # measured, host and device): equal on an unhurried run, apart by at most what that lateness lets the TCP travel
    plan_peak = float(_decode(whole["speed"]).max())
    late = max([float(e.get("lateness", 0.0)) for e in run.get("sent", [])] + [0.0])
    late += float(run.get("firmware_lag_ms", {}).get("max", 0.0) if isinstance(run.get("firmware_lag_ms"), dict) else 0.0) / 1000
    assert abs(_rms(err_alone) - _rms(err_whole)) < 0.0005 + plan_peak * late
    assert err_alone.max() * 1000 < run["summary"]["tracking_mm"]["max"] + 0.5
    # the commanded arm on the plan's clock: its TCP speed peaks where the plan's does
    assert _decode(alone["speed"]).max() < 1.05 * plan_peak
    # commanded and planned TCP on one clock: within the sag offset (a few mm), not the ~16 mm of 80 ms ahead
    t_a, tcp_a = _decode(alone["times"]), _decode(alone["tcp"]).reshape(-1, 3)
    t_w, tcp_w = _decode(whole["times"]), _decode(whole["tcp"]).reshape(-1, 3)
    planned_at = np.column_stack([np.interp(t_a, t_w, tcp_w[:, k]) for k in range(3)])
    assert _rms(np.linalg.norm(tcp_a - planned_at, axis=1)) < 0.005
    (note,) = [n for n in alone["notes"] if "give" in n]
    assert "-t/--trajectory" in note and alone["items"] == []
    code, out = write_html(tmp_path, log, "-t", str(traj_file), name="run.html")
    assert code == 0
    text = out.read_text()
    assert '"name":"cube"' in text and '"kind":"grasp"' in text


def test_page_reads_each_joints_torque_as_a_share_of_its_own_limit(chromium, planned, tmp_path):
    """plans/payload.yaml holding its 0.2 kg weight: the panel's torque column reads each joint's RNEA torque over
    that joint's own limit (the M3's differ: 2.94 N m shoulder, 1.47 elbow), the figure the PNG's panel draws."""
    from roarmctl.robot.dynamics import inverse_dynamics
    from roarmctl.robot.model import Inertial
    from roarmctl.viz.data import robot_for

    f, traj = planned["payload"]
    robot = robot_for(traj)
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        times = page.evaluate("Array.from(new Float32Array(Uint8Array.from(atob(window.roarmView.data.times), "
                              "c => c.charCodeAt(0)).buffer))")
        grasp = next(e for e in traj.events if e.kind == "grasp").time
        i = int(np.searchsorted(times, grasp + 0.3))
        page.evaluate(f"window.roarmView.setIndex({i})")
        rows = page.locator("#joints tbody tr").all()
        k = sample_at(traj, float(times[i]))
        (p,) = traj.payloads
        body = {p["link"]: Inertial(p["mass"], np.array(p["com"]), np.array(p["inertia"]))}
        tau = inverse_dynamics(robot, traj.positions[k], traj.velocities[k], traj.accelerations[k], payload=body)
        for j, row in enumerate(rows):
            cell = row.locator("td").nth(3)
            text = cell.inner_text()
            assert text.endswith(" %") and abs(float(text[:-2]) - 100 * tau[j] / robot.effort_limits[j]) <= 0.51
            assert float(cell.get_attribute("title").split()[0]) == pytest.approx(tau[j], abs=2e-3)
        assert watch.errors == []
    finally:
        page.close()


def _pixel(image: np.ndarray, xy) -> np.ndarray:
    """Median RGB of the 5 x 5 pixels around page pixel ``xy``."""
    x, y = int(round(xy[0])), int(round(xy[1]))
    return np.median(image[y - 2:y + 3, x - 2:x + 3].reshape(-1, 3).astype(float), axis=0)


def _look(page, position, target) -> np.ndarray:
    """Put the page's camera at ``position`` looking at ``target`` (world m); the pixel colour where ``target`` lands."""
    page.evaluate(f"window.roarmView.lookAt({list(map(float, position))}, {list(map(float, target))})")
    return _pixel(br.screenshot(page), br.project(page.evaluate("window.roarmView.state()"), target))


def _around(centre, azimuth_deg: float, elevation_deg: float, distance: float) -> np.ndarray:
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.asarray(centre) + distance * np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])


@pytest.mark.slow
def test_scene_items_are_opaque_and_keep_their_colour_as_the_view_turns(chromium, planned, tmp_path):
    """Pixels in Chromium, plans/pick_place.yaml's cube on its table: the cube's top is opaque (its colour does not
    change when the table behind it is hidden or made see-through: drawn see-through without depth, a solid showed
    its far faces and whatever lay behind) and, lit by lights that depend on the surface's normal only, the same from
    two azimuths. Seen from under the table, an opaque table hides the cube; a see-through one shows it, in one
    colour from both sides (not greyed by a draw order that flips as the view turns)."""
    f, _ = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri(), {"width": 720, "height": 480})  # software GL: fewer pixels
    try:
        page.uncheck("#show-path")  # the path comes down onto the cube's top; the labels float over it
        page.uncheck("#show-labels")
        top, bottom = np.array([0.25, -0.15, 0.04]), np.array([0.25, -0.15, 0.0])
        seen = _look(page, _around(top, -38, 40, 0.45), top)
        assert page.evaluate("window.roarmView.showItem('table', false)")
        assert np.abs(_look(page, _around(top, -38, 40, 0.45), top) - seen).max() <= 2
        page.evaluate("window.roarmView.showItem('table', true)")
        page.check("#see-through-table")
        assert np.abs(_look(page, _around(top, -38, 40, 0.45), top) - seen).max() <= 2
        assert np.abs(_look(page, _around(top, 70, 40, 0.45), top) - seen).max() <= 3
        # from under the table, looking up at the cube's bottom face
        through = [_look(page, _around(bottom, a, -35, 0.45), bottom) for a in (-38, 70)]
        assert np.abs(through[0] - through[1]).max() <= 3
        page.evaluate("window.roarmView.showItem('cube', false)")
        bare = _look(page, _around(bottom, -38, -35, 0.45), bottom)
        assert np.abs(through[0] - bare).max() > 10  # the cube shows through
        page.uncheck("#see-through-table")
        hidden = _look(page, _around(bottom, -38, -35, 0.45), bottom)
        page.evaluate("window.roarmView.showItem('cube', true)")
        assert np.abs(_look(page, _around(bottom, -38, -35, 0.45), bottom) - hidden).max() <= 2  # opaque: hidden
        assert watch.errors == []
    finally:
        page.close()


@pytest.mark.slow
def test_clearance_strip_goes_to_the_tightest_moment_and_tells_intended_contact(chromium, planned, tmp_path):
    """plans/pick_place.yaml: "min" goes to the smallest clearance that is not intended contact (found here from the
    page's per-item arrays and the plan's segments: the jaws on the cube and the cube on the table from its
    descent to its lift, and from its lowering to the retreat, are meant); the panel reads every item's distance
    there, and every item's closest-point pair is drawn in 3D with its distance (on screen, in its colour); at the
    grasp the cube's contact reads as intended, not as a violation, and on the way down its pair is drawn green."""
    f, traj = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        doc = page.evaluate("window.roarmView.data")
        n, names = doc["n"], [it["name"] for it in doc["items"]]
        times, each = _decode(doc["times"]), _decode(doc["item_clearance"]).reshape(n, len(names))
        meant = np.zeros_like(each, dtype=bool)
        for e in traj.events:  # the non-free run of segments around each grasp and release
            runs = [(s.start, s.end) for s in traj.segments if s.kind != "free"]
            lo = hi = e.time
            for _ in runs:
                for a, b in runs:
                    if a <= hi + 1e-6 and b >= lo - 1e-6:
                        lo, hi = min(lo, a), max(hi, b)
            meant[(times >= lo - 1e-6) & (times <= hi + 1e-6)] = True  # both items touch only there in this plan
        free = np.where(meant | (each < 0), np.inf, each)
        i, k = np.unravel_index(np.argmin(free), free.shape)
        assert free[i, k] > 0.005  # the plan keeps its padding outside intended contact
        assert page.is_visible("#strip") and page.inner_text("#go-min") == f"min {1000 * free[i, k]:.1f} mm"
        page.click("#go-min")
        assert page.evaluate("window.roarmView.state().index") == i
        rows = page.locator("#item-clearance tbody tr").all()
        for kk, row in enumerate(rows):
            assert row.locator("td").nth(1).inner_text() == f"{1000 * each[i, kk]:.1f} mm"
        _check_gaps(page, doc, i)
        grasp = next(e for e in doc["events"] if e["kind"] == "grasp")["index"]
        page.evaluate(f"window.roarmView.setIndex({grasp - 1})")
        cube = rows[names.index("cube")]
        assert "intended" in cube.locator("td").nth(2).inner_text()
        assert cube.locator("td").nth(1).get_attribute("class") == "intended"
        # on the way down to the cube (intended contact, not yet touching): its pair is drawn in the intended green
        down = [j for j in range(grasp) if meant[j, names.index("cube")] and each[j, names.index("cube")] > 0]
        assert down
        gaps = _check_gaps(page, doc, down[len(down) // 2])
        assert gaps[names.index("cube")]["color"] == "#1a9850"
        assert watch.errors == []
    finally:
        page.close()


def _check_gaps(page, doc: dict, i: int) -> dict[int, dict]:
    """At sample ``i``: one closest-point pair is drawn per item the arm does not touch (item -> the page's pair),
    each the document's pair (FCL's, checked against closed forms above), its label the item's distance in mm, and
    its line on screen: pixels of its colour where the camera projects the pair's points (labels hidden)."""
    page.evaluate(f"window.roarmView.setIndex({i})")
    n, m = doc["n"], len(doc["items"])
    each = _decode(doc["item_clearance"]).reshape(n, m)[i]
    pts = _decode(doc["item_points"]).reshape(n, m, 2, 3)[i]
    gaps = {g["item"]: g for g in page.evaluate("window.roarmView.gaps()")}
    assert set(gaps) == {k for k in range(m) if each[k] > 0 and np.isfinite(pts[k]).all()} and len(gaps) >= 1
    for k, g in gaps.items():
        assert np.allclose([g["from"], g["to"]], pts[k], atol=1e-6)
        assert page.locator(f'.label.gap[data-item="{k}"]').inner_text() == f"{1000 * each[k]:.1f} mm"
    page.evaluate("document.getElementById('labels').style.visibility = 'hidden'")
    try:
        state = page.evaluate("window.roarmView.state()")
        image = br.screenshot(page).astype(int)
    finally:
        page.evaluate("document.getElementById('labels').style.visibility = ''")
    for k, g in gaps.items():
        a, b = br.project(state, g["from"]), br.project(state, g["to"])
        colour = np.array([int(g["color"][j:j + 2], 16) for j in (1, 3, 5)])
        hits = 0
        for f in (0.3, 0.5, 0.7):  # along the line, away from its ends (the TCP dot sits on one of them)
            x, y = np.round(a + f * (b - a)).astype(int)
            window = image[y - 2:y + 3, x - 2:x + 3]
            hits += bool(np.any(np.all(np.abs(window - colour) <= 3, axis=-1)))
        assert hits >= 2, (k, g)
    return gaps


def test_software_gl_draws_without_multisampling_in_few_draw_calls(chromium, planned, tmp_path):
    """Headless Chromium draws with SwiftShader: the page finds it and leaves multisampling off (most of a software
    frame's cost: bench/bench_view.py), and one frame of pick_place is a few dozen draw calls, counted by three.js."""
    f, _ = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri(), {"width": 640, "height": 400})
    try:
        assert page.evaluate("window.roarmView.softwareGL") is True
        attrs = page.evaluate("document.getElementById('canvas3d').getContext('webgl2').getContextAttributes()")
        assert attrs["antialias"] is False
        stats = page.evaluate("window.roarmView.stats()")
        assert 0 < stats["calls"] <= 45 and stats["programs"] <= 8
        t = page.evaluate("window.roarmView.timing")
        assert t["scriptStart"] <= t["parsed"] <= t["context"] <= t["built"] <= t["drawn"] <= t["ready"]
        assert watch.errors == []
    finally:
        page.close()


def test_the_tcp_path_is_drawn_where_fk_puts_it_in_its_speed_colour(chromium, planned, tmp_path):
    """The fat-line path (drawn as one plain draw of three.js's line quads, not one instance per segment): with the
    arm and the scene hidden, the pixels where the camera projects the TCP of the trajectory's samples (FK of its
    joints, computed here) carry that sample's speed colour (the PNG's colour map at |J(q) qdot|, computed here)."""
    from matplotlib import colormaps

    from roarmctl.viz.data import path_data, robot_for
    from roarmctl.viz.path_figure import PATH_CMAP

    f, traj = planned["pick_place"]
    robot = robot_for(traj)
    data = path_data(traj, robot)
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        page.uncheck("#show-collision")
        for it in page.evaluate("window.roarmView.data.items.map((it) => it.name)"):
            assert page.evaluate(f"window.roarmView.showItem({json.dumps(it)}, false)")
        page.evaluate("document.getElementById('labels').style.visibility = 'hidden'")
        page.evaluate("window.roarmView.setView('top')")
        state = page.evaluate("window.roarmView.state()")
        image = br.screenshot(page).astype(int)
        doc = page.evaluate("window.roarmView.data")
        vmax = doc["speed_max"]
        marks = [e["target"] for e in doc["events"]] + [t["position"] for t in doc["targets"]] + [data.tcp[0], data.tcp[-1]]
        marks += [data.tcp[int(np.argmin(np.abs(traj.times - b["time"])))] for b in doc["blends"]]
        marked = np.array([br.project(state, m) for m in marks])
        checked = found = 0
        for i in range(5, len(traj.times) - 5, 4):
            xy = br.project(state, robot.kin.fk(traj.positions[i])[:3, 3])
            if np.min(np.linalg.norm(marked - xy, axis=1)) < 25:
                continue  # under a mark (a ball, a cross, a label's anchor)
            colour = np.round(np.asarray(colormaps[PATH_CMAP](min(data.tcp_speed[i] / vmax, 1.0)))[:3] * 255)
            x, y = np.round(xy).astype(int)
            window = image[y - 1:y + 2, x - 1:x + 2]
            checked += 1
            found += bool(np.any(np.abs(window - colour).max(axis=-1) <= 24))
        assert checked >= 40 and found >= 0.9 * checked, (found, checked)
        assert watch.errors == []
    finally:
        page.close()


WATCH_WRITES = """() => {
  window.__writes = { fixed: 0, cursor: 0, panel: 0 };
  new MutationObserver((ms) => { for (const m of ms) window.__writes[m.target.classList.contains('gap') ? 'cursor' : 'fixed']++; })
    .observe(document.getElementById('labels'), { attributes: true, subtree: true, attributeFilter: ['style'] });
  new MutationObserver((ms) => { window.__writes.panel += ms.length; })
    .observe(document.getElementById('panel'), { attributes: true, childList: true, characterData: true, subtree: true });
}"""
WRITES = "() => new Promise((done) => setTimeout(() => { const w = Object.assign({}, window.__writes); " \
         "for (const k in window.__writes) window.__writes[k] = 0; done(w); }, 0))"


def test_a_frame_writes_only_what_changed(chromium, planned, tmp_path):
    """Work per frame, counted (MutationObserver): the same sample again changes nothing in the panel (a cell written
    with its own text would replace its text node: 27 changes a frame when every cell is written); stepping the
    cursor with the camera still changes no label fixed in the world (events, targets), only those at the cursor
    (each item's distance); turning the camera moves the fixed ones."""
    f, _ = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri(), {"width": 640, "height": 400})
    try:
        n = page.evaluate("window.roarmView.data.n")
        page.evaluate(WATCH_WRITES)
        for i in range(0, n, max(1, n // 12)):
            page.evaluate(f"window.roarmView.setIndex({i})")
        writes = page.evaluate(WRITES)
        assert writes["fixed"] == 0 and writes["cursor"] > 0 and writes["panel"] > 0
        page.evaluate(f"window.roarmView.setIndex({n // 2})")
        page.evaluate(WRITES)
        page.evaluate(f"window.roarmView.setIndex({n // 2})")
        assert page.evaluate(WRITES)["panel"] == 0
        page.evaluate("window.roarmView.lookAt([0.7, -0.4, 0.5], [0.2, 0.0, 0.05])")
        assert page.evaluate(WRITES)["fixed"] > 0
        assert watch.errors == []
    finally:
        page.close()


@pytest.mark.slow
def test_views_orthographic_zoom_toward_the_cursor_and_the_grid_scale(chromium, planned, tmp_path):
    """Top / front / side look along -z / -x / +y (two points apart only along that axis land on one pixel with the
    orthographic camera, not with the perspective one); the wheel zooms toward the cursor (the point under it stays
    there, the camera comes closer), in both cameras; the grid's spacing is said and is a round number."""
    f, _traj = planned["pick_place"]
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri(), {"width": 900, "height": 600})
    state = lambda: page.evaluate("window.roarmView.state()")  # noqa: E731
    try:
        p = np.array([0.25, -0.15, 0.04])
        for view, axis in (("top", 2), ("front", 0), ("side", 1)):
            page.click(f"#views button[data-view={view}]")
            q = p.copy()
            q[axis] += 0.2
            persp = np.linalg.norm(br.project(state(), p) - br.project(state(), q))
            page.check("#orthographic")
            ortho = np.linalg.norm(br.project(state(), p) - br.project(state(), q))
            page.uncheck("#orthographic")
            assert ortho < 0.5 and persp > 2.0, (view, ortho, persp)
        page.click("#views button[data-view=iso]")
        for ortho in (False, True):
            page.set_checked("#orthographic", ortho)
            before = state()
            at = br.project(before, p)
            page.mouse.move(*at)
            page.mouse.wheel(0, -240)
            page.wait_for_function(f"window.roarmView.state().view.join() !== {json.dumps(','.join(map(str, before['view'])))}")
            after = state()
            assert np.linalg.norm(br.project(after, p) - at) < 1.5
            scale = lambda s: np.linalg.norm(br.project(s, p) - br.project(s, p + [0, 0, 0.05]))  # noqa: E731
            assert scale(after) > 1.3 * scale(before)  # closer: 5 cm looks longer
        grid = page.evaluate("window.roarmView.grid")
        mantissa = grid["spacing"] / 10 ** np.floor(np.log10(grid["spacing"]))
        assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9 and 8 <= grid["cells"] <= 30
        assert page.inner_text("#grid-scale") == f"grid {grid['spacing'] * 1000:g} mm"
        assert watch.errors == []
    finally:
        page.close()


@pytest.mark.slow
def test_each_target_is_marked_with_its_miss(chromium, planned, tmp_path):
    """The trajectory's per-target table (issue 32) in the page: every named target marked with its miss in mm, the
    line to the TCP where it came closest ending at FK of the trajectory at that time."""
    from roarmctl.viz.data import robot_for

    f, traj = planned["pick_place"]
    assert traj.targets
    robot = robot_for(traj)
    code, out = write_html(tmp_path, f)
    assert code == 0
    page, watch = br.open_page(chromium, out.as_uri())
    try:
        doc = page.evaluate("window.roarmView.data")
        assert [t["name"] for t in doc["targets"]] == [t["name"] for t in traj.targets]
        for row, t in zip(traj.targets, doc["targets"]):
            k = int(np.clip(np.searchsorted(traj.times, row["time"] - 1e-9), 0, len(traj.times) - 1))
            assert np.allclose(t["closest"], robot.kin.fk(traj.positions[k])[:3, 3], atol=1e-9)
            assert np.linalg.norm(np.subtract(t["closest"], row["position"])) == pytest.approx(row["distance"], abs=1e-6)
        texts = page.locator(".label.miss").all_inner_texts()
        assert texts == [f"{1000 * row['distance']:.1f} mm" + (f" (zone {1000 * row['zone']:.0f})" if row["zone"] > 0 else "")
                         for row in traj.targets]
        assert watch.errors == []
    finally:
        page.close()


def test_visualize_path_trajectory_option_goes_with_a_page_only(planned, tmp_path, capsys):
    f, _ = planned["pick_place"]
    assert run_cli(["visualize-path", str(f), "-t", str(f), "-o", str(tmp_path / "x.png")]) == 2
    assert "-o NAME.html" in capsys.readouterr().err and not (tmp_path / "x.png").exists()


@pytest.mark.slow
def test_physics_run_shows_the_simulated_arm_and_where_the_cube_went(planned, tmp_path):
    """`roarmctl simulate`'s run file: the ghost is the simulated arm, and the simulated cube's outline ends where
    plans/pick_place.yaml places it (within the run's own 10 mm placing tolerance)."""
    import base64

    from roarmctl.viz.web.sources import load_view_source, source_document

    f, _ = planned["pick_place"]
    run = tmp_path / "pick_place.run.json"
    assert run_cli(["simulate", str(f), "-o", str(run)]) == 0
    doc = source_document(load_view_source(run, f))
    ghost = doc["ghost"]
    assert ghost["label"] == "simulated"
    (cube,) = ghost["items"]
    assert doc["items"][cube["item"]]["name"] == "cube"
    track = np.frombuffer(base64.b64decode(cube["track"]), dtype="<f4").reshape(doc["n"], 3, 4)
    assert np.linalg.norm(track[-1, :, 3] - [0.25, 0.15, 0.02]) < 0.010
    assert np.linalg.norm(track[0, :, 3] - [0.25, -0.15, 0.02]) < 0.002  # it started where it stood
    # the run file alone carries its trajectory: the page is the one made with -t
    assert source_document(load_view_source(run)) == doc
    # one of an older roarmctl carries only its scene: the cube and where physics put it, the run's own tracking figures
    alone = source_document(load_view_source(_older_log(run, tmp_path)))
    assert [it["name"] for it in alone["items"]] == [it["name"] for it in doc["items"]]
    (cube_alone,) = alone["ghost"]["items"]
    end = np.frombuffer(base64.b64decode(cube_alone["track"]), dtype="<f4").reshape(alone["n"], 3, 4)[-1, :, 3]
    assert np.linalg.norm(end - track[-1, :, 3]) < 0.001
    summary = json.loads(run.read_text())["summary"]["tracking_mm"]
    err = np.frombuffer(base64.b64decode(alone["ghost"]["error"]), dtype="<f4")
    assert abs(1000 * np.sqrt(np.mean(err.astype(float) ** 2)) - summary["rms"]) < 0.5
