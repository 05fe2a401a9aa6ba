"""The Python API (roarmctl.api) and the example scripts in examples/, each run as a user would."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import roarmctl.api as rc

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("[0-9][0-9]_*.py"))

SHORT = {  # one free move and back: about 2 s of motion
    "robot": "roarm_m3_pro",
    "tasks": [{"move": {"joints": [0.4, 0.1, 1.4, 0.1, 0.0]}}, {"move": {"pose": "home"}}],
    "planner": {"seed": 3},
    "limits": {"blend": False},  # stop between the two moves (blended they take about 1 s)
}


@pytest.fixture(scope="module")
def short_traj(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("api") / "short.traj.json"
    rc.save_trajectory(rc.plan(SHORT).trajectory, p)
    return p


def test_plan_from_dict_equals_plan_from_the_same_yaml(tmp_path):
    f = tmp_path / "short.yaml"
    f.write_text(yaml.safe_dump(SHORT))
    a, b = rc.plan(SHORT).trajectory, rc.plan(f).trajectory
    assert np.array_equal(a.times, b.times) and np.array_equal(a.positions, b.positions)
    assert a.plan["path"] == "<plan dict>" and b.plan["path"] == str(f)


def test_plan_errors_are_typed_with_exit_codes():
    with pytest.raises(rc.PlanFileError) as e:
        rc.plan({"robot": "roarm_m3_pro", "tasks": [{"wait": 1}, {"pick": {"objectt": "cube"}}]})
    assert e.value.exit_code == 2 and "task 2: pick.objectt" in e.value.message
    far = dict(SHORT, tasks=[{"move": {"xyz": [0.9, 0.0, 0.1]}}])
    with pytest.raises(rc.InfeasibleError) as e:
        rc.plan(far)
    assert e.value.exit_code == 3 and e.value.partial.target == [0.9, 0.0, 0.1]


def test_sample_save_load_and_joint_trajectory_dict(short_traj, tmp_path):
    traj = rc.load_trajectory(short_traj)
    # sampling at the sample times returns the samples; a scalar gives one vector
    assert np.allclose(rc.sample(traj, traj.times[::7]), traj.positions[::7], atol=1e-12)
    assert rc.sample(traj, 0.0).shape == (len(traj.joint_names),)
    assert np.allclose(rc.sample(traj, 1e6), traj.positions[-1])  # clamped to the end
    # a midpoint lies within the step the velocities allow (|q(t+h/2) - q(t)| <= vmax h/2 + tiny)
    mid = rc.sample(traj, 0.5 * (traj.times[:-1] + traj.times[1:]))
    step = np.abs(mid - traj.positions[:-1])
    assert np.all(step <= np.abs(traj.velocities).max(axis=0) * 0.006 + 1e-6)
    again = rc.load_trajectory(rc.save_trajectory(traj, tmp_path / "again.traj.json"))
    assert np.allclose(again.positions, traj.positions, atol=1e-9)
    msg = json.loads(json.dumps(rc.to_joint_trajectory(traj, frame_id="base_link")))
    assert msg["joint_names"] == traj.joint_names and msg["header"]["frame_id"] == "base_link"
    assert len(msg["points"]) == len(traj.times)
    t = [p["time_from_start"]["sec"] + p["time_from_start"]["nanosec"] * 1e-9 for p in msg["points"]]
    assert np.allclose(t, traj.times, atol=1e-9)
    assert np.allclose([p["accelerations"] for p in msg["points"]], traj.accelerations)


def test_draw_and_export_refuse_unknown_extensions_before_work(short_traj, tmp_path):
    with pytest.raises(rc.InputError):
        rc.draw(short_traj, tmp_path / "x.gif")
    with pytest.raises(rc.InputError):
        rc.export(short_traj, tmp_path / "x.txt")
    assert list(tmp_path.iterdir()) == []


def test_examples_are_numbered_one_concept_each():
    names = [p.name[:2] for p in EXAMPLES]
    assert names == [f"{i:02d}" for i in range(1, len(EXAMPLES) + 1)] and len(EXAMPLES) >= 4


def run_script(script: Path, args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``python SCRIPT ARGS`` in ``cwd``, run in this process as ``__main__`` (runpy) with its own ``sys.argv``:
    an example's point is what it does with the API, not the interpreter's start-up (about a second of imports per
    example). Exit code, stdout and stderr as a shell sees them."""
    import contextlib
    import io
    import runpy

    out, err, argv = io.StringIO(), io.StringIO(), sys.argv
    code: int | str | None = 0
    try:
        sys.argv = [str(script), *args]
        with contextlib.chdir(cwd), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                runpy.run_path(str(script), run_name="__main__")
            except SystemExit as exc:
                code = exc.code
    finally:
        sys.argv = argv
    if isinstance(code, str):
        err.write(code + "\n")
    return subprocess.CompletedProcess([str(script), *args], code if isinstance(code, int) else int(code is not None),
                                       out.getvalue(), err.getvalue())


@pytest.mark.slow  # the examples plan, execute, export
@pytest.mark.parametrize("script", EXAMPLES, ids=lambda p: p.name)
def test_example_runs(script, short_traj, tmp_path, request):
    """Every example runs as `python examples/NN_x.py`, on the short trajectory where it takes one. 03's
    ``rc.execute(sim=True)`` runs on the virtual clock (``virtual_sim``): in real time a loaded machine made the
    streamer lower its rate, and the run sent 48 commands where the check asks for more than 50 (the real-time run of
    the same library entry is tests/device/test_execute.py's)."""
    if script.name.startswith("03"):
        request.getfixturevalue("virtual_sim")
    args = {"01": [str(tmp_path)], "02": [str(short_traj)], "03": [str(short_traj), str(tmp_path / "run.exec.json")],
            "04": [str(short_traj), str(tmp_path)]}.get(script.name[:2], [str(tmp_path)])
    r = run_script(script, args, tmp_path)
    assert r.returncode == 0, r.stderr
    if script.name.startswith("01"):
        traj = rc.load_trajectory(tmp_path / "from_dict.traj.json")
        assert [e.kind for e in traj.events] == ["grasp", "release"]
    elif script.name.startswith("03"):
        assert r.stdout.startswith("completed")
        log = json.loads((tmp_path / "run.exec.json").read_text())
        assert log["summary"]["outcome"] == "completed" and log["summary"]["commands"] > 50
    elif script.name.startswith("04"):
        from rosbags.rosbag2 import Reader

        with Reader(tmp_path / "pick_place.mcap") as reader:
            assert reader.topics["/joint_states"].msgcount == len(json.loads(short_traj.read_text())["points"])
        assert (tmp_path / "pick_place_bag" / "metadata.yaml").is_file()
        assert (tmp_path / "pick_place.svg").read_bytes().startswith(b"<?xml")
    elif script.name[:2] not in ("02",):  # 02 prints what it reads: its exit code is the check
        from test_api_planner import check_example

        check_example(script.name[:2], tmp_path)
