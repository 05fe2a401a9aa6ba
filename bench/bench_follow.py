"""What following costs per target, and how closely a simulated arm follows a simulated leader (issue 38).

Run: .venv/bin/python bench/bench_follow.py [--targets 400] [--seconds 6] [--no-sim]

1. Per target, the computation ``roarmctl follow`` does before a target may move the arm (``Follower._take``: the
   guard's checks, the Ruckig motion toward it and the check of that motion's set-points and chords), timed with
   ``time.perf_counter`` and ``time.process_time`` around each call: a policy's random walk of ``--targets``
   targets from home at 10 Hz and at 30 Hz, in three scenes (none; ``plans/pick_place.yaml``'s table and cube;
   ``plans/obstacle.yaml``'s wall), the first target (first use of Ruckig and the checker's buffers) reported apart.
   Printed: median, 99th percentile and max in ms, and the share of targets refused.
2. A clean leader, followed on the simulators (``follow_live`` with ``--leader-guide``'s simulated leader, every
   joint on slow cosines for ``--seconds``): the lag that fits the follower's true joints to the leader's best, and
   the RMS and max of the largest arm-joint error at that lag (``follow_session.leader_tracking``), with the
   per-target cost of that run. The machine's load average is printed with the figures.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time
from pathlib import Path

import numpy as np

from roarmctl.device.follow import FollowConfig, Follower
from roarmctl.device.follow_guard import Guard, GuardLimits, Target
from roarmctl.device.follow_motion import Smoother
from roarmctl.device.follow_session import LeaderSpec, follow_live, leader_tracking
from roarmctl.device.guide import Guide
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.planning.context import scene_item
from roarmctl.motion.scene import Scene
from roarmctl.plan.schema import load_plan
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]
ROBOT = load_robot("roarm_m3_pro")
HOME = np.array([0.0, 0.0, 1.5708, 0.0, 0.0, 0.0])
START = np.clip(HOME, ROBOT.lower + 0.2, ROBOT.upper - 0.2)  # home, the gripper a little open: the walk's start


def checker_of(plan: str | None) -> CollisionChecker:
    if plan is None:
        return CollisionChecker(ROBOT, Scene([]), singularity_margin=0.02)
    p = load_plan(ROOT / "plans" / plan)
    return CollisionChecker(ROBOT, Scene([scene_item(s) for s in p.scene + p.objects]), padding=p.planner.padding,
                            singularity_margin=p.planner.singularity_margin)


def walk(n: int, hz: float, seed: int, checker: CollisionChecker) -> list[np.ndarray]:
    """A policy's targets: a smooth random walk from home (a low-passed random velocity, a quarter of the joints'
    limits) that turns back where a pose would be invalid (so most targets are acceptable, as a trained policy's)."""
    rng = np.random.default_rng(seed)
    v = np.zeros(ROBOT.dof)
    q = START.copy()
    out = []
    for _ in range(n):
        v = 0.9 * v + 0.1 * rng.normal(0.0, 0.5, ROBOT.dof) * ROBOT.velocity_limits
        v = np.clip(v, -0.25 * ROBOT.velocity_limits, 0.25 * ROBOT.velocity_limits)
        nxt = np.clip(q + v / hz, ROBOT.lower + 0.2, ROBOT.upper - 0.2)
        if checker.is_valid(nxt[:5]) and checker.margin_measure(nxt[None, :5])[0] > 0.04:
            q = nxt
        else:
            v = -v
        out.append(q.copy())
    return out


class _NoLink:
    port = "none"
    firmware = None


def cost(plan: str | None, hz: float, n: int, seed: int = 1) -> dict[str, float]:
    """Per-target computation of the follower (its own ``_take``) on a walk of ``n`` targets at ``hz``."""
    checker = checker_of(plan)
    fol = Follower(_NoLink(), ROBOT, checker, source=None, config=FollowConfig(guard=GuardLimits(max_refusals=1000)))  # type: ignore[arg-type]
    fol.t0 = 0.0
    fol.guard = Guard(ROBOT, checker, fol.cfg.guard, start=START)
    fol.smoother = Smoother(ROBOT, START, fol.dt)
    wall, cpu = [], []
    for k, q in enumerate(walk(n, hz, seed, checker)):
        t = (k + 1) / hz
        w0, c0 = time.perf_counter(), time.process_time()
        fol._take([Target(t, q, t)])
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
        for _ in range(round(fol.cfg.rate / hz)):  # the set-points sent until the next target
            if fol.smoother.moving:
                fol.smoother.step()
    w = np.array(wall[1:]) * 1e3
    return {"first_ms": wall[0] * 1e3, "p50_ms": float(np.median(w)), "p99_ms": float(np.percentile(w, 99)),
            "max_ms": float(w.max()),
            "cpu_p50_ms": statistics.median(cpu[1:]) * 1e3, "cpu_p99_ms": float(np.percentile(cpu[1:], 99)) * 1e3,
            "cpu_max_ms": max(cpu[1:]) * 1e3,
            "refused": fol.guard.refused / n, "kinds": dict(fol.guard.by_kind)}


def swing(seconds: float) -> Guide:
    ts = np.arange(0.1, seconds + 2.0, 0.1)

    def c(t: float, f: float) -> float:
        return 0.5 * (1 - math.cos(2 * math.pi * f * t))

    qs = [HOME + [0.5 * c(t, 0.25), 0.15 * c(t, 0.125), -0.1 * c(t, 0.25), 0.3 * c(t, 0.25), 0.2 * c(t, 0.125),
                  0.4 * c(t, 0.25)] for t in ts]
    return Guide(ts, np.array(qs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--targets", type=int, default=400)
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--no-sim", action="store_true", help="only the per-target cost")
    a = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print("per target, ms (wall; cpu: this process's CPU time)")
    print(f"{'scene':16s} {'rate':>5s} {'first':>7s} {'p50':>7s} {'p99':>7s} {'max':>7s} {'cpu p50':>8s} {'cpu p99':>8s} "
          f"{'cpu max':>8s} {'refused':>8s}")
    for plan in (None, "pick_place.yaml", "obstacle.yaml"):
        for hz in (10.0, 30.0):
            r = cost(plan, hz, a.targets)
            print(f"{plan or 'no scene':16s} {hz:4.0f}Hz {r['first_ms']:7.2f} {r['p50_ms']:7.3f} {r['p99_ms']:7.3f} "
                  f"{r['max_ms']:7.2f} {r['cpu_p50_ms']:8.3f} {r['cpu_p99_ms']:8.3f} {r['cpu_max_ms']:8.3f} "
                  f"{r['refused']:8.1%} {r['kinds'] or ''}")
    if a.no_sim:
        return
    checker = checker_of("pick_place.yaml")
    done = follow_live(ROBOT, checker, sim=True, leader=LeaderSpec(guide=swing(a.seconds)),
                       config=FollowConfig(duration=a.seconds))
    trk = leader_tracking(done.recording, done.leader_recording)
    s = done.result.summary()
    print(f"clean simulated leader, {a.seconds:g} s: {s['targets']['accepted']} targets accepted, "
          f"{s['targets']['refused']} refused, {s['setpoints']} set-points")
    print(f"  tracking: latency {trk['latency_s'] * 1e3:.0f} ms, RMS {trk['rms_rad']:.4f} rad, max {trk['max_rad']:.4f} rad "
          f"(largest arm-joint error at that lag)")
    c = s["cost_ms"]
    print(f"  per target: {c['p50']:.3f} ms median, {c['p99']:.3f} ms p99, {c['max']:.3f} ms max")
    print(f"load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
