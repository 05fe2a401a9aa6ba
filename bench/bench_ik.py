"""Numerical IK (damped least squares) speed: per solve, per straight line, batched vs one start at a time.

Run: .venv/bin/python bench/bench_ik.py [--repeats 5] [--plan PLAN.yaml ...]
Robots: the bundled ``roarm_m3_pro`` (closed form, pitch 90 deg), ``ur10`` (position only: DLS),
``planar_2r`` and ``scara_2r``, and the 5-joint
hobby arm of tests/test_ik_generic.py (SO-100-like, boxes) with the tool pitch held (90 deg) and
without. Figures are medians over repeats, in ms, pinned to one core:
  solve_all   ``solve_ik(..., all_solutions=True)`` from the home pose (what the planner asks first);
              the solver's kept outcomes are dropped before every timed call (first solves)
  solve_one   ``solve_ik(...)`` (one solution)
  line 5 cm   ``cartesian_line``: a 5 cm descent sampled every 5 mm, each point seeded from the last
              (RoArm: ``LineIK``'s batch over the samples)
  1-by-1      the same samples as one ``solve_ik_near`` each from the previous solution (what
              ``cartesian_line`` did before ``LineIK``; same solutions)
  batch16 / seq16   ``dls_batch`` on 16 random starts at once / one start at a time
``--plan`` also plans each given plan file (``roarmctl.api.plan``, the kept DLS outcomes dropped before
each run) and prints the median planning time and its IK stage (e.g. a user's SO-100 plan; its
description is not bundled).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import importlib.util  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from roarmctl.motion.cartesian import cartesian_line  # noqa: E402
from roarmctl.robot.ik import pitch_aim, solve_ik, solve_ik_near  # noqa: E402
from roarmctl.robot.ik.dls import Aim, dls_batch  # noqa: E402
from roarmctl.robot.loader import load_robot  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def hobby_arm(folder: Path) -> str:
    """The test suite's SO-100-like arm, written to ``folder``; its sidecar path."""
    spec = importlib.util.spec_from_file_location("tig", ROOT / "tests/test_ik_generic.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    (folder / "hobby5.urdf").write_text(mod.URDF)
    (folder / "hobby5.yaml").write_text(yaml.safe_dump(mod.SIDECAR))
    return str(folder / "hobby5.yaml")


def median_ms(fn, repeats: int, robot=None) -> float:
    """Median wall time of ``fn()`` in ms; ``robot``'s kept DLS outcomes are dropped before each call
    (a first solve, not a repeat: see ``ik.dls.dls_solve``)."""
    out = []
    for _ in range(repeats):
        if robot is not None:
            robot.derived.pop("dls_memo", None)
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1000)
    return statistics.median(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--plan", nargs="*", default=[])
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
    hobby = load_robot(hobby_arm(Path(tempfile.mkdtemp())))
    ur10, planar, scara = load_robot("ur10"), load_robot("planar_2r"), load_robot("scara_2r")
    roarm = load_robot("roarm_m3_pro")
    cases = [  # (label, robot, target, pitch)
        ("roarm pitch 90 deg", roarm, np.array([0.25, 0.1, 0.03]), math.pi / 2),
        ("ur10 position only", ur10, ur10.kin.fk(np.radians([10, 30, 40, -20, 50, 10]))[:3, 3], None),
        ("planar_2r", planar, planar.kin.fk([0.3, 0.9])[:3, 3], None),
        ("scara_2r", scara, scara.kin.fk([0.3, 0.9])[:3, 3], None),
        ("hobby5 position only", hobby, np.array([0.2, 0.05, 0.01]), None),
        ("hobby5 pitch 90 deg", hobby, np.array([0.2, 0.05, 0.01]), math.pi / 2),
    ]
    print(f"{'case':24s} {'solve_all':>10s} {'solve_one':>10s} {'line 5 cm':>10s} {'1-by-1':>9s} {'batch16':>9s} "
          f"{'seq16':>9s}")
    for label, r, p, pitch in cases:
        home = r.full_q(r.named_poses.get("home", np.zeros(r.arm_dof)))
        all_ms = median_ms(lambda r=r, p=p, pitch=pitch, home=home: solve_ik(r, p, pitch=pitch, q_ref=home, all_solutions=True),
                           args.repeats, r)
        one_ms = median_ms(lambda r=r, p=p, pitch=pitch, home=home: solve_ik(r, p, pitch=pitch, q_ref=home), args.repeats, r)
        line = one_by_one = "-"
        if r is hobby or r is roarm:
            q0 = solve_ik(r, p + [0, 0, 0.05], pitch=pitch, q_ref=home)[0]
            line = f"{median_ms(lambda r=r, q0=q0, p=p, pitch=pitch: cartesian_line(r, q0, p, pitch=pitch), args.repeats, r):10.1f}"
            pts = cartesian_line(r, q0, p, pitch=pitch)[1:]
            pts = r.kin.fk(pts)[:, :3, 3]

            def seq(r=r, q0=q0, pts=pts, pitch=pitch):
                prev = q0
                for x in pts:
                    prev = solve_ik_near(r, x, prev, pitch=pitch)
            one_by_one = f"{median_ms(seq, args.repeats, r):9.1f}"
        arm = r.arm_indices
        if r is roarm:  # closed form: no DLS batches
            print(f"{label:24s} {all_ms:10.1f} {one_ms:10.1f} {line:>10s} {one_by_one:>9s} {'-':>9s} {'-':>9s}")
            continue
        rng = np.random.default_rng(0)
        starts = np.array([r.full_q(rng.uniform(r.lower[arm], r.upper[arm])) for _ in range(16)])
        aim = pitch_aim(r, p, pitch, None, None) if pitch is not None else Aim()
        lo, hi = r.lower[arm], r.upper[arm]
        b_ms = median_ms(lambda r=r, starts=starts, p=p, aim=aim, lo=lo, hi=hi: dls_batch(r, starts, p, aim, lo, hi), args.repeats)
        s_ms = median_ms(lambda r=r, starts=starts, p=p, aim=aim, lo=lo, hi=hi: [dls_batch(r, starts[i:i + 1], p, aim, lo, hi)
                                                                               for i in range(16)], args.repeats)
        print(f"{label:24s} {all_ms:10.1f} {one_ms:10.1f} {line:>10s} {one_by_one:>9s} {b_ms:9.1f} {s_ms:9.1f}")
    if args.plan:
        import roarmctl.api as rc
        from roarmctl.robot import loader

        print(f"\n{'plan':40s} {'planning ms':>12s} {'ik ms':>9s}")
        for path in args.plan:
            tot, ik = [], []
            for _ in range(args.repeats):
                for robot, _ in loader._CACHE.values():  # loaded once per process: drop the kept DLS outcomes
                    robot.derived.pop("dls_memo", None)
                t = time.perf_counter()
                res = rc.plan(path)
                tot.append((time.perf_counter() - t) * 1000)
                ik.append(res.timings.get("ik", 0.0) * 1000)
            print(f"{path[-40:]:40s} {statistics.median(tot):12.0f} {statistics.median(ik):9.0f}")


if __name__ == "__main__":
    main()
