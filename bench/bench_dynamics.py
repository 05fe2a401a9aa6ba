"""roarmctl's inverse dynamics (the compiled Newton-Euler of src/roarmctl/_kernel.c) against Pinocchio's RNEA.

Run: .venv/bin/python bench/bench_dynamics.py [--states 2000] [--robots roarm_m3_pro roarm_m2_s ur10 planar_2r]
     [--venv /tmp/roarmctl-bench-pin]

An independent cross-check and a speed comparison, not a test: Pinocchio (PyPI ``pin``) is not a
dependency of roarmctl, so it lives in its own throwaway venv (created with pip on first use, reused
afterwards) and runs as a worker process fed over a pipe.

Each bundled robot with inertial data is exported here to a URDF with the same joint frames, axes and
inertials (a DH ``post`` becomes a fixed joint to the link, a joint offset is folded into the joint's
origin), Pinocchio builds its model from that file, and both sides compute the torques of the same
random states (q within the limits, qd in +-2 rad/s, qdd in +-4 rad/s^2, gravity 9.81 m/s^2 along -z).
Printed per robot: the largest torque difference (N m) and the largest torque, and the time per state:
roarmctl one state per call, roarmctl one batch of all states, Pinocchio ``pin.rnea`` one state per
call from Python (each side timed in its own process, medians of 5 repeats).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from peers import peer_python, urdf_origin

WORKER = r"""
import json, sys, time, statistics
import numpy as np
import pinocchio as pin
req = json.loads(sys.stdin.read())
model = pin.buildModelFromUrdf(req["urdf"])
data = model.createData()
names = req["joints"]
idx = []
for n in names:
    jid = model.getJointId(n)
    if jid >= model.njoints or model.joints[jid].nq != 1:
        raise SystemExit(f"joint {n} missing or not 1-dof in Pinocchio's model")
    idx.append(model.joints[jid].idx_q)
if model.nq != len(names):
    raise SystemExit(f"Pinocchio's model has nq = {model.nq}, roarmctl {len(names)} joints")
def to_pin(rows):
    out = np.zeros((len(rows), model.nq))
    out[:, idx] = np.asarray(rows)
    return out
q, qd, qdd = (to_pin(req[k]) for k in ("q", "qd", "qdd"))
tau = np.array([pin.rnea(model, data, a, b, c).copy() for a, b, c in zip(q, qd, qdd)])[:, idx]
times = []
for _ in range(5):
    t0 = time.perf_counter()
    for a, b, c in zip(q, qd, qdd):
        pin.rnea(model, data, a, b, c)
    times.append((time.perf_counter() - t0) / len(q))
print(json.dumps({"tau": tau.tolist(), "us": statistics.median(times) * 1e6, "version": pin.__version__}))
"""


def _motion(joint, value: float) -> np.ndarray:
    """The joint's motion by ``value`` (rad about its axis, or m along it) as a 4 x 4 transform."""
    m = np.eye(4)
    u = np.asarray(joint.axis, dtype=float)
    if joint.kind == "revolute":
        ux = np.array([[0, -u[2], u[1]], [u[2], 0, -u[0]], [-u[1], u[0], 0]])
        m[:3, :3] = np.eye(3) + math.sin(value) * ux + (1 - math.cos(value)) * ux @ ux
    elif joint.kind == "prismatic":
        m[:3, 3] = value * u
    return m


def export_urdf(robot, folder: Path) -> Path:
    """URDF with ``robot``'s joint frames, axes, limits and inertials (no geometry)."""
    if any(j.mimic for j in robot.joints):
        raise SystemExit(f"{robot.name}: mimic joints are not exported")
    links = [robot.root] + [j.child for j in robot.joints]
    out = [f'<robot name="{robot.name}">']
    joints = []
    for j in robot.joints:
        child = j.child
        if not np.allclose(j.post, np.eye(4)):  # DH: motion, then the fixed post to the link frame
            child = f"{j.child}__dh"
            links.append(child)
            joints.append(f'<joint name="{j.name}__post" type="fixed"><parent link="{child}"/><child link="{j.child}"/>'
                          f'{urdf_origin(j.post)}</joint>')
        body = f'<parent link="{j.parent}"/><child link="{child}"/>{urdf_origin(j.origin @ _motion(j, j.offset))}'
        if j.kind != "fixed":
            i = robot.joint_names.index(j.name)
            ax = " ".join(repr(float(v)) for v in j.axis)
            body += f'<axis xyz="{ax}"/><limit lower="{float(robot.lower[i])!r}" upper="{float(robot.upper[i])!r}" effort="10" velocity="1"/>'
        joints.append(f'<joint name="{j.name}" type="{j.kind}">{body}</joint>')
    for name in links:
        inn = robot.inertials.get(name)
        if inn is None:
            out.append(f'<link name="{name}"/>')
            continue
        cx, cy, cz = (float(v) for v in inn.com)
        i = [[float(v) for v in row] for row in np.asarray(inn.inertia, dtype=float)]
        out.append(f'<link name="{name}"><inertial><origin xyz="{cx!r} {cy!r} {cz!r}" rpy="0 0 0"/>'
                   f'<mass value="{float(inn.mass)!r}"/><inertia ixx="{i[0][0]!r}" ixy="{i[0][1]!r}" ixz="{i[0][2]!r}" '
                   f'iyy="{i[1][1]!r}" iyz="{i[1][2]!r}" izz="{i[2][2]!r}"/></inertial></link>')
    out += joints + ["</robot>"]
    path = folder / f"{robot.name}.urdf"
    path.write_text("\n".join(out))
    return path


def per_state_us(fn, n: int) -> float:
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t0) / n)
    return statistics.median(times) * 1e6


def main() -> None:
    from roarmctl.robot.dynamics import inverse_dynamics
    from roarmctl.robot.loader import load_robot

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--robots", nargs="+", default=["roarm_m3_pro", "roarm_m2_s", "ur10", "planar_2r"])
    parser.add_argument("--venv", type=Path, default=Path(tempfile.gettempdir()) / "roarmctl-bench-pin")
    args = parser.parse_args()
    py = peer_python(args.venv, ["pin"], "pin (Pinocchio)")
    print(f"{args.states} random states per robot; time per state in us (medians of 5 repeats)")
    print(f"{'robot':<14}{'max |tau diff| N m':>20}{'max |tau| N m':>15}{'ours 1/call':>13}{'ours batch':>12}{'pin 1/call':>12}")
    version = "?"
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.robots:
            robot = load_robot(name)
            if not robot.inertials:
                print(f"{name:<14}  no inertial data: skipped")
                continue
            rng = np.random.default_rng(0)
            n = args.states
            q = rng.uniform(np.maximum(robot.lower, -math.pi), np.minimum(robot.upper, math.pi), (n, robot.dof))
            qd, qdd = rng.uniform(-2, 2, (n, robot.dof)), rng.uniform(-4, 4, (n, robot.dof))
            urdf = export_urdf(robot, Path(tmp))
            req = {"urdf": str(urdf), "joints": list(robot.joint_names), "q": q.tolist(), "qd": qd.tolist(), "qdd": qdd.tolist()}
            proc = subprocess.run([str(py), "-c", WORKER], input=json.dumps(req), capture_output=True, text=True)
            if proc.returncode != 0:
                print(f"{name:<14}  Pinocchio failed: {proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else proc.returncode}")
                continue
            res = json.loads(proc.stdout)
            version = res["version"]
            ours = inverse_dynamics(robot, q, qd, qdd)
            diff = float(np.max(np.abs(ours - np.asarray(res["tau"]))))
            single = per_state_us(lambda robot=robot, q=q, qd=qd, qdd=qdd: [inverse_dynamics(robot, a, b, c) for a, b, c in zip(q, qd, qdd)], n)
            batch = per_state_us(lambda robot=robot, q=q, qd=qd, qdd=qdd: inverse_dynamics(robot, q, qd, qdd), n)
            print(f"{name:<14}{diff:>20.2e}{float(np.max(np.abs(ours))):>15.3g}{single:>13.2f}{batch:>12.3f}{res['us']:>12.2f}")
    print(f"Pinocchio {version}")


if __name__ == "__main__":
    main()
