"""CPU time to refuse a scene mesh of too many separate parts (issue 40): N separate triangles (what a 48 MB
STL of a million triangles holds), through ``roarmctl.motion.scenefiles.mesh_data`` as a plan's or a scene's
mesh item is read, and, for comparison, trimesh's merge and split (what the refusal waited for before).

Run: .venv/bin/python bench/bench_mesh_parts.py [--sizes 10000 100000 1000000] [--split-up-to 100000]
Prints CPU seconds (process time: the load of other processes does not count, a busy core still slows it).
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def triangles(n: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    tri = rng.uniform(-0.5, 0.5, (n, 1, 3)) + np.array([[0, 0, 0], [0.001, 0, 0], [0, 0.001, 0]])
    return tri.reshape(-1, 3), np.arange(3 * n).reshape(-1, 3)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--split-up-to", type=int, default=100_000, help="run trimesh's split only up to this size")
    args = ap.parse_args()
    import trimesh

    from roarmctl.errors import InputError
    from roarmctl.motion.scenefiles import mesh_data

    print(f"{'triangles':>10} {'refused in (CPU s)':>19} {'trimesh merge+split (CPU s)':>28}")
    for n in args.sizes:
        v, f = triangles(n)
        t = time.process_time()
        try:
            mesh_data(v, f, False, "m.stl", "bench")
            verdict = "taken?"
        except InputError:
            verdict = "refused"
        ours = time.process_time() - t
        split = "-"
        if n <= args.split_up_to:
            t = time.process_time()
            whole = trimesh.Trimesh(v, f, process=False)
            whole.merge_vertices()
            whole.split(only_watertight=False)
            split = f"{time.process_time() - t:.2f}"
        print(f"{n:>10,} {ours:>11.2f} ({verdict}) {split:>28}")


if __name__ == "__main__":
    main()
