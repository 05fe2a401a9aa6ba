"""The install without a working C compiler: setup.py's build of the kernel stops with one line saying what to
install, not a traceback or a compiler's log.

The build runs as ``python setup.py build_ext`` in a scratch copy of setup.py and the kernel's C sources (nothing is
written into the tree), with ``CC`` naming a compiler that does not exist, or one that fails (``false``): the same
``BuildExt.run`` a ``pip install`` reaches, without pip's isolated build environment (which would download
setuptools)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def build_ext(tmp_path: Path, cc: str) -> subprocess.CompletedProcess:
    pytest.importorskip("setuptools", reason="setup.py runs on setuptools (pip's build would fetch it)")
    shutil.copy(ROOT / "setup.py", tmp_path / "setup.py")
    (tmp_path / "src" / "roarmctl").mkdir(parents=True)
    for source in ("_kernel.c", "_kernel_jerk.c"):
        shutil.copy(ROOT / "src" / "roarmctl" / source, tmp_path / "src" / "roarmctl" / source)
    env = dict(os.environ, CC=cc)
    return subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--build-lib", "lib", "--build-temp", "tmp"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)


@pytest.mark.slow
@pytest.mark.parametrize("cc, first", [("/nonexistent/cc", "error: missing a C compiler ('/nonexistent/cc')"),
                                       ("false", "error: building the kernel failed")])
def test_a_missing_or_failing_compiler_is_one_line_naming_what_to_install(tmp_path, cc, first):
    r = build_ext(tmp_path, cc)
    assert r.returncode != 0
    lines = [ln for ln in (r.stdout + r.stderr).splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stdout + r.stderr
    assert lines[0].startswith(first), lines[0]
    assert "sudo apt-get install gcc python3-dev" in lines[0] and "Python headers" in lines[0]
    assert not list((tmp_path / "lib").rglob("_kernel*"))  # nothing built
