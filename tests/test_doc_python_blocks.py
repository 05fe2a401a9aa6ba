"""Every Python block of the README and docs/*.md runs here as written, as a script in a scratch folder with the
bundled plans, and does what the text beside it says. A block that needs inputs the text leaves to the
reader (a recorded array of targets, a dataset's joint states) gets them from a preamble here, and nothing else is
changed, except that the real-time ``rc.execute`` line is left out (tests/device runs execute on the simulated arm).
A new block fails here until it is given its entry in ``BLOCKS``. (The README's own block also runs from the folder
that holds a clone: tests/test_readme_examples.py.)"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shutil
import subprocess
import traceback
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TEXTS = {"README.md": (ROOT / "README.md").read_text()} | {f"docs/{p.name}": p.read_text() for p in sorted((ROOT / "docs").glob("*.md"))}

#: a line that tells the block apart -> (preamble, checks run after it, whether it plans: slow)
BLOCKS: dict[str, tuple[str, str, bool]] = {
    'result = rc.plan("plans/pick_place.yaml", seed=1)    # or a dict of the plan file\'s form': (
        "", "assert traj.duration > 0 and traj.robot == 'roarm_m3_pro'\nassert Path('pick_place.traj.json').is_file()\n", True),
    'targets = np.load("episode_actions.npy")': (
        "import numpy as _np\n_np.save('episode_actions.npy', _np.array([[0.0, 0.1, 1.5, 0.2, 0.0, 1.0]] * 3))\n", "", False),
    "spec = DatasetSpec(fps=30, robot_type=\"roarm_m3_pro\", joint_names=names)": (
        "import numpy as _np\nnames = ['base', 'shoulder', 'elbow', 'wrist', 'roll', 'gripper']\n"
        "state = _np.linspace(0, 1, 12).reshape(2, 6)\naction = state + 0.01\n",
        "assert t.shape == (2,) and _np.allclose(action, state + 0.01)\n", False),  # read back as written
    'robot = rc.load_robot("roarm_m3_pro")                # bundled name or a description file': (
        "", "assert q.shape == (2, robot.dof) and tcp.shape == (2, 3) and len(msg['points']) == len(traj.times)\n"
        "assert all(Path(p).exists() for p in ('pick_place.traj.json', 'pick_place.svg', 'pick_place.mcap'))\n", True),
    "found = planner.ik(rc.Pose((0.25, -0.15, 0.06), pitch=math.pi / 2), q_ref=robot.named_poses[\"home\"])": (
        "", "assert planner.is_valid(found.best) and traj.duration > 0 and len(path.waypoints) >= 2\n", True),
}


def python_blocks() -> list[tuple[str, str]]:
    """(where, code) of every ```python block of the README and docs."""
    return [(f"{name}:{text[:m.start()].count(chr(10)) + 1}", m.group(1))
            for name, text in TEXTS.items() for m in re.finditer(r"```python\n(.*?)```", text, re.S)]


BLOCK_LIST = python_blocks()


def entry(code: str) -> tuple[str, str, bool] | None:
    found = [v for k, v in BLOCKS.items() if k in code]
    return found[0] if len(found) == 1 else None


def test_every_block_has_its_entry():
    missing = [where for where, code in BLOCK_LIST if entry(code) is None]
    assert not missing, f"Python blocks without an entry in BLOCKS (give one): {missing}"
    assert len(BLOCK_LIST) == len(BLOCKS)  # and no entry for a block that is gone


def _run(where: str, code: str, tmp_path: Path) -> subprocess.CompletedProcess[str]:
    """The block (its preamble before, its checks after) run as a script (``__main__``, a namespace of its own) in this
    process, in ``tmp_path`` with the bundled plans: exit code 1 and the traceback on stderr when it raises. A fresh
    interpreter per block cost about a second of imports each; the block imports what it uses all the same (a name
    it forgets is a NameError here too), and the README's block also runs in a fresh interpreter from the folder that
    holds a clone (tests/test_readme_examples.py)."""
    pre, checks, _ = entry(code) or ("", "", False)
    body = "\n".join(line for line in code.splitlines() if "rc.execute(" not in line)
    shutil.copytree(ROOT / "plans", tmp_path / "plans")
    script = "from pathlib import Path\n" + pre + body + "\n" + checks
    out, err = io.StringIO(), io.StringIO()
    returncode = 0
    with contextlib.chdir(tmp_path), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            exec(compile(script, where, "exec"), {"__name__": "__main__"})  # noqa: S102 - the docs' own blocks
        except SystemExit as exc:
            returncode = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
        except Exception:  # noqa: BLE001 - any failure of the block is the test's failure, with its traceback
            traceback.print_exc()
            returncode = 1
    return subprocess.CompletedProcess(["<block>", where], returncode, out.getvalue(), err.getvalue())


def _params(slow: bool) -> list:
    return [pytest.param(w, c, id=w, marks=[pytest.mark.slow] if slow else []) for w, c in BLOCK_LIST
            if (entry(c) or ("", "", False))[2] == slow]


@pytest.mark.parametrize(("where", "code"), _params(False) + _params(True))
def test_the_block_runs_as_written(where, code, tmp_path):
    proc = _run(where, code, tmp_path)
    assert proc.returncode == 0, f"{where}:\n{proc.stderr[-3000:]}"
    if "episode_actions.npy" in code:  # the policy prints one JSON target per line, as follow reads them
        lines = [json.loads(x) for x in proc.stdout.splitlines()]
        assert [x["t"] for x in lines] == [0.0, 0.1, 0.2]
        assert all(len(x["joints"]) == 5 and isinstance(x["gripper"], float) for x in lines)
