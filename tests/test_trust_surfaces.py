"""Trust no file, part 3 (issue 40), beyond xacro: a payload on a link the robot lacks, scene meshes of many
pieces, stale temporaries of a killed write, a tiny --speed-scale in physics, huge coordinates, terminal
sequences in names. The xacro cases are tests/test_trust_xacro.py, the view server's tests/test_view_server.py."""

from __future__ import annotations

import json
from pathlib import Path

import hostile
import pytest
from test_trust import cli, refused

#: Every command that reads a trajectory, with its output (``{d}``: the test's folder).
TRAJECTORY_COMMANDS = {
    "simulate": ["simulate", "{f}"],
    "execute --sim": ["execute", "{f}", "--sim"],
    "execute --output": ["execute", "{f}", "--output", "{d}/out.jsonl"],
    "export mcap": ["export", "{f}", "-o", "{d}/out.mcap"],
    "export csv": ["export", "{f}", "-o", "{d}/out.csv"],
    "export bag": ["export", "{f}", "-o", "{d}/out_bag"],
    "visualize-path": ["visualize-path", "{f}", "-o", "{d}/out.png"],
    "visualize-path html": ["visualize-path", "{f}", "-o", "{d}/out.html"],
}


def foreign_payload(link: str) -> dict:
    """The hostile trajectory with a held object's payload on ``link``."""
    doc = hostile.trajectory_doc()
    doc["payloads"] = [{"start": 0.1, "end": 0.5, "link": link, "mass": 0.05, "com": [0, 0, 0],
                        "inertia": [[1e-5, 0, 0], [0, 1e-5, 0], [0, 0, 1e-5]]}]
    return doc


@pytest.mark.parametrize("command", list(TRAJECTORY_COMMANDS))
@pytest.mark.parametrize("link", ["no_such_link", "wrist_link_of_another_arm", "", "base_link\x1b]0;pwned\x07"])
def test_a_payload_on_a_link_the_robot_lacks_is_refused_by_every_command(tmp_path, command, link):
    """One validator (motion/validate.py) refuses it for every command: exit 2, one line naming the field
    (before: simulate exit 1 on a KeyError, execute --sim 130 with the simulator's traceback, export and
    execute --output wrote it)."""
    f = tmp_path / "t.traj.json"
    f.write_text(json.dumps(foreign_payload(link)))
    args = [a.format(f=f, d=tmp_path) for a in TRAJECTORY_COMMANDS[command]]
    err = refused(args, "payloads[0].link")
    assert "\x1b" not in err and "\x07" not in err
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("out")], "an output was written"


def test_a_payload_on_one_of_the_robot_s_links_is_taken(tmp_path):
    """The control: the same trajectory with the payload on the M3's gripper link exports."""
    from roarmctl.robot.loader import load_robot

    f = tmp_path / "t.traj.json"
    f.write_text(json.dumps(foreign_payload(load_robot("roarm_m3_pro").tcp_link)))

    code, _, err = cli(["export", str(f), "-o", str(tmp_path / "out.csv")])
    assert code == 0 and (tmp_path / "out.csv").exists(), err


# --------------------------------------------------------------------------- scene meshes of many pieces
def _separate_triangles(n: int, seed: int = 0):
    import numpy as np

    rng = np.random.default_rng(seed)
    tri = rng.uniform(-0.5, 0.5, (n, 1, 3)) + np.array([[0, 0, 0], [0.001, 0, 0], [0, 0.001, 0]])
    return tri.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3)


def test_a_mesh_of_many_separate_triangles_is_refused_before_trimesh_splits_it(monkeypatch):
    """The part count comes first, by a linear method: trimesh's merge and split (a mesh made per part: minutes
    for a million) never run on a mesh that has too many parts. bench/bench_mesh_parts.py has the times."""
    import trimesh

    from roarmctl.errors import InputError
    from roarmctl.motion.scenefiles import MAX_PIECES, mesh_data

    def never(*a, **k):
        raise AssertionError("trimesh split the mesh before its parts were counted")

    monkeypatch.setattr(trimesh.Trimesh, "split", never)
    monkeypatch.setattr(trimesh.Trimesh, "merge_vertices", never)
    v, f = _separate_triangles(5000)
    with pytest.raises(InputError, match=f"5000 separate parts or more, more than {MAX_PIECES}"):
        mesh_data(v, f, False, "m.stl", "scene.items[0]")


@pytest.mark.parametrize("seed", range(6))
def test_the_part_count_is_never_more_than_trimesh_s(seed):
    """Differential, over generated meshes: boxes (as an STL stores them: each triangle's vertices apart), single
    triangles, pairs touching at one vertex (one part here, two for trimesh, which joins by edges) and copies of
    one box on top of each other (one part): the count is at most trimesh's split, and equal where no two parts
    share a vertex."""
    import numpy as np
    import trimesh

    from roarmctl.motion.scenefiles import fewest_parts

    rng = np.random.default_rng(seed)
    meshes, touching = [], 0
    for k in range(int(rng.integers(1, 40))):
        at = np.array([k * 0.1, rng.uniform(-1, 1), 0.0])
        kind = int(rng.integers(0, 3))
        if kind == 0:
            box = trimesh.creation.box(rng.uniform(0.01, 0.05, 3))
            meshes.append(box.vertices[box.faces].reshape(-1, 3) + at)
        elif kind == 1:
            meshes.append(_separate_triangles(1, k)[0] * 0.01 + at)
        else:  # two triangles that share only their first vertex
            a = np.array([[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]])
            meshes.append(np.vstack([a, a * [-1, -1, 1]]) + at)
            touching += 1
    v = np.vstack(meshes)
    f = np.arange(len(v)).reshape(-1, 3)
    whole = trimesh.Trimesh(v, f, process=False)
    whole.merge_vertices()
    split = len(whole.split(only_watertight=False))
    assert fewest_parts(v, f) == split - touching


# --------------------------------------------------------------------------- leftovers of a killed write
_KILLED_WRITE = """
import os, signal, sys
from pathlib import Path
from roarmctl import fileio
folder = Path(sys.argv[1])
def writer(f):
    f.write(b"half of a trajectory")
    f.flush()
    os.kill(os.getpid(), signal.SIGKILL)
if sys.argv[2] == "file":
    fileio.atomic_write_with(folder / "out.traj.json", writer)
else:
    tmp = fileio.new_folder_beside(folder / "out_bag")
    (tmp / "out_bag_0.mcap").write_bytes(b"half of a bag")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def _killed_write(folder: Path, kind: str) -> int:
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, "-c", _KILLED_WRITE, str(folder), kind], capture_output=True)
    assert proc.returncode == -9, proc.stderr
    return proc.returncode


def test_a_later_run_removes_the_temporaries_of_a_killed_write_and_nothing_else(tmp_path):
    """SIGKILL during an atomic write and during a bag's folder: the hidden temporaries stay (nothing can run
    on SIGKILL); the next roarmctl that writes into the folder removes them - by their name, which only roarmctl
    makes, and only when their process is gone - and leaves every other file, however alike."""
    import os
    import subprocess
    import sys

    out = tmp_path / "outputs"
    out.mkdir()
    _killed_write(out, "file")
    left = [p.name for p in out.iterdir()]
    assert len(left) == 1 and left[0].startswith(".out.traj.json.roarmctl-") and left[0].endswith(".tmp"), left
    _killed_write(out, "folder")  # a later write: the killed file's temporary is removed, its own folder stays
    left = [p.name for p in out.iterdir()]
    assert len(left) == 1 and left[0].startswith(".out_bag.roarmctl-") and (out / left[0]).is_dir(), left
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    user = {".notes.txt.abcd1234.tmp": "file", ".out.traj.json.x1y2z3w4.tmp": "file",  # tempfile's old names: not ours
            f".mine.roarmctl-{os.getpid()}-abcdefgh.tmp": "file",  # a process that runs (this one)
            f".dir.roarmctl-{dead_pid}-abcdefgh.tmp": "folder",  # a folder where we write files
            f".file.roarmctl-{dead_pid}-abcdefgh": "file",  # a file where we make folders
            f".link.roarmctl-{dead_pid}-abcdefgh": "link",  # a symlink: never followed
            "out.traj.json.tmp": "file", "keep": "folder"}
    target = tmp_path / "users_folder"
    target.mkdir()
    (target / "precious.txt").write_text("the user's")
    for name, kind in user.items():
        if kind == "file":
            (out / name).write_text("the user's")
        elif kind == "folder":
            (out / name).mkdir()
            (out / name / "inside.txt").write_text("the user's")
        else:
            (out / name).symlink_to(target)
    code, _, err = cli(["export", str(_traj(tmp_path)), "-o", str(out / "new.csv")])
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == sorted([*user, "new.csv"])
    assert (target / "precious.txt").read_text() == "the user's"
    assert all((out / n / "inside.txt").exists() for n, k in user.items() if k == "folder")


def _traj(folder: Path) -> Path:
    f = folder / "t.traj.json"
    f.write_text(json.dumps(hostile.trajectory_doc()))
    return f


# --------------------------------------------------------------------------- huge coordinates
def _plan_with(folder: Path, item: dict) -> Path:
    import yaml

    plan = yaml.safe_load((Path(__file__).parents[1] / "plans" / "obstacle.yaml").read_text())
    plan["scene"]["obstacles"] = [item]
    path = folder / "p.yaml"
    path.write_text(yaml.safe_dump(plan))
    return path


@pytest.mark.slow
@pytest.mark.parametrize("case", ["cloud 1e30", "cloud 1e308", "stl 1e38", "stl 1e30 scaled", "obj 1e300"])
def test_huge_coordinates_are_one_error_line_without_numpy_warnings(tmp_path, case):
    """A cloud or a mesh with coordinates near float32's or float64's end: exit 2 and the one error line, no
    RuntimeWarning of numpy before it. In this process (``clirun.roarmctl``; a fresh interpreter per case cost ~1 s of
    CPU): every warning raised during the command is recorded (filter "always", so none is swallowed as already
    shown), which is stricter than reading a fresh process's stderr, where a filter of the CLI could hide one."""
    import warnings

    import numpy as np
    import trimesh
    from clirun import roarmctl

    if case.startswith("cloud"):
        big = float(case.split()[1])
        np.save(tmp_path / "c.npy", np.array([[big, 0.0, 0.0], [0.0, -big, 0.0], [0.1, 0.1, 0.1]]))
        item = {"name": "w", "shape": "cloud", "file": "c.npy", "resolution": 0.0001, "xyz": [0, 0, 0]}
    else:
        kind, big = case.split()[0], float(case.split()[1])
        box = trimesh.creation.box((1.0, 1.0, 1.0))
        box.vertices *= big
        (tmp_path / f"m.{kind}").write_bytes(box.export(file_type=kind) if kind == "stl" else box.export(file_type=kind).encode())
        item = {"name": "w", "shape": "mesh", "file": f"m.{kind}", "xyz": [0, 0, 0],
                **({"scale": 1e5} if "scaled" in case else {})}
    with warnings.catch_warnings(record=True) as raised:
        warnings.simplefilter("always")
        run = roarmctl("plan", str(_plan_with(tmp_path, item)), "-o", str(tmp_path / "o.traj.json"))
    lines = [x for x in run.stderr.splitlines() if x.strip()]
    assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), run.stderr
    assert "Warning" not in run.stderr and not raised, (run.stderr, [str(w.message) for w in raised])


# --------------------------------------------------------------------------- terminal sequences in names
def test_view_prints_a_file_name_s_terminal_sequences_as_text(tmp_path, monkeypatch):
    """A trajectory named with a title sequence (ESC ] 0 ; ... BEL), a colour change and rich markup: `view`
    prints its lines with the sequences escaped (common.shown / one_line, as error lines do) and the markup as
    written."""
    from roarmctl.viz.web import server

    def stop(self, on_poll=None):
        raise KeyboardInterrupt

    monkeypatch.setattr(server.ViewServer, "serve_forever", stop)
    name = "t\x1b]0;pwned\x07\x1b[31m[bold]x[red].traj.json"
    f = tmp_path / name
    f.write_text(json.dumps(hostile.trajectory_doc()))
    code, out, err = cli(["view", str(f)])
    assert code == 0, err
    assert "\x1b" not in out + err and "\x07" not in out + err, repr(out + err)
    assert "view of t\\x1b]0;pwned\\x07\\x1b[31m[bold]x[red].traj.json at" in out.replace("\n", ""), out


# --------------------------------------------------------------------------- a tiny --speed-scale in physics
@pytest.mark.slow
@pytest.mark.parametrize("scale, warned", [(0.001, True), (0.005, True), (0.5, False), (1.0, False)])
def test_simulate_warns_before_a_slowed_run_of_minutes_of_physics(tmp_path, monkeypatch, scale, warned):
    """--speed-scale 0.001 makes the 0.6 s trajectory 600 s of physics (pick_place: 27 min): a warning line
    says so before the run, with the way out; the run itself is stopped here at once (Ctrl-C)."""
    from roarmctl.physics import run

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(run, "simulate", stop)
    f = tmp_path / "t.traj.json"
    f.write_text(json.dumps(hostile.trajectory_doc()))
    code, _, err = cli(["simulate", str(f), "--speed-scale", str(scale)])
    assert code == 130, err
    assert ("warning: --speed-scale" in err and "s of motion to simulate" in err) == warned, err
