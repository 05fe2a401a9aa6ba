"""`roarmctl plan` end to end, verified independently of the planner.

Every bundled example plan is planned once, when a test first reads it (module fixture); the written trajectory files are
then checked with means the planner does not use: python-fcl called directly on boxes built from
the robot description and the generic (non-lean) FK at 5x the output rate, the plan's own target
coordinates, finite differences of FK for the TCP speed, and the scaled limits.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
from pathlib import Path

import fcl
import numpy as np
import pytest

from roarmctl.motion.validate import load_trajectory
from roarmctl.plan.schema import load_plan
from roarmctl.plan.types import PickTask, PlaceTask
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[1]
PLANS = sorted((ROOT / "plans").glob("*.yaml"))


from clirun import Result, roarmctl  # noqa: E402  (in-process; the tests of the process itself start one)


class _Planned(dict):
    """A bundled plan planned by ``roarmctl plan`` the first time a test reads it (name -> (trajectory file, the
    command's JSON summary)), then kept: a worker plans only the plans its tests read (the busy-cores test reads
    obstacle alone; it planned all six, 0.8 s of CPU, on a worker of its own)."""

    def __init__(self, folder: Path) -> None:
        super().__init__()
        self.folder = folder

    def __missing__(self, name: str) -> tuple[Path, dict]:
        (plan,) = [p for p in PLANS if p.stem == name]
        target = self.folder / f"{name}.traj.json"
        proc = roarmctl("plan", str(plan), "-o", str(target), "--json")
        assert proc.returncode == 0, proc.stderr
        self[name] = (target, json.loads(proc.stdout))
        return self[name]


@pytest.fixture(scope="module")
def planned(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    """Each bundled plan planned once, when first read (``_Planned``)."""
    return _Planned(tmp_path_factory.mktemp("plans"))


@pytest.mark.slow
@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_every_example_plan_is_planned(planned):
    assert {p.stem for p in PLANS} >= {"pick_place", "obstacle", "multi_object"}
    for path, summary in (planned[p.stem] for p in PLANS):
        assert summary["ok"] and Path(summary["output"]) == path and path.is_file()
        traj = load_trajectory(path)
        assert summary["duration"] == pytest.approx(traj.duration)
        assert traj.times[0] == 0.0 and np.all(np.diff(traj.times) > 0)
        assert np.allclose(traj.velocities[[0, -1]], 0.0)
        from roarmctl.motion.validate import validate_trajectory

        validate_trajectory(path)  # what execute accepts: the planner's output passes the one validator


def _box(size) -> fcl.CollisionObject:
    return fcl.CollisionObject(fcl.Box(*size), fcl.Transform())


def _scene_objects(scene: dict, roles: tuple[str, ...]) -> list[tuple[str, str, fcl.CollisionObject]]:
    from roarmctl.robot.model import transform

    out = []
    for item in scene["items"]:
        if item["role"] not in roles:
            continue
        if item["shape"] == "box":
            geom = fcl.Box(*item["size"])
        elif item["shape"] == "cylinder":
            geom = fcl.Cylinder(item["radius"], item["length"])
        else:
            geom = fcl.Sphere(item["radius"])
        t = transform(item["xyz"], item["rpy"])
        out.append((item["name"], item["role"], fcl.CollisionObject(geom, fcl.Transform(t[:3, :3], t[:3, 3]))))
    return out


def _first_contact(robot, q: np.ndarray, scene: dict) -> tuple[float, str] | None:
    """Arm links vs table and obstacles, python-fcl directly, generic FK, no padding."""
    frames = robot.kin.link_frames(q)
    statics = _scene_objects(scene, ("table", "obstacle"))
    links = [(s, _box(s.size)) for s in robot.collision if s.kind == "box"]
    assert len(links) == len(robot.collision)
    for k in range(len(q)):
        for shape, obj in links:
            if shape.link in ("world", "base_link", "link1"):
                continue  # stands on the table by construction
            t = frames[k, robot.kin.link_index[shape.link]] @ shape.origin
            obj.setTransform(fcl.Transform(t[:3, :3], t[:3, 3]))
            for name, _, other in statics:
                if fcl.collide(obj, other, fcl.CollisionRequest(), fcl.CollisionResult()):
                    return k, f"{shape.name} hits {name}"
    return None


def _fine(q: np.ndarray, substeps: int) -> np.ndarray:
    t = np.linspace(0, len(q) - 1, (len(q) - 1) * substeps + 1)
    i = np.minimum(t.astype(int), len(q) - 2)
    f = (t - i)[:, None]
    return q[i] * (1 - f) + q[i + 1] * f


@pytest.mark.slow
@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
@pytest.mark.parametrize("name", ["pick_place", "obstacle", "multi_object"])
def test_samples_are_within_limits_and_collision_free(planned, name):
    traj = load_trajectory(planned[name][0])
    robot = load_robot(traj.robot)
    assert np.all(traj.positions >= robot.lower - 1e-9) and np.all(traj.positions <= robot.upper + 1e-9)
    vmax = np.array(traj.limits["velocity"]) * traj.limits["velocity_scale"]
    amax = np.array(traj.limits["acceleration"]) * traj.limits["acceleration_scale"]
    assert np.allclose(vmax, robot.velocity_limits * load_plan(ROOT / "plans" / f"{name}.yaml").limits.velocity_scale)
    assert np.all(np.abs(traj.velocities) <= vmax + 1e-6)
    assert np.all(np.abs(traj.accelerations) <= amax + 1e-6)
    # finer than the planner's own 4x re-check, and with other code
    hit = _first_contact(robot, _fine(traj.positions, 5), traj.scene)
    assert hit is None, f"{name}: collision at fine sample {hit}"


@pytest.mark.slow
@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_the_obstacle_forces_a_detour(planned):
    """In obstacle.yaml the wall stands between pick and place: the TCP must pass above or around it."""
    traj = load_trajectory(planned["obstacle"][0])
    robot = load_robot(traj.robot)
    wall = next(i for i in traj.scene["items"] if i["name"] == "wall")
    tcp = robot.kin.fk(traj.positions)[:, :3, 3]
    crossing = np.abs(tcp[:, 1] - wall["xyz"][1]) < 0.01  # the TCP passes the wall's plane y = 0
    assert crossing.any()
    top = wall["xyz"][2] + wall["size"][2] / 2
    radial = np.hypot(tcp[crossing, 0], tcp[crossing, 1])
    front = wall["xyz"][0] - wall["size"][0] / 2
    back = wall["xyz"][0] + wall["size"][0] / 2
    assert np.all((tcp[crossing, 2] > top) | (radial < front) | (radial > back))


@pytest.mark.slow
@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
@pytest.mark.parametrize("name", ["pick_place", "obstacle", "multi_object"])
def test_objects_sit_against_the_fixed_jaw_and_reach_their_place(planned, name):
    """The RoArm's jaws: one fixed (its face in the description), one swinging toward it. At a grasp the
    object's side lies 1 mm from the fixed face with the face's normal through its centre (a box: across
    its narrow side); carried rigidly with the TCP, its centre reaches the place's xyz at the release."""
    plan = load_plan(ROOT / "plans" / f"{name}.yaml")
    traj = load_trajectory(planned[name][0])
    robot = load_robot(traj.robot)
    jaw = robot.gripper.fixed_jaw
    specs = {o.name: o for o in plan.objects}
    expected = []
    for task in plan.tasks * plan.cycles:
        if isinstance(task, PickTask):
            expected.append(("grasp", task.object))
        elif isinstance(task, PlaceTask):
            expected.append(("release", np.asarray(task.xyz)))
    assert [e.kind for e in traj.events] == [k for k, _ in expected]
    held = None
    for event, (_, target) in zip(traj.events, expected):
        k = int(np.argmin(np.abs(traj.times - event.time)))
        tcp = robot.kin.fk(traj.positions[k])
        if event.kind == "grasp":
            spec = specs[target]
            centre = spec.pose[:3, 3] + [0, 0, next(t for t in plan.tasks if isinstance(t, PickTask) and t.object == target).grasp_offset]
            width = min(spec.size[:2]) if spec.shape == "box" else 2 * spec.radius
            link = robot.kin.fk(traj.positions[k], jaw.link)
            n = link[:3, :3] @ np.asarray(jaw.normal)
            face = link[:3, :3] @ np.asarray(jaw.point) + link[:3, 3]
            assert abs(float(n @ (centre - face)) - (width / 2 + 0.001)) < 2e-4, event
            lateral = (centre - tcp[:3, 3]) - n * float(n @ (centre - tcp[:3, 3]))
            assert np.linalg.norm(lateral) < 5e-4, event  # the face's normal through the centre passes the TCP
            if spec.shape == "box":  # the jaws close across a box side: the normal is one of its axes
                assert np.max(np.abs(spec.pose[:3, :3].T @ n)) > 0.9999, event
            held = tcp[:3, :3].T @ (centre - tcp[:3, 3])
        else:
            carried = tcp[:3, :3] @ held + tcp[:3, 3]
            assert np.linalg.norm(carried - target) < 0.002, (event, carried, target)
        # the gripper closes on grasp and opens on release
    gi = robot.joint_index(robot.gripper.joint)
    for event in traj.events:
        k = int(np.argmin(np.abs(traj.times - event.time)))
        before = traj.positions[max(k - 30, 0), gi]
        if event.kind == "grasp":
            assert traj.positions[k, gi] < before
        else:
            assert traj.positions[k, gi] > before


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_cartesian_segments_follow_the_line_within_1mm(planned):
    for name in ("pick_place", "multi_object"):
        traj = load_trajectory(planned[name][0])
        robot = load_robot(traj.robot)
        lines = [s for s in traj.segments if s.kind == "cartesian"]
        assert len(lines) >= 4
        for seg in lines:
            sel = (traj.times >= seg.start - 1e-9) & (traj.times <= seg.end + 1e-9)
            p = robot.kin.fk(traj.positions[sel])[:, :3, 3]
            a, b = p[0], p[-1]
            d = (b - a) / np.linalg.norm(b - a)
            off = (p - a) - np.outer((p - a) @ d, d)
            assert np.max(np.linalg.norm(off, axis=1)) < 0.001, seg.label
            assert abs(d[2]) > 0.99  # approach and lift are vertical in these plans


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_max_tcp_speed_holds_on_the_samples(planned):
    traj = load_trajectory(planned["obstacle"][0])
    robot = load_robot(traj.robot)
    limit = traj.limits["max_tcp_speed"]
    assert limit == 0.25
    p = robot.kin.fk(traj.positions)[:, :3, 3]
    fd_speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / np.diff(traj.times)
    assert fd_speed.max() <= limit * 1.01
    assert fd_speed.max() > 0.5 * limit  # the motion does use the allowance


def test_same_seed_same_file_and_seed_option(tmp_path):
    plan = ROOT / "plans" / "pick_place.yaml"
    a, b = tmp_path / "a.traj.json", tmp_path / "b.traj.json"
    assert roarmctl("plan", str(plan), "-o", str(a), "--json", "--seed", "5").returncode == 0
    assert roarmctl("plan", str(plan), "-o", str(b), "--json", "--seed", "5").returncode == 0
    assert a.read_bytes() == b.read_bytes()
    data = json.loads(a.read_text())
    assert data["plan"]["seed"] == 5 and data["plan"]["sha256"]


@pytest.mark.slow  # a fresh interpreter beside a CPU hog on its core
def test_same_seed_same_bytes_with_every_core_busy(planned, tmp_path):
    """Budgets count work, not seconds: a CPU hog on every core the planner may run on (and a niced planner)
    must not change a single byte of the file planned on the idle machine (same plan, same seed).

    The planner and one hog are pinned to one core (where the system allows it): the planner gets the same
    share of a core as beside a hog on every core, and the suite's other workers keep the other core (a hog per
    core burnt ~20 s of CPU the rest of the suite waited for)."""
    import os

    core = {min(os.sched_getaffinity(0))} if hasattr(os, "sched_setaffinity") else None

    def pinned(proc: subprocess.Popen, niceness: int) -> subprocess.Popen:
        # set from this process after the start, not in a preexec_fn: Python code between fork and exec in a worker
        # that runs threads (pyarrow's, MuJoCo's) can deadlock on a lock held at the fork, and Popen then waits for
        # the exec for ever (a clean-clone CI run hung there)
        with contextlib.suppress(ProcessLookupError):
            os.setpriority(os.PRIO_PROCESS, proc.pid, niceness)
            if core is not None:
                os.sched_setaffinity(proc.pid, core)
        return proc

    n_hogs = 1 if core is not None else (os.cpu_count() or 2)
    hogs = [pinned(subprocess.Popen([sys.executable, "-c", "while True: pass"]), 0) for _ in range(n_hogs)]
    try:
        out = tmp_path / "busy.traj.json"
        planner = pinned(subprocess.Popen([sys.executable, "-m", "roarmctl", "plan", str(ROOT / "plans" / "obstacle.yaml"),
                                           "-o", str(out), "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                          text=True), 5)
        try:
            _, stderr = planner.communicate(timeout=300)
        finally:
            planner.kill()
            for h in hogs:  # before waiting for the planner: a hog that outranks it would keep it from dying
                h.kill()
            planner.wait(60)
    finally:
        for h in hogs:
            h.kill()
            h.wait(60)
    assert planner.returncode == 0, stderr
    idle_file, _ = planned["obstacle"]
    assert out.read_bytes() == idle_file.read_bytes()


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "plan.yaml"
    path.write_text(text)
    return path


BASE = (ROOT / "plans" / "pick_place.yaml").read_text()


def test_unreachable_target_exits_3_naming_the_task(tmp_path):
    path = _write(tmp_path, BASE.replace("xyz: [0.25, 0.15, 0.02], approach", "xyz: [0.75, 0.15, 0.02], approach"))
    out = tmp_path / "o.traj.json"
    proc = roarmctl("plan", str(path), "-o", str(out))
    assert proc.returncode == 3, proc.stderr
    assert "task 2 (place" in proc.stderr and "(0.750, 0.150, 0.020)" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and not out.exists()


def test_start_in_collision_exits_3(tmp_path):
    wall = "  obstacles:\n    - {name: slab, shape: box, size: [0.1, 0.1, 0.05], xyz: [0.2, 0.0, 0.36]}\n"
    path = _write(tmp_path, BASE.replace("objects:", wall + "\nobjects:", 1))
    proc = roarmctl("plan", str(path), "-o", str(tmp_path / "o.traj.json"))
    assert proc.returncode == 3, proc.stderr
    assert "start" in proc.stderr and "slab" in proc.stderr


def test_no_path_within_budget_exits_3(tmp_path):
    # a box over the place target with no opening: the place pose itself is inside it
    cage = "  obstacles:\n    - {name: cage, shape: box, size: [0.12, 0.12, 0.2], xyz: [0.25, 0.15, 0.1]}\n"
    path = _write(tmp_path, BASE.replace("objects:", cage + "\nobjects:", 1))
    proc = roarmctl("plan", str(path), "-o", str(tmp_path / "o.traj.json"))
    assert proc.returncode == 3, proc.stderr
    assert "task 2" in proc.stderr and "cage" in proc.stderr


def test_pick_and_place_across_the_base_warns_and_keeps_the_margin(tmp_path):
    """Pick, base and place collinear (the path passes over the singular base axis). We warn and stay clear of it."""
    text = BASE.replace("xyz: [0.25, 0.15, 0.02], approach", "xyz: [-0.22, 0.13, 0.02], approach")
    text = text.replace("xyz: [0.15, 0.0, -0.01]", "xyz: [0.0, 0.0, -0.01]")
    out = tmp_path / "across.traj.json"
    proc = roarmctl("plan", str(_write(tmp_path, text)), "-o", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert any("collinear with the base" in w for w in summary["warnings"])
    traj = load_trajectory(out)
    robot = load_robot(traj.robot)
    sigma_min = np.linalg.svd(robot.kin.jacobian(traj.positions)[:, :3, :], compute_uv=False)[:, -1]
    assert sigma_min.min() >= traj.singularity_margin["min_singular_value"]
    tcp = robot.kin.fk(traj.positions)[:, :3, 3]
    assert np.hypot(tcp[:, 0], tcp[:, 1]).min() > 0.05  # never over the base axis


UR5E_PLAN = Path(__file__).parent / "data" / "arms" / "ur5e" / "plan.yaml"


@pytest.mark.slow  # plans a whole plan per arm (25 s for the UR5e at load 20)
@pytest.mark.parametrize("plan_path", ["roarm_m3_pro", UR5E_PLAN])
def test_the_collinear_warning_names_a_singular_pose_only_where_the_description_models_it(plan_path):
    """A pick and a place across the base: the RoArm's description (singularity_model: roarm5) has a singular class
    for the TCP on the base axis, and the warning names it; the UR5e's names no model, so the warning claims no
    singularity there (the old text said "base-axis singularity" for every arm)."""
    from roarmctl.motion.pipeline import Planner as PlanPipeline
    from roarmctl.motion.pipeline import robot_spec
    from roarmctl.motion.planning import tasks

    if plan_path == "roarm_m3_pro":
        plan = load_plan({"robot": "roarm_m3_pro", "tasks": [{"wait": 0.1}]})
    else:
        plan = load_plan(plan_path)
    robot = load_robot(robot_spec(plan))
    ctx = PlanPipeline(plan, robot).ctx
    ctx.object_pose["block"] = np.eye(4)
    ctx.object_pose["block"][:3, 3] = [0.3, 0.1, 0.02]
    tasks.warn_collinear(ctx, [PickTask("block"), PlaceTask(np.array([-0.3, -0.1, 0.02]))])
    [said] = [w for w in ctx.warnings if "collinear with the base" in w]
    assert "base-axis singularity" not in said and "over the base axis" in said
    if robot.singularity_model == "roarm5":
        assert "a singular pose (roarm5 model: tcp_on_base_axis)" in said
    else:
        assert robot.singularity_model is None
        assert "may be near a singularity" in said and "model" not in said and "singular pose" not in said


def _wait_for_stop_handlers(pid: int, timeout: float = 30.0) -> None:
    """Wait until the process catches SIGTERM (Linux /proc SigCgt): roarmctl's entry point installs
    its SIGINT/SIGTERM/SIGHUP handlers together, before its first heavy import. Python itself never
    catches SIGTERM, so this marks the end of the interpreter's own start-up, which no program can
    guard and which takes from 40 ms to seconds on a busy machine."""
    import signal
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = Path(f"/proc/{pid}/status").read_text()
        caught = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)
        if caught & (1 << (signal.SIGTERM - 1)):
            return
        time.sleep(0.002)
    raise AssertionError("roarmctl did not install its stop handlers within 30 s")


@pytest.mark.slow  # a fresh interpreter loading the planning libraries (0.1-1.1 s of CPU, as the signal lands)
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux /proc to see the handlers")
@pytest.mark.parametrize("delay", [0.02, 0.6])
def test_ctrl_c_while_planning_exits_130_and_writes_nothing(tmp_path, delay):
    """0.02 s after the entry point's handlers are in place lands in the CLI's imports, 0.6 s in the
    imports or the planning: either way one line, exit 130."""
    import signal
    import time

    out = tmp_path / "never.traj.json"
    proc = subprocess.Popen([sys.executable, "-m", "roarmctl", "plan", str(ROOT / "plans" / "multi_object.yaml"), "-o", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_stop_handlers(proc.pid)
    time.sleep(delay)  # well before the file is written
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["error: interrupted (nothing was written)"]
    assert not out.exists() and list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ jerk, torque, payload (issue 11)
def _payload_torques(robot, traj, plan_path: Path) -> np.ndarray:
    """RNEA torques (N, dof) of every sample, with each held object as a rigid body on the TCP link from
    grasp to release. The object's inertia is written out here (uniform solid), not taken from the planner."""
    from roarmctl.robot.dynamics import inverse_dynamics
    from roarmctl.robot.model import Inertial

    plan = load_plan(plan_path)
    tau = inverse_dynamics(robot, traj.positions, traj.velocities, traj.accelerations)
    grasps = [e for e in traj.events if e.kind == "grasp"]
    releases = [e for e in traj.events if e.kind == "release"]
    picks = [t for t in plan.tasks if isinstance(t, PickTask)]
    for g, r, task in zip(grasps, releases, picks):
        obj = next(o for o in plan.objects if o.name == task.object)
        if not obj.mass:
            continue
        k = int(np.searchsorted(traj.times, g.time))
        tcp = robot.kin.fk(traj.positions[k])
        centre_in_tcp = np.linalg.inv(tcp) @ np.append(obj.pose[:3, 3], 1.0)
        if obj.shape == "cylinder":
            side = obj.mass * (3 * obj.radius**2 + obj.length**2) / 12
            inertia_obj = np.diag([side, side, obj.mass * obj.radius**2 / 2])
        else:
            x, y, z = obj.size
            inertia_obj = obj.mass / 12 * np.diag([y * y + z * z, x * x + z * z, x * x + y * y])
        rot = np.linalg.inv(tcp)[:3, :3] @ obj.pose[:3, :3]
        body = {robot.tcp_link: Inertial(obj.mass, centre_in_tcp[:3], rot @ inertia_obj @ rot.T)}
        sel = (traj.times > g.time + 1e-9) & (traj.times < r.time - 1e-9)
        tau[sel] = inverse_dynamics(robot, traj.positions[sel], traj.velocities[sel], traj.accelerations[sel], payload=body)
    return tau


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
@pytest.mark.parametrize("name", ["pick_place", "payload", "obstacle"])
def test_jerk_by_finite_differences_is_within_the_limits(planned, name):
    traj = load_trajectory(planned[name][0])
    robot = load_robot(traj.robot)
    jerk = np.diff(traj.accelerations, axis=0) / np.diff(traj.times)[:, None]
    assert np.all(np.abs(jerk) <= robot.jerk_limits * (1 + 1e-6) + 1e-6), np.max(np.abs(jerk) / robot.jerk_limits, axis=0)
    # no acceleration jumps: the largest step between samples is what the jerk limit allows in 10 ms
    assert np.max(np.abs(np.diff(traj.accelerations, axis=0))) <= np.max(robot.jerk_limits) * 0.01 + 1e-6


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
@pytest.mark.parametrize("name", ["pick_place", "payload"])
def test_torque_by_rnea_with_the_held_load_is_within_the_limits(planned, name):
    traj = load_trajectory(planned[name][0])
    robot = load_robot(traj.robot)
    tau = _payload_torques(robot, traj, ROOT / "plans" / f"{name}.yaml")
    assert np.all(np.abs(tau) <= robot.effort_limits + 1e-6), np.max(np.abs(tau) / robot.effort_limits, axis=0)


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_the_payload_example_lifts_0_2_kg_at_0_4_m_reach(planned):
    traj = load_trajectory(planned["payload"][0])
    robot = load_robot(traj.robot)
    grasp = next(e for e in traj.events if e.kind == "grasp")
    k = int(np.searchsorted(traj.times, grasp.time))
    assert np.hypot(*robot.kin.fk(traj.positions[k])[:2, 3]) == pytest.approx(0.40, abs=0.005)
    assert load_plan(ROOT / "plans" / "payload.yaml").objects[0].mass == pytest.approx(0.2)
    # the load matters: holding it at the grasp needs clearly more shoulder torque than the bare arm
    from roarmctl.robot.dynamics import gravity_vector

    tau = _payload_torques(robot, traj, ROOT / "plans" / "payload.yaml")
    shoulder = robot.joint_index("link1_to_link2")
    assert abs(tau[k + 1, shoulder]) > 2 * abs(gravity_vector(robot, traj.positions[k + 1])[shoulder])


def test_a_load_the_arm_cannot_hold_exits_3_naming_joint_torque_and_limit(tmp_path):
    text = (ROOT / "plans" / "payload.yaml").read_text().replace("mass: 0.2}", "mass: 2.0}")
    assert "mass: 2.0}" in text
    plan = _write(tmp_path, text)
    proc = roarmctl("plan", str(plan), "-o", str(tmp_path / "out.json"))
    assert proc.returncode == 3, proc.stderr
    assert "link1_to_link2 needs" in proc.stderr and "limit 2.94 N m" in proc.stderr and "2.00 kg" in proc.stderr
    assert not (tmp_path / "out.json").exists()


# ------------------------------------------------------------------ blending (issue 11)
@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_blended_joins_keep_moving_with_continuous_velocity(planned):
    traj = load_trajectory(planned["pick_place"][0])
    robot = load_robot(traj.robot)
    assert len(traj.blends) >= 4  # pre-grasp, lift, pre-place, retreat
    amax = np.array(traj.limits["acceleration"]) * traj.limits["acceleration_scale"]
    # the file's velocities are the positions' derivative (central differences, independent of the planner)
    fd = (traj.positions[2:] - traj.positions[:-2]) / (traj.times[2:] - traj.times[:-2])[:, None]
    assert np.max(np.abs(fd - traj.velocities[1:-1])) < 0.02
    moving = 0
    for tb in traj.blends:
        k = int(np.searchsorted(traj.times, tb))
        window = slice(max(k - 3, 0), k + 4)
        speed = np.max(np.abs(traj.velocities[window][:, robot.arm_indices]), axis=1)
        moving += bool(speed.min() > 0.3)
        dv = np.abs(np.diff(traj.velocities[window], axis=0))
        assert np.all(dv <= amax * np.diff(traj.times[window])[:, None] * (1 + 1e-6) + 1e-9)  # no velocity step
    # the joins flow at speed, also where the wrist reverses (after the retreat): there a time-optimal corner
    # move keeps decelerating through the reversal instead of stopping. The pre-grasp join may stop: the
    # wrist roll turns the fixed jaw square to the cube at the end of the transit, and a rounded corner there
    # brings that jaw within the padding of the cube while the transit's collision state still applies.
    assert moving >= len(traj.blends) - 1


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_the_gripper_opens_during_the_transit(planned):
    traj = load_trajectory(planned["pick_place"][0])
    robot = load_robot(traj.robot)
    gi = robot.joint_index(robot.gripper.joint)
    transit = traj.segments[0]
    assert transit.kind == "free" and not any("open gripper" in s.label for s in traj.segments)
    sel = (traj.times > transit.start) & (traj.times < transit.end)
    moving_arm = np.max(np.abs(traj.velocities[sel][:, robot.arm_indices]), axis=1) > 1e-3
    moving_jaw = np.abs(traj.velocities[sel][:, gi]) > 1e-3
    assert np.any(moving_arm & moving_jaw)
    descent = traj.segments[1]
    k = int(np.searchsorted(traj.times, descent.start))
    assert traj.positions[k, gi] == pytest.approx(1.0)  # open before the straight approach starts


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_blend_false_keeps_the_stops_and_takes_longer(tmp_path, planned):
    text = BASE.replace("limits: {velocity_scale: 0.6, acceleration_scale: 0.6, gripper_time: 0.5}",
                        "limits: {velocity_scale: 0.6, acceleration_scale: 0.6, gripper_time: 0.5, blend: false}")
    assert "blend: false" in text
    out = tmp_path / "stops.traj.json"
    proc = roarmctl("plan", str(_write(tmp_path, text)), "-o", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    stops = load_trajectory(out)
    blended = load_trajectory(planned["pick_place"][0])
    assert stops.blends == [] and any("open gripper" in s.label for s in stops.segments)
    for seg in stops.segments:  # every segment starts and ends at rest
        for t in (seg.start, seg.end):
            k = int(np.argmin(np.abs(stops.times - t)))
            assert np.max(np.abs(stops.velocities[k])) < 1e-6, seg.label
    assert blended.duration < 0.75 * stops.duration  # blended joins, gripper opened in transit, close/open overlapped
    # issue 11's target at today's scales: at most 0.7x of the 9.51 s the planner took before blending and jerk
    # limits; since the fixed jaw is squared to the cube (issue 23) the wrist roll turns at the end of the transit
    # and its pre-grasp join stops (see test_blended_joins_keep_moving_with_continuous_velocity): 0.72x
    assert blended.duration <= 0.72 * 9.51


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
@pytest.mark.parametrize("name", ["pick_place", "payload"])
def test_no_acceleration_chatter(planned, name):
    """Within each segment a joint's jerk changes sign only a few times: a jerk-limited rest-to-rest move
    changes it twice (+, -, -, +), two of them overlapped at a blend a few times more, and a corner move
    (Ruckig's profile, at most 7 phases of constant jerk) up to 3 more at each blended join on the
    segment's edges. TOPP-RA's raw bang-bang output flips it at almost every grid interval on a curved path."""
    traj = load_trajectory(planned[name][0])
    jerk = np.diff(traj.accelerations, axis=0) / np.diff(traj.times)[:, None]
    mids = 0.5 * (traj.times[1:] + traj.times[:-1])
    for seg in traj.segments:
        sel = (mids > seg.start) & (mids < seg.end)
        for j in range(jerk.shape[1]):
            x = jerk[sel, j]
            if not len(x) or np.max(np.abs(x)) < 1e-6:
                continue
            x = x[np.abs(x) > 0.05 * np.max(np.abs(x))]  # ignore rounding-level wiggles
            flips = int(np.sum(np.diff(np.sign(x)) != 0))
            joins = sum(seg.start - 1e-6 <= b <= seg.end + 1e-6 for b in traj.blends)
            assert flips <= 5 + 3 * joins, f"{seg.label}: {traj.joint_names[j]} jerk changes sign {flips} times"


def _moving_jaw_boxes(robot) -> list:
    """Collision boxes of the links the gripper joint moves (its child and descendants), from the joint tree."""
    moved = set()
    frontier = {next(j.child for j in robot.joints if j.name == robot.gripper.joint)}
    while frontier:
        moved |= frontier
        frontier = {j.child for j in robot.joints if j.parent in frontier} - moved
    return [(s, _box(s.size)) for s in robot.collision if s.link in moved and s.kind == "box"]


@pytest.mark.xdist_group("planned-examples")  # the bundled plans planned once (module fixture)
def test_the_jaws_close_during_the_descent_and_open_during_the_retreat_but_never_into_the_object(planned):
    """The gripper moves while the arm descends to the grasp and while it retreats from the place, but the moving
    jaw stays at least the planner's padding away from the cube (python-fcl distance, generic FK) whenever the
    TCP is not at the grasp (release) pose: it closes around the cube only once the arm has arrived."""
    plan = load_plan(ROOT / "plans" / "pick_place.yaml")
    traj = load_trajectory(planned["pick_place"][0])
    robot = load_robot(traj.robot)
    gi = robot.joint_index(robot.gripper.joint)
    jaws = _moving_jaw_boxes(robot)
    assert jaws and all(s.link != "link5" for s, _ in jaws)  # the fixed jaw on link5 does not move with the joint
    (cube_spec,) = plan.objects
    cube = fcl.CollisionObject(fcl.Box(*cube_spec.size))
    grasp, release = traj.events
    q = _fine(traj.positions, 4)
    t = _fine(traj.times[:, None], 4)[:, 0]
    tcp = robot.kin.fk(q)
    frames = robot.kin.link_frames(q)
    k_g, k_r = int(np.argmin(np.abs(t - grasp.time))), int(np.argmin(np.abs(t - release.time)))
    cube_at_place = tcp[k_r] @ np.linalg.inv(tcp[k_g]) @ cube_spec.pose
    retreat = next(s for s in traj.segments if s.label.endswith("retreat from 'cube'"))
    windows = [(t <= grasp.time, tcp[k_g], cube_spec.pose), ((t >= release.time) & (t <= retreat.end), tcp[k_r], cube_at_place)]
    for sel, at, pose in windows:
        cube.setTransform(fcl.Transform(pose[:3, :3], pose[:3, 3]))
        away = sel & (np.linalg.norm(tcp[:, :3, 3] - at[:3, 3], axis=1) > 1e-4)
        jaw_moves = away & (np.abs(np.gradient(q[:, gi], t)) > 1e-3)
        assert np.count_nonzero(jaw_moves) > 10  # the gripper does move while the arm is away from the pose
        for k in np.flatnonzero(away):
            for shape, obj in jaws:
                f = frames[k, robot.kin.link_index[shape.link]] @ shape.origin
                obj.setTransform(fcl.Transform(f[:3, :3], f[:3, 3]))
                d = fcl.distance(obj, cube, fcl.DistanceRequest(), fcl.DistanceResult())
                assert d >= plan.planner.padding - 2e-4, (t[k], q[k, gi], d)
    # and at the grasp pose the closed jaw does reach into the padding (the check above is not vacuous)
    cube.setTransform(fcl.Transform(cube_spec.pose[:3, :3], cube_spec.pose[:3, 3]))
    closest = []
    for shape, obj in jaws:
        f = frames[k_g, robot.kin.link_index[shape.link]] @ shape.origin
        obj.setTransform(fcl.Transform(f[:3, :3], f[:3, 3]))
        closest.append(fcl.distance(obj, cube, fcl.DistanceRequest(), fcl.DistanceResult()))
    assert min(closest) < plan.planner.padding


def test_a_gripper_action_that_swings_the_jaw_into_an_obstacle_is_refused(tmp_path):
    """Opening the gripper at rest is checked along the jaw's sweep: a small post beside the moving jaw at home,
    clear of the closed jaw but inside the padding somewhere on the jaw's way to open (python-fcl distance,
    generic FK, boxes from the description), makes the plan fail with exit 3 naming the jaw link and the post
    and writing nothing; 10 cm further out the same plan is planned."""
    robot = load_robot("roarm_m3_pro")
    gi = robot.joint_index(robot.gripper.joint)
    padding = 0.005
    home = robot.full_q(robot.named_poses["home"])
    jaws = _moving_jaw_boxes(robot)

    def clearance(y: float, g: float) -> float:
        post = fcl.CollisionObject(fcl.Box(0.01, 0.01, 0.01), fcl.Transform(np.eye(3), np.array([0.30, y, 0.344])))
        q = home.copy()
        q[gi] = g
        frames = robot.kin.link_frames(q)
        out = []
        for shape, obj in jaws:
            f = frames[robot.kin.link_index[shape.link]] @ shape.origin
            obj.setTransform(fcl.Transform(f[:3, :3], f[:3, 3]))
            out.append(fcl.distance(obj, post, fcl.DistanceRequest(), fcl.DistanceResult()))
        return min(out)

    sweep = np.linspace(robot.gripper.closed, robot.gripper.open, 61)
    assert clearance(-0.06, robot.gripper.closed) > padding
    assert min(clearance(-0.06, g) for g in sweep) < padding
    assert min(clearance(-0.16, g) for g in sweep) > padding

    def plan(y: float) -> tuple[Result, Path]:
        src = tmp_path / f"jaw_{-y:.2f}.yaml"
        src.write_text("robot: roarm_m3_pro\nstart: home\nscene:\n  obstacles:\n"
                       f"    - {{name: post, shape: box, size: [0.01, 0.01, 0.01], xyz: [0.30, {y}, 0.344]}}\n"
                       "tasks:\n  - move: {pose: home, gripper: open}\n"
                       f"planner: {{padding: {padding}}}\n")
        out = tmp_path / f"jaw_{-y:.2f}.traj.json"
        return roarmctl("plan", str(src), "-o", str(out)), out

    bad, out = plan(-0.06)
    assert bad.returncode == 3, bad.stderr
    (line,) = bad.stderr.strip().splitlines()
    assert "moving jaw collides" in line and "gripper_link" in line and "'post'" in line
    assert not out.exists()
    good, out = plan(-0.16)
    assert good.returncode == 0, good.stderr
    assert out.is_file()
