"""Streaming benchmark: the bundled pick-and-place streamed to the simulated firmware (its own
process, over a real pseudo-terminal), per firmware build and spd/acc strategy, and the hold.

    .venv/bin/python bench/bench_stream.py [--repeats 2] [--traj FILE] [--servos MODULE:FACTORY] [--sag]

Per build (0.84: every waiting line each loop pass; 20260701: one queued line per pass) and
strategy it prints, medians over the repeats:
- TCP RMS / max: the simulator's true servo positions against the plan through the FK (mm);
- lag: the delay of the plan that fits the executed path best (ms);
- late p99: the host's schedule lateness (ms);
- link: the share of the 11.5 kB/s host->arm direction the stream uses, and lines/s;
- hold: from sending the hold to the firmware running it, in a run stopped half-way (ms).
Then the hold choice: where to hold when a run is stopped mid-motion (path point at the hold's
arrival, last set-point, last measured pose), by how far the arm still moves and whether it moves back.

``--servos MODULE:FACTORY`` plugs another servo model into the simulated firmware (a zero-argument
callable returning a ``roarmctl.device.servos.ServoModel``; e.g. the physics servos). ``--sag`` offsets the
goals by the servos' sag as ``execute`` does by default (``roarmctl.device.sag``; without it the plan's own
goals, as ``execute --no-sag``).
"""

from __future__ import annotations

import argparse
import importlib
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
    """Plan plans/pick_place.yaml with the real planner."""
    r = subprocess.run([sys.executable, "-m", "roarmctl", "plan", str(ROOT / "plans" / "pick_place.yaml"), "-o", str(out)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"planning failed: {r.stderr.strip()[:200]}")
    return out


def servo_factory(spec: str | None):
    if not spec:
        return None
    module, _, name = spec.partition(":")
    return getattr(importlib.import_module(module), name)


def run_one(traj, robot, firmware: str, strategy: str, *, rate: float = 50.0, servos=None, stop_at: float | None = None,
            hold: str = "auto", sag: bool = False) -> dict:
    """One run; ``stop_at``: fraction of the schedule at which a Ctrl-C is simulated (the hold)."""
    from roarmctl.device.link import Link
    from roarmctl.device.simulator import PtySimulator, SimConfig
    from roarmctl.device.streamer import StreamConfig, Streamer
    from roarmctl.device.tracking import true_tracking
    from roarmctl.errors import DeviceError, Interrupted

    with PtySimulator(SimConfig(firmware=firmware), servos=servos, process=True) as sim:
        link = Link(sim.path).open()
        info = link.connect()
        # the measured pose is held only when fresh (50 ms); the bench takes any age to show what it does
        cfg = StreamConfig(rate=rate, strategy=strategy, max_error=1.0, hold=hold, sag=sag,
                           hold_max_age=0.5 if hold == "measured" else 0.05)
        st = Streamer(link, robot, traj, cfg, extra_lateness=sim.recent_lateness)
        stop_k = None if stop_at is None else int(len(st.schedule) * stop_at)

        def hook(k: int) -> None:
            if k == stop_k:
                raise KeyboardInterrupt

        st.hook = hook
        failed = None
        try:
            res = st.run()
        except Interrupted as exc:
            res = exc.result  # type: ignore[attr-defined]
        except DeviceError as exc:  # a run the streamer stopped (counted, not averaged)
            res, failed = exc.result, exc.message  # type: ignore[attr-defined]
        time.sleep(0.6 if stop_at is not None else 0.0)
        link.close()
        rec, executed, late = sim.recording(), sim.executed(), sim.lateness()
    log = res.log
    host = np.array([[e["t"], e["lateness"]] for e in log["sent"] if "tick" in e]).reshape(-1, 2)
    out = {"p99": res.summary()["lateness_ms"]["p99"], "link": log["link_budget"]["up_share"],
           "lines": log["link_budget"]["lines_per_s"], "rtt": info.rtt, "failed": failed}
    if failed is not None:
        print(f"  ({firmware}, {strategy}: stopped: {failed})", flush=True)
        return out
    if stop_at is None:
        trk = true_tracking(robot, traj, rec, res.t0, host_late=host, device_late=late, lag=True, paused=log["paused"])
        out |= {"rms": trk["rms_mm"], "max": trk["max_mm"], "lag": trk["lag_s"] * 1e3}
        return out
    hold = [e for e in log["sent"] if e["cmd"].get("T") == 102][-1]
    t_sent = log["t0_monotonic"] + hold["t"]
    ran = [t for _, t, c in executed if c == hold["cmd"] and t >= t_sent - 1e-3]
    out["hold_ms"] = (ran[0] - t_sent) * 1e3 if ran else float("nan")
    ts, q, _ = rec
    i0 = int(np.searchsorted(ts, t_sent))
    before = q[max(i0 - 3, 0)]
    at, after = q[i0], q[i0:]
    moved = np.max(np.abs(after - at), axis=0)[:5]
    direction = np.sign(at - before)[:5]
    back = np.max(np.maximum(0.0, -(after[:, :5] - at[:5]) * direction), axis=0)  # against the direction of travel
    tcp = robot.kin.fk(robot.full_q(np.vstack([at, after[-1]])))[:, :3, 3]
    out |= {"moved": float(moved.max()), "back": float(back.max()), "tcp_mm": float(np.linalg.norm(tcp[1] - tcp[0])) * 1e3,
            "kind": (log.get("hold") or {}).get("kind")}
    return out


def med(runs: list[dict], key: str) -> float:
    vals = [r[key] for r in runs if r.get(key) is not None and not np.isnan(r[key])]
    return statistics.median(vals) if vals else float("nan")


def main() -> None:
    from roarmctl.device.schedule import DEFAULT_STRATEGY, STRATEGIES
    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--traj", type=Path, default=None)
    ap.add_argument("--servos", default=None, help="MODULE:FACTORY of another servo model (default: the kinematic servos)")
    ap.add_argument("--strategies", default="timed,timed-lead,timed-acc,per-joint,dense")
    ap.add_argument("--builds", default="m3-0.84,m3-2026", help="firmware builds, comma-separated")
    ap.add_argument("--no-hold-choice", action="store_true", help="skip the comparison of where to hold")
    ap.add_argument("--sag", action="store_true", help="goals offset by the servos' sag, as execute sends them by default")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    traj_path = args.traj or bundled_trajectory(tmp / "pick_place.traj.json")
    traj = load_trajectory(traj_path)
    robot = load_robot(traj.robot)
    servos = servo_factory(args.servos)
    strategies = [s for s in args.strategies.split(",") if s in STRATEGIES]
    print(f"trajectory: {traj_path.name}, {traj.duration:.2f} s; servos: {args.servos or 'kinematic (ideal trapezoids)'}; "
          f"sag compensation {'on' if args.sag else 'off'}; "
          f"{args.repeats} runs each, medians")
    print(f"{'build':<9}{'strategy':<11}{'TCP RMS':>8}{'max':>7}{'lag':>6}{'p99':>6}{'link':>6}{'lines/s':>8}{'hold':>6}"
          "   (mm, mm, ms, ms, share, -, ms)")
    for firmware in args.builds.split(","):
        for strategy in strategies:
            full = [run_one(traj, robot, firmware, strategy, servos=servos, sag=args.sag) for _ in range(args.repeats)]
            stop = [run_one(traj, robot, firmware, strategy, servos=servos, stop_at=0.5, sag=args.sag) for _ in range(args.repeats)]
            print(f"{firmware:<9}{strategy:<11}{med(full, 'rms'):>8.2f}{med(full, 'max'):>7.1f}{med(full, 'lag'):>6.0f}"
                  f"{med(full, 'p99'):>6.1f}{med(full, 'link'):>6.0%}{med(full, 'lines'):>8.0f}{med(stop, 'hold_ms'):>6.0f}",
                  flush=True)
    if args.no_hold_choice:
        return
    print(f"\nthe hold, stopped at 30/45/60/75 % of the run (0.84 build, {DEFAULT_STRATEGY}): joint motion after the hold was sent")
    print(f"{'hold at':<12}{'moved':>8}{'back':>8}{'TCP':>8}   (rad, rad against the travel, mm)")
    for mode in ("path", "setpoint", "measured"):
        runs = [run_one(traj, robot, "m3-0.84", DEFAULT_STRATEGY, servos=servos, stop_at=f, hold=mode)
                for f in (0.3, 0.45, 0.6, 0.75) for _ in range(max(1, args.repeats // 2))]
        runs = [r for r in runs if "moved" in r]
        print(f"{mode:<12}{max(r['moved'] for r in runs):>8.3f}{max(r['back'] for r in runs):>8.3f}"
              f"{max(r['tcp_mm'] for r in runs):>8.1f}   (worst of {len(runs)})", flush=True)


if __name__ == "__main__":
    t = time.monotonic()
    main()
    print(f"({time.monotonic() - t:.0f} s)")
