"""State-validity checks per second and planning time per OMPL planner, RoArm in the example scene.

Run: .venv/bin/python bench/bench_checker.py [--repeats 5]
Pinned to one core (sched_setaffinity, single-threaded BLAS). Prints medians over repeats.
Every check goes through the compiled kernel (src/roarmctl/_kernel.c) and FCL for the pairs
its conservative filters leave; the baselines below show what the filters and the kernel buy.

Scene (roarmctl.motion.scene.example_scene): table top at z = 0, a 0.04 x 0.10 x 0.15 m wall at
(0.28, 0, 0.075), a 40 mm cube and a small can. States are uniform random arm configurations
(about 80 % valid) or the states of straight joint-space segments between them at 0.01 rad.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from roarmctl.motion.collision import CollisionChecker, interpolate  # noqa: E402
from roarmctl.motion.scene import example_scene  # noqa: E402
from roarmctl.robot.loader import load_robot  # noqa: E402

LEFT = np.array([-0.45, 0.9, 0.87, 1.5, 0.0])  # TCP low beside the wall, either side of it
RIGHT = np.array([0.45, 0.9, 0.87, 1.5, 0.0])


def rate(fn, count: int, repeats: int) -> float:
    """Median of count / seconds over ``repeats`` runs of ``fn``."""
    fn()  # warm-up
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(count / (time.perf_counter() - t))
    return statistics.median(out)


def naive_checker(robot, scene):
    """Baseline without the compiled kernel's filters: the library's FK per state (numpy), then FCL for every
    shape/item and self pair."""
    import fcl

    checker = CollisionChecker(robot, scene)  # for the masks and pairs only
    items = checker._item_objs
    shapes = checker._moving_shapes
    kin = robot.kin
    links = [kin.link_index[s.link] for s in robot.collision]
    origins = [s.origin for s in robot.collision]

    def is_valid(q) -> bool:
        frames = kin.link_frames(robot.full_q(q))
        for a, (li, o) in enumerate(zip(links, origins)):
            t = frames[li] @ o
            shapes[a].obj_scene.setTransform(fcl.Transform(t[:3, :3], t[:3, 3]))
            shapes[a].obj_self.setTransform(fcl.Transform(t[:3, :3], t[:3, 3]))
        for a in range(len(links)):
            for k, obj in enumerate(items):
                if checker._scene_mask[a, k] and fcl.collide(shapes[a].obj_scene, obj):
                    return False
        for a, b in checker._pairs:
            if fcl.collide(shapes[a].obj_self, shapes[b].obj_self):
                return False
        return True

    return is_valid


def manager_checker(robot, scene):
    """Arm-vs-scene only, through FCL's DynamicAABBTree broadphase managers (fast FK, no pre-filter)."""
    import fcl

    checker = CollisionChecker(robot, scene)
    arm = fcl.DynamicAABBTreeCollisionManager()
    objs = [mv.obj_scene for mv in checker._moving_shapes]
    arm.registerObjects(objs)
    arm.setup()
    world = fcl.DynamicAABBTreeCollisionManager()
    world.registerObjects(checker._item_objs)
    world.setup()
    links = checker._mv_link
    q_full = robot.full_q(np.zeros(robot.arm_dof))[None, :]

    def is_valid(q) -> bool:
        q_full[0, robot.arm_indices] = q
        rot, pos = checker._fk.frames(q_full)
        for a, obj in enumerate(objs):
            r = rot[0, links[a]]
            obj.setRotation(r @ checker._mv_rot[a])
            obj.setTranslation(pos[0, links[a]] + r @ checker._mv_pos[a])
        arm.update()
        data = fcl.CollisionData()
        arm.collide(world, data, fcl.defaultCollisionCallback)
        return not data.result.is_collision

    return is_valid


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--states", type=int, default=2000)
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})

    robot = load_robot("roarm_m3_pro")
    scene = example_scene()
    checker = CollisionChecker(robot, scene)
    rng = np.random.default_rng(0)
    q = rng.uniform(checker._lower, checker._upper, (args.states, robot.arm_dof))
    print(f"RoArm-M3 Pro, example scene ({len(scene.items)} items), one core, median of {args.repeats}")
    print(f"  random states valid: {checker.validity_batch(q).mean():.0%}")

    def single():
        for qi in q:
            checker.is_valid(qi)

    print(f"  is_valid loop (1 state per call)       {rate(single, len(q), args.repeats):>10,.0f} checks/s")
    for batch in (10, 100, 400):
        def batched(batch=batch):
            for k in range(0, len(q), batch):
                checker.validity_batch(q[k:k + batch])
        print(f"  validity_batch, {batch:>3} states per call   {rate(batched, len(q), args.repeats):>10,.0f} checks/s")

    valid = q[checker.validity_batch(q)]
    segments = [interpolate(a, b, 0.01) for a, b in zip(valid[0:400:2], valid[1:400:2])]
    n_seg = sum(len(s) for s in segments)

    def seg_batch():
        for s in segments:
            checker.validity_batch(s)

    def seg_valid():
        for s in segments:
            checker.segment_valid(s[0], s[-1], 0.01)

    print(f"  motion segments at 0.01 rad (mean {n_seg / len(segments):.0f} states), one batch each:")
    print(f"    validity_batch of all states           {rate(seg_batch, n_seg, args.repeats):>10,.0f} checks/s")
    print(f"    segment_valid (early exit + refine)    {rate(seg_valid, n_seg, args.repeats):>10,.0f} states/s")

    naive = naive_checker(robot, scene)
    few = q[:400]
    print(f"  baseline: numpy FK + FCL on every pair   {rate(lambda: [naive(x) for x in few], len(few), args.repeats):>10,.0f} checks/s")
    managed = manager_checker(robot, scene)
    print(f"  FCL DynamicAABBTree managers (arm vs scene only, no self pairs)"
          f" {rate(lambda: [managed(x) for x in few], len(few), args.repeats):>8,.0f} checks/s")

    from roarmctl.motion.ompl_planner import PLANNERS, plan_joint_path_with_stats

    print("\n  planning LEFT -> RIGHT around the wall (TCP low on either side), seeds 1..5, medians:")
    print(f"    {'planner':<11} {'total ms':>9} {'solve ms':>9} {'simplify ms':>12} {'checks':>8} {'length rad':>11}")
    for name in PLANNERS:
        rows = []
        for seed in range(1, 6):
            fresh = CollisionChecker(robot, scene)
            _, st = plan_joint_path_with_stats(fresh, LEFT, RIGHT, planner=name, seed=seed, time_budget=5.0)
            rows.append((st.total_time, st.solve_time, st.simplify_time, st.checks, st.length))
        med = [statistics.median(c) for c in zip(*rows)]
        print(f"    {name:<11} {med[0] * 1e3:>9.1f} {med[1] * 1e3:>9.1f} {med[2] * 1e3:>12.1f} {med[3]:>8.0f} {med[4]:>11.2f}")
    os._exit(0)  # skip OMPL's nanobind leak report at interpreter exit


if __name__ == "__main__":
    main()
