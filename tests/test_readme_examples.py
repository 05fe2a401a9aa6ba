"""Every command line the README and docs/*.md show runs here, as written (in a scratch folder with the
bundled plans), and does what the text says next to it; the README fits a screen and every relative
link of README and docs/ leads to a file (and a heading) that exists.

The commands run in this process (tests/clirun.py: the same ``roarmctl.cli.run`` the console script calls, with
the shell's view of exit code, stdout and stderr): what a command line does is the point here, not the fresh
interpreter, whose start-up, console script and signals tests/test_startup.py and tests/device/test_signals.py
check. The commands that serve until Ctrl-C (``sim-device``, ``view``) and the one that needs a terminal on stdin
(``--port /dev/ttyUSB0``, which asks before moving) still run as a user's shell runs them, in a process of their own."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from clirun import roarmctl

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
DOCS = sorted((ROOT / "docs").glob("*.md"))
TEXTS = {"README.md": README} | {f"docs/{p.name}": p.read_text() for p in DOCS}


def readme_commands(text: str) -> list[str]:
    """Indented example lines starting with 'roarmctl ', and backticked ones without placeholders."""
    cmds = [m.group(1).split("  #")[0].strip() for m in re.finditer(r"^ {4}(roarmctl .*)$", text, re.M)]
    for span in re.findall(r"`(roarmctl [^`]*)`", text):
        placeholder = re.search(r"\b[A-Z][A-Z_]+\b|\.\.\.|\||\[", span)
        if not placeholder and span not in cmds and len(span.split()) > 2:  # `roarmctl follow` names a command
            cmds.append(span)
    return [c for c in dict.fromkeys(cmds) if "--install-completion" not in c]  # never touch the shell rc files


COMMANDS = list(dict.fromkeys(c for text in TEXTS.values() for c in readme_commands(text)))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces as hyphens."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_the_readme_fits_a_screen_and_points_to_the_docs():
    assert len(README.splitlines()) <= 250
    assert README.splitlines()[2].strip().startswith("make demo") and README.splitlines()[3].strip().startswith("make test")
    for name in ("guide", "reference", "design", "benchmarks"):
        assert f"docs/{name}.md" in README and (ROOT / "docs" / f"{name}.md").is_file()


@pytest.mark.parametrize("name", sorted(TEXTS))
def test_relative_links_lead_somewhere(name):
    """Each relative link names an existing file and, with '#', one of that file's headings."""
    here = (ROOT / name).parent
    for target in re.findall(r"\]\(([^)\s]+)\)", TEXTS[name]):
        if re.match(r"[a-z]+:", target):
            continue
        path, _, anchor = target.partition("#")
        file = (here / path).resolve() if path else ROOT / name
        assert file.exists(), f"{name}: link to {target}: no such file"
        if anchor:
            headings = re.findall(r"^#+ (.*)$", file.read_text(), re.M)
            assert anchor in {slug(h) for h in headings}, f"{name}: link to {target}: no such heading"


def run(cmd: str, cwd: Path, tty: bool = False) -> subprocess.CompletedProcess:
    args = [sys.executable, "-m", "roarmctl", *cmd.split()[1:]]
    env = dict(os.environ, COLUMNS="80")
    if not tty:
        return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=300, env=env, stdin=subprocess.DEVNULL)
    import pty

    master, slave = pty.openpty()  # a terminal on stdin, as a user at a shell has
    try:
        return subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=300, env=env, stdin=slave)
    finally:
        os.close(master)
        os.close(slave)


def interrupt(proc: subprocess.Popen) -> None:
    """Ctrl-C, as a user ends a command that serves; killed (and the test failed) if it has not ended within the
    bound. The bound only catches a hang: at nice 10 beside CPU hogs a process waited over 30 s for its turn."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate(timeout=60)
        raise


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("readme")
    shutil.copytree(ROOT / "plans", d / "plans")
    (d / "tests" / "data").mkdir(parents=True)  # the corpus of published arms, read in place
    (d / "tests" / "data" / "arms").symlink_to(ROOT / "tests" / "data" / "arms")
    r = roarmctl("plan", "plans/pick_place.yaml", "-o", "pick_place.traj.json", cwd=d)
    assert r.returncode == 0, r.stderr
    return d


def test_the_readme_shows_the_main_commands():
    assert {"plan", "visualize-path", "execute", "export"} <= {c.split()[1] for c in readme_commands(README)}
    verbs = {c.split()[1] for c in COMMANDS}
    assert {"plan", "visualize-path", "execute", "kin", "export", "ports", "sim-device", "workspace", "robots"} <= verbs


def _in_order(cmd: str) -> object:
    """``cmd``, in one xdist group with the other commands that write the same ``datagen`` dataset when one of them
    resumes it: each worker has a scratch folder of its own, and a ``--resume`` sent to another worker than the run
    before it found no dataset there and wrote all of it again (13 s of CPU) instead of resuming a finished one."""
    if not cmd.startswith("roarmctl datagen") or " -o " not in cmd:
        return cmd
    out = cmd.split(" -o ")[1].split()[0]
    same = [c for c in COMMANDS if c.startswith("roarmctl datagen") and f" -o {out} " in f"{c} "]
    if len(same) < 2 or not any("--resume" in c for c in same):
        return cmd
    return pytest.param(cmd, marks=pytest.mark.xdist_group(f"readme-datagen-{out}"))


# execute --sim runs on a virtual clock (virtual_sim: the pty and real time have tests/device/test_execute.py);
# datagen renders and encodes, and three commands start an interpreter of their own
@pytest.mark.slow
@pytest.mark.parametrize("cmd", [_in_order(c) for c in COMMANDS])
def test_readme_command(cmd, workdir, virtual_sim):
    if cmd.startswith("roarmctl datagen") and "--ray local" in cmd:
        pytest.skip("run as written by tests/test_datagen.py's Ray test (Ray started once): in an empty home and "
                    "temporary folder, the same bytes as the command below without --ray, nothing of that Ray left")
    if cmd.startswith("roarmctl datagen") and "--size 96x96" in cmd:
        pytest.skip("run as written by tests/test_datagen.py's dataset96 fixture (the dataset written once), which its "
                    "dataset tests, the killed run's and the Ray test's read")
    if cmd.startswith("roarmctl follow"):
        pytest.skip("follow needs a live source (a leader arm, a policy process, a recorded dataset) and the user's scene: "
                    "tests/device/test_follow_cli.py and test_follow_sim.py run it end to end")
    if "--port /dev/ttyUSB0" in cmd:  # no arm here: a clean one-line device error (exit 4) after the checks
        r = run(cmd, workdir, tty=True)
        assert r.returncode == 4 and r.stderr.startswith("error: ") and r.stderr.count("\n") == 1, r.stderr
        assert "/dev/ttyUSB0" in r.stderr
        return
    if cmd.startswith("roarmctl sim-device"):  # serves until Ctrl-C: its first line is the pty to open
        proc = subprocess.Popen([sys.executable, "-m", "roarmctl", *cmd.split()[1:]], cwd=workdir, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            path = proc.stdout.readline().strip()
            assert path.startswith("/dev/pts/") and os.path.exists(path)
        finally:
            interrupt(proc)
        assert proc.returncode == 0
        return
    if cmd.startswith("roarmctl view"):  # serves until Ctrl-C: its first line names the URL, which answers with the page
        proc = subprocess.Popen([sys.executable, "-m", "roarmctl", *cmd.split()[1:]], cwd=workdir, text=True,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            url = re.search(r"http://127\.0\.0\.1:\d+/\S*", proc.stdout.readline())  # with its token
            assert url, "no URL printed"
            import urllib.request

            with urllib.request.urlopen(url.group(0), timeout=60) as page:
                assert page.status == 200 and b"roarm-view-data" in page.read()
        finally:
            interrupt(proc)
        assert proc.returncode == 0  # Ctrl-C is view's normal end (it prints how to reopen the page)
        return
    if "pick_place.exec.json" in cmd and not (workdir / "pick_place.exec.json").exists():
        assert roarmctl("execute", "pick_place.traj.json", "--sim", "--yes", cwd=workdir).returncode == 0
    r = roarmctl(*cmd.split()[1:], cwd=workdir)
    assert r.returncode == 0, f"{cmd}: {r.stderr}"
    if cmd.startswith("roarmctl datagen") and "--resume" in cmd:  # after the same run (one group): nothing left to do
        assert "nothing to resume" in r.stdout, r.stdout
    if cmd.startswith("roarmctl kin jacobian scara_2r 0 0 --json"):  # "singular: ellipsoid radii (0.7616, 0)"
        out = json.loads(r.stdout)
        assert out["ellipsoid_radii"] == pytest.approx([0.7616, 0.0], abs=1e-4) and out["singularity"] == "elbow_stretched"
    if "--frame firmware" in cmd and cmd.startswith("roarmctl kin fk"):  # "end point (346.26, 0, 223.12) mm"
        row = re.search(r"end point, firmware frame \(mm\)\s*│\s*\[([^\]]*)\]", r.stdout)
        assert row, r.stdout
        assert [float(v) for v in row.group(1).split()] == pytest.approx([346.26, 0.0, 223.12], abs=0.01)
    if "-o " in cmd:
        out = workdir / cmd.split("-o ")[1].split()[0]
        assert out.exists()


@pytest.mark.slow  # a fresh interpreter that plans (about 5 s idle)
def test_the_readme_python_snippet_runs_from_the_folder_that_holds_the_clone(tmp_path):
    """A new user's script beside the clone: the folder that holds it also holds a directory named ``roarmctl`` (the
    clone). With the package at the repository's top that folder was imported as a namespace package ("unknown robot
    'roarm_m3_pro' (bundled robots: ;...)"); under src/ the installed package wins. The README's block runs as
    written, its paths taken from inside the clone, the real-time execute left out."""
    block = re.search(r"```python\n(.*?)```", README, re.S)
    assert block is not None
    code = "\n".join(line for line in block.group(1).splitlines() if "rc.execute(" not in line)
    assert "plans/pick_place.yaml" in code
    code = code.replace('"plans/', '"roarmctl/plans/')
    clone = tmp_path / "roarmctl"  # the clone's folder, as git names it
    clone.mkdir()
    shutil.copytree(ROOT / "plans", clone / "plans")
    (clone / "README.md").write_text(README)
    check = (f"\nimport roarmctl\nassert roarmctl.__file__ is not None and "
             f"roarmctl.__file__.startswith({str(ROOT / 'src')!r}), roarmctl.__path__\n"
             "assert traj.duration > 0\nprint('ok', traj.robot)\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", code + check], cwd=tmp_path, capture_output=True, text=True,
                          timeout=600, env=env)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok roarm_m3_pro", proc.stderr[-2000:]
    assert (tmp_path / "pick_place.traj.json").is_file()
