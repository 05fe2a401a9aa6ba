"""The one trajectory validator (issue 13, findings 1 and 5): nothing that breaks the robot's limits
or the file format reaches the port, the picture or an export.

Expected values are hand-derived from the M3 Pro description (elbow limits [0, 2.95] rad, velocity
limit 1.8 rad/s, acceleration 5 rad/s^2), not read back from the validator.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from devtraj import HOME, min_jerk

from roarmctl.cli import run as run_cli
from roarmctl.device.simulator import PtySimulator, SimConfig
from roarmctl.errors import TrajectoryFileError
from roarmctl.motion.validate import validate_trajectory
from roarmctl.robot.loader import load_robot

ROBOT = load_robot("roarm_m3_pro")
NAMES = list(ROBOT.joint_names)




def three_points() -> dict:
    """The issue's file: elbow 1.5708 -> -0.5 -> 1.5708 rad at 0, 0.5, 1 s (below its 0 rad limit)."""
    pts = []
    for t, e in ((0.0, 1.5708), (0.5, -0.5), (1.0, 1.5708)):
        pts.append({"time_from_start": t, "positions": [0.0, 0.0, e, 0.0, 0.0, 0.0]})
    return {"format": "roarmctl.trajectory/1", "robot": "roarm_m3_pro", "joint_names": NAMES,
            "sample_rate": 2, "points": pts}


def test_limit_breaking_file_sends_nothing_to_the_simulator(tmp_path, capsys):
    p = tmp_path / "bad.traj.json"
    p.write_text(json.dumps(three_points()))
    with PtySimulator(SimConfig(), process=True) as sim:
        rc = run_cli(["execute", str(p), "--port", sim.path, "--yes"])
        received = sim.received()
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1
    # point index, joint, value and limit
    assert "points[1]" in err and "link2_to_link3" in err and "-0.5000" in err and "[0.0000, 2.9500]" in err
    assert received == []  # the port was never even opened: not one byte
    assert not (tmp_path / "bad.exec.json").exists()


@pytest.mark.parametrize("edit,field,value", [
    ("positions", 2, -0.5),   # elbow below 0 rad
    ("positions", 2, 3.0),    # elbow above 2.95 rad
    ("positions", 0, 1.0),    # base jumps 1 rad (inside its limits) in one 10 ms sample
    ("velocities", 1, 1e6),   # velocities edited
])
def test_one_edited_point_of_a_valid_file_is_refused(tmp_path, capsys, edit, field, value):
    good = min_jerk([HOME, [0.8, 0.3, 1.9, -0.5, 0.3, 0.5]], [1.0])
    validate_trajectory(good, ROBOT)  # the unedited file passes
    doc = good.to_dict()
    doc["points"][50][edit][field] = value
    p = tmp_path / "edited.traj.json"
    p.write_text(json.dumps(doc))
    rc = run_cli(["execute", str(p), "--output", str(tmp_path / "cmds.jsonl")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert "points[50]" in err and NAMES[field] in err
    assert not (tmp_path / "cmds.jsonl").exists()


def test_step_inconsistent_with_velocities_names_the_step():
    # 0.02 rad in 10 ms at rest on both ends: A dt^2 / 2 = 5 * 1e-4 / 2 = 2.5e-4 rad allowed
    t = np.arange(5) * 0.01
    q = np.tile(HOME, (5, 1))
    q[3:, 0] += 0.02
    doc = {"format": "roarmctl.trajectory/1", "robot": "roarm_m3_pro", "joint_names": NAMES, "sample_rate": 100,
           "points": [{"time_from_start": float(a), "positions": list(b)} for a, b in zip(t, q)]}
    with pytest.raises(TrajectoryFileError, match=r"points\[3\]\.positions \(base_link_to_link1\).*\+0\.0200"):
        validate_trajectory(doc, ROBOT)
    q[3:, 0] = HOME[0] + 2e-4  # within the bound: accepted
    doc["points"] = [{"time_from_start": float(a), "positions": list(b)} for a, b in zip(t, q)]
    validate_trajectory(doc, ROBOT)


def _doc(**change) -> dict:
    d = min_jerk([HOME, [0.2, 0.1, 1.7, 0.0, 0.0, 0.0]], [0.3]).to_dict()
    d["scene"] = {"items": [{"name": "cube", "role": "object", "shape": "box", "size": [0.04, 0.04, 0.04],
                             "xyz": [0.2, 0, 0.02], "rpy": [0, 0, 0]}]}
    d["limits"] = {"velocity": [1.0] * 6, "acceleration": [2.0] * 6, "velocity_scale": 0.5}
    for path, value in change.items():
        node = d
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        last = keys[-1]
        if isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value
    return d


BAD_DOCS = {
    "sample_rate string": (_doc(sample_rate="fast"), "sample_rate"),
    "sample_rate zero": (_doc(sample_rate=0), "sample_rate"),
    "sample_rate negative": (_doc(sample_rate=-5), "sample_rate"),
    "limits list": (_doc(limits=[1, 2]), "limits"),
    "negative velocity limit": (_doc(limits={"velocity": [-1.0] * 6}), "limits.velocity[0]"),
    "null scene item": (_doc(scene={"items": [None]}), "scene.items[0]"),
    "huge size": (_doc(scene__items__0__size=[1e308, 1, 1]), "scene.items[0].size[0]"),
    "time as string": (_doc(points__3__time_from_start="0.03"), "points[3].time_from_start"),
    "first time not 0": (_doc(points__0__time_from_start=0.5), "points[0].time_from_start"),
    "segment start after end": (_doc(segments=[{"start": 0.2, "end": 0.1, "kind": "free"}]), "segments[0].end"),
    "event position NaN-like": (_doc(events=[{"time_from_start": 0.1, "kind": "grasp", "position": [0, "x", 0]}]), "events[0].position[1]"),
    "event outside": (_doc(events=[{"time_from_start": 9.0, "kind": "grasp"}]), "events[0].time_from_start"),
    "position as bool": (_doc(points__2__positions=[True, 0, 1.5708, 0, 0, 0]), "points[2].positions[0]"),
    "joint names wrong": (_doc(joint_names=["a", "b", "c", "d", "e", "f"]), "joint_names"),
    "huge int": (_doc(points__2__positions=[10 ** 400, 0, 1.5708, 0, 0, 0]), "points[2].positions[0]"),
}


@pytest.mark.parametrize("name", sorted(BAD_DOCS))
def test_malformed_documents_exit_2_naming_the_field(tmp_path, capsys, name):
    doc, field = BAD_DOCS[name]
    p = tmp_path / "t.traj.json"
    p.write_text(json.dumps(doc))
    rc = run_cli(["visualize-path", str(p), "-o", str(tmp_path / "t.png")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and field in err, err
    assert not (tmp_path / "t.png").exists()


@pytest.mark.parametrize("text,what", [
    ("[" * 100000 + "]" * 100000, "nested"),
    ('{"format": NaN}', "NaN"),
    (b"\xff\xfe{}", "UTF-8"),
])
def test_unreadable_json_is_exit_2(tmp_path, capsys, text, what):
    p = tmp_path / "t.traj.json"
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    rc = run_cli(["execute", str(p), "--output", str(tmp_path / "x.jsonl")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and what in err, err


def test_times_scaled_far_out_are_refused_without_allocating(tmp_path, capsys):
    doc = _doc()
    for pt in doc["points"]:
        pt["time_from_start"] *= 1e9
    doc["sample_rate"] = 1e-7
    p = tmp_path / "slow.traj.json"
    p.write_text(json.dumps(doc))
    rc = run_cli(["execute", str(p), "--output", str(tmp_path / "x.jsonl")])
    err = capsys.readouterr().err
    assert rc == 2 and ("time_from_start" in err or "sample_rate" in err)


def test_validator_accepts_the_planners_kind_of_output():
    # sampled at the declared rate, within limits, consistent steps: a hand-derived minimum-jerk move
    t = min_jerk([HOME, [-0.7, 0.3, 1.9, -0.6, 0.5, 0.3]], [1.3])
    out = validate_trajectory(t.to_dict(), "roarm_m3_pro")
    assert out.duration == pytest.approx(1.3) and math.isclose(out.sample_rate, 100.0)
