"""Streaming benchmark: schedule lateness and TCP tracking error of the bundled pick-and-place,
executed on the firmware simulator over a real pseudo-terminal, for each spd/acc strategy.

    .venv/bin/python bench/bench_stream.py [--repeats 3] [--traj FILE]

Figures are medians over the repeats. "true" tracking error compares the simulator's recorded
servo positions (1 kHz model, 250 Hz record) with the plan through the TCP forward kinematics;
"feedback" is what the streamer itself saw through T:1051 (what a real run reports).
Targets (issue 4): lateness p99 < 2 ms at 50 Hz; TCP RMS < 5 mm at full speed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "device"))


def bundled_trajectory(out: Path) -> Path:
    """Plan plans/pick_place.yaml with the real planner; fall back to the test trajectory."""
    r = subprocess.run([sys.executable, "-m", "roarmctl", "plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out)],
                       capture_output=True, text=True)
    if r.returncode == 0:
        return out
    from devtraj import pick_place

    print(f"(planner failed: {r.stderr.strip()[:120]}; using the test pick-and-place)")
    pick_place().save(out)
    return out


def run_inprocess(traj_path: Path, strategy: str, rate: float, speed_scale: float = 1.0) -> dict:
    from roarmctl.device.link import Link
    from roarmctl.device.simulator import PtySimulator, SimConfig
    from roarmctl.device.streamer import StreamConfig, Streamer, sample
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot

    traj = load_trajectory(traj_path)
    robot = load_robot(traj.robot)
    sys.setswitchinterval(0.0005)  # same as `execute --sim`
    with PtySimulator(SimConfig()) as sim:
        link = Link(sim.path).open()
        link.handshake()
        cfg = StreamConfig(rate=rate, strategy=strategy, speed_scale=speed_scale, max_error=1.0)
        res = Streamer(link, robot, traj, cfg).run()
        link.close()
        ts, q, _ = sim.recording()
    tt = ts - res.t0
    m = (tt >= 0) & (tt <= traj.duration / speed_scale)
    plan = sample(traj, tt[m] * speed_scale)
    e = np.linalg.norm(robot.kin.fk(q[m])[:, :3, 3] - robot.kin.fk(plan)[:, :3, 3], axis=1) * 1e3
    s = res.summary()
    return {"true_rms": float(np.sqrt(np.mean(e ** 2))), "true_max": float(e.max()),
            "fb_rms": s["tracking_mm"]["rms"], "p50": s["lateness_ms"]["p50"], "p99": s["lateness_ms"]["p99"],
            "max_late": s["lateness_ms"]["max"]}


def run_separate_process(traj_path: Path, rate: float) -> dict:
    """Lateness with the simulator in its own process (as a real arm: no shared GIL)."""
    sim = subprocess.Popen([sys.executable, "-m", "roarmctl", "sim-device", "--no-boot", "--json"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        port = json.loads(sim.stdout.readline())["port"]
        with tempfile.TemporaryDirectory() as d:
            r = subprocess.run([sys.executable, "-m", "roarmctl", "execute", str(traj_path), "--port", port, "--yes",
                                "--json", "--rate", str(rate), "--log", str(Path(d) / "log.json")],
                               capture_output=True, text=True, stdin=subprocess.DEVNULL)
        s = json.loads(r.stdout)
        return {"p50": s["lateness_ms"]["p50"], "p99": s["lateness_ms"]["p99"], "max_late": s["lateness_ms"]["max"],
                "fb_rms": s["tracking_mm"]["rms"]}
    finally:
        sim.send_signal(2)
        sim.wait(timeout=5)


def med(runs: list[dict], key: str) -> float:
    vals = [r[key] for r in runs if r.get(key) is not None]
    return statistics.median(vals) if vals else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--traj", type=Path, default=None)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    traj_path = args.traj or bundled_trajectory(tmp / "pick_place.traj.json")
    from roarmctl.motion.validate import load_trajectory

    traj = load_trajectory(traj_path)
    print(f"trajectory: {traj_path.name}, {traj.duration:.2f} s, peak |qd| "
          f"{np.round(np.abs(traj.velocities).max(0), 2).tolist()} rad/s; {args.repeats} runs each, medians")
    configs = [("timed", 50), ("timed", 25), ("timed-shared", 50), ("dense-ahead", 50), ("dense", 50), ("timed-acc", 50)]
    print(f"{'strategy':<14}{'Hz':>4}{'TCP RMS':>10}{'TCP max':>10}{'fb RMS':>9}{'late p50':>10}{'late p99':>10}{'max':>8}   (mm, ms)")
    for strategy, rate in configs:
        runs = [run_inprocess(traj_path, strategy, rate) for _ in range(args.repeats)]
        print(f"{strategy:<14}{rate:>4}{med(runs, 'true_rms'):>10.2f}{med(runs, 'true_max'):>10.2f}{med(runs, 'fb_rms'):>9.2f}"
              f"{med(runs, 'p50'):>10.3f}{med(runs, 'p99'):>10.3f}{med(runs, 'max_late'):>8.2f}")
    runs = [run_separate_process(traj_path, 50) for _ in range(args.repeats)]
    print(f"simulator in its own process, timed at 50 Hz: lateness p50 {med(runs, 'p50'):.3f} ms, "
          f"p99 {med(runs, 'p99'):.3f} ms, max {med(runs, 'max_late'):.2f} ms; feedback TCP RMS {med(runs, 'fb_rms'):.2f} mm")


if __name__ == "__main__":
    t = time.monotonic()
    main()
    print(f"({time.monotonic() - t:.0f} s)")
