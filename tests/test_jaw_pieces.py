"""The physics' jaws are the jaw table's geometry (issue 35, item 5): the convex pieces of the description's jaw
meshes (``roarmctl.robot.jaw_pieces``), checked against the table the planner closes by and against the meshes
themselves (read here with trimesh, not through roarmctl), and the decomposition's cache."""

from __future__ import annotations

import json
from pathlib import Path

import fcl
import numpy as np
import pytest
import trimesh

from roarmctl.errors import DescriptionError
from roarmctl.motion.scene import Scene, SceneItem
from roarmctl.physics.world import World
from roarmctl.robot import jaw_pieces as jp
from roarmctl.robot.loader import load_robot

ROBOTS = Path(jp.__file__).resolve().parent.parent / "robots"
#: Where each bundled description's jaw table measures from (its sidecar's comment: "the smallest distance from
#: the fixed fingertip (...) to the moving jaw"): the fixed jaw mesh's vertices beyond this plane of its link.
TIPS = {"roarm_m3_pro": (2, 1.0, 0.118),    # link5 z > 0.118 m
        "roarm_m2_s": (1, -1.0, -0.278)}    # link3 y < -0.278 m
#: Waveshare's published jaw meshes (tests/data/meshes/README.md: repository, path, commit), which the bundled
#: descriptions' pieces were made from: link -> (file, scale to m)
MESHES = Path(__file__).resolve().parent / "data" / "meshes"
PUBLISHED = {"roarm_m3_pro": {link: (MESHES / "waveshare_roarm_m3" / f"{link}.stl", 0.001) for link in ("link5", "gripper_link")},
             "roarm_m2_s": {link: (MESHES / "waveshare_roarm_m2_s" / f"{link}.stl", 1.0) for link in ("link3", "gripper_link")}}


def _published(name: str, link: str):
    """The published mesh of ``link`` of bundled robot ``name`` as a ``JawMesh`` (vertices in m)."""
    from roarmctl.robot.model import JawMesh

    path, scale = PUBLISHED[name][link]
    return JawMesh(link, str(path), scale)


def _object_world(robot):
    """The robot's MuJoCo model with one small free object far from the arm (it sets the objects' contact bits)."""
    return World(robot, Scene([SceneItem.from_dict({"name": "probe", "role": "object", "shape": "box",
                                                    "size": [0.01, 0.01, 0.01], "xyz": [2.0, 2.0, 0.005]})]))


def _meets_objects(world, geom: int, probe: int) -> bool:
    m = world.model
    return bool((m.geom_contype[geom] & m.geom_conaffinity[probe]) or (m.geom_contype[probe] & m.geom_conaffinity[geom]))


def _geom_points(world, geom: int) -> np.ndarray:
    """The points (K, 3) in the world frame whose convex hull is the geom (a mesh's vertices, a box's corners)."""
    import mujoco

    m, d = world.model, world.data
    if m.geom_type[geom] == mujoco.mjtGeom.mjGEOM_MESH:
        k = m.geom_dataid[geom]
        local = m.mesh_vert[m.mesh_vertadr[k]:m.mesh_vertadr[k] + m.mesh_vertnum[k]]
    elif m.geom_type[geom] == mujoco.mjtGeom.mjGEOM_BOX:
        local = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * m.geom_size[geom]
    else:
        pytest.fail(f"geom {geom}: type {m.geom_type[geom]} not measured here")
    return local @ d.geom_xmat[geom].reshape(3, 3).T + d.geom_xpos[geom]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(TIPS))
def test_the_physics_jaws_open_as_the_jaw_table_says(name):
    """At every row of the jaw table, the least distance from the fixed fingertip (the jaw mesh's own vertices, read
    with trimesh) to the moving jaw's shapes that objects meet in the physics model is the table's width, within
    1 mm (the table was measured from the tip's surface, here from its vertices; CoACD's pieces stand up to ~0.4 mm
    proud of the mesh there). Before, objects met the URDF's finger boxes: 1.7 mm (closed) to 29.7 mm nearer than the
    table on the M3."""
    import mujoco

    robot = load_robot(name)
    gr = robot.gripper
    joint = next(j for j in robot.joints if j.name == gr.joint)
    world = _object_world(robot)
    probe = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_GEOM, "item:probe")
    path, scale = PUBLISHED[name][gr.fixed_jaw.link]
    mesh = trimesh.load(path, force="mesh")
    axis, sign, cut = TIPS[name]
    v = np.asarray(mesh.vertices) * scale
    tip = v[sign * v[:, axis] > sign * cut]
    assert len(tip) > 10
    moving = [g for g in range(world.model.ngeom) if world.doc.geom_owner.get(mujoco.mj_id2name(
        world.model, mujoco.mjtObj.mjOBJ_GEOM, g)) == ("link", joint.child) and _meets_objects(world, g, probe)]
    assert moving
    gi = robot.joint_index(gr.joint)

    def convex(points: np.ndarray) -> fcl.CollisionObject:
        hull = trimesh.Trimesh(points).convex_hull
        f = np.asarray(hull.faces)
        return fcl.CollisionObject(fcl.Convex(np.asarray(hull.vertices), len(f), np.hstack([np.full((len(f), 1), 3), f]).ravel()))

    for q, width in zip(gr.jaw_q, gr.jaw_width):
        world.set_q(np.where(np.arange(robot.dof) == gi, q, 0.0))
        body = world.link_body[gr.fixed_jaw.link]
        fingertip = convex(tip @ world.data.xmat[body].reshape(3, 3).T + world.data.xpos[body])  # the tip is a plate
        gap = min(fcl.distance(fingertip, convex(_geom_points(world, g)), fcl.DistanceRequest(), fcl.DistanceResult())
                  for g in moving)
        assert gap == pytest.approx(width, abs=1e-3), (q, gap, width)


@pytest.mark.parametrize("name", sorted(TIPS))
def test_the_bundled_descriptions_pieces_are_those_of_the_published_meshes(name):
    """Every jaw of a bundled description is a pieces file in the package (no run decomposes, no vendor mesh ships),
    made from that link's published mesh with today's settings (its key is the mesh's), and read as the pieces."""
    from roarmctl.robot.jaw_meshes import jaw_triangles

    robot = load_robot(name)
    assert {m.link for m in robot.gripper.jaw_meshes} == set(PUBLISHED[name])
    for mesh in robot.gripper.jaw_meshes:
        assert mesh.pieces is not None and Path(mesh.pieces).parent == jp.BUNDLED and not mesh.file
        data = json.loads(Path(mesh.pieces).read_text())
        assert data["key"] == jp.cache_key(*jaw_triangles(_published(name, mesh.link)))
        assert data["parameters"] == jp.PARAMETERS and len(data["pieces"]) >= 4
        pieces = jp.convex_pieces(mesh)
        assert len(pieces) == len(data["pieces"]) and np.array_equal(pieces[0], np.asarray(data["pieces"][0]))
    assert not list(ROBOTS.rglob("*.stl")) and not list(ROBOTS.rglob("*.STL"))


def _claw(tmp_path: Path) -> Path:
    """A description with a concave jaw: the planar 2R arm's sidecar plus a U-shaped jaw mesh on its last link."""
    u = trimesh.util.concatenate([trimesh.creation.box((0.04, 0.01, 0.01), trimesh.transformations.translation_matrix(t))
                                  for t in ((0, 0, 0),)] + [
        trimesh.creation.box((0.01, 0.03, 0.01), trimesh.transformations.translation_matrix((x, 0.02, 0)))
        for x in (-0.015, 0.015)])
    u.export(tmp_path / "jaw.stl")
    return tmp_path / "jaw.stl"


@pytest.mark.slow
def test_pieces_are_cached_and_the_same_bytes_each_time(tmp_path, monkeypatch):
    """A decomposition is written once (the second call reads it: CoACD is not run again), a fresh one gives the
    same bytes, a spoiled cache file is made again, and the pieces cover the mesh's concave U, not its hull."""
    from roarmctl.robot.model import JawMesh

    monkeypatch.setenv("ROARMCTL_CACHE", str(tmp_path / "cache"))
    # a shallow search without CoACD's remeshing (with the bundled settings this U of three overlapping boxes takes
    # ~25 s: the slow test below runs them on a real jaw)
    monkeypatch.setattr(jp, "PARAMETERS", {**jp.PARAMETERS, "preprocess_mode": "off", "resolution": 300,
                                           "mcts_iterations": 20, "mcts_max_depth": 1, "max_convex_hull": 6})
    mesh = JawMesh("link", str(_claw(tmp_path)), 1.0)
    runs = []
    real = jp.decompose
    monkeypatch.setattr(jp, "decompose", lambda v, f: runs.append(1) or real(v, f))
    first = jp.convex_pieces(mesh)
    (path,) = (tmp_path / "cache" / "jaw_pieces").iterdir()
    written = path.read_bytes()
    jp._READ.clear()  # the process's own store: the file is read back
    assert jp.convex_pieces(mesh) and len(runs) == 1
    path.write_text("{not json")
    jp._READ.clear()
    again = jp.convex_pieces(mesh)
    assert len(runs) == 2 and path.read_bytes() == written
    assert [p.tolist() for p in again] == [p.tolist() for p in first]
    # the U's gap (x -0.01 .. 0.01, y 0.005 .. 0.035) is left open: its middle lies in no piece
    middle = np.array([[0.0, 0.025, 0.0]])
    assert len(first) >= 3
    assert not any(trimesh.Trimesh(p).convex_hull.contains(middle)[0] for p in first)


def _sidecar(tmp_path: Path, entry: str) -> Path:
    text = (ROBOTS / "roarm_m2_s.yaml").read_text()
    text = text.replace("urdf: roarm_m2_s.urdf", f"urdf: {ROBOTS / 'roarm_m2_s.urdf'}")
    start = text.index("          jaw_meshes:")
    end = text.index("}]}", start) + 3
    out = tmp_path / "arm.yaml"
    out.write_text(text[:start] + f"          jaw_meshes: [{entry}]}}" + text[end:])
    return out


@pytest.mark.parametrize("entry, words", [
    ("{link: nowhere, file: TMP/jaw.stl}", "'nowhere' is not a link"),
    ("{link: link3, file: TMP/jaw.stl, scale: -1}", "too small"),
    ("{link: link3, file: TMP/jaw.stl, size: 1}", "unknown key"),
    ("{link: link3, file: /etc/hostname}", "gripper.jaw_meshes[0]"),
])
def test_a_bad_jaw_mesh_entry_is_refused_in_one_line(tmp_path, entry, words):
    _claw(tmp_path)
    with pytest.raises(DescriptionError) as err:
        load_robot(str(_sidecar(tmp_path, entry.replace("TMP", str(tmp_path)))))
    assert words in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("text, words", [
    ("{\"format\": \"something else\"}", "is not a file of convex pieces"),
    ("not json", "is not a file of convex pieces"),
    ("{\"format\": \"roarmctl.jaw_pieces/1\", \"pieces\": [[[0, 0, 0], [1, 0, 0]]]}", "is not a file of convex pieces"),
    ("{\"format\": \"roarmctl.jaw_pieces/1\", \"pieces\": []}", "is not a file of convex pieces"),
    ("[" * 200_000 + "]" * 200_000, "is not a file of convex pieces"),  # nested deeper than json goes
])
def test_a_bad_pieces_file_is_refused_in_one_line_when_read(tmp_path, text, words):
    (tmp_path / "jaw.json").write_text(text)
    robot = load_robot(str(_sidecar(tmp_path, f"{{link: link3, pieces: {tmp_path}/jaw.json}}")))
    with pytest.raises(DescriptionError) as err:
        jp.jaw_pieces(robot)
    assert words in str(err.value) and "jaw.json" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("entry, words", [
    ("{link: link3, pieces: TMP/jaw.json, file: TMP/jaw.stl}", "exactly one of file"),
    ("{link: link3}", "exactly one of file"),
    ("{link: link3, pieces: TMP/jaw.json, scale: 0.001}", "no scale"),
])
def test_a_jaw_entry_gives_a_mesh_or_its_pieces(tmp_path, entry, words):
    with pytest.raises(DescriptionError) as err:
        load_robot(str(_sidecar(tmp_path, entry.replace("TMP", str(tmp_path)))))
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_missing_jaw_mesh_is_left_out_with_a_note(tmp_path):
    robot = load_robot(str(_sidecar(tmp_path, f"{{link: link3, file: {tmp_path}/missing.stl}}")))
    assert robot.gripper.jaw_meshes == () and any("missing.stl' not found" in n for n in robot.notes)


def test_a_jaw_mesh_entry_is_read_in_the_links_frame(tmp_path):
    from roarmctl.robot.jaw_meshes import jaw_triangles

    _claw(tmp_path)
    robot = load_robot(str(_sidecar(tmp_path, f"{{link: link3, file: {tmp_path}/jaw.stl, scale: 2}}")))
    (mesh,) = robot.gripper.jaw_meshes
    v, _ = jaw_triangles(mesh)
    assert mesh.link == "link3" and np.allclose(v.max(axis=0), 2 * trimesh.load(tmp_path / "jaw.stl").bounds[1])


@pytest.mark.slow  # CPU: one CoACD run with the bundled settings (~12 s on the M2-S's forearm)
def test_a_fresh_decomposition_is_the_bundled_file_byte_for_byte():
    """The M2-S's fixed jaw (its forearm mesh) decomposed here gives the bundled file, made in another process by
    ``bench/bench_jaw_pieces.py --write``: the decomposition is deterministic and the bundle is current."""
    from roarmctl.robot.jaw_meshes import jaw_triangles

    robot = load_robot("roarm_m2_s")
    bundled = next(m for m in robot.gripper.jaw_meshes if m.link == robot.gripper.fixed_jaw.link)
    v, f = jaw_triangles(_published("roarm_m2_s", bundled.link))
    key = jp.cache_key(v, f)
    assert jp.cache_text(key, jp.decompose(v, f)).encode() == Path(str(bundled.pieces)).read_bytes()


@pytest.mark.slow
def test_a_jaw_mesh_is_cut_into_pieces_under_a_progress_stage_of_its_own_and_carried(tmp_path, monkeypatch):
    """A description that gives its jaws as meshes (here the M3 with Waveshare's, as a user's copy would): the pieces
    are made (CoACD, 15-60 s of CPU a mesh the first time) while the plan's progress names that stage, not the first
    pick's IK; the plan then closes by them as by the bundled pieces (same trajectory bytes), and its trajectory
    carries them."""
    import shutil

    import yaml

    from roarmctl.motion.pipeline import plan_file

    shutil.copy(ROBOTS / "roarm_m3_pro.urdf", tmp_path / "roarm_m3_pro.urdf")
    side = yaml.safe_load((ROBOTS / "roarm_m3_pro.yaml").read_text())
    for path, _ in PUBLISHED["roarm_m3_pro"].values():  # inside the description's folder, as a user keeps them
        shutil.copy(path, tmp_path / path.name)
    side["gripper"]["jaw_meshes"] = [{"link": link, "file": path.name, "scale": scale}
                                     for link, (path, scale) in PUBLISHED["roarm_m3_pro"].items()]
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    plan = yaml.safe_load((ROBOTS.parents[2] / "plans" / "pick_place.yaml").read_text())
    monkeypatch.setenv("ROARMCTL_CACHE", str(tmp_path / "cache"))
    stages: list[str] = []
    during: list[str] = []
    bundled = {m.link: jp.convex_pieces(m) for m in load_robot("roarm_m3_pro").gripper.jaw_meshes}

    def decompose(v, f):  # the bundled pieces are CoACD's of these meshes (checked above): not 30 s of CPU again
        during.append(stages[-1])
        link = "link5" if len(during) == 1 else "gripper_link"
        return bundled[link]

    monkeypatch.setattr(jp, "decompose", decompose)
    mine = plan_file(dict(plan, robot=str(tmp_path / "arm.yaml")), seed=1,
                     progress=lambda stage, done, total: stages.append(stage))
    assert len(during) == 2 and all("jaw meshes' convex pieces" in s for s in during)
    assert stages.index(during[0]) < next(i for i, s in enumerate(stages) if s.startswith("task 1/"))
    ours = plan_file(dict(plan), seed=1)
    assert np.array_equal(mine.trajectory.positions, ours.trajectory.positions)
    # the trajectory carries the pieces it closed by: loaded with its description's folder gone, on a machine
    # without the cache, its robot has the same jaws (the physics squeezes with them, not the links' boxes)
    from roarmctl.motion.validate import robot_of

    for f in tmp_path.glob("*"):
        shutil.rmtree(f) if f.is_dir() else f.unlink()
    carried = robot_of(mine.trajectory)
    assert [m.link for m in carried.gripper.jaw_meshes] == ["link5", "gripper_link"]
    assert not [n for n in carried.notes if "jaw" in n] and len(during) == 2  # nothing decomposed again
    for link, pieces in jp.jaw_pieces(carried).items():
        assert len(pieces) == len(bundled[link]) and all(np.array_equal(a, b) for a, b in zip(pieces, bundled[link]))


@pytest.mark.slow
def test_what_a_description_leaves_out_is_in_the_physics_notes(tmp_path):
    """A jaw mesh the description names but does not have: the physics model says so in its notes (the run's
    ``model.notes``, printed by simulate), as the plan does, instead of squeezing with the links' boxes unsaid."""
    import shutil

    import yaml

    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.setup import build

    shutil.copy(ROBOTS / "roarm_m3_pro.urdf", tmp_path / "roarm_m3_pro.urdf")
    side = yaml.safe_load((ROBOTS / "roarm_m3_pro.yaml").read_text())
    side["gripper"]["jaw_meshes"] = [{"link": "link5", "file": "missing.stl", "scale": 0.001}]
    (tmp_path / "arm.yaml").write_text(yaml.safe_dump(side))
    robot = load_robot(str(tmp_path / "arm.yaml"))
    assert robot.gripper.jaw_meshes == ()
    traj = plan_file(dict(yaml.safe_load((ROBOTS.parents[2] / "plans" / "pick_place.yaml").read_text()),
                          robot=str(tmp_path / "arm.yaml")), seed=1)
    assert any("missing.stl' not found" in n for n in traj.notes)
    assert any("missing.stl' not found" in n for n in build(traj.trajectory, robot).notes)
