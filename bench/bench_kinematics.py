"""FK, Jacobian, TCP velocity, inverse dynamics and IK throughput for a bundled robot (default roarm_m3_pro),
configurations per second.

Run: .venv/bin/python bench/bench_kinematics.py [--robot NAME] [--repeats N]

"single" calls the function once per configuration in a Python loop; "batch N" passes an (N, dof)
array in one call. Each figure is the median over the repeats of (configurations / wall time);
random configurations within the joint limits, fixed seed (rates and accelerations uniform in +-1 rad/s,
+-2 rad/s^2). Inverse dynamics is skipped for robots without inertial data. IK: one closed-form/DLS solve
per target.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from roarmctl.robot.loader import load_robot


def rate(fn, n_configs: int, repeats: int) -> float:
    """Median configurations per second of ``fn()`` (which handles ``n_configs`` configurations)."""
    fn()  # warm-up
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        rates.append(n_configs / (time.perf_counter() - t0))
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="roarm_m3_pro")
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    robot = load_robot(args.robot)
    rng = np.random.default_rng(0)
    lo, hi = np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi)
    qs = {n: rng.uniform(lo, hi, size=(n, robot.dof)) for n in (1000, 10000)}
    single = qs[1000][:500]
    kin = robot.kin

    print(f"{robot.name}: {robot.dof} joints, {len(robot.link_names)} links; medians of {args.repeats} repeats")
    print(f"{'operation':<34}{'configs/s':>14}{'us/config':>12}")

    def show(label: str, r: float) -> None:
        print(f"{label:<34}{r:>14,.0f}{1e6 / r:>12.2f}")

    show("FK (TCP) single-call loop", rate(lambda: [kin.fk(q) for q in single], len(single), args.repeats))
    for n in (1000, 10000):
        show(f"FK (all links) batch {n}", rate(lambda n=n: kin.link_frames(qs[n]), n, args.repeats))
    show("Jacobian single-call loop", rate(lambda: [kin.jacobian(q) for q in single], len(single), args.repeats))
    for n in (1000, 10000):
        show(f"Jacobian batch {n}", rate(lambda n=n: kin.jacobian(qs[n]), n, args.repeats))

    qd = {n: rng.uniform(-1, 1, size=(n, robot.dof)) for n in (1000, 10000)}
    qdd = {n: rng.uniform(-2, 2, size=(n, robot.dof)) for n in (1000, 10000)}
    arm = robot.arm_indices
    show("TCP velocity batch 1000", rate(lambda: kin.tcp_velocity(qs[1000], qd[1000][:, arm]), 1000, args.repeats))
    if robot.inertials:
        from roarmctl.robot.dynamics import inverse_dynamics

        show("inverse dynamics single-call loop",
             rate(lambda: [inverse_dynamics(robot, q, v, a) for q, v, a in zip(single, qd[1000], qdd[1000])],
                  len(single), args.repeats))
        for n in (1000, 10000):
            show(f"inverse dynamics batch {n}", rate(lambda n=n: inverse_dynamics(robot, qs[n], qd[n], qdd[n]), n, args.repeats))
        show("holding torques (at rest) batch 1000",
             rate(lambda: inverse_dynamics(robot, qs[1000], 0 * qd[1000], 0 * qdd[1000]), 1000, args.repeats))

    from roarmctl.errors import UnreachableError
    from roarmctl.robot.ik import solve_ik
    from roarmctl.robot.model import rpy_from_matrix

    targets = kin.fk(qs[1000][:100])
    if robot.singularity_model == "roarm5":
        def pitch(t):
            a, p = t[:3, 0], t[:3, 3]
            u = p[:2] / np.hypot(p[0], p[1])
            return float(np.arctan2(-a[2], a[:2] @ u))

        args_ik = [(t[:3, 3], dict(pitch=pitch(t))) for t in targets]
        label = "IK position + pitch, all branches"
    else:
        args_ik = [(t[:3, 3], dict(rpy=rpy_from_matrix(t[:3, :3]))) for t in targets]
        label = "IK full pose, all solutions"

    def ik_all() -> None:
        for p, kw in args_ik:
            try:
                solve_ik(robot, p, all_solutions=True, **kw)
            except UnreachableError:
                pass

    show(label, rate(ik_all, len(args_ik), max(3, args.repeats // 2)))


if __name__ == "__main__":
    main()
