"""The single-query API (issue 22, item 5): ``Planner`` (ik, is_valid, plan_to_joints, plan_to_pose, time) and
``Scene`` (add, remove, attach, detach), checked against independent measures: FK of IK answers, a second
collision checker at a finer resolution over the returned paths, the trajectory validator ``execute`` uses,
and hand-placed scene items. ``check_example`` checks what the example scripts 05-13 wrote."""

from __future__ import annotations

import inspect
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

import roarmctl.api as rc
import roarmctl.errors as errors
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.scene import Scene as WorldScene
from roarmctl.motion.scene import SceneItem
from roarmctl.plan.schema import load_plan
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.model import Robot

ROBOT = rc.load_robot("roarm_m3_pro")
HOME = ROBOT.named_poses["home"]
DOWN = math.pi / 2
TABLE = SceneItem.box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
WALL = SceneItem.box("wall", (0.04, 0.10, 0.15), (0.28, 0.0, 0.075))
LEFT, RIGHT = [-0.54, 0.53, 1.93, 0.67, 0.0], [0.54, 0.53, 1.93, 0.67, 0.0]  # low, either side of the wall


def scene_with_wall() -> rc.Scene:
    s = rc.Scene()
    s.add_box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
    s.add_box("wall", (0.04, 0.10, 0.15), (0.28, 0.0, 0.075))
    return s


def path_is_free(waypoints: np.ndarray, items: list[SceneItem], padding: float = 0.005) -> bool:
    """An independent check of a path: a fresh checker, every straight step cut at 2 mrad."""
    checker = CollisionChecker(ROBOT, WorldScene([SceneItem.box(i.name, i.size, i.xyz, role=i.role) for i in items]),
                               padding=padding)
    wps = np.asarray(waypoints)[:, ROBOT.arm_indices]
    dense = [wps[0]]
    for a, b in itertools.pairwise(wps):
        n = max(int(np.ceil(np.max(np.abs(b - a)) / 0.002)), 1)
        dense += [a + (b - a) * k / n for k in range(1, n + 1)]
    return bool(np.all(checker.validity_batch(np.array(dense))))


def test_every_error_class_is_exported():
    classes = {n for n, c in inspect.getmembers(errors, inspect.isclass) if issubclass(c, BaseException)
               and c.__module__ == errors.__name__}
    assert classes <= set(rc.__all__) and all(getattr(rc, n) is getattr(errors, n) for n in classes)


def test_ik_solutions_are_valid_and_reach_the_pose_by_fk():
    planner = rc.Planner(ROBOT, scene_with_wall())
    found = planner.ik(rc.Pose((0.25, -0.15, 0.08), pitch=DOWN), q_ref=HOME)
    assert found.ok
    for q in found.solutions:
        t = ROBOT.kin.fk(q)
        np.testing.assert_allclose(t[:3, 3], [0.25, -0.15, 0.08], atol=1e-6)
        assert t[:3, 0] @ [0, 0, -1] > math.cos(1e-4)  # the approach axis straight down
        assert planner.is_valid(q)
    with pytest.raises(rc.UnreachableError):
        planner.ik(rc.Pose((2.0, 0.0, 0.1)))


def test_is_valid_says_why():
    planner = rc.Planner(ROBOT, scene_with_wall())
    assert planner.is_valid(HOME)
    v = planner.is_valid([0.0, 0.0, 3.5, 0.0, 0.0])
    assert not v and "outside its limits" in v.reason
    v = planner.is_valid([0.0, 1.4, 1.2, 0.0, 0.0])
    assert not v and "table" in v.reason


def test_best_of_no_valid_solution_raises_with_the_reason_and_the_hint():
    found = rc.Planner(ROBOT, scene_with_wall()).ik(rc.Pose((0.28, 0.0, 0.075), pitch=DOWN), q_ref=HOME)  # in the wall
    assert not found.ok and found.rejected and all("wall" in why for why in found.rejected)
    with pytest.raises(rc.UnreachableError) as ei:
        found.best  # noqa: B018
    assert ei.value.reason == "collision"
    assert ei.value.hint == "move the target or change the orientation asked for"


def test_plan_to_joints_goes_around_the_wall_and_the_path_is_free_for_another_checker():
    planner = rc.Planner(ROBOT, scene_with_wall(), seed=3)
    path = planner.plan_to_joints(LEFT, RIGHT)
    np.testing.assert_allclose(path.waypoints[0][ROBOT.arm_indices], LEFT)
    np.testing.assert_allclose(path.waypoints[-1][ROBOT.arm_indices], RIGHT)
    assert len(path.waypoints) > 2  # the straight move goes through the wall
    assert not path_is_free(np.array([ROBOT.full_q(LEFT), ROBOT.full_q(RIGHT)]), [TABLE, WALL])
    assert path_is_free(path.waypoints, [TABLE, WALL])
    again = rc.Planner(ROBOT, scene_with_wall(), seed=3).plan_to_joints(LEFT, RIGHT)
    np.testing.assert_array_equal(again.waypoints, path.waypoints)  # same seed, same calls: same path


def test_plan_to_joints_refuses_an_invalid_goal():
    planner = rc.Planner(ROBOT, scene_with_wall())
    with pytest.raises(rc.PlanningError, match=r"goal configuration is invalid: .*table"):
        planner.plan_to_joints(HOME, [0.0, 1.4, 1.2, 0.0, 0.0])


def test_plan_to_pose_ends_at_the_pose():
    planner = rc.Planner(ROBOT, scene_with_wall(), seed=1)
    path = planner.plan_to_pose(LEFT, rc.Pose((0.25, 0.15, 0.06), pitch=DOWN))
    np.testing.assert_allclose(ROBOT.kin.fk(path.waypoints[-1])[:3, 3], [0.25, 0.15, 0.06], atol=1e-6)
    assert path_is_free(path.waypoints, [TABLE, WALL])


def _states_free(robot: Robot, qs: list[np.ndarray], items: list[SceneItem]) -> list[bool]:
    """An independent check of single states: a fresh checker without the singularity margin."""
    checker = CollisionChecker(robot, WorldScene(items), padding=0.005)
    return [bool(v) for v in checker.validity_batch(np.array([q[robot.arm_indices] for q in qs]))]


def test_plan_to_pose_says_the_wall_is_in_the_way():
    pose = rc.Pose((0.28, 0.0, 0.075), pitch=DOWN)  # in the wall
    sols = solve_ik(ROBOT, pose.xyz, pitch=pose.pitch, q_ref=HOME, all_solutions=True)
    assert sols and not any(_states_free(ROBOT, sols, [TABLE, WALL])) and all(_states_free(ROBOT, sols, [TABLE]))
    with pytest.raises(rc.UnreachableError) as ei:
        rc.Planner(ROBOT, scene_with_wall()).plan_to_pose(HOME, pose)
    assert ei.value.reason == "collision"  # was "joint_limit"
    assert "in collision" in ei.value.message and "'wall'" in ei.value.message and "\n" not in ei.value.message


def test_plan_to_pose_says_the_singularity_margin_rejects_every_solution():
    pose = rc.Pose((0.25, 0.15, 0.06), pitch=DOWN)
    sols = solve_ik(ROBOT, pose.xyz, pitch=pose.pitch, q_ref=HOME, all_solutions=True)
    checker = CollisionChecker(ROBOT, WorldScene([]))
    assert sols and all(checker.margin_measure(q[ROBOT.arm_indices])[0] < 0.9 for q in sols)
    with pytest.raises(rc.UnreachableError) as ei:
        rc.Planner(ROBOT, singularity_margin=0.9).plan_to_pose(HOME, pose)
    assert ei.value.reason == "singularity" and "within the singularity margin" in ei.value.message


def test_a_plan_says_the_singularity_margin_rejects_its_target():
    """The planner's own IK choice (a plan's move) names the cause too: the margin, not a collision."""
    start = solve_ik(ROBOT, (0.25, 0.15, 0.06), pitch=DOWN)[0]
    target = (0.12, 0.0, 0.06)
    checker = CollisionChecker(ROBOT, WorldScene([]))
    sols = solve_ik(ROBOT, target, pitch=DOWN, all_solutions=True)
    assert checker.margin_measure(start[ROBOT.arm_indices])[0] > 0.2  # the start clears the margin, every goal not
    assert sols and all(checker.margin_measure(q[ROBOT.arm_indices])[0] < 0.2 for q in sols)
    assert all(_states_free(ROBOT, sols, []))
    plan = {"robot": "roarm_m3_pro", "start": list(start), "planner": {"singularity_margin": 0.2},
            "tasks": [{"move": {"xyz": list(target), "pitch": {"deg": 90}}}]}
    with pytest.raises(rc.UnreachableError) as ei:
        rc.plan(plan)
    assert ei.value.reason == "singularity" and "singularity" in ei.value.message  # was "collision"


UR5E = Path(__file__).parent / "data" / "arms" / "ur5e" / "robot.yaml"  # ur6 closed form: eight IK branches


def test_plan_to_pose_counts_each_cause_when_they_differ():
    robot = rc.load_robot(UR5E)
    pose, margin = rc.Pose((0.4, 0.2, 0.3), rpy=(math.pi, 0, 0)), 0.28
    crate = SceneItem.box("crate", (0.2, 0.2, 0.2), (0.4, 0.2, 0.3))
    sols = solve_ik(robot, pose.xyz, rpy=pose.rpy, all_solutions=True)
    sigma = CollisionChecker(robot, WorldScene([])).margin_measure(np.array([q[robot.arm_indices] for q in sols]))
    near = int(np.sum(sigma < margin))
    assert len(sols) == 8 and 0 < near < 8
    assert not any(_states_free(robot, sols, [crate])) and all(_states_free(robot, sols, []))
    scene = rc.Scene()
    scene.add_box("crate", (0.2, 0.2, 0.2), (0.4, 0.2, 0.3))
    with pytest.raises(rc.UnreachableError) as ei:
        rc.Planner(robot, scene, singularity_margin=margin).plan_to_pose(np.zeros(6), pose)
    assert ei.value.reason == "mixed"
    assert f"{8 - near} in collision (" in ei.value.message and "'crate'" in ei.value.message
    assert f"{near} within the singularity margin (" in ei.value.message
    scene_only = rc.Scene()
    scene_only.add_box("crate", (0.2, 0.2, 0.2), (0.4, 0.2, 0.3))
    with pytest.raises(rc.UnreachableError) as ei:
        rc.Planner(robot, scene_only, singularity_margin=0).plan_to_pose(np.zeros(6), pose)
    assert ei.value.reason == "collision" and "all 8 IK solutions are in collision" in ei.value.message


def test_time_gives_a_trajectory_the_validator_accepts(tmp_path):
    planner = rc.Planner(ROBOT, scene_with_wall(), seed=3, velocity_scale=0.4)
    traj = planner.time(planner.plan_to_joints(LEFT, RIGHT))
    assert isinstance(traj, rc.Trajectory)
    assert np.all(np.abs(traj.velocities) <= ROBOT.velocity_limits * 0.4 * (1 + 1e-6) + 1e-9)
    np.testing.assert_allclose(traj.positions[0][ROBOT.arm_indices], LEFT, atol=1e-9)
    np.testing.assert_allclose(traj.positions[-1][ROBOT.arm_indices], RIGHT, atol=1e-9)
    assert [i["name"] for i in traj.scene["items"]] == ["table", "wall"]
    back = rc.load_trajectory(rc.save_trajectory(traj, tmp_path / "t.traj.json"))  # execute's validator
    assert back.duration == pytest.approx(traj.duration)


def test_scene_changes_reach_the_next_query():
    scene = rc.Scene()
    planner = rc.Planner(ROBOT, scene)
    q = [0.0, 0.6, 1.8, 0.0, 0.0]
    assert planner.is_valid(q)
    scene.add_box("crate", (0.10, 0.10, 0.10), (0.30, 0.0, 0.0))
    assert "crate" in planner.is_valid(q).reason
    scene.remove("crate")
    assert planner.is_valid(q)
    with pytest.raises(rc.InputError, match="already there"):
        scene.add_box("wall", (0.1, 0.1, 0.1), (1, 1, 1)) and scene.add_box("wall", (0.1, 0.1, 0.1), (1, 1, 1))


def test_a_carried_item_moves_with_the_tcp_and_is_checked_like_the_arm():
    """Attach a cube at the grasp; at another configuration the cube is where the TCP took it (FK, by hand:
    the grasp offset kept), it collides with a post the bare arm clears, and detach puts it down there."""
    scene = scene_with_wall()
    scene.add_box("cube", (0.04, 0.04, 0.04), (0.25, -0.15, 0.02), role="object")
    planner = rc.Planner(ROBOT, scene, seed=1)
    grasp = planner.ik(rc.Pose((0.25, -0.15, 0.02), pitch=DOWN), q_ref=HOME, touching="cube").best
    assert not planner.is_valid(grasp)  # without 'touching' the jaws hit the cube they hold
    scene.attach("cube", grasp)
    assert planner.is_valid(grasp)
    up = planner.ik(rc.Pose((0.25, -0.15, 0.12), pitch=DOWN), q_ref=grasp).best
    # a post under the cube's bottom face (the cube is centred on the TCP, 2 cm down to its face): the cube hits
    # it, the arm alone clears it (a scene without the cube, a new planner)
    post = ((0.02, 0.02, 0.02), (0.25, -0.15, 0.095))
    scene.add_box("post", *post)
    v = planner.is_valid(up)
    assert not v and "cube" in v.reason
    bare = scene_with_wall()
    bare.add_box("post", *post)
    assert rc.Planner(ROBOT, bare).is_valid(up)
    scene.remove("post")
    cube = scene.detach("cube", up)
    np.testing.assert_allclose(cube.pose[:3, 3], [0.25, -0.15, 0.12], atol=1e-6)  # centred on the TCP, as grasped


def check_example(number: str, out: Path) -> None:
    """What the examples 05-13 wrote, checked independently."""
    if number == "05":
        data = json.loads((out / "ik.json").read_text())
        assert data["solutions"]
        for q in data["solutions"]:
            np.testing.assert_allclose(ROBOT.kin.fk(np.array(q))[:3, 3], data["xyz"], atol=1e-6)
    elif number == "06":
        data = json.loads((out / "is_valid.json").read_text())
        assert data["home"][0] and not data["into the desk"][0] and "table" in data["into the desk"][1]
        assert "outside its limits" in data["elbow past its limit"][1]
    elif number == "07":
        wps = np.array(json.loads((out / "path.json").read_text())["waypoints"])
        assert path_is_free(wps, [TABLE, WALL]) and len(wps) > 2
    elif number == "08":
        data = json.loads((out / "pose_path.json").read_text())
        np.testing.assert_allclose(ROBOT.kin.fk(np.array(data["waypoints"][-1]))[:3, 3], data["xyz"], atol=1e-6)
        assert path_is_free(np.array(data["waypoints"]), [TABLE, WALL])
    elif number == "09":
        traj = rc.load_trajectory(out / "timed.traj.json")
        np.testing.assert_allclose(traj.positions[-1][ROBOT.arm_indices], ROBOT.named_poses["ready"][ROBOT.arm_indices],
                                   atol=1e-9)
    elif number == "10":
        data = json.loads((out / "scene.json").read_text())
        assert "crate" in data["blocked"] and data["items"] == ["post", "ball"]
    elif number == "11":
        data = json.loads((out / "carried.json").read_text())
        np.testing.assert_allclose(np.array(data["cube"])[:3, 3], [0.25, 0.15, 0.02], atol=1e-6)
        np.testing.assert_allclose(ROBOT.kin.fk(np.array(data["put"]))[:3, 3], [0.25, 0.15, 0.02], atol=1e-6)
    elif number in ("12", "13"):
        # the same pose is free without the item (example 10); with the mesh crate / the scan it is not, and the
        # reason names the item
        data = json.loads((out / ("mesh.json" if number == "12" else "cloud.json")).read_text())
        assert not data["valid"] and ("'crate'" if number == "12" else "'scan'") in data["blocked"]
        assert rc.Planner(ROBOT, rc.Scene()).is_valid([0.0, 0.6, 1.8, 0.0, 0.0])
    else:
        raise AssertionError(f"example {number}: nothing checks what it does")


@pytest.mark.slow
def test_dict_plans_name_the_task_and_field_and_find_a_relative_robot(tmp_path, monkeypatch):
    """A plan given as a dict has no lines: its messages name the task and the field, never 'line 0' or ':1';
    a relative robot path starts at base_dir (default the current folder)."""
    corpus = Path(__file__).parent / "data" / "arms"
    plan = {"robot": "so100/robot.yaml", "start": [0, 1.5, -1.5, 0.5, 0], "tasks": [{"wait": {"seconds": 0.1}}]}
    traj = rc.plan(plan, base_dir=corpus).trajectory
    assert traj.robot == "so_arm100" and traj.robot_description is not None  # the description travels with it
    monkeypatch.chdir(corpus)
    assert rc.plan(plan).trajectory.duration == pytest.approx(0.1)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(rc.PlanFileError) as err:
        rc.plan(plan)
    assert err.value.message.startswith("<plan dict>: robot: no such description file 'so100/robot.yaml'")  # a path: not 'unknown robot'
    assert "base_dir" in err.value.hint
    for bad, needle in (({"move": {"xyz": [2.2, 0, 0.1]}}, "task 1 (move): target"),
                        ({"pick": {"object": "nope"}}, "task 1: pick.object: no object named 'nope'")):
        with pytest.raises(rc.RoarmError) as err:
            rc.plan({"robot": "roarm_m3_pro", "tasks": [bad]})
        assert needle in err.value.message and "line" not in err.value.message and ":0" not in err.value.message


def test_scene_mesh_from_triangles_and_a_cloud_block_what_a_box_there_blocks():
    """A mesh given as triangles (a 10 cm box's) and a cloud of points filling that box block the same pose as
    a box item of that size does (three shapes, one answer), and the free pose stays free."""
    import trimesh

    q = [0.0, 0.6, 1.8, 0.0, 0.0]
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    g = np.linspace(-0.045, 0.045, 10)
    cloud = np.array([(a, b, c) for a in g for b in g for c in g])
    for add in (lambda s: s.add_box("thing", (0.1, 0.1, 0.1), (0.3, 0.0, 0.0)),
                lambda s: s.add_mesh("thing", box.vertices, (0.3, 0.0, 0.0), faces=box.faces),
                lambda s: s.add_point_cloud("thing", cloud, 0.01, (0.3, 0.0, 0.0))):
        scene = rc.Scene()
        planner = rc.Planner(ROBOT, scene)
        assert planner.is_valid(q)
        add(scene)
        v = planner.is_valid(q)
        assert not v and "'thing'" in v.reason


@pytest.mark.parametrize("margin", [1.5, -0.01, True])
def test_singularity_margin_out_of_range_is_the_same_error_from_planner_and_plan_file(tmp_path, margin):
    """One bound, one check: api.Planner and a plan file (YAML and dict) refuse the same values with the same
    words after where they were given (the plan file's field is planner.singularity_margin)."""
    with pytest.raises(errors.InputError) as by_api:
        rc.Planner("roarm_m3_pro", singularity_margin=margin)
    path = tmp_path / "plan.yaml"
    path.write_text(f"robot: roarm_m3_pro\nplanner: {{singularity_margin: {str(margin).lower()}}}\ntasks:\n  - wait: 0.1\n")
    with pytest.raises(errors.PlanFileError) as by_file:
        load_plan(path)
    with pytest.raises(errors.PlanFileError) as by_dict:
        load_plan({"robot": "roarm_m3_pro", "planner": {"singularity_margin": margin}, "tasks": [{"wait": 0.1}]})
    said = by_api.value.message.removeprefix("Planner: ")
    assert said.startswith("singularity_margin: ") and "\n" not in said
    assert by_file.value.message.endswith(f": planner.{said}") and by_dict.value.message.endswith(f": planner.{said}")


def test_a_margin_a_larger_arm_can_keep_is_taken_by_both():
    """0.35 m/rad (above the plan file's old cap of 0.3) is a margin the UR10 keeps at some poses (its smallest
    translational singular value, by numpy SVD, is 0.409 at q below): the plan file takes it as the Planner does."""
    robot = rc.load_robot("ur10")
    q = np.array([-2.6, 2.1, 1.8, -1.6, 2.4, -2.8])
    assert np.linalg.svd(robot.kin.jacobian(q)[:3], compute_uv=False)[-1] > 0.35
    assert load_plan({"robot": "ur10", "planner": {"singularity_margin": 0.35},
                      "tasks": [{"wait": 0.1}]}).planner.singularity_margin == 0.35
    assert rc.Planner(robot, singularity_margin=0.35).is_valid(q)


@pytest.mark.parametrize("section, name, value", [
    ("limits", "velocity_scale", 0.005), ("limits", "velocity_scale", 1.5), ("limits", "acceleration_scale", 0.005),
    ("limits", "acceleration_scale", 0.0), ("planner", "padding", 0.2), ("planner", "padding", -0.001),
    ("limits", "max_tcp_speed", 6.0), ("limits", "max_tcp_speed", 0.0005)])
def test_scales_and_padding_out_of_range_are_the_same_error_from_planner_and_plan_file(tmp_path, section, name, value):
    """One bound per field (plan.fields.FIELD_BOUNDS), one check: api.Planner and a plan file (YAML and dict) refuse
    the same values with the same words after where they were given. The Planner took scales from 0.001 and a
    padding up to 0.1 m with its own words ("velocity_scale = 0.005 is outside ..."); a plan file took scales
    only above 0.01 and a padding up to 0.05 m."""
    with pytest.raises(errors.InputError) as by_api:
        rc.Planner("roarm_m3_pro", **{name: value})
    path = tmp_path / "plan.yaml"
    path.write_text(f"robot: roarm_m3_pro\n{section}: {{{name}: {value}}}\ntasks:\n  - wait: 0.1\n")
    with pytest.raises(errors.PlanFileError) as by_file:
        load_plan(path)
    with pytest.raises(errors.PlanFileError) as by_dict:
        load_plan({"robot": "roarm_m3_pro", section: {name: value}, "tasks": [{"wait": 0.1}]})
    said = by_api.value.message.removeprefix("Planner: ")
    assert said.startswith(f"{name}: {value:g} is too ") and "\n" not in said
    assert by_file.value.message.endswith(f": {section}.{said}") and by_dict.value.message.endswith(f": {section}.{said}")


@pytest.mark.parametrize("section, name, value", [("limits", "velocity_scale", 0.01), ("limits", "acceleration_scale", 1.0),
                                                  ("planner", "padding", 0.08), ("planner", "padding", 0.1),
                                                  ("limits", "max_tcp_speed", 0.001), ("limits", "max_tcp_speed", 5.0)])
def test_the_bounds_themselves_are_taken_by_both(section, name, value):
    """The ends of each range are inside it for both (a plan file refused a scale of 0.01, "must be > 0.01", and a
    padding above 0.05 m)."""
    plan = load_plan({"robot": "roarm_m3_pro", section: {name: value}, "tasks": [{"wait": 0.1}]})
    assert getattr(getattr(plan, section), name) == value
    planner = rc.Planner("roarm_m3_pro", **{name: value})
    assert getattr(planner._limits if section == "limits" else planner._config, name) == value


@pytest.mark.slow
def test_a_trajectory_file_records_a_margin_within_the_same_bound():
    """The trajectory validator took a recorded singularity margin up to 10 m/rad, which neither a plan file nor the
    Planner can give; it now checks FIELD_BOUNDS' 0 to 1 as they do (1 taken, 1.5 refused in one line)."""
    from viz_fixtures import pick_place_trajectory

    from roarmctl.motion.validate import parse_document

    for margin, ok in ((1.0, True), (1.5, False)):
        doc = pick_place_trajectory(min_singular_value=margin).to_dict()
        if ok:
            assert parse_document(doc).singularity_margin == {"min_singular_value": margin}
            continue
        with pytest.raises(errors.TrajectoryFileError) as ei:
            parse_document(doc)
        assert ei.value.message.endswith("singularity_margin.min_singular_value: 1.5 is too large (must be <= 1)")


def test_a_plan_with_a_larger_padding_gives_a_trajectory_that_reads_back():
    """The trajectory records its plan's padding and the validator checks it against the same bound: a plan with
    0.08 m (now taken) gives a trajectory that parses, padding and all (the validator capped it at 0.05)."""
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.motion.validate import parse_document

    doc = plan_file({"robot": "roarm_m3_pro", "planner": {"padding": 0.08}, "tasks": [{"wait": 0.1}]}).trajectory.to_dict()
    assert parse_document(doc).plan["padding"] == 0.08
