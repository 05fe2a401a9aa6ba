"""CLI conventions a shell user relies on: picture format by extension, failing plans drawn, --version,
-h, completion, boolean flags, JSON on failure, 80-column tables, units, task numbering."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def roarmctl(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    import os

    e = dict(os.environ, COLUMNS="80", **(env or {}))
    return subprocess.run([sys.executable, "-m", "roarmctl", *args], capture_output=True, text=True, timeout=180, env=e)


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


@pytest.mark.parametrize("ext, magic", [(".png", b"\x89PNG"), (".svg", b"<?xml"), (".pdf", b"%PDF")])
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
    assert list(tmp_path.iterdir()) == []


def test_failing_plan_is_drawn_with_the_failing_target_and_exits_3(far_plan, tmp_path):
    out = tmp_path / "far.svg"
    r = roarmctl("visualize-path", str(far_plan), "-o", str(out))
    assert r.returncode == 3
    assert "task 2 (place" in r.stderr and "unreachable" in r.stderr and str(out) in r.stderr
    svg = out.read_text()
    assert 'id="target:failed"' in svg and 'id="target:grasp"' in svg  # the pick was planned; the place target marked
    assert "PLANNING FAILED at task 2" in svg
