"""What the side-by-side benches share: a throwaway venv for a peer library and URDF text of 4 x 4 transforms.

Peers (mplib, Pinocchio) run in their own venv (mplib needs numpy < 2), created with pip on first use and
reused afterwards; the bench drives them as a worker process.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path


def peer_python(venv: Path, packages: list[str], label: str) -> Path:
    """The python of ``venv``, created with ``packages`` installed if it does not exist yet."""
    py = venv / "bin" / "python"
    if not py.exists():
        print(f"creating {venv} with {label} (once) ...", flush=True)
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
        subprocess.run([str(py), "-m", "pip", "install", "-q", *packages], check=True)
    return py


def urdf_rpy(r) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (rad) of a rotation matrix (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2][0])))
    if abs(math.cos(pitch)) > 1e-9:
        return math.atan2(r[2][1], r[2][2]), pitch, math.atan2(r[1][0], r[0][0])
    return math.atan2(-r[1][2], r[1][1]), pitch, 0.0


def urdf_origin(t) -> str:
    """``<origin xyz rpy>`` of a 4 x 4 transform (m, rad), with every digit of the floats."""
    x, y, z = (float(v) for v in t[:3, 3])
    r, p, yw = urdf_rpy(t[:3, :3])
    return f'<origin xyz="{x!r} {y!r} {z!r}" rpy="{r!r} {p!r} {yw!r}"/>'
