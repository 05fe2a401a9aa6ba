"""The plan file: every mistake of form names the file, the line and the field, and exits 2."""

import math
from pathlib import Path

import numpy as np
import pytest
from clirun import roarmctl

from roarmctl.errors import PlanFileError
from roarmctl.plan.schema import load_plan
from roarmctl.plan.types import PickTask, PlaceTask

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "plans" / "pick_place.yaml"


def _variant(tmp_path: Path, old: str, new: str) -> Path:
    text = EXAMPLE.read_text()
    assert old in text, old
    path = tmp_path / "plan.yaml"
    path.write_text(text.replace(old, new, 1))
    return path


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_example_plan_reads_with_units_converted():
    plan = load_plan(EXAMPLE)
    pick, place = plan.tasks[0], plan.tasks[1]
    assert isinstance(pick, PickTask) and isinstance(place, PlaceTask)
    assert pick.pitch == pytest.approx(math.pi / 2)  # {deg: 90}
    assert pick.object == "cube" and pick.gripper_closed == 0.6
    assert np.allclose(place.xyz, [0.25, 0.15, 0.02])
    cube = plan.objects[0]
    assert cube.size == (0.04, 0.04, 0.04) and np.allclose(cube.pose[:3, 3], [0.25, -0.15, 0.02])
    assert plan.scene[0].role == "table"
    assert len(plan.sha256) == 64


CASES = [
    # (old text, new text, line marker, expected fragments)
    ("approach_height: 0.06, pitch: {deg: 90}, gripper_open: 1.0, gripper_closed",
     "aproach_height: 0.06, pitch: {deg: 90}, gripper_open: 1.0, gripper_closed",
     "aproach_height", ["task 1: pick.aproach_height", "unknown key", "did you mean 'approach_height'"]),
    ("{object: cube, approach", "{object: cub, approach", "object: cub,", ["task 1: pick.object", "no object named 'cub'"]),
    ("velocity_scale: 0.6", "velocity_scale: 1.6", "velocity_scale", ["limits.velocity_scale", "too large"]),
    ("name: RRTConnect", "name: RRTconnect", "RRTconnect", ["planner.name", "did you mean 'RRTConnect'"]),
    ("size: [0.04, 0.04, 0.04]", "size: [0.04, 0.04]", "size: [0.04, 0.04]", ["objects[0].size", "list of 3 numbers"]),
    ("xyz: [0.25, 0.15, 0.02]", "xyz: [0.25, 0.15, high]", "high", ["task 2: place.xyz[2]", "expected a number"]),
    ("{pose: home,", "{pose: hom,", "pose: hom", ["task 3: move.pose", "did you mean 'home'"]),
    ("  - move:  {pose: home,", "  - mvoe:  {pose: home,", "mvoe", ["unknown task 'mvoe'", "did you mean 'move'"]),
    ("seed: 1", "seed: -1", "seed: -1", ["planner.seed", "whole number"]),
    ("shape: box, size: [0.04", "shape: cube, size: [0.04", "shape: cube", ["objects[0].shape", "'cube' is not one of"]),
]


@pytest.mark.parametrize("old,new,marker,fragments", CASES)
def test_schema_errors_name_file_line_and_field(tmp_path, old, new, marker, fragments):
    path = _variant(tmp_path, old, new)
    with pytest.raises(PlanFileError) as info:
        load_plan(path, named_poses=["home", "ready", "observe"])
    msg = str(info.value)
    assert msg.startswith(f"{path}:{_line_of(path, marker)}:"), msg
    for fragment in fragments:
        assert fragment in msg, msg


def test_yaml_syntax_error_has_a_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("robot: roarm_m3_pro\ntasks:\n  - pick: {object: cube\n")
    with pytest.raises(PlanFileError) as info:
        load_plan(path)
    assert f"{path}:" in str(info.value) and "not valid YAML" in str(info.value)


def test_missing_file_and_missing_tasks(tmp_path):
    with pytest.raises(PlanFileError, match="no such file"):
        load_plan(tmp_path / "nope.yaml")
    path = tmp_path / "p.yaml"
    path.write_text("robot: roarm_m3_pro\n")
    with pytest.raises(PlanFileError, match="'tasks' is missing"):
        load_plan(path)


def test_cli_reports_one_line_and_exit_2_without_traceback(tmp_path):
    path = _variant(tmp_path, "velocity_scale: 0.6", "velocity_scal: 0.6")
    out = tmp_path / "out.traj.json"
    proc = roarmctl("plan", str(path), "-o", str(out))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "limits.velocity_scal" in lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_yaml_merge_keys_and_x_anchors(tmp_path):
    """`<<: *name` merges a mapping (keys written beside it win); top-level `x-` keys hold anchors."""
    p = tmp_path / "merge.yaml"
    p.write_text(
        "robot: roarm_m3_pro\n"
        "x-grip: &grip {approach_height: 0.05, pitch: {deg: 80}, gripper_open: 1.1}\n"
        "objects:\n"
        "  - {name: cube, shape: box, size: [0.04, 0.04, 0.04], xyz: [0.25, -0.15, 0.02]}\n"
        "tasks:\n"
        "  - pick: {<<: *grip, object: cube}\n"
        "  - place: {<<: *grip, xyz: [0.25, 0.15, 0.02], approach_height: 0.07}\n")
    pick, place = load_plan(p).tasks
    assert pick.approach_height == 0.05 and pick.gripper_open == 1.1 and pick.pitch == pytest.approx(math.radians(80))
    assert place.approach_height == 0.07 and place.gripper_open == 1.1  # the explicit key overrides the merge
    p.write_text(p.read_text().replace("gripper_open: 1.1}", "gripper_opn: 1.1}"))
    with pytest.raises(PlanFileError, match=r"merge.yaml:2: task 1: pick.gripper_opn: unknown key"):
        load_plan(p)


def test_plan_from_a_dict_names_the_task_from_1():
    d = {"robot": "roarm_m3_pro", "tasks": [{"wait": 0.5}, {"move": {"pose": "home", "xyz": [0, 0, 0]}}]}
    with pytest.raises(PlanFileError, match=r"^<plan dict>: task 2: move: give exactly one"):
        load_plan(d)
    assert load_plan({"robot": "roarm_m3_pro", "tasks": [{"wait": 0.5}]}).tasks[0].seconds == 0.5


def test_a_plan_dicts_digest_is_its_located_json_and_an_odd_key_is_named():
    """The digest of a plan dict (the trajectory's provenance) is the sha256 of its JSON with numpy values as lists and
    numbers, as before; a key that JSON cannot sort beside the names is a plan error naming it, not a TypeError."""
    import hashlib
    import json

    from roarmctl.validation import locate

    d = {"robot": "roarm_m3_pro", "start": np.zeros(6), "tasks": [{"wait": np.float32(0.5)}, {"wait": np.int64(1)}],
         "planner": {"seed": 3, "padding": np.float64(0.004)}, "x-notes": (1, np.bool_(True), {2, 3})}
    expected = hashlib.sha256(json.dumps(locate(d), sort_keys=True, default=str).encode()).hexdigest()
    assert load_plan(d).sha256 == expected
    with pytest.raises(PlanFileError, match=r"^<plan dict>: 5: unknown key"):
        load_plan({"robot": "roarm_m3_pro", "tasks": [{"wait": 1}], 5: 1})


def test_plain_primitives_read_at_once_give_the_spec_the_full_reader_gives():
    """The quick reading of plain boxes, cylinders and spheres (most of a big scene) gives the same spec, field for
    field, as the field-by-field reader; whatever that reader refuses, or anything else, the quick one leaves to it."""
    import dataclasses
    import itertools

    from roarmctl.plan import items as plan_items
    from roarmctl.plan.fields import ReadContext
    from roarmctl.validation import locate

    ctx = ReadContext(Path("plans") / "x.yaml")
    items = []
    for xyz, rpy in itertools.product(([0.1, -0.2, 0.3], [1, 0, 2], [0, 0, 10.5], [0.1, 0.2], [0.1, True, 0.2],
                                       {"world": [0.1, 0.2, 0.3]}, [float("nan"), 0, 0]),
                                      (None, [0, 0, 0], [0.1, -0.0, 3], [0, 0, 20], {"deg": [0, 0, 90]})):
        for body in ({"shape": "box", "size": [0.02, 0.02, 0.04]}, {"shape": "box", "size": [0, 1, 1]},
                     {"shape": "box", "size": [1, 2, 3]}, {"shape": "box"}, {"shape": "cylinder", "radius": 0.01, "length": 1},
                     {"shape": "cylinder", "radius": 0.01}, {"shape": "sphere", "radius": 2}, {"shape": "sphere", "radius": 11},
                     {"shape": "sphere", "radius": 0.1, "mass": 1}, {"shape": "capsule", "radius": 0.1},
                     {"shape": "box", "size": [0.1, 0.1, 0.1], "colour": 1}):
            item = dict(body, name="it", xyz=xyz)
            if rpy is not None:
                item["rpy"] = rpy
            items.append(item)
    quick = 0
    for raw, role in itertools.product(items, ("obstacle", "table", "object")):
        located = locate(raw)
        fast = plan_items._plain_primitive(ctx, located, "scene.obstacles[0]", role)
        try:
            slow = plan_items._item_spec(ctx, located, 0, "scene.obstacles[0]", role)
        except PlanFileError:
            assert fast is None, raw
            continue
        if fast is None:
            continue
        quick += 1
        for f in dataclasses.fields(slow):
            a, b = getattr(fast, f.name), getattr(slow, f.name)
            assert type(a) is type(b) and (np.array_equal(a, b) if isinstance(a, np.ndarray) else a == b), (raw, f.name)
        assert fast.pose.tobytes() == slow.pose.tobytes() and [type(v) for v in fast.size] == [type(v) for v in slow.size]
    assert quick >= 40  # the quick reading did take the plain ones (48 of these)
    # all of them in one list (as a plan's obstacles are read): each gets what it got alone, in its place
    for role in ("obstacle", "table"):
        located = [locate(raw) for raw in items]
        wheres = [f"scene.obstacles[{i}]" for i in range(len(items))]
        together = plan_items._plain_primitives(ctx, located, role, wheres)
        alone = [plan_items._plain_primitive(ctx, raw, where, role) for raw, where in zip(located, wheres)]
        assert [a is None for a in together] == [a is None for a in alone]
        for a, b in zip(together, alone):
            if a is not None:
                assert a.where == b.where and a.pose.tobytes() == b.pose.tobytes() and a.size == b.size
                assert (a.name, a.shape, a.radius, a.length, a.line) == (b.name, b.shape, b.radius, b.length, b.line)


def test_a_plan_dicts_obstacles_read_as_they_are_give_the_files_specs(tmp_path):
    """A plan dict's obstacles are read without a located copy of each: the specs are those of the same plan read from
    its YAML text (field for field but the line), plain primitives or not (numpy numbers, tuples, a mesh); the second
    reading (with the robot's poses) takes the first one's specs; a bad field is still named."""
    import dataclasses

    import yaml

    from roarmctl.plan import items
    from roarmctl.plan.fields import ReadContext

    (tmp_path / "tri.stl").write_text("solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.01 0 0\n"
                                      "vertex 0 0.01 0\nendloop\nendfacet\nendsolid t\n")
    obstacles = [{"name": f"b{i}", "shape": "box", "size": [0.02, 0.02, 0.04], "xyz": [0.5 + i * 0.01, -0.3, 0.02]}
                 for i in range(30)]
    obstacles += [{"name": "turned", "shape": "cylinder", "radius": 0.01, "length": 0.1, "xyz": [0.4, 0.3, 0.05],
                   "rpy": [0.1, 0.2, 0.3]},
                  {"name": "ball", "shape": "sphere", "radius": 0.02, "xyz": [-0.3, 0.3, 0.02]},
                  {"name": "deg", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [-0.3, -0.3, 0.05], "rpy": {"deg": [0, 0, 45]}},
                  {"name": "mesh", "shape": "mesh", "file": "tri.stl", "xyz": [-0.3, 0.0, 0.0]}]
    d = {"robot": "roarm_m3_pro", "scene": {"obstacles": obstacles}, "tasks": [{"wait": 1.0}]}
    (tmp_path / "p.yaml").write_text(yaml.safe_dump(d))
    as_code = dict(d, scene={"obstacles": [dict(o) for o in obstacles]})
    as_code["scene"]["obstacles"][3] = dict(obstacles[3], xyz=np.array(obstacles[3]["xyz"]))  # numpy: read field by field
    as_code["scene"]["obstacles"][4] = dict(obstacles[4], size=tuple(obstacles[4]["size"]))
    from_file = load_plan(tmp_path / "p.yaml")
    from_dict = load_plan(as_code, base_dir=tmp_path)
    assert len(from_dict.scene) == len(from_file.scene) == len(obstacles)
    for a, b in zip(from_dict.scene, from_file.scene):
        for f in dataclasses.fields(a):
            if f.name in ("line", "where"):
                continue
            x, y = getattr(a, f.name), getattr(b, f.name)
            assert type(x) is type(y) and (x.tobytes() == y.tobytes() if isinstance(x, np.ndarray) else x == y), (a.name, f.name)
        assert a.line == 0 and a.where.startswith("<plan dict>: scene.obstacles[")
    again = load_plan(as_code, base_dir=tmp_path, parsed=from_dict, named_poses=["home"])
    assert all(x is y for x, y in zip(again.scene, from_dict.scene))
    assert type(as_code["scene"]["obstacles"][33]) is dict  # the caller's dicts are left as they were
    bad = dict(as_code, scene={"obstacles": [*obstacles[:20], dict(obstacles[20], size=[0.02, -1, 0.04]), *obstacles[21:]]})
    with pytest.raises(PlanFileError, match=r"^<plan dict>: scene\.obstacles\[20\]\.size\[1\]: "):
        load_plan(bad, base_dir=tmp_path)
    assert items._plain_primitives(ReadContext(tmp_path / "p.yaml"), obstacles[:3], "obstacle", ["a", "b", "c"])[2].size == (0.02, 0.02, 0.04)


def test_angles_in_degrees_are_bounded_as_angles():
    """``rpy: {deg: [...]}`` is turned to radians before its bounds are checked (45 deg was refused as "45 is too large
    (must be <= 12.5664)"): the pose is the one of the same angle in radians; an angle beyond the bound is named."""
    from roarmctl.robot.model import transform

    def plan(rpy):
        return {"robot": "roarm_m3_pro", "tasks": [{"wait": 1.0}],
                "scene": {"obstacles": [{"name": "w", "shape": "box", "size": [0.1, 0.1, 0.1], "xyz": [0.3, 0, 0.05], "rpy": rpy}]}}

    pose = load_plan(plan({"deg": [10, -30, 45]})).scene[0].pose
    np.testing.assert_allclose(pose, transform([0.3, 0, 0.05], np.radians([10, -30, 45])), atol=1e-15)
    assert load_plan({"robot": "roarm_m3_pro", "start": {"deg": [0, 0, 90, 0, 0, 0]}, "tasks": [{"wait": 1}]}).start[2] == math.pi / 2
    with pytest.raises(PlanFileError, match=r"scene\.obstacles\[0\]\.rpy\[2\]: .* too large"):
        load_plan(plan({"deg": [0, 0, 800]}))
    with pytest.raises(PlanFileError, match=r"scene\.obstacles\[0\]\.rpy: expected a list of 3 numbers of degrees"):
        load_plan(plan({"deg": [0, 0]}))


def test_a_datagen_template_given_to_plan_names_the_command_that_reads_it():
    """plans/datagen/pick_place.yaml is a plan file plus a datagen: block: plan refuses it (exit 2) naming its line and
    `roarmctl datagen`, not as a typo among the plan's keys."""
    from roarmctl.errors import PlanFileError
    from roarmctl.plan.schema import load_plan

    template = Path(__file__).resolve().parents[1] / "plans" / "datagen" / "pick_place.yaml"
    line = next(i for i, text in enumerate(template.read_text().splitlines(), 1) if text.startswith("datagen:"))
    with pytest.raises(PlanFileError) as exc:
        load_plan(template)
    assert f"pick_place.yaml:{line}: datagen: this is a datagen template" in str(exc.value)
    assert "roarmctl datagen" in (exc.value.hint or "")
    assert exc.value.exit_code == 2


@pytest.mark.parametrize("plan", ["pick_place.yaml", "multi_object.yaml"])
def test_a_plan_and_its_robot_are_read_once(plan, monkeypatch):
    """``load_plan_and_robot`` (what planning, teach and follow start from) reads the file once and checks each task and
    item once, against the robot's poses and frames: counted by wrapping the reader's functions; the same Plan as
    ``load_plan`` given the robot's poses and frames."""
    import roarmctl.plan.schema as schema
    from roarmctl.motion.pipeline import load_plan_and_robot

    counts = {"yaml": 0, "task": 0, "item": 0}

    def counted(name, real):
        def wrapper(*args, **kwargs):
            counts[name] += 1
            return real(*args, **kwargs)
        return wrapper

    monkeypatch.setattr(schema, "load_yaml", counted("yaml", schema.load_yaml))
    monkeypatch.setattr(schema, "read_task", counted("task", schema.read_task))
    monkeypatch.setattr(schema, "read_item", counted("item", schema.read_item))
    got, robot = load_plan_and_robot(ROOT / "plans" / plan)
    assert counts["yaml"] == 1 and counts["task"] == len(got.tasks) and counts["item"] == len(got.objects) + 1  # + the table
    monkeypatch.undo()
    ref = load_plan(ROOT / "plans" / plan, list(robot.named_poses), frames=robot.frames)
    assert [type(t) for t in got.tasks] == [type(t) for t in ref.tasks] and got.sha256 == ref.sha256
    assert [(s.name, s.role, s.shape) for s in got.scene + got.objects] == [(s.name, s.role, s.shape) for s in ref.scene + ref.objects]
    assert all(np.array_equal(a.pose, b.pose) for a, b in zip(got.scene + got.objects, ref.scene + ref.objects))
