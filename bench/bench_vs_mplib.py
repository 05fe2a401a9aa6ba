"""roarmctl against mplib 0.2.1 (C++ OMPL + FCL + toppra) on the same queries, interleaved in one run.

Run: .venv/bin/python bench/bench_vs_mplib.py [--rounds 20] [--venv /tmp/mplib-venv]

At the end it prints issue 25's figures in one table, each beside mplib's where mplib has one: api.plan and
Planner.run on queries a-e (the public API on the five queries below, nothing held), the wall query with 200
boxes off the path (and its set-up: api.plan outside Planner.run, against mplib adding the boxes), the desk
cloud (wall, and in CPU time: each side's process, every thread of it, around the same call, which the machine's load
does not inflate as it does wall time), and from the same interleaved rounds: a fresh ``roarmctl plan plans/pick_place.yaml`` process and
``roarmctl --help`` (wall, beside ``python -c pass``; bytecode compiled first, as bench/bench_startup.py does), and
the planning time per task of a 20-task plan (pick_place's cube carried there and back, 5 cycles of 4 tasks)
with TOPP-RA's share.

mplib needs numpy < 2, so it lives in its own throwaway venv (created with pip on first use, reused
afterwards) and runs as a worker process that this script drives over a pipe; both sides time only
their own work, in the same rounds, one query after the other (so machine load hits both alike).

mplib's model is built here from the bundled robot: a URDF whose collision geometry is exactly
roarmctl's collision boxes (the same link frames and joint limits), an SRDF whose
disable_collisions are roarmctl's allowed pairs, the scene as FCL boxes and cylinders, the table
allowed against the base links (as roarmctl's checker does). mplib cannot pad the arm, so the worker grows its
scene by the plan's padding instead (boxes and cylinders by the padding on every side, spheres in radius, the desk
cloud by whole cells, ceil(padding / resolution)); mplib has no singularity margin, roarmctl keeps the plans' (0.02 m/rad),
so it does a little more per state. On the planner-level queries that carry an object (wall, post, tray, posts)
the worker attaches it to mplib's TCP link as a box where roarmctl carries it, at the size roarmctl checks it at
(shrunk by the contact tolerance) less the padding on each side, which the grown scene already adds; the API
queries hold nothing on either side (a plan starts with empty hands). Both sides' paths are judged by one metric,
``clearance``: the FCL distance of the unpadded arm to the unpadded scene, against the padding.

Queries (the start and goal configurations are the ones the pipeline plans, captured from a run):
  free  pick_place.yaml, home -> above the cube (the straight joint move is valid)
  wall  obstacle.yaml, above pick -> above place, through the wall
  post  multi_object.yaml, above the can -> above its place, past the post
  tray  bench/scenes.py tray_plan: above the cube -> above a tray behind a wall 0.20 m high, the cube held
  posts bench/scenes.py posts_plan: above the cube -> above its place, past twelve posts in two rows, the cube held
Per query and round: roarmctl's free-motion geometry (OMPL RRTConnect + shortcutting) plus its timing
and re-check of that motion, against mplib's plan_qpos (RRTConnect + simplify + TOPP-RA). Each
round uses another seed on both sides. On the wall and post queries also "like for like": roarmctl's geometry
with only the timing mplib does (one plain TOPP-RA under joint velocity and acceleration limits), which shows
how much of the gap is the jerk limit, torque and TCP-speed checks and the re-check mplib does not do. Also: single-state validity checks per second (roarmctl
``CollisionChecker.is_valid`` with the margin, one state per call, vs mplib's public per-state check
``PlanningWorld.is_state_colliding`` after ``set_qpos``) on the same random states.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from peers import peer_python, urdf_origin

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/scenes.py

ROOT = Path(__file__).resolve().parents[1]
MPLIB = "mplib==0.2.1"
QUERIES = {  # name -> (plan: a bundled plan's name or a plan dict of bench/scenes.py, label fragment of the free motion)
    "free": ("pick_place", "transit above 'cube'"),
    "wall": ("obstacle", "transit above the place for 'cube'"),
    "post": ("multi_object", "transit above the place for 'can'"),
    "tray": ("tray", "transit above the place for 'cube'"),
    "posts": ("posts", "transit above the place for 'cube'"),
}


# --------------------------------------------------------------------------- the mplib side
WORKER = r'''
import json, sys, time
import numpy as np
import mplib
from mplib import Planner, Pose
from mplib.collision_detection.fcl import Box, Cylinder, Sphere, CollisionObject, FCLObject

spec = json.loads(sys.stdin.readline())
grow = spec["padding"]  # roarmctl pads the arm; mplib cannot, so its scene is grown by the same amount


def geometry(it):
    if it["shape"] == "box":
        return Box(np.array(it["size"]) + 2 * grow)
    if it["shape"] == "cylinder":
        return Cylinder(it["radius"] + grow, it["length"] + 2 * grow)
    return Sphere(it["radius"] + grow)


def add_items(p, items):
    for it in items:
        obj = FCLObject(it["name"], Pose(np.array(it["pose"])), [CollisionObject(geometry(it))], [Pose()])
        p.planning_world.add_object(obj)
        if it["role"] == "table":
            p.planning_world.get_allowed_collision_matrix().set_entry(it["name"], spec["base_links"], True)


def new_planner(q):
    return Planner(urdf=spec["urdf"], srdf=spec["srdf"], move_group=spec["tcp"], user_joint_names=spec["joints"],
                   joint_vel_limits=q["vmax"], joint_acc_limits=q["amax"])


planners = {}
for name, q in spec["queries"].items():
    p = new_planner(q)
    add_items(p, q["items"])
    if q.get("held"):  # the held object, attached to the TCP link as roarmctl carries it
        h = q["held"]
        p.update_attached_box(np.array(h["size"]), Pose(np.array(h["pose"])), link_id=spec["tcp_index"])
    planners[name] = p
api_planners = {name: new_planner(q) for name, q in spec["api"].items()}  # robot loaded once, as a user would
print("ready", flush=True)
for line in sys.stdin:
    cmd = json.loads(line)
    if cmd["op"] == "api":  # the public API: the scene set up, the query planned (and timed), the scene taken down
        q = spec["api"][cmd["query"]]
        p = api_planners[cmd["query"]]
        mplib.set_global_seed(cmd["seed"])
        t0, c0 = time.perf_counter(), time.process_time()
        add_items(p, q["items"])
        if q.get("cloud") is not None:
            p.update_point_cloud(np.array(q["cloud"]), resolution=q["resolution"])
            p.planning_world.get_allowed_collision_matrix().set_entry("scene_pcd", spec["base_links"], True)
        t1 = time.perf_counter()
        res = p.plan_qpos([np.array(q["goal"])], np.array(q["start"]), time_step=0.01, planning_time=1.0)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        for it in q["items"]:
            p.remove_object(it["name"])
        if q.get("cloud") is not None:
            p.remove_point_cloud()
        ok = res["status"] == "Success"
        out = {"ok": ok, "wall": wall, "cpu": cpu, "setup": t1 - t0, "duration": float(res["duration"]) if ok else None,
               "path": res["position"].tolist() if ok else None}
    elif cmd["op"] == "plan":
        p = planners[cmd["query"]]
        q = spec["queries"][cmd["query"]]
        mplib.set_global_seed(cmd["seed"])
        t0 = time.perf_counter()
        res = p.plan_qpos([np.array(q["goal"])], np.array(q["start"]), time_step=0.01, planning_time=1.0)
        wall = time.perf_counter() - t0
        ok = res["status"] == "Success"
        out = {"ok": ok, "wall": wall, "duration": float(res["duration"]) if ok else None,
               "path": res["position"].tolist() if ok else None}
    else:  # single-state rate
        p = planners[cmd["query"]]
        states = np.array(cmd["states"])
        world, robot = p.planning_world, p.robot
        t0 = time.perf_counter()
        hits = 0
        for s in states:
            robot.set_qpos(s, True)
            hits += world.is_state_colliding()
        dt = time.perf_counter() - t0
        out = {"rate": len(states) / dt, "colliding": int(hits)}
    print(json.dumps(out), flush=True)
'''


# --------------------------------------------------------------------------- model export
def export_model(robot, folder: Path) -> tuple[Path, Path]:
    """URDF (kinematics + roarmctl's collision boxes) and SRDF (allowed pairs) of ``robot``."""
    import numpy as np

    links = {robot.root: []}
    for j in robot.joints:
        links.setdefault(j.child, [])
        if not np.allclose(j.post, np.eye(4)) or j.offset:
            raise SystemExit(f"{robot.name}: joint {j.name} has a post-transform or offset; not exported")
    for c in robot.collision:
        if c.kind != "box":
            raise SystemExit(f"{robot.name}: only box collision shapes are exported, found {c.kind}")
        sx, sy, sz = (float(v) for v in c.size)
        links[c.link].append(f'<collision>{urdf_origin(c.origin)}<geometry><box size="{sx!r} {sy!r} {sz!r}"/></geometry></collision>')
    out = [f'<robot name="{robot.name}">']
    for name, shapes in links.items():
        out.append(f'<link name="{name}"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'
                   + "".join(shapes) + "</link>")
    for j in robot.joints:
        body = f'<parent link="{j.parent}"/><child link="{j.child}"/>{urdf_origin(j.origin)}'
        if j.kind != "fixed":
            i = robot.joint_names.index(j.name)
            ax = " ".join(repr(float(v)) for v in j.axis)
            body += (f'<axis xyz="{ax}"/><limit lower="{float(robot.lower[i])!r}" upper="{float(robot.upper[i])!r}" '
                     f'effort="10" velocity="{float(robot.velocity_limits[i])!r}"/>')
        out.append(f'<joint name="{j.name}" type="{j.kind}">{body}</joint>')
    out.append("</robot>")
    urdf = folder / f"{robot.name}.urdf"
    urdf.write_text("\n".join(out))
    pairs = sorted(tuple(sorted(p)) for p in robot.allowed_collisions)
    srdf = folder / f"{robot.name}.srdf"
    srdf.write_text(f'<robot name="{robot.name}">\n' + "\n".join(
        f'<disable_collisions link1="{a}" link2="{b}" reason="roarmctl"/>' for a, b in pairs) + "\n</robot>\n")
    return urdf, srdf


# --------------------------------------------------------------------------- the roarmctl side
def plan_source(plan_name: str) -> dict:
    """The plan a query comes from, as a dict: a bundled plan file's, or one of bench/scenes.py's (tray, posts)."""
    import yaml
    from scenes import posts_plan, tray_plan

    made = {"tray": tray_plan, "posts": posts_plan}
    if plan_name in made:
        return made[plan_name]()
    return yaml.safe_load((ROOT / "plans" / f"{plan_name}.yaml").read_text())


def capture(plan_name: str, fragment: str):
    """Plan ``plan_name`` and stop at the free motion whose label contains ``fragment``: returns
    (ctx, step, q) there (the planning context, with the world state (held object, object poses) as the
    pipeline has it)."""
    from roarmctl.motion import pipeline
    from roarmctl.motion.planning import motions

    found = {}
    original = motions.geometry

    class Captured(Exception):
        pass

    def hook(ctx, step, q):
        if step.kind == "free" and fragment in step.label and not found:
            found.update(ctx=ctx, step=step, q=q.copy())
            raise Captured
        return original(ctx, step, q)

    motions.geometry = hook
    try:
        pipeline.plan_file(ROOT / "plans" / f"{plan_name}.yaml") if (ROOT / "plans" / f"{plan_name}.yaml").exists() \
            else pipeline.plan_file(plan_source(plan_name), base_dir=ROOT / "plans")
    except Captured:
        pass
    finally:
        motions.geometry = original
    if not found:
        raise SystemExit(f"{plan_name}: no free motion labelled '{fragment}'")
    return found["ctx"], found["step"], found["q"]


def roarmctl_query(ctx, step, q, seed: int):
    """One free motion as the pipeline does it: geometry (OMPL + shortcuts), timing and re-check.
    Returns (wall s, geometry s, motion duration s, waypoints)."""
    from roarmctl.motion.planning import motions

    ctx.config = dataclasses.replace(ctx.config, seed=seed)  # the planner's options are frozen (issue 37)
    ctx.free_count = 0
    ctx.timed.clear()  # the query is timed afresh in every round (a plan keeps what it timed: motions.time_path)
    t0 = time.perf_counter()
    motion = motions.geometry(ctx, step, q)
    t1 = time.perf_counter()
    piece = motions.time_motion(ctx, motion)
    return time.perf_counter() - t0, t1 - t0, piece.tp.duration, motion.wps


def roarmctl_like_mplib(ctx, step, q, seed: int):
    """The same free motion with only the work mplib's plan_qpos does after planning: the geometry as above,
    then one plain TOPP-RA timing under the joint velocity and acceleration limits (no jerk limit, torque
    limit, TCP speed limit or re-check of the timed samples). Returns (wall s, motion duration s)."""
    from roarmctl.motion.planning import motions
    from roarmctl.motion.planning.pieces import SAMPLE_DT
    from roarmctl.motion.timing import time_parameterise

    ctx.config = dataclasses.replace(ctx.config, seed=seed)  # the planner's options are frozen (issue 37)
    ctx.free_count = 0
    ctx.timed.clear()  # the query is timed afresh in every round (a plan keeps what it timed: motions.time_path)
    arm = ctx.arm
    t0 = time.perf_counter()
    motion = motions.geometry(ctx, step, q)
    tp = time_parameterise(motion.wps[:, arm], ctx.vmax[arm], ctx.amax[arm], None, sample_dt=SAMPLE_DT)
    return time.perf_counter() - t0, tp.duration


# --------------------------------------------------------------------------- one metric for both sides' paths
def clearance(robot, items, q_full, cap: float = 0.03) -> float:
    """Smallest FCL distance (m, at most ``cap``) over the states ``q_full`` (K, dof) between the arm's collision
    shapes as the description gives them (no padding) and the scene ``items`` as they are (no growth), the table
    left out for the base links (as both checkers do). A path whose clearance is below the padding entered it."""
    import fcl
    import numpy as np

    from roarmctl.motion.geometry import fcl_geometry, item_parts

    kin = robot.kin
    shapes = [(kin.link_index[c.link], c.origin, fcl.CollisionObject(fcl_geometry(c.kind, c.size, c.radius, c.length, mesh=c.mesh)),
               float(np.linalg.norm(c.size)) / 2 + c.radius + c.length / 2, c.link in robot.base_links) for c in robot.collision]
    parts = [(p, p.item.role == "table", p.centre, np.abs(p.rot) @ p.half) for it in items for p in item_parts(it)]
    req, best = fcl.DistanceRequest(), cap
    for q in np.asarray(q_full, dtype=float):
        f = kin.frames4(q[None])[0]
        for link, origin, obj, reach, base in shapes:
            pose = f[link] @ origin
            obj.setRotation(pose[:3, :3])
            obj.setTranslation(pose[:3, 3])
            for part, table, centre, half in parts:
                if (table and base) or np.any(np.abs(pose[:3, 3] - centre) > half + reach + best):
                    continue
                d = fcl.distance(obj, part.obj, req, fcl.DistanceResult())
                best = min(best, max(d, 0.0))
    return best


def item_dict(it) -> dict:
    """A primitive scene item as the mplib worker takes it (world pose 4 x 4)."""
    return {"name": it.name, "role": it.role, "shape": it.shape, "pose": it.pose.tolist(), "size": list(it.size),
            "radius": it.radius, "length": it.length}


API_FROM = {"a": "free", "b": "wall", "c": "post", "d": "tray", "e": "posts", "b200": "wall", "desk": "free"}  # API query -> captured query
DESK_RESOLUTION = 0.005  # m: the desk cloud's cells (both sides)


def api_queries(captured: dict, goals: dict, folder: Path) -> tuple[dict, dict]:
    """The public-API queries: name -> (plan dict for roarmctl.api.plan, primitive items for mplib, cloud points
    for mplib or None), and name -> the roarmctl SceneItems of its scene (for the clearance metric). a, b, c: the
    captured motions in their plans' scenes (nothing held: a plan starts with empty hands); b200: b with 200
    boxes off the path; desk: a in a 100,000-point cloud of a cluttered desk (bench/scenes.py), the table's place."""
    import numpy as np
    from scenes import boxes_off_path, desk_cloud

    from roarmctl.motion.octree import cells_of
    from roarmctl.motion.planning.context import scene_item
    from roarmctl.plan.schema import load_plan

    out, scenes = {}, {}
    points = desk_cloud()
    np.save(folder / "desk.npy", points)
    for name, source in API_FROM.items():
        ctx, _, q = captured[source]
        plan_doc = plan_source(QUERIES[source][0])
        scene = dict(plan_doc.get("scene") or {})
        cloud = None
        if name == "b200":
            scene["obstacles"] = list(scene.get("obstacles") or []) + boxes_off_path(200)
        if name == "desk":
            scene = {"table": {"shape": "cloud", "file": "desk.npy", "resolution": DESK_RESOLUTION, "xyz": [0, 0, 0]}}
            # mplib's octree gets the centres of the same cells grown by the padding (whole cells: one here)
            cells = cells_of(points, DESK_RESOLUTION)
            grow = int(np.ceil(ctx.plan.planner.padding / DESK_RESOLUTION))
            steps = np.array([[i, j, k] for i in range(-grow, grow + 1) for j in range(-grow, grow + 1) for k in range(-grow, grow + 1)])
            grown = np.unique((cells[:, None, :] + steps[None]).reshape(-1, 3), axis=0)
            cloud = ((grown + 0.5) * DESK_RESOLUTION).tolist()
        doc = api_query(q, goals[source], scene, plan_doc.get("objects") or [], plan_doc)
        specs = load_plan(doc, base_dir=folder)
        items = [scene_item(s) for s in specs.scene + specs.objects]
        scenes[name] = items
        out[name] = (doc, [item_dict(it) for it in items if it.shape in ("box", "cylinder", "sphere")], cloud)
    return out, scenes


def api_query(start, goal, scene: dict, objects: list, plan: dict) -> dict:
    """A one-motion plan dict for ``roarmctl.api.plan``: from ``start`` to ``goal`` (full configurations, rad)."""
    return {"robot": "roarm_m3_pro", "start": [float(v) for v in start], "scene": scene, "objects": objects,
            "tasks": [{"move": {"joints": [float(v) for v in goal]}}], "planner": plan["planner"], "limits": plan["limits"]}


def twenty_tasks() -> dict:
    """A 20-task plan: pick_place.yaml's cube carried to its place and back, 5 cycles of pick, place, pick, place."""
    doc = plan_source("pick_place")
    pick, place, _home = doc["tasks"]
    back = {"place": {**place["place"], "xyz": doc["objects"][0]["xyz"]}}
    doc["tasks"], doc["cycles"] = [pick, place, {"pick": dict(pick["pick"])}, back], 5
    return doc


def fresh_processes() -> tuple[dict[str, list[str]], dict[str, str], Path]:
    """The fresh-process commands timed in every round (name -> argv), their environment, and the plan's output:
    bytecode written first and PYTHONDONTWRITEBYTECODE unset, as an installed copy runs (bench/bench_startup.py)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "src" / "roarmctl")], check=True, env=env, capture_output=True)
    out = Path(tempfile.mkdtemp()) / "pick_place.traj.json"
    cli = [sys.executable, "-m", "roarmctl"]
    cmds = {"python -c pass": [sys.executable, "-c", "pass"], "roarmctl --help": cli + ["--help"],
            "roarmctl plan pick_place": cli + ["plan", "plans/pick_place.yaml", "-o", str(out), "--json"]}
    for cmd in cmds.values():  # once untimed: writes what bytecode is still missing, as a user's first run does
        subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, check=True)
    return cmds, env, out


def main() -> None:
    import numpy as np

    from roarmctl.motion.pipeline import load_planning_libraries

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--venv", type=Path, default=Path(tempfile.gettempdir()) / "roarmctl-bench-mplib")
    parser.add_argument("--states", type=int, default=3000)
    parser.add_argument("--metric-rounds", type=int, default=5, help="rounds whose paths get the clearance metric")
    args = parser.parse_args()
    py = peer_python(args.venv, [MPLIB, "numpy<2"], f"{MPLIB} and numpy<2")
    load_planning_libraries()

    folder = Path(tempfile.mkdtemp(prefix="roarmctl-mplib-"))
    captured = {name: capture(*q) for name, q in QUERIES.items()}
    robot = captured["free"][0].robot
    urdf, srdf = export_model(robot, folder)
    arm = robot.arm_indices
    padding = captured["free"][0].plan.planner.padding
    spec = {"urdf": str(urdf), "srdf": str(srdf), "tcp": robot.tcp_link, "joints": list(robot.joint_names),
            "base_links": list(robot.base_links), "queries": {}, "api": {}, "padding": padding,
            "tcp_index": -1}  # roarmctl's checker: the base links never meet the table
    goals = {}
    for name, (ctx, step, q) in captured.items():
        goal = step.q_to.copy()
        goal[ctx.gi] = q[ctx.gi]
        goals[name] = goal
        items = [item_dict(it) for it in ctx.checker.scene.items]
        held = None
        if ctx.held:  # roarmctl's held object is shrunk by the contact tolerance and not padded: so is mplib's
            item, rel = ctx.checker._attached[ctx.held]
            shrink = 2 * (padding + ctx.checker.contact_tolerance)
            held = {"size": (np.asarray(item.size) - shrink).tolist(), "pose": rel.tolist()}
        spec["queries"][name] = {"start": q.tolist(), "goal": goal.tolist(), "items": items, "held": held,
                                 "vmax": ctx.vmax[arm].tolist(), "amax": ctx.amax[arm].tolist()}
    api, api_scenes = api_queries(captured, goals, folder)
    for name, (doc, items, cloud) in api.items():
        source = captured[API_FROM[name]][0]
        spec["api"][name] = {"start": doc["start"], "goal": doc["tasks"][0]["move"]["joints"], "items": items,
                             "cloud": cloud, "resolution": DESK_RESOLUTION,
                             "vmax": source.vmax[arm].tolist(), "amax": source.amax[arm].tolist()}
    worker = subprocess.Popen([str(py), "-c", WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    worker.stdin.write(json.dumps(spec) + "\n")
    worker.stdin.flush()
    line = worker.stdout.readline()
    if line.strip() != "ready":
        raise SystemExit("mplib worker failed to start")

    def ask(cmd: dict) -> dict:
        worker.stdin.write(json.dumps(cmd) + "\n")
        worker.stdin.flush()
        return json.loads(worker.stdout.readline())

    ours = {k: [] for k in QUERIES}
    geometry = {k: [] for k in QUERIES}
    theirs = {k: [] for k in QUERIES}
    durations = {k: ([], []) for k in QUERIES}
    padding_hits = {k: 0 for k in QUERIES}
    fails = {k: [0, 0] for k in QUERIES}
    like = {k: [] for k in QUERIES if k != "free"}  # our geometry + plain TOPP-RA only (mplib's post-planning work)
    like_dur = {k: [] for k in like}
    clear = {k: ([], []) for k in QUERIES}  # clearance (m) of each side's path, arm vs the unpadded scene
    import roarmctl.api as rc
    from roarmctl.motion import pipeline
    from roarmctl.motion.collision import densify

    run_times: list[float] = []
    plain_run = pipeline.Planner.run

    run_cpu: list[float] = []

    def timed_run(self):  # the planner's own time inside api.plan (wall, and this thread's CPU)
        t, c = time.perf_counter(), time.thread_time()
        try:
            return plain_run(self)
        finally:
            run_times.append(time.perf_counter() - t)
            run_cpu.append(time.thread_time() - c)

    pipeline.Planner.run = timed_run
    api_ours = {k: ([], []) for k in api}  # (api.plan wall, Planner.run wall)
    api_cpu = {k: ([], []) for k in api}  # the same, this thread's CPU time
    api_theirs = {k: ([], []) for k in api}  # (set-up + plan_qpos wall, set-up wall)
    # each side's process CPU time of the call (every thread of it: OpenBLAS's too), which the machine's load
    # does not inflate as it does wall time: (roarmctl api.plan, mplib set-up + plan_qpos)
    api_pcpu = {k: ([], []) for k in api}
    api_clear = {k: ([], []) for k in api}
    api_fails = {k: [0, 0] for k in api}
    cmds, env, _ = fresh_processes()
    fresh = {k: [] for k in cmds}  # wall s of each fresh process
    fresh_planning: list[float] = []  # the fresh plan process's own planning_time
    tasks20 = twenty_tasks()
    per_task: list[tuple[float, float]] = []  # (planning s per task, TOPP-RA share) of the 20-task plan
    for r in range(args.rounds):
        for name, cmd in cmds.items():
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
            fresh[name].append(time.perf_counter() - t0)
            if proc.returncode != 0:
                raise SystemExit(f"{' '.join(cmd)} failed: {proc.stderr.strip()}")
            if name.startswith("roarmctl plan"):
                fresh_planning.append(json.loads(proc.stdout)["planning_time"])
        long_plan = pipeline.plan_file(copy.deepcopy(tasks20), seed=100 + r, base_dir=ROOT / "plans")
        per_task.append((long_plan.planning_time / 20, long_plan.timings.get("toppra", 0.0) / long_plan.planning_time))
        for name, (doc, _, _) in api.items():
            try:
                t0, c0, p0 = time.perf_counter(), time.thread_time(), time.process_time()
                result = rc.plan(doc, seed=100 + r, base_dir=folder)
                api_ours[name][0].append(time.perf_counter() - t0)
                api_cpu[name][0].append(time.thread_time() - c0)
                api_pcpu[name][0].append(time.process_time() - p0)
                api_ours[name][1].append(run_times[-1])
                api_cpu[name][1].append(run_cpu[-1])
                if r < args.metric_rounds:
                    api_clear[name][0].append(clearance(robot, api_scenes[name], result.trajectory.positions))
            except Exception as exc:  # noqa: BLE001 (a bench counts failures)
                api_fails[name][0] += 1
                print(f"  roarmctl api {name} round {r}: {exc}", file=sys.stderr)
            res = ask({"op": "api", "query": name, "seed": 100 + r})
            if res["ok"]:
                api_theirs[name][0].append(res["wall"])
                api_theirs[name][1].append(res["setup"])
                api_pcpu[name][1].append(res["cpu"])
                if r < args.metric_rounds:
                    path = np.array(res["path"])
                    full = np.repeat(np.array(doc["start"])[None, :], len(path), axis=0)
                    full[:, arm] = path[:, :len(arm)]
                    api_clear[name][1].append(clearance(robot, api_scenes[name], full))
            else:
                api_fails[name][1] += 1
        for name, (ctx, step, q) in captured.items():
            try:
                wall, geo, dur, wps = roarmctl_query(ctx, step, q, seed=100 + r)
                if r < args.metric_rounds:
                    clear[name][0].append(clearance(robot, ctx.checker.scene.items, densify(wps, 0.01)))
                ours[name].append(wall)
                geometry[name].append(geo)
                durations[name][0].append(dur)
            except Exception as exc:  # noqa: BLE001 (a bench counts failures)
                fails[name][0] += 1
                print(f"  roarmctl {name} round {r}: {exc}", file=sys.stderr)
            if name != "free":
                wall, dur = roarmctl_like_mplib(ctx, step, q, seed=100 + r)
                like[name].append(wall)
                like_dur[name].append(dur)
            res = ask({"op": "plan", "query": name, "seed": 100 + r})
            if res["ok"]:
                theirs[name].append(res["wall"])
                durations[name][1].append(res["duration"])
                # does mplib's timed path enter roarmctl's padding (or margin)? checked by roarmctl's checker
                path = np.array(res["path"])
                full = np.repeat(q[None, :], len(path), axis=0)
                full[:, arm] = path
                if r < args.metric_rounds:
                    clear[name][1].append(clearance(robot, ctx.checker.scene.items, full))
                ctx.set_state(q[ctx.gi], grasp_target=None)
                padding_hits[name] += ctx.checker.first_invalid(full[:, arm]) is not None
            else:
                fails[name][1] += 1

    print(f"\n{args.rounds} interleaved rounds, medians (ms); ratio = roarmctl / mplib")
    print(f"{'query':<6}{'roarmctl':>10}{'mplib':>10}{'ratio':>8}   motion duration (s) ours / mplib   "
          "mplib paths invalid for our checker (padding, margin, held object)   failures ours/mplib")
    for name in QUERIES:
        a, b = statistics.median(ours[name]) * 1000, statistics.median(theirs[name]) * 1000
        da, db = statistics.median(durations[name][0]), statistics.median(durations[name][1])
        print(f"{name:<6}{a:>10.1f}{b:>10.1f}{a / b:>7.2f}x   {da:.2f} / {db:.2f}"
              f"{'':>22}{padding_hits[name]:>3} of {len(theirs[name])}{'':>28}{fails[name][0]}/{fails[name][1]}")
    print(f"one metric for both (first {args.metric_rounds} rounds): the arm's smallest FCL distance to the unpadded scene "
          f"along the path; paths closer than the padding ({padding * 1000:.0f} mm), ours / mplib; median clearance (mm)")
    for name in QUERIES:
        a, b = clear[name]
        print(f"  {name:<6} {sum(c < padding - 1e-6 for c in a)} of {len(a)} / {sum(c < padding - 1e-6 for c in b)} of {len(b)}"
              f"   {statistics.median(a) * 1000:.1f} / {statistics.median(b) * 1000:.1f}")
    print("\nthe public API, medians (ms): roarmctl.api.plan (plan dict -> checked, timed trajectory) against mplib "
          "(scene set up + plan_qpos); a plan starts with empty hands, so nothing is held here. api/run: ratio of the "
          "medians; per call: median over the calls of each call's api.plan / its own Planner.run (paired: no planner "
          "spread); outside: median of api.plan - Planner.run per call, wall | this thread's CPU; run p25-p75: the "
          "planner's spread over the seeds, which moves the ratio of the medians when it is wider than the set-up (their "
          "medians can be different calls); CPU per call: as per call, in CPU time")
    print(f"{'query':<6}{'api.plan':>10}{'Planner.run':>13}{'run p25-p75':>14}{'outside':>14}{'api/run':>9}{'per call':>10}"
          f"{'CPU per call':>14}{'mplib':>10}{'its set-up':>12}{'ratio':>8}   paths inside the padding ours / mplib   "
          "failures ours/mplib")
    for name in api:
        a, run = (statistics.median(v) * 1000 for v in api_ours[name])
        per_call = statistics.median(x / y for x, y in zip(*api_ours[name]))  # each call against its own planner
        outside = statistics.median(x - y for x, y in zip(*api_ours[name])) * 1000
        outside_cpu = statistics.median(x - y for x, y in zip(*api_cpu[name])) * 1000
        cpu_call = statistics.median(x / y for x, y in zip(*api_cpu[name]))
        q1, _, q3 = (v * 1000 for v in statistics.quantiles(api_ours[name][1], n=4))
        b, setup = (statistics.median(v) * 1000 for v in api_theirs[name])
        ca, cb = api_clear[name]
        print(f"{name:<6}{a:>10.1f}{run:>13.1f}{f'{q1:.1f}-{q3:.1f}':>14}{f'{outside:.1f} | {outside_cpu:.1f}':>14}"
              f"{a / run:>8.2f}x{per_call:>9.2f}x{cpu_call:>13.2f}x"
              f"{b:>10.1f}{setup:>12.1f}{a / b:>7.2f}x"
              f"   {sum(c < padding - 1e-6 for c in ca)} of {len(ca)} / {sum(c < padding - 1e-6 for c in cb)} of {len(cb)}"
              f"{'':>16}{api_fails[name][0]}/{api_fails[name][1]}")
    print("\nthe same calls in CPU time (each side's process, all its threads; medians, ms): roarmctl.api.plan against "
          "mplib's set-up + plan_qpos")
    for name in api:
        a, b = (statistics.median(v) * 1000 for v in api_pcpu[name])
        print(f"  {name:<6}{a:>10.1f}{b:>10.1f}{a / b:>7.2f}x")
    print_issue_table(api, api_ours, api_theirs, fresh, fresh_planning, per_task)
    print("roarmctl's part, medians (ms): geometry (OMPL tries + shortcutting) | timing + re-check (TOPP-RA etc.)")
    for name in QUERIES:
        g = statistics.median(geometry[name]) * 1000
        t = statistics.median(w - x for w, x in zip(ours[name], geometry[name])) * 1000
        print(f"  {name:<6}{g:>8.1f} | {t:.1f}")

    print("like for like: roarmctl's geometry + one plain TOPP-RA (joint velocity/acceleration limits only, as mplib "
          "times its path), medians (ms); ratio to mplib's query | motion duration (s)")
    for name in like:
        a, b = statistics.median(like[name]) * 1000, statistics.median(theirs[name]) * 1000
        print(f"  {name:<6}{a:>8.1f}{a / b:>7.2f}x | {statistics.median(like_dur[name]):.2f}")

    # single-state validity, the same random states on both sides
    ctx = captured["wall"][0]
    rng = np.random.default_rng(0)
    states = rng.uniform(robot.lower, robot.upper, (args.states, robot.dof))
    states[:, ctx.gi] = captured["wall"][2][ctx.gi]
    res = ask({"op": "rate", "query": "wall", "states": states.tolist()})
    checker = ctx.checker
    qa = states[:, arm]
    t0 = time.perf_counter()
    valid = sum(checker.is_valid(s) for s in qa)
    ours_rate = len(qa) / (time.perf_counter() - t0)
    print(f"\nsingle-state validity, {args.states} random states: roarmctl is_valid (margin + padding) "
          f"{ours_rate:,.0f}/s ({len(qa) - valid} invalid), mplib is_state_colliding {res['rate']:,.0f}/s "
          f"({res['colliding']} colliding): ratio {ours_rate / res['rate']:.2f}x")
    worker.stdin.close()
    worker.wait(timeout=30)


def print_issue_table(api: dict, ours: dict, theirs: dict, fresh: dict, fresh_planning: list[float],
                      per_task: list[tuple[float, float]]) -> None:
    """Issue 25's figures, medians of the interleaved rounds, each beside mplib's where it has one."""
    med = statistics.median
    print("\nissue 25's figures (medians of the same interleaved rounds; ratio = roarmctl / mplib)")
    print(f"  {'what':<58}{'roarmctl':>11}{'mplib':>11}{'ratio':>8}")

    def row(what: str, a: float, b: float | None = None, unit: str = "ms") -> None:
        print(f"  {what:<58}{a:>8.1f} {unit}" + (f"{b:>8.1f} {unit}{a / b:>7.2f}x" if b else ""))

    labels = {"a": "free move", "b": "through the wall", "c": "past the post", "d": "tray behind a tall wall",
              "e": "twelve posts", "b200": "b + 200 boxes off the path", "desk": "a in the 100,000-point desk cloud"}
    for name in api:
        a, run = (med(v) * 1000 for v in ours[name])
        b, setup = (med(v) * 1000 for v in theirs[name])
        row(f"api.plan, {name}: {labels[name]}", a, b)
        per_call = med(x / y for x, y in zip(*ours[name]))
        outside = med(x - y for x, y in zip(*ours[name])) * 1000
        row(f"  its Planner.run (api.plan / run {a / run:.2f}x; per call {per_call:.2f}x; set-up {outside:.1f} ms)", run, b)
        if name in ("b200", "desk"):
            row("  api.plan outside Planner.run (set-up) | mplib's scene set-up", outside, setup)
    for name, v in fresh.items():
        row(f"{name}, fresh process (wall)", med(v) * 1000)
    row("  its planning_time", med(fresh_planning) * 1000)
    row(f"20-task plan, planning per task (TOPP-RA {med(s for _, s in per_task):.0%})", med(t for t, _ in per_task) * 1000)


if __name__ == "__main__":
    main()
