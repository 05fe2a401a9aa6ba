"""Jerk-limited timing: what it costs, and the options compared on the bundled pick-and-place's motions.

Run: .venv/bin/python bench/bench_jerk.py [--repeats N]

For each rest-to-rest motion of plans/pick_place.yaml (scaled limits 0.6/0.6, the robot's jerk limits):
  toppra      TOPP-RA alone (bang-bang acceleration, jerk unbounded)
  toppra+fir  roarmctl's timing: TOPP-RA, then the moving-average (FIR) filter on s(t) plus the
              TOPP-RA bound on the path's own jerk term; the path is unchanged
  ruckig      Ruckig (a roarmctl dependency, used only for blended corners), time-optimal jerk-limited
              state-to-state with phase synchronisation: a straight line in JOINT space between the
              ends. It cannot follow a given path (the community version has no intermediate
              waypoints), so for a Cartesian line it leaves the TCP line (deviation printed) and for
              an OMPL path with detours it would leave the collision-checked corridor.
Printed: duration (s), timing time (ms, median), peak jerk / limit, TCP line deviation (mm).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from roarmctl.motion.cartesian import cartesian_line, line_deviation
from roarmctl.motion.pipeline import load_planning_libraries
from roarmctl.motion.timing import _ONE_JOINT_LINES, time_parameterise
from roarmctl.plan.schema import load_plan
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]


def motions(robot, plan):
    """(name, waypoints (K, n) over the moving joints, joint indices, straight TCP line or None)."""
    arm, gi = robot.arm_indices, robot.joint_index(robot.gripper.joint)
    home = robot.full_q(robot.named_poses["home"])
    cube = plan.objects[0].pose[:3, 3]
    above = cube + [0, 0, 0.06]
    q_above = solve_ik(robot, above, pitch=np.pi / 2, q_ref=home)
    q_above = np.asarray(q_above).reshape(-1)
    line = cartesian_line(robot, q_above, cube, pitch=np.pi / 2)
    return [
        ("transit (direct joint move)", np.array([home[arm], q_above[arm]]), arm, None),
        ("descent 6 cm (Cartesian line)", line[:, arm], arm, (above, cube)),
        ("gripper open 1.0 rad", np.array([[0.0], [1.0]]), [gi], None),
        ("gripper close 0.4 rad", np.array([[1.0], [0.6]]), [gi], None),
    ]


def ruckig_time(wps, v, a, j):
    from ruckig import InputParameter, Result, Ruckig, Synchronization, Trajectory

    n = wps.shape[1]
    inp = InputParameter(n)
    inp.current_position, inp.target_position = wps[0].tolist(), wps[-1].tolist()
    inp.current_velocity = inp.current_acceleration = inp.target_velocity = inp.target_acceleration = [0.0] * n
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = v.tolist(), a.tolist(), j.tolist()
    inp.synchronization = Synchronization.Phase
    traj = Trajectory(n)
    assert Ruckig(n).calculate(inp, traj) in (Result.Working, Result.Finished)
    return traj


def median_ms(fn, repeats):
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = fn()
        out.append(time.perf_counter() - t0)
    return r, statistics.median(out) * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    load_planning_libraries()
    robot = load_robot("roarm_m3_pro")
    plan = load_plan(ROOT / "plans" / "pick_place.yaml")
    vs, as_ = plan.limits.velocity_scale, plan.limits.acceleration_scale
    try:
        import ruckig  # noqa: F401
        have_ruckig = True
    except ImportError:
        have_ruckig = False
    print(f"{'motion':<31}{'option':<12}{'duration s':>11}{'time ms':>9}{'jerk/limit':>11}{'line dev mm':>12}")
    for name, wps, idx, line in motions(robot, plan):
        v, a, j = robot.velocity_limits[idx] * vs, robot.acceleration_limits[idx] * as_, robot.jerk_limits[idx]
        full = robot.full_q(robot.named_poses["home"])

        def dev(q, line=line, full=full, idx=idx):
            if line is None:
                return "-"
            qq = np.repeat(full[None, :], len(q), axis=0)
            qq[:, idx] = q
            return f"{line_deviation(robot, qq, *line) * 1000:.2f}"

        for option, jm in (("toppra", None), ("toppra+fir", j)):
            # each from scratch: timing.py keeps one-joint line timings (a plan's gripper moves reuse them)
            tp, ms = median_ms(lambda wps=wps, v=v, a=a, jm=jm: (_ONE_JOINT_LINES.clear(), time_parameterise(wps, v, a, jm))[1],
                               args.repeats)
            jerk = np.max(np.abs(np.diff(tp.qdd, axis=0)) / np.diff(tp.times)[:, None] / j)
            print(f"{name:<31}{option:<12}{tp.duration:>11.3f}{ms:>9.1f}{jerk:>11.2f}{dev(tp.q):>12}")
        if have_ruckig:
            traj, ms = median_ms(lambda wps=wps, v=v, a=a, j=j: ruckig_time(wps, v, a, j), args.repeats)
            t = np.arange(0.0, traj.duration, 0.01)
            q = np.array([traj.at_time(x)[0] for x in t] + [wps[-1].tolist()])
            acc = np.array([traj.at_time(x)[2] for x in t])
            jerk = np.max(np.abs(np.diff(acc, axis=0)) / 0.01 / j)
            print(f"{name:<31}{'ruckig':<12}{traj.duration:>11.3f}{ms:>9.2f}{jerk:>11.2f}{dev(q):>12}")
        else:
            print(f"{name:<31}{'ruckig':<12}{'(pip install ruckig to compare)':>43}")


if __name__ == "__main__":
    main()
