"""A slow 20260701 loop: the bundled pick-and-place streamed to the firmware model (one queued line per loop pass)
at loop passes of 6, 14, 22 and 30 ms, on a virtual clock (the same bytes on an idle or a busy machine).

    .venv/bin/python bench/bench_slow_loop.py [--passes 6,14,22,30] [--stops 36] [--traj FILE]

Per loop pass it prints:
- queue wait p50 / max: from a motion line's arrival at the firmware's UART to the pass that ran it (ms);
- overrun: the last motion line ran this much after the plan's end (ms; negative: before);
- rate: the tick rate the stream went on at (Hz; it asks for 50);
- lag p50 / max: the firmware's lag the execution log records (ms);
- tracking RMS / max: the recorded TCP against the plan at the best-fitting delay (mm; ``true_tracking``);
- hold travel: Ctrl-C at ``--stops`` times evenly from 15 to 85 % of the motion (whatever the stream is doing then,
  mostly waiting for its next tick, as a real Ctrl-C comes), the farthest the TCP got from where it was at the
  interrupt (mm, the worst and the median), how far the hold then brought it back (mm, the worst: a reversal), and
  its largest distance from the planned path meanwhile (mm).
The servos are the firmware model's kinematic servos (no lag, no gravity): the figures are the stream's.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "device"))
sys.path.insert(0, str(ROOT / "bench"))


def run(traj, robot, loop_pass: float, stop: float | None = None) -> dict:
    from roarmctl.device.protocol import WireMap, encode
    from roarmctl.device.streamer import StreamConfig, Streamer
    from roarmctl.device.virtual import VirtualClock, queued_link
    from roarmctl.errors import Interrupted

    clock = VirtualClock()
    link = queued_link(clock, loop_pass)
    link.fw.receive(encode(WireMap(robot).command(traj.positions[0], 0, 0)), clock())  # the arm at the start
    clock.now += 3.0
    link.fw.advance(clock())
    t_stop: list[float] = []

    def sleep(dt: float) -> None:  # Ctrl-C at a time: the stream waits in its sleep most of the time
        clock.sleep(dt)
        if stop is not None and not t_stop and st.sent_lateness and clock() - st.t0 >= stop * traj.duration:
            t_stop.append(clock())
            raise KeyboardInterrupt

    st = Streamer(link, robot, traj, StreamConfig(rate=50, max_error=1.0, settle=0.0), clock=clock, sleep=sleep)
    try:
        res = st.run()
    except Interrupted as exc:
        res = exc.result  # type: ignore[attr-defined]
    out = {"rate": st.rate, "lag": res.log.get("firmware_lag_ms", {})}
    if stop is None:
        from roarmctl.device.tracking import true_tracking

        trk = true_tracking(robot, traj, link.fw.recording(), res.t0, lag=True, paused=res.log["paused"])
        out |= {"rms": trk["rms_mm"], "max": trk["max_mm"]}
        waits = [c - t_line for t_line, c, cmd in link.fw.executed if cmd.get("T") in (101, 102)]
        last = max(c for _, c, cmd in link.fw.executed if cmd.get("T") == 102)
        out |= {"wait50": np.median(waits) * 1e3, "wait_max": max(waits) * 1e3,
                "overrun": (last - res.t0 - traj.duration) * 1e3}
        return out
    clock.now += 2.0
    link.fw.advance(clock())
    ts, q, _ = link.fw.recording()
    after = q[int(np.searchsorted(ts, t_stop[0])):]
    tcp = robot.kin.fk(robot.full_q(after))[:, :3, 3]
    from roarmctl.device.streamer import sample

    path = robot.kin.fk(robot.full_q(sample(traj, np.linspace(0.0, traj.duration, 4001))))[:, :3, 3]
    off = max(float(np.min(np.linalg.norm(path - p, axis=1))) for p in tcp[:: max(1, len(tcp) // 200)])
    far = np.linalg.norm(tcp - tcp[0], axis=1)
    # travel: the farthest the TCP got from where it was at the interrupt; back: how far the hold then pulled it back
    return out | {"travel": float(far.max()) * 1e3, "back": float(far.max() - far[-1]) * 1e3, "off": off * 1e3}


def main() -> None:
    from bench_stream import bundled_trajectory

    from roarmctl.motion.validate import load_trajectory
    from roarmctl.robot.loader import load_robot

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", default="6,14,22,30", help="loop passes (ms), comma-separated")
    ap.add_argument("--stops", type=int, default=36, help="Ctrl-C times, evenly from 15 to 85 %% of the motion")
    ap.add_argument("--traj", type=Path, default=None)
    args = ap.parse_args()
    traj_path = args.traj or bundled_trajectory(Path(tempfile.mkdtemp()) / "pick_place.traj.json")
    traj = load_trajectory(traj_path)
    robot = load_robot(traj.robot)
    print(f"trajectory: {traj_path.name}, {traj.duration:.2f} s; 20260701 build model, virtual clock; asked 50 Hz")
    print(f"{'pass':>5}{'wait p50':>9}{'max':>6}{'overrun':>9}{'rate':>6}{'lag p50':>8}{'max':>6}{'track rms':>10}{'max':>6}"
          f"{'hold travel max':>16}{'p50':>6}{'back':>6}{'off path':>9}   (ms, ms, ms, Hz, ms, ms, mm, mm, mm, mm, mm, mm)")
    for ms in (float(x) for x in args.passes.split(",")):
        full = run(traj, robot, ms / 1e3)
        holds = [run(traj, robot, ms / 1e3, stop=float(f)) for f in np.linspace(0.15, 0.85, args.stops)]
        travel = [h["travel"] for h in holds]
        print(f"{ms:>5.0f}{full['wait50']:>9.0f}{full['wait_max']:>6.0f}{full['overrun']:>9.0f}{full['rate']:>6.1f}"
              f"{full['lag'].get('p50') or 0:>8.0f}{full['lag'].get('max') or 0:>6.0f}{full['rms']:>10.1f}{full['max']:>6.1f}"
              f"{max(travel):>16.1f}"
              f"{statistics.median(travel):>6.1f}{max(h['back'] for h in holds):>6.1f}{max(h['off'] for h in holds):>9.1f}",
              flush=True)


if __name__ == "__main__":
    t = time.monotonic()
    main()
    print(f"({time.monotonic() - t:.0f} s)")
