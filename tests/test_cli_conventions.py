"""CLI conventions a shell user relies on: picture format by extension, failing plans drawn, --version,
-h, completion, boolean flags, JSON on failure, 80-column tables, units, task numbering."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from clirun import roarmctl

ROOT = Path(__file__).resolve().parents[1]


def process(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """The console script in a new interpreter (shell completion is the program's, not run()'s)."""
    import os

    e = dict(os.environ, COLUMNS="80", **(env or {}))
    return subprocess.run([sys.executable, "-m", "roarmctl", *args], capture_output=True, text=True, timeout=180, env=e)


@pytest.fixture
def cli():
    """The CLI in this process (no interpreter start-up per call), 80 columns wide."""
    return roarmctl


@pytest.fixture(scope="module")
def traj(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("conv") / "pp.traj.json"
    r = roarmctl("plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def far_plan(tmp_path_factory) -> Path:
    """The demo plan with the place target moved out of reach (0.772 m from the shoulder axis)."""
    p = tmp_path_factory.mktemp("far") / "far.yaml"
    p.write_text((ROOT / "plans" / "pick_place.yaml").read_text().replace("xyz: [0.25, 0.15, 0.02]", "xyz: [0.75, 0.15, 0.02]"))
    assert "0.75, 0.15" in p.read_text()
    return p


@pytest.mark.parametrize("ext, magic", [(".png", b"\x89PNG"), pytest.param(".svg", b"<?xml", marks=pytest.mark.slow),
                                        pytest.param(".pdf", b"%PDF", marks=pytest.mark.slow)])  # make test-fast draws the PNG
def test_picture_format_follows_the_extension(traj, tmp_path, ext, magic):
    out = tmp_path / f"pic{ext}"
    r = roarmctl("visualize-path", str(traj), "-o", str(out), "--dpi", "30")
    assert r.returncode == 0, r.stderr
    assert out.read_bytes().startswith(magic)


@pytest.mark.parametrize("args", [["visualize-path", "TRAJ"], ["workspace", "planar_2r", "--samples", "10"]])
@pytest.mark.parametrize("name", ["pic.gif", "pic.jpg", "pic"])
def test_unknown_picture_format_is_exit_2_and_writes_nothing(traj, tmp_path, args, name):
    args = [str(traj) if a == "TRAJ" else a for a in args]
    r = roarmctl(*args, "-o", str(tmp_path / name))
    assert r.returncode == 2 and "png, .svg or .pdf" in r.stderr
    # visualize-path also writes the 3D page: its hint names .html too (it did not), workspace's does not
    assert (".html" in r.stderr) == (args[0] == "visualize-path"), r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["run.png", None])
def test_an_execution_log_as_a_picture_is_exit_2_pointing_to_the_html_page(tmp_path, name):
    """Only the 3D page draws a run (README and docs run `visualize-path pick_place.exec.json -o run.html`); a
    picture of one says so and how, not the trajectory reader's 'format: expected ...'."""
    log = tmp_path / "run.exec.json"
    log.write_text(json.dumps({"format": "roarmctl.execlog/1"}))
    r = roarmctl("visualize-path", str(log), *(["-o", str(tmp_path / name)] if name else []))
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "execution log is drawn only as the 3D page" in r.stderr and "-o run.exec.html" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.exec.json"]


@pytest.mark.slow
def test_failing_plan_is_drawn_with_the_failing_target_and_exits_3(far_plan, tmp_path):
    out = tmp_path / "far.svg"
    r = roarmctl("visualize-path", str(far_plan), "-o", str(out))
    assert r.returncode == 3
    assert "task 2 (place" in r.stderr and "unreachable" in r.stderr and str(out) in r.stderr
    svg = out.read_text()
    assert 'id="target:failed"' in svg and 'id="target:grasp"' in svg  # the pick was planned; the place target marked
    assert "PLANNING FAILED at task 2" in svg


def test_version_and_short_help(cli):
    from roarmctl import __version__

    for flag in ("--version", "-V"):
        r = cli(flag)
        assert r.returncode == 0 and r.stdout.strip() == f"roarmctl {__version__}"
    for args in (["-h"], ["plan", "-h"], ["kin", "ik", "-h"]):
        r = cli(*args)
        assert r.returncode == 0 and "Usage: roarmctl" in r.stdout


def test_flags_are_shown_as_flags_and_take_no_value(cli):
    for args in (["plan", "-h"], ["execute", "-h"], ["kin", "jacobian", "-h"], ["export", "-h"], ["-h"]):
        out = cli(*args).stdout
        assert "<bool>" not in out and "--help" in out
    assert "--json " in cli("plan", "-h").stdout
    r = cli("robots", "--json", "true")
    assert r.returncode == 2  # a flag: 'true' is an unexpected extra argument


def test_shell_completion():
    # --show-completion names the shell it runs under (typer asks shellingham), whatever started the suite
    # (make's /bin/sh refuses): run under bash, as a user who types it in bash.
    r = subprocess.run(["bash", "-c", '"$0" -m roarmctl --show-completion; exit $?', sys.executable],
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0 and "_roarmctl_completion" in r.stdout, r.stderr
    r = process(env={"_ROARMCTL_COMPLETE": "complete_bash", "COMP_WORDS": "roarmctl ex", "COMP_CWORD": "1"})
    assert r.returncode == 0 and r.stdout.split() == ["execute", "export"]


@pytest.mark.parametrize("args, code, words", [
    (["plan", "no-such-plan.yaml"], 2, "no such file"),
    (["plan", "FAR"], 3, "unreachable"),
    (["kin", "ik", "roarm_m3_pro", "--xyz", "2", "0", "0"], 3, "out_of_reach"),
    (["kin", "fk", "ur10", "1"], 2, "6 arm joint values"),
    (["kin", "dynamics", "ur10", "--q", "0 x"], 2, "not a number"),
    (["kin", "jacobian", "nobot", "0"], 2, "nobot"),
    (["execute", "TRAJ"], 2, "exactly one of"),
    (["export", "TRAJ", "-o", "x.txt"], 2, "unknown export format"),
    (["ports", "--bogus"], 2, "No such option"),
])
def test_json_commands_print_a_json_object_on_failure(args, code, words, traj, far_plan, tmp_path):
    args = [str(traj) if a == "TRAJ" else str(far_plan) if a == "FAR" else a for a in args]
    r = roarmctl(*args, "--json", cwd=tmp_path)
    assert r.returncode == code
    out = json.loads(r.stdout)  # exactly one JSON object on stdout
    assert out["ok"] is False and out["exit_code"] == code and words in out["error"] and "hint" in out
    assert r.stderr.startswith("error: ") or "Error" in r.stderr  # the line for the human stays on stderr


def test_json_success_says_ok(cli, traj):
    assert json.loads(cli("robots", "--json").stdout)["ok"] is True
    assert json.loads(cli("kin", "fk", "scara_2r", "0", "0", "--json").stdout)["ok"] is True


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def test_tables_fit_80_columns_with_every_value(cli):
    q = ["0.1", "-1", "1", "0.2", "0.3", "0.1"]
    for args in (["kin", "ik", "ur10", "--xyz", "0.5", "0.2", "0.4", "--rpy", "180", "0", "0", "--all", "--deg"],
                 ["kin", "jacobian", "ur10", *q], ["kin", "dynamics", "ur10", "--q", " ".join(q)],
                 ["kin", "fk", "ur10", *q], ["robots"]):
        r = cli(*args)
        assert r.returncode == 0, r.stderr
        assert max(len(line) for line in _lines(r.stdout)) <= 80 and "…" not in r.stdout, r.stdout
    # every Jacobian entry is printed, row by row, as the JSON has it (4 decimals)
    jac = json.loads(cli("kin", "jacobian", "ur10", *q, "--json").stdout)["jacobian"]
    text = cli("kin", "jacobian", "ur10", *q).stdout
    for name, row in zip(("vx", "vy", "vz", "wx", "wy", "wz"), jac):
        line = next(line for line in text.splitlines() if f" {name} (" in line)
        printed = [float(v) for v in line.split("│")[2:-1]]
        assert printed == pytest.approx(row, abs=5e-5)
    mm = json.loads(cli("kin", "dynamics", "ur10", "--q", " ".join(q), "--json").stdout)["mass_matrix"]
    text = cli("kin", "dynamics", "ur10", "--q", " ".join(q)).stdout
    for i, row in enumerate(mm):
        line = next(line for line in text.splitlines() if f" row q{i + 1} " in line)
        assert [float(v) for v in line.split("│")[2:-1]] == pytest.approx(row, abs=5e-6)


def test_units_and_singularity_are_spelled_out(cli):
    text = cli("kin", "jacobian", "scara_2r", "0", "0").stdout
    assert "translational, 3x2 Jv ((m/rad)^2)" in text and "full, 6x2 J (mixed units)" in text
    assert "elbow_stretched" in text and "(m/rad)" in text
    text = cli("kin", "jacobian", "ur10", "0.3", "-1", "1", "0.2", "0.3", "0.1").stdout
    assert "None" not in text and "none (no known singular configuration)" in text


@pytest.mark.slow  # includes a run on the simulated arm (real time)
def test_commands_mean_the_same_in_output_json_text_and_sim(tmp_path, virtual_sim):
    plan = tmp_path / "short.yaml"
    plan.write_text("robot: roarm_m3_pro\ntasks:\n  - move: {joints: [0.4, 0.1, 1.4, 0.1, 0.0]}\n  - move: {pose: home}\n"
                    "objects: []\n")
    traj = tmp_path / "short.traj.json"
    assert roarmctl("plan", str(plan), "-o", str(traj), "--json").returncode == 0
    out = json.loads(roarmctl("execute", str(traj), "--output", str(tmp_path / "c.jsonl"), "--json").stdout)
    lines = [json.loads(x)["cmd"] for x in (tmp_path / "c.jsonl").read_text().splitlines()]
    assert out["commands"] == sum(c["T"] == 102 for c in lines) and out["lines"] == len(lines)
    assert out["gripper_commands"] == sum(c["T"] == 101 for c in lines)
    text = roarmctl("execute", str(traj), "--output", str(tmp_path / "c.jsonl")).stderr
    assert f"wrote {out['commands']} motion commands" in text
    # ideal servos: the point is what is counted and sent, not how the arm follows (tests/device/test_physics_execute.py)
    sim = json.loads(roarmctl("execute", str(traj), "--sim", "--servos", "ideal", "--yes", "--json", "--log",
                              str(tmp_path / "l.json")).stdout)
    # every tick goes out, in order (a busy machine pauses the plan instead of skipping ticks): the same commands
    assert sim["commands"] == out["commands"] and "skipped" not in sim


def test_json_failure_after_a_json_success_in_the_same_process(traj, tmp_path, capsys):
    """main() keeps no state between calls: a failure after a success still prints its JSON object."""
    from roarmctl.cli import main

    def call(args):
        try:
            main(args)
        except SystemExit as exc:
            return exc.code
        return 0

    assert call(["export", str(traj), "-o", str(tmp_path / "a.csv"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["ok"] is True
    assert call(["export", str(traj), "-o", str(tmp_path / "a.txt"), "--json"]) == 2
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] is False and out["exit_code"] == 2


@pytest.mark.parametrize("args", [("execute", "{traj}", "--sim", "--servos", "ideal", "--yes", "--log", "{bad}"),
                                  ("simulate", "{traj}", "-o", "{bad}")])
def test_an_output_that_cannot_be_written_is_refused_before_the_run(traj, tmp_path, virtual_sim, args):
    """A log or run file under a file (any user, root too, cannot write there) is exit 2 before the arm moves: execute
    ran the whole motion, then warned that its log was lost, exit 0; simulate ran the physics, then exit 2."""
    (tmp_path / "a_file").write_text("x")
    bad = tmp_path / "a_file" / "run.json"
    r = roarmctl(*(a.format(traj=traj, bad=bad) for a in args))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "cannot write" in lines[0] and "a_file" in lines[0], r.stderr
    assert virtual_sim == [] and sorted(p.name for p in tmp_path.iterdir()) == ["a_file"]


def test_check_writable_probes_the_folder_and_leaves_nothing(tmp_path):
    from roarmctl.errors import InputError
    from roarmctl.fileio import check_writable

    assert check_writable(tmp_path / "new" / "deeper" / "out.json") == tmp_path / "new" / "deeper" / "out.json"
    assert list(tmp_path.iterdir()) == []  # no folder made, no probe left
    (tmp_path / "f").write_text("x")
    for bad in (tmp_path / "f" / "out.json", tmp_path / "f" / "sub" / "out.json", tmp_path):
        with pytest.raises(InputError, match="cannot write"):
            check_writable(bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


@pytest.mark.parametrize("args", [("plan", "{plan}", "-o", "{plan}"), ("plan", "{plan}", "-o", "{plan_link}"),
                                  ("simulate", "{traj}", "-o", "{traj}"),
                                  ("execute", "{traj}", "--output", "{traj}"),
                                  ("execute", "{traj}", "--sim", "--servos", "ideal", "--yes", "--log", "{traj}")])
def test_an_output_that_is_the_input_file_is_refused_and_the_input_kept(traj, tmp_path, virtual_sim, args):
    """Each of these replaced the user's plan or trajectory with its result (a trajectory, a run, commands), exit 0."""
    plan = tmp_path / "pp.yaml"
    plan.write_text((ROOT / "plans" / "pick_place.yaml").read_text())
    (tmp_path / "link.yaml").symlink_to(plan)
    mine = tmp_path / "pp.traj.json"
    mine.write_bytes(traj.read_bytes())
    before = {p: p.read_bytes() for p in (plan, mine)}
    r = roarmctl(*(a.format(plan=plan, plan_link=tmp_path / "link.yaml", traj=mine) for a in args))
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "is the input file" in lines[0], r.stderr
    assert {p: p.read_bytes() for p in before} == before and virtual_sim == []


def test_sim_device_link_never_replaces_what_it_did_not_make(tmp_path):
    """--link over a symlink to elsewhere replaced it, and removed it at the end: the user's link was gone."""
    import os

    (tmp_path / "mine.txt").write_text("keep")
    os.symlink(tmp_path / "mine.txt", tmp_path / "users_link")
    for name in ("users_link", "mine.txt"):
        r = roarmctl("sim-device", "--servos", "ideal", "--link", str(tmp_path / name))
        lines = r.stderr.strip().splitlines()
        assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: --link: "), r.stderr
    assert os.readlink(tmp_path / "users_link") == str(tmp_path / "mine.txt")
    assert (tmp_path / "mine.txt").read_text() == "keep"


def test_port_holders_are_one_warning_line(traj, tmp_path, monkeypatch):
    """A port open in many processes (/dev/null given as the port: every shell) gave one warning line per process."""
    from roarmctl.cli import execute_cmd

    monkeypatch.setattr(execute_cmd, "port_holders", lambda port: [(100 + i, f"proc{i}") for i in range(20)])
    r = roarmctl("execute", str(traj), "--port", str(tmp_path / "ttyNONE"), "--yes")
    warn = [line for line in r.stderr.splitlines() if line.startswith("warning:")]
    assert r.returncode == 4 and len(warn) == 1, r.stderr
    assert "processes 100 (proc0), 101 (proc1), 102 (proc2) and 17 more" in warn[0]


@pytest.mark.parametrize("port", ["{tmp}", "/dev/null"])
def test_a_port_that_is_not_a_serial_port_says_so(traj, tmp_path, port, monkeypatch):
    """A folder or /dev/null as --port: 'cannot open serial port /tmp: [Errno 21] could not open port /tmp: [Errno 21]
    Is a directory: ...', the errno twice and no way forward."""
    from roarmctl.cli import execute_cmd

    monkeypatch.setattr(execute_cmd, "port_holders", lambda port: [])  # /dev/null is open in every shell
    r = roarmctl("execute", str(traj), "--port", port.format(tmp=tmp_path), "--yes")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 4 and len(lines) == 1 and "is not a serial port" in lines[0] and "roarmctl ports" in lines[0], r.stderr


def test_names_with_brackets_are_printed_as_they_are(tmp_path, virtual_sim):
    """An object named 'cu[/]be' in the plan, or an output named 'o[/]x.jsonl': rich read '[/]' as markup, and
    simulate and execute ended as internal errors (MarkupError, exit 1) after their work."""
    plan = tmp_path / "mk.yaml"
    plan.write_text((ROOT / "plans" / "pick_place.yaml").read_text().replace("cube", '"cu[/]be"'))
    traj = tmp_path / "mk.traj.json"
    assert roarmctl("plan", str(plan), "-o", str(traj)).returncode == 0
    r = roarmctl("simulate", str(traj))
    assert r.returncode == 0 and "object cu[/]be (" in r.stdout, r.stdout + r.stderr
    out = tmp_path / "o[/]x.jsonl"
    r = roarmctl("execute", str(traj), "--output", str(out))
    assert r.returncode == 0 and str(out) in r.stderr.replace("\n", ""), r.stderr
    log = tmp_path / "l[/]og.json"
    r = roarmctl("execute", str(traj), "--sim", "--servos", "ideal", "--yes", "--log", str(log))
    assert r.returncode == 0 and f"log: {log}" in r.stdout.replace("\n", ""), r.stdout + r.stderr


@pytest.mark.parametrize("args", [("plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", "{d}/p[/]x.json"),
                                  ("visualize-path", "{traj}", "-o", "{d}/v[/]x.png"),
                                  ("workspace", "planar_2r", "--samples", "10", "-o", "{d}/w[/]x.png"),
                                  ("export", "{traj}", "-o", "{d}/e[/]x.csv"),
                                  ("export", "{traj}", "-o", "{d}/e[/]x.mcap")])
def test_an_output_name_with_brackets_is_written_and_named(traj, tmp_path, args):
    """Every 'wrote NAME' line was rich markup: '[/]' in the name was an internal error (exit 1) after the file was written."""
    args = [a.format(d=tmp_path, traj=traj) for a in args]
    r = roarmctl(*args)
    assert r.returncode == 0 and Path(args[-1]).is_file(), r.stdout + r.stderr
    if args[0] != "plan":  # plan's table may shorten a long path
        assert "[/]x." in (r.stdout + r.stderr).replace("\n", ""), r.stdout + r.stderr


@pytest.mark.slow  # a fresh interpreter and the simulated arm in real time until the signal
def test_teach_stopped_by_a_signal_says_what_it_wrote(tmp_path):
    """teach --raw LOG stopped by SIGTERM wrote the log and said '(nothing was written)'; and a raw log's name with
    '[/]' was rich markup (the 'feedback stream:' line was lost)."""
    import os
    import signal
    import time

    raw = tmp_path / "r[x]aw.json"
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "teach", "--sim", "--raw", str(raw), "-o",
                             str(tmp_path / "t.yaml")], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=dict(os.environ, COLUMNS="200"))
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and "torque off" not in (proc.stdout.readline() or "torque off"):
            pass
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
        proc.wait(10)
    assert proc.returncode == 143, out
    assert f"feedback stream: {raw}" in out and f"terminated by SIGTERM (the feedback stream is in {raw})" in out, out
    assert raw.is_file() and not (tmp_path / "t.yaml").exists()
