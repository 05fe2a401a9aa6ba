"""Physics benchmark: every bundled plan planned and played into the MuJoCo model (`roarmctl simulate`).

    .venv/bin/python bench/bench_physics.py [--repeats 3] [--stiffness 0.5,1,1.5,2,2.5]

Per plan, as execute sends it by default (sag compensation on: goals offset by the servos' sag under
gravity and payload) and with ``--no-sag``: each picked object's placement error (mm, deg) against its place pose, the TCP
tracking error (RMS, max) and the largest sag at rest (mm), unintended contacts, and the real-time
factor (simulated seconds per wall second, and per second of the simulating thread's CPU time; medians over
the repeats). The simulation is one thread: on a 2-core machine shared with other work the wall figure
includes waiting for a core, the CPU figure is what one free core gives. Target (issue 23): every object
placed within 10 mm, no unintended contact, real-time factor above 5 (checked on the CPU figure; both printed).

``--stiffness``: the payload plan again on servos whose position loop is that many times as stiff as the
model the compensation assumes (the real ST3235's stiffness is known from one sister-servo measurement,
docs/physics.md): the weight's placement error and the TCP's sag while it is held, compensated and not.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--stiffness", default="", help="comma-separated stiffness factors for the payload study")
    ap.add_argument("--friction", default="", help="comma-separated sliding friction coefficients for the grip study "
                                                   "(alone: only that study)")
    args = ap.parse_args()
    if args.friction:
        friction_study([float(v) for v in args.friction.split(",")])
        if not args.stiffness:
            return 0
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.report import measure
    from roarmctl.physics.run import Options, simulate
    from roarmctl.robot.loader import load_robot

    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; MuJoCo time step 1 ms; {args.repeats} repeats")
    print(f"{'plan':16} {'sag comp.':9} {'object':8} {'placed':>6} {'error mm':>9} {'deg':>6} {'TCP RMS':>8} {'max':>6} "
          f"{'sag':>5} {'contacts':>8} {'sim s':>6} {'wall s':>7} {'RTF':>6} {'CPU RTF':>7}")
    worst_rtf = worst_cpu = float("inf")
    ok = {False: True, True: True}
    with tempfile.TemporaryDirectory() as tmp:
        for plan in sorted((ROOT / "plans").glob("*.yaml")):
            traj = plan_file(plan, seed=None).trajectory
            path = Path(tmp) / f"{plan.stem}.traj.json"
            traj.save(path)
            from roarmctl.motion.validate import validate_trajectory

            traj = validate_trajectory(path)
            robot = load_robot(traj.robot)
            for sag in (True, False):
                opts = Options(sag=sag)
                rtfs, cpus, rep = [], [], None
                for _ in range(args.repeats):
                    setup, rec = simulate(traj, robot, opts)
                    rep = measure(traj, robot, setup, rec, opts)
                    rtfs.append(rep["run"]["simulated_s"] / rep["run"]["wall_s"])
                    cpus.append(rep["run"]["simulated_s"] / max(rep["run"]["cpu_s"], 1e-9))
                rtf, cpu = statistics.median(rtfs), statistics.median(cpus)
                worst_rtf, worst_cpu = min(worst_rtf, rtf), min(worst_cpu, cpu)
                ok[sag] &= rep["ok"]
                tcp = rep["tcp"]
                for k, o in enumerate(rep["objects"] or [{"name": "-", "placed": True, "error_mm": 0.0, "error_deg": 0.0}]):
                    lead = (f"{tcp['rms_mm']:8.1f} {tcp['max_mm']:6.1f} {tcp['sag_mm'] or 0:5.1f} {len(rep['contacts']):8d} "
                            f"{rep['run']['simulated_s']:6.2f} {rep['run']['wall_s']:7.2f} {rtf:6.1f} {cpu:7.1f}") if k == 0 else ""
                    print(f"{plan.stem if k == 0 and sag else '':16} {('on' if sag else '--no-sag') if k == 0 else '':9} "
                          f"{o['name']:8} {'yes' if o['placed'] else 'NO':>6} {o['error_mm']:9.1f} {o['error_deg']:6.1f} {lead}")
    print(f"slowest real-time factor {worst_cpu:.1f} on the CPU time of one core (target > 5), {worst_rtf:.1f} on the wall clock "
          f"at load average {os.getloadavg()[0]:.1f}; every object placed, no unintended contact: "
          f"{ok[True]} as execute sends by default, {ok[False]} with --no-sag")
    if args.stiffness:
        stiffness_study([float(v) for v in args.stiffness.split(",")])
    return 0 if ok[True] and worst_cpu > 5 else 1


def stiffness_study(factors: list[float]) -> None:
    """The payload plan on servos ``factor`` times as stiff as the model (every servo's loop gain scaled),
    compensated (as the model predicts the sag) and not."""
    from dataclasses import replace

    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.report import measure
    from roarmctl.physics.run import Options, simulate
    from roarmctl.physics.setup import build
    from roarmctl.robot.loader import load_robot

    traj = plan_file(ROOT / "plans" / "payload.yaml", seed=None).trajectory
    robot = load_robot(traj.robot)
    print("\npayload (0.2 kg) on servos of another stiffness than the compensation assumes")
    print(f"{'stiffness':>9} {'sag comp.':9} {'placed':>6} {'error mm':>9} {'held: off mm':>12} {'below mm':>9}")
    for f in factors:
        for sag in (True, False):
            setup = build(traj, robot)
            bank = setup.actuation.bank
            bank.spec = [replace(spec, kp=spec.kp * f) for spec in bank.spec]
            opts = Options(sag=sag)
            setup, rec = simulate(traj, robot, opts, setup=setup)
            rep = measure(traj, robot, setup, rec, opts)
            (o,) = rep["objects"]
            held = next(r for r in rep["tcp"]["rests"] if r["label"].endswith("wait 0.5 s"))
            print(f"{f:9.2f} {'on' if sag else '--no-sag':9} {'yes' if o['placed'] else 'NO':>6} {o['error_mm']:9.1f} "
                  f"{held['error_mm']:12.1f} {held['below_mm']:9.1f}")


def friction_study(coefficients: list[float]) -> None:
    """The pick-and-place and the payload plan with every contact's sliding friction set to each coefficient (the
    model assumes 0.6): where the grip starts to fail, i.e. the margin the assumed friction has."""
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.report import measure
    from roarmctl.physics.run import Options, simulate
    from roarmctl.physics.setup import build
    from roarmctl.robot.loader import load_robot

    print("\nthe grip against friction (every contact's sliding coefficient; the model assumes 0.6)")
    print(f"{'plan':12} {'friction':>8} {'lifted':>6} {'placed':>6} {'error mm':>9}")
    for name in ("pick_place", "payload"):
        traj = plan_file(ROOT / "plans" / f"{name}.yaml", seed=None).trajectory
        robot = load_robot(traj.robot)
        for mu in coefficients:
            setup = build(traj, robot)
            setup.world.model.geom_friction[:, 0] = mu
            opts = Options()
            setup, rec = simulate(traj, robot, opts, setup=setup)
            rep = measure(traj, robot, setup, rec, opts)
            (o,) = rep["objects"]
            print(f"{name:12} {mu:8.2f} {'yes' if o['lifted'] else 'NO':>6} {'yes' if o['placed'] else 'NO':>6} "
                  f"{o['error_mm']:9.1f}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
