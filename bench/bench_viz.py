"""Time visualize-path and workspace rendering (median of several runs; target < 2 s each).

    .venv/bin/python bench/bench_viz.py [TRAJ.traj.json ...] [--runs N]

Without trajectory files it plans the bundled plans/pick_place.yaml once (not timed) and renders
that; with files it renders each. Times are in-process (imports excluded: they are paid once per
command and printed separately), each render writes a full-size PNG (1600 x 1000 px at 100 dpi).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def median_time(fn, runs: int) -> tuple[float, float]:
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trajectories", nargs="*", type=Path)
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()

    t0 = time.perf_counter()
    from roarmctl.viz import path_figure, workspace_figure  # noqa: F401  (matplotlib import)

    print(f"import roarmctl.viz.path_figure + workspace_figure (matplotlib): {time.perf_counter() - t0:.2f} s")

    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot
    from roarmctl.viz.data import path_data, robot_for
    from roarmctl.viz.path_figure import visualize_trajectory
    from roarmctl.viz.workspace_figure import visualize_workspace

    if args.trajectories:
        trajs = [(p.name, load_trajectory(p)) for p in args.trajectories]
    else:
        from roarmctl.motion.pipeline import plan_file

        trajs = [("plans/pick_place.yaml", plan_file(ROOT / "plans" / "pick_place.yaml").trajectory)]

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.png"
        for name, traj in trajs:
            robot = robot_for(traj)
            med_d, _ = median_time(lambda traj=traj, robot=robot: path_data(traj, robot), args.runs)
            med, best = median_time(lambda traj=traj, name=name: visualize_trajectory(traj, out, name=name), args.runs)
            print(f"visualize-path {name}: {len(traj.times)} samples, {traj.duration:.1f} s of motion: "
                  f"render+save median {med:.3f} s (best {best:.3f} s; data {med_d * 1000:.1f} ms), "
                  f"PNG {out.stat().st_size / 1024:.0f} KiB")
        robot = load_robot("roarm_m3_pro")
        med, best = median_time(lambda: visualize_workspace(robot, out), args.runs)
        print(f"workspace roarm_m3_pro (80000 samples): median {med:.3f} s (best {best:.3f} s)")

        # End to end as a user runs it: a fresh process, imports included.
        if args.trajectories:
            src = args.trajectories[0]
        else:
            src = Path(tmp) / "pp.traj.json"
            trajs[0][1].save(src)
        cmd = [sys.executable, "-m", "roarmctl", "visualize-path", str(src), "-o", str(out)]
        med, best = median_time(lambda: subprocess.run(cmd, check=True, capture_output=True), max(3, args.runs // 2))
        print(f"'roarmctl visualize-path' whole command (fresh process): median {med:.3f} s (best {best:.3f} s)")
        cmd = [sys.executable, "-m", "roarmctl", "workspace", "roarm_m3_pro", "-o", str(out)]
        med, best = median_time(lambda: subprocess.run(cmd, check=True, capture_output=True), max(3, args.runs // 2))
        print(f"'roarmctl workspace roarm_m3_pro' whole command (fresh process): median {med:.3f} s (best {best:.3f} s)")


if __name__ == "__main__":
    main()
