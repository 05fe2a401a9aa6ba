"""Does a looser TCP speed limit ever give a longer motion? (issue 39: the timing stage's search, seen from outside)

Run: .venv/bin/python bench/bench_tcp_monotone.py [--part sweep,trace,random,plans]

* sweep: tests/test_timing.py's slowed-a-lot waypoints (RoArm-M3 arm, its rounded limits) timed by
  ``time_parameterise`` at TCP limits 0.100-0.200 m/s in steps of 1 mm/s: the duration, the jerk filter's width, and
  each duration's excess over the shortest at any tighter limit (flagged over 0.5 %).
* trace: the same waypoints at 0.124 and 0.125 m/s, margin by margin of ``timing.SAFETY_STEPS``: TOPP-RA's time, the
  narrowest filter width w0, which construction the jerk filter returned (the widened filter or the cruise of
  ``jerk_filter._plateau``), the result's end before and after the slowing down in time (``slowed_by``).
* random: RoArm-M3 arm paths drawn as tests/test_timing_properties.py draws them (2-5 waypoints, sometimes a short
  segment in the middle, joint limits scaled 0.3-1, jerk limits 0.2-1), each at a TCP limit L0 of 5-30 cm/s and at
  L0 x 1.01 ... 1.10: the cases where a looser limit is longer than a tighter one by over 0.2 %, and the worst.
* plans: bundled plans (seed 1) with ``limits.max_tcp_speed`` set to 0.15-0.35 m/s.

Durations are functions of the inputs, not of the machine: the same on an idle or a busy one. Nothing is timed.
"""

from __future__ import annotations

import argparse
import copy
from pathlib import Path

import numpy as np
import yaml

import roarmctl.motion.jerk_filter as jerk_filter
import roarmctl.motion.timing as timing
from roarmctl.motion.timing import time_parameterise
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]
ROBOT = load_robot("roarm_m3_pro")
ARM = list(ROBOT.arm_indices)
# tests/test_timing.py, test_a_result_slowed_down_a_lot_is_compared_with_the_next_margin
WP = np.array([[0.8171, -0.2311, 0.5175, -0.3131, 0.6578], [1.1758, -0.0234, 0.6107, -0.4982, 0.9665],
               [0.9675, 0.4141, 0.4426, -0.3698, 0.5196], [1.1448, 0.8314, 0.6448, -0.4192, 0.6398],
               [1.0165, 1.1818, 0.2470, -0.8313, 0.4386]])
VMAX, AMAX = np.array([1.792, 1.344, 1.613, 1.971, 2.240]), np.array([4.835, 3.868, 4.835, 5.802, 5.802])
JMAX = np.array([11.40, 9.12, 11.40, 13.69, 13.69])


def timed(wp: np.ndarray, vmax: np.ndarray, amax: np.ndarray, jmax: np.ndarray, limit: float,
          grip: float = 0.0) -> timing.TimedPath:
    """``time_parameterise`` of arm waypoints ``wp`` (K, 5) under a TCP speed ``limit`` (m/s), the gripper at ``grip``
    rad (tests/test_timing.py holds it at 0, tests/test_timing_properties.py at 0.5)."""
    def tcp_velocity(qa: np.ndarray, dqa: np.ndarray) -> np.ndarray:
        full = np.zeros((len(qa), ROBOT.dof))
        full[:, -1] = grip
        full[:, ARM] = qa
        return ROBOT.kin.tcp_velocity(full, dqa)

    return time_parameterise(wp, vmax, amax, jmax, tcp_velocity_per_ds=tcp_velocity, max_tcp_speed=float(limit))


def excess(durations: list[float]) -> np.ndarray:
    """Each duration's share over the shortest at any tighter limit (the list in order of looser limits)."""
    d = np.asarray(durations)
    return d / np.minimum.accumulate(d) - 1.0


def sweep() -> None:
    limits = np.round(np.arange(0.100, 0.2005, 0.001), 3)
    rows = [timed(WP, VMAX, AMAX, JMAX, lim) for lim in limits]
    ex = excess([r.duration for r in rows])
    for lim, r, e in zip(limits, rows, ex):
        print(f"  {lim:.3f} m/s  {r.duration:7.3f} s  filter {r.jerk_filter:.3f} s" + (f"  +{e:.1%} over a tighter limit" if e > 0.005 else ""))
    print(f"sweep: worst excess {ex.max():.2%} at {limits[int(np.argmax(ex))]:.3f} m/s; {int(np.sum(ex > 0.005))} of {len(limits)} limits over 0.5 %")


def trace() -> None:
    log: list[str] = []
    real_filtered, real_sampled, real_plateau = timing.jerk_filtered, timing.sampled_within_limits, jerk_filter._plateau

    def plateau(*args):
        out = real_plateau(*args)
        log.append("cruise fails" if out is None else f"cruise passes (end {out[0].T + out[1]:.3f} s)")
        return out

    def filtered(algo, constraints, path, grid, prof, alim, jm, alim_known):
        out = real_filtered(algo, constraints, path, grid, prof, alim, jm, alim_known)
        w0 = max(float(np.max(alim / jm)), 2 * jerk_filter.FINE_DT)
        log.append(f"TOPP-RA {prof.T:.3f} s, w0 {w0:.3f} s -> " + ("none" if out is None else f"filter {out[1]:.3f} s"))
        return out

    def sampled(path, prof, w, *args):
        out = real_sampled(path, prof, w, *args)
        log.append(f"end {prof.T + w:.3f} s, slowed by {out[5]:.3f} -> {out[0].T + out[1]:.3f} s")
        return out

    timing.jerk_filtered, timing.sampled_within_limits, jerk_filter._plateau = filtered, sampled, plateau
    try:
        for lim in (0.124, 0.125):
            log.clear()
            r = timed(WP, VMAX, AMAX, JMAX, lim)
            print(f"trace {lim:.3f} m/s -> {r.duration:.3f} s:")
            margin = iter(timing.SAFETY_STEPS)
            for line in log:
                print(f"    margin {next(margin)}: {line}" if line.startswith("TOPP") else f"      {line}")
    finally:
        timing.jerk_filtered, timing.sampled_within_limits, jerk_filter._plateau = real_filtered, real_sampled, real_plateau


def roarm_case(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """Waypoints (K, 5), vmax, amax, jmax (5,) and a TCP limit (m/s), drawn as tests/test_timing_properties.py draws."""
    lo, hi = np.maximum(ROBOT.lower[ARM], -2.5), np.minimum(ROBOT.upper[ARM], 2.5)
    k = int(rng.integers(2, 6))
    first = rng.uniform(lo + 0.2, hi - 0.2)
    wp = np.clip(first + np.cumsum(np.vstack([np.zeros(5), rng.uniform(-0.5, 0.5, (k - 1, 5))]), axis=0), lo, hi)
    if k >= 3 and rng.random() < 0.5:
        wp = np.insert(wp, 2, wp[1] + rng.uniform(-1, 1, 5) * 10 ** rng.uniform(-3, -2), axis=0)
    vmax = ROBOT.velocity_limits[ARM] * rng.uniform(0.3, 1.0)
    amax = ROBOT.acceleration_limits[ARM] * rng.uniform(0.3, 1.0)
    jmax = ROBOT.jerk_limits[ARM] * rng.uniform(0.2, 1.0)
    return wp, vmax, amax, jmax, float(rng.uniform(0.05, 0.3))


def random_cases(seeds: tuple[int, ...] = (11, 12, 13), cases: int = 30) -> None:
    worst = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        for case in range(cases):
            wp, vmax, amax, jmax, lim0 = roarm_case(rng)
            factors = 1 + np.arange(0, 0.1001, 0.01)
            ex = excess([timed(wp, vmax, amax, jmax, lim0 * f, grip=0.5).duration for f in factors])
            worst.append(ex.max())
            if ex.max() > 0.002:
                print(f"  seed {seed} case {case}: L0 {lim0:.4f} m/s, +{ex.max():.2%} at L0 x {factors[int(np.argmax(ex))]:.2f}")
    w = np.array(worst)
    print(f"random: {len(w)} paths x 11 limits; over 0.2 %: {int(np.sum(w > 0.002))}, over 1 %: {int(np.sum(w > 0.01))}, "
          f"worst {w.max():.2%}")


def plans() -> None:
    from roarmctl.motion.pipeline import load_planning_libraries, plan_file

    load_planning_libraries()
    for name in ("obstacle", "pick_place", "multi_object"):
        doc = yaml.safe_load((ROOT / "plans" / f"{name}.yaml").read_text())
        limits = np.round(np.arange(0.15, 0.3501, 0.02), 3)
        durations = []
        for lim in limits:
            d = copy.deepcopy(doc)
            d["limits"]["max_tcp_speed"] = float(lim)
            durations.append(plan_file(d, seed=1, base_dir=ROOT / "plans").trajectory.duration)
        ex = excess(durations)
        print(f"plans {name}: " + ", ".join(f"{lim:.2f} {d:.3f}" + ("(!)" if e > 0.005 else "") for lim, d, e in zip(limits, durations, ex))
              + f"; worst excess {ex.max():.2%}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="sweep,trace,random,plans")
    parts = ap.parse_args().part.split(",")
    for name, fn in (("sweep", sweep), ("trace", trace), ("random", random_cases), ("plans", plans)):
        if name in parts:
            fn()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
