"""Bounded, validated plan files (issue 13, finding 3): every input of the issue's fuzz run that was
an internal error (exit 1) or a hang is now exit 2 with one line naming the file, the line and the
field; DH robots plan.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from roarmctl.cli import run as run_cli
from roarmctl.motion.validate import validate_trajectory
from roarmctl.robot.loader import bundled_dir

HEAD = "robot: roarm_m3_pro\n"




def plan_text(tmp_path: Path, text: str | bytes, capsys) -> tuple[int, str, Path]:
    p = tmp_path / "p.yaml"
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    out = tmp_path / "p.traj.json"
    rc = run_cli(["plan", str(p), "-o", str(out)])
    err = capsys.readouterr().err
    assert not out.exists() or rc == 0
    assert not list(tmp_path.glob(".*.tmp"))
    return rc, err, p


BAD = {
    "control character": (HEAD.encode() + b"tasks: [{wait: 1}]\nx: \x01\n", ":3:"),
    "recursive alias": (HEAD + "tasks: &a [*a]\n", ":2:"),
    "500-deep nesting": (HEAD + "tasks: " + "[" * 500 + "]" * 500 + "\n", "nested"),
    "unhashable key": (HEAD + "tasks: [{? [a, b] : 1}]\n", ":2: a key must be a plain name"),
    "float tag on text": (HEAD + "tasks: [{wait: !!float abc}]\n", ":2:"),
    "integer too large": (HEAD + "tasks: [{wait: " + "9" * 400 + "}]\n", ":2:"),
    "long robot name": ("robot: " + "r" * 300 + "\ntasks: [{wait: 1}]\n", ":1: robot: unknown robot"),
    "wait 1e300": (HEAD + "tasks: [{wait: 1.0e+300}]\n", ":2: task 1: wait"),
    "wait 1e8": (HEAD + "tasks: [{wait: 1.0e+8}]\n", ":2: task 1: wait"),
    "velocity_scale 1e-9": (HEAD + "limits: {velocity_scale: 1.0e-9}\ntasks: [{wait: 1}]\n", ":2: limits.velocity_scale"),
    "gripper_open 1e308": (HEAD + "objects: [{name: c, shape: box, size: [0.03, 0.03, 0.03], xyz: [0.2, 0, 0.015]}]\n"
                           "tasks: [{pick: {object: c, gripper_open: 1.0e+308}}]\n", ":3: task 1: pick.gripper_open"),
    "alias bomb": (HEAD + "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]\n"
                   + "".join(f"a{i}: &a{i} [{', '.join(['*a' + ('' if i == 1 else str(i - 1))] * 9)}]\n" for i in range(1, 9))
                   + "tasks: [{wait: 1}]\n", "more than 100000 values"),
    "a billion cycles": (HEAD + "cycles: 1000000000\ntasks: [{wait: 1}]\n", ":2: cycles"),
    "max_tcp_speed 1e-6": (HEAD + "limits: {max_tcp_speed: 1.0e-6}\ntasks: [{wait: 1}]\n", ":2: limits.max_tcp_speed"),
    "100k tasks": (HEAD + "tasks:\n" + "  - wait: 1\n" * 100_000, "more than the 1 MiB allowed"),
    "2000 tasks": (HEAD + "tasks:\n" + "  - wait: 1\n" * 2000, ":2: tasks: 2000 tasks are more than 1000"),
    "wait with an extra key": (HEAD + "tasks: [{wait: {seconds: 1, extra: 2}}]\n", ":2: task 1: wait.extra"),
    "start with two joints": (HEAD + "start: [0, 0]\ntasks: [{wait: 1}]\n", ":2: start: roarm_m3_pro takes 5"),
    "unknown robot": ("robot: roarm_m9\ntasks: [{wait: 1}]\n", ":1: robot: unknown robot 'roarm_m9'"),
    "too long in total": (HEAD + "cycles: 100\ntasks: [{wait: 40}]\n", ":2: cycles: the plan needs at least 4000 s"),
    "non-UTF-8": (HEAD.encode() + b"tasks: [{wait: 1}]  # caf\xe9\n", ":2: not UTF-8"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_plans_exit_2_naming_file_line_and_field(tmp_path, capsys, name):
    text, expected = BAD[name]
    rc, err, p = plan_text(tmp_path, text, capsys)
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith(f"error: {p}") and expected in err, err


def test_a_dh_robot_plans(tmp_path, capsys):
    # SCARA (DH table, no collision geometry): joints (0.3, 0.5) -> (0.9, 1.2) rad
    rc, err, _ = plan_text(tmp_path, "robot: scara_2r\nstart: [0.3, 0.5]\ntasks:\n  - move: {joints: [0.9, 1.2]}\n", capsys)
    assert rc == 0, err
    traj = validate_trajectory(tmp_path / "p.traj.json")
    assert np.allclose(traj.positions[0], [0.3, 0.5]) and np.allclose(traj.positions[-1], [0.9, 1.2], atol=1e-6)


def test_relative_robot_path_without_suffix_is_relative_to_the_plan(tmp_path, capsys, monkeypatch):
    (tmp_path / "robots").mkdir()
    shutil.copy(bundled_dir() / "scara_2r.yaml", tmp_path / "robots" / "myscara")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    rc, err, _ = plan_text(tmp_path, "robot: robots/myscara\nstart: [0.3, 0.5]\ntasks:\n  - move: {joints: [0.5, 0.2]}\n", capsys)
    assert rc == 0, err
    doc = json.loads((tmp_path / "p.traj.json").read_text())
    # the trajectory carries the description it was planned for (issue 19): the file beside the plan
    carried = yaml.safe_load(doc["robot_description"]["files"]["robot.yaml"])
    assert doc["robot"] == "scara_2r" and carried == yaml.safe_load((tmp_path / "robots" / "myscara").read_text())


def test_short_waits_are_sampled_at_the_declared_rate(tmp_path, capsys):
    # a 14 ms wait used to be one 14 ms step, longer than a sample at 100 Hz: execute refused the file
    rc, err, _ = plan_text(tmp_path, "robot: roarm_m3_pro\ntasks: [{wait: 0.014}, {wait: 0.5}]\n", capsys)
    assert rc == 0, err
    traj = validate_trajectory(tmp_path / "p.traj.json")
    assert traj.duration == pytest.approx(0.514) and np.diff(traj.times).max() <= 0.01 + 1e-9
