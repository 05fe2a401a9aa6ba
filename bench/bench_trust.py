"""Time to refuse each hostile description of issue 19 (the bombs and FIFOs must answer within 5 s), and
what the safe xacro evaluator costs on a valid description.

Run: .venv/bin/python bench/bench_trust.py [--repeats 3]
Each case runs ``roarmctl kin fk`` in a fresh process (start-up included, as a user sees it) on a file
from tests/hostile.py; the table prints the exit code and the median wall time. The refusals are
decided by counts of work (src/roarmctl/robot/xacro_eval.py, xacro_safe.py), so the verdict is the same on any machine;
only the time varies with the machine's load. The last rows compare the expansion of the bundled
M3 URDF as a xacro by the safe evaluator and by xacro's own ``eval`` (``--trust-xacro``), in-process.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import hostile  # noqa: E402

CASES = {
    "${9**9**9}": lambda d: hostile.m3_xacro(d, hostile.POW_BOMB),
    "macro doubling x20": lambda d: hostile.m3_xacro(d, "'a'", hostile.macro_doubling(20)),
    "block doubling x20": lambda d: hostile.m3_xacro(d, "'a'", hostile.block_doubling(20)),
    "string doubling x60": lambda d: hostile.m3_xacro(d, "'a'", hostile.string_doubling(60)),
    "self include": hostile.self_include,
    "include of a FIFO": lambda d: hostile.m3_xacro(d, "'a'", f'<xacro:include filename="{hostile.fifo(d, "p.xacro")}"/>'),
    "load_yaml of a FIFO": lambda d: hostile.m3_xacro(d, f"xacro.load_yaml('{hostile.fifo(d, 'p.yaml')}')"),
    "code payload": lambda d: hostile.m3_xacro(d, hostile.payload(d / "MARKER")),
    "valid xacro (control)": lambda d: hostile.m3_xacro(d, "'roarm_m3_pro'"),
}


def run(path: Path) -> tuple[int, float]:
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "roarmctl", "kin", "fk", str(path), *hostile.M3_Q],
                          capture_output=True, text=True, timeout=120)
    return proc.returncode, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    print(f"{'case':28s} {'exit':>4s} {'median s':>9s} {'max s':>7s}")
    for name, build in CASES.items():
        times, code = [], None
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                code, dt = run(build(Path(tmp)))
                times.append(dt)
        print(f"{name:28s} {code:>4d} {statistics.median(times):9.2f} {max(times):7.2f}")

    from roarmctl.robot import xacro_input

    with tempfile.TemporaryDirectory() as tmp:
        arm = hostile.m3_xacro(Path(tmp), "'roarm_m3_pro'")
        xacro_input.expand(arm, {}, "warm-up")
        for label, trusted in (("safe evaluator", False), ("xacro's eval (trusted)", True)):
            t = time.perf_counter()
            for _ in range(10):
                xacro_input.expand(arm, {}, "bench", trusted=trusted)
            print(f"expand M3 xacro, {label:24s} {1000 * (time.perf_counter() - t) / 10:7.1f} ms")


if __name__ == "__main__":
    main()
