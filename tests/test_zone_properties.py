"""Zones over generated plans (issue 32, item 4): a seeded generator builds move/pick/place sequences for the RoArm
and two published arms of tests/data/arms (the UR5e, gripperless: moves only; the xArm6 with its gripper), with
random zones and blending on or off. For every plan that plans (an unreachable draw is exit 3 and skipped, and
counted), checked by means the planner does not use:

* every move target is within its zone (0: 0.5 mm) of the TCP at some sample of its own motion, by the naive chain
  product of ``test_kinematics.naive_link_frames``; every grasp and release is reached (0.5 mm);
* every straight descent and lift stays within 1 mm of its vertical line (same FK);
* every sample is within the joint limits and clear of the table (a collision checker over the table alone,
  without the planner's padding, the gripper as sampled).

The seed of a failing draw is in the assertion message: ``generated(arm, seed)`` rebuilds its plan.
``make test-fast`` runs a few draws per arm; ``make test`` the sweep (slow, ``SWEEP``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_kinematics import naive_link_frames

from roarmctl import api
from roarmctl.errors import InfeasibleError
from roarmctl.robot.loader import load_robot

CORPUS = Path(__file__).parent / "data" / "arms"
TABLE_TOP = 0.0
# per arm: where the plan lives (its robot path is relative to it), the robot, its start, the box move targets are
# drawn in (m, world frame), the object spots' box (centres on the table), the approach height, whether it grasps
ARMS = {
    "roarm_m3_pro": dict(base=None, robot="roarm_m3_pro", start="home", box=((0.17, -0.2, 0.05), (0.3, 0.2, 0.16)),
                         spots=((0.18, -0.2), (0.3, 0.2)), approach=0.06, pitch=None, grasps=True,
                         table=dict(size=[0.8, 0.6, 0.02], xyz=[0.15, 0.0, -0.01])),
    "ur5e": dict(base=CORPUS / "ur5e", robot="robot.yaml", start=[0, -1.571, 1.571, -1.571, -1.571, 0],
                 box=((0.3, -0.35, 0.05), (0.55, 0.35, 0.3)), spots=None, approach=0.08, pitch={"deg": 90},
                 grasps=False, table=dict(size=[1.32, 1.32, 0.02], xyz=[0.27, 0.0, -0.011])),
    "xarm6": dict(base=CORPUS / "xarm6", robot="robot.yaml", start=[1.2, -0.3, -0.6, 0, 0.9, 0],
                  box=((0.3, -0.3, 0.08), (0.5, 0.3, 0.3)), spots=((0.32, -0.3), (0.48, 0.3)), approach=0.08,
                  pitch={"deg": 90}, grasps=True, table=dict(size=[1.2, 1.2, 0.02], xyz=[0.24, 0.0, -0.011])),
}
CUBE = 0.04


def generated(arm: str, seed: int) -> tuple[dict, list[dict]]:
    """A plan (as a dict) for ``arm`` from ``seed`` and what it names, in order: {kind, xyz, zone} per target
    (kind move, grasp or release; a grasp's and release's zone 0)."""
    rng = np.random.default_rng(seed)
    spec = ARMS[arm]
    lo, hi = (np.array(v) for v in spec["box"])
    tasks, named = [], []
    obj = None
    holding = False
    n = int(rng.integers(2, 6))
    for _ in range(n):
        if spec["grasps"] and not holding and obj is None and rng.random() < 0.4:
            (x0, y0), (x1, y1) = spec["spots"]
            obj = [float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)), TABLE_TOP + CUBE / 2]
            tasks.append({"pick": {"object": "cube", "approach_height": spec["approach"]}})
            named.append({"kind": "grasp", "xyz": np.array(obj), "up": spec["approach"]})
            holding = True
        elif holding and rng.random() < 0.5:
            (x0, y0), (x1, y1) = spec["spots"]
            xyz = [float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)), TABLE_TOP + CUBE / 2]
            tasks.append({"place": {"xyz": xyz, "approach_height": spec["approach"]}})
            named.append({"kind": "release", "xyz": np.array(xyz), "up": spec["approach"]})
            holding = False
        else:
            xyz = [float(v) for v in rng.uniform(lo, hi)]
            move = {"xyz": xyz}
            tasks.append({"move": move})
            named.append({"kind": "move", "xyz": np.array(xyz), "task": move, "up": 0.0})
    if holding:
        (x0, y0), (x1, y1) = spec["spots"]
        xyz = [float(rng.uniform(x0, x1)), float(rng.uniform(y0, y1)), TABLE_TOP + CUBE / 2]
        tasks.append({"place": {"xyz": xyz, "approach_height": spec["approach"]}})
        named.append({"kind": "release", "xyz": np.array(xyz), "up": spec["approach"]})
    if spec["pitch"] is not None:
        for t in tasks:
            next(iter(t.values()))["pitch"] = spec["pitch"]
    # zones: 0 often, else up to 0.9 of the way to where the next motion ends (a pick's or place's approach point)
    for k, tgt in enumerate(named):
        tgt["zone"] = 0.0
        if tgt["kind"] != "move":
            continue
        if k + 1 < len(named):
            nxt = named[k + 1]
            gap = float(np.linalg.norm(nxt["xyz"] + [0.0, 0.0, nxt["up"]] - tgt["xyz"]))
            zone = 0.0 if rng.random() < 0.35 else round(float(rng.uniform(0.0, 0.9 * min(gap, 0.08))), 4)
        else:
            zone = round(float(rng.uniform(0.0, 0.03)), 4)
        tgt["zone"] = zone
        tgt["task"]["zone"] = zone
    plan = {"robot": spec["robot"], "start": spec["start"],
            "scene": {"table": {"shape": "box", **spec["table"]}},
            "tasks": tasks, "limits": {"blend": bool(rng.random() < 0.75), "velocity_scale": 1.0,
                                       "acceleration_scale": 1.0},
            "planner": {"seed": int(seed), "max_checks": 200_000}}
    if obj is not None:
        plan["objects"] = [{"name": "cube", "shape": "box", "size": [CUBE] * 3, "xyz": obj, "mass": 0.02}]
    return plan, named


_ROBOTS: dict[str, object] = {}


def robot_of(arm: str):
    if arm not in _ROBOTS:
        spec = ARMS[arm]
        _ROBOTS[arm] = load_robot(spec["robot"] if spec["base"] is None else str(spec["base"] / spec["robot"]))
    return _ROBOTS[arm]


def windows(traj, kinds: list[str]) -> list[np.ndarray]:
    """Per named target (``kinds`` in order): the sample indices of its own motion (the segment that ends at it
    and the next one), found by the segment labels the planner writes (``move``, ``descend to``, ``lower``)."""
    words = {"move": ": move", "grasp": ": descend to", "release": ": lower"}
    out, start = [], 0
    for kind in kinds:
        k = next(i for i in range(start, len(traj.segments)) if words[kind] in traj.segments[i].label)
        start = k + 1
        hi = traj.segments[k + 1].end if k + 1 < len(traj.segments) else traj.duration
        out.append(np.flatnonzero((traj.times >= traj.segments[k].start - 1e-9) & (traj.times <= hi + 1e-9)))
    return out


def check(arm: str, seed: int) -> bool:
    """Plan draw ``seed`` for ``arm`` and check it; False if it is unreachable (exit 3 from the IK or OMPL)."""
    from roarmctl.motion.collision import CollisionChecker
    from roarmctl.motion.scene import Scene, SceneItem

    plan, named = generated(arm, seed)
    spec = ARMS[arm]
    try:
        result = api.plan(plan, base_dir=spec["base"])
    except InfeasibleError as exc:
        assert "outside its zone" not in exc.message and "move target passed at" not in exc.message, f"seed {seed}: {exc.message}"
        return False
    traj = result.trajectory
    robot = robot_of(arm)
    tcp = naive_link_frames(robot, traj.positions)[:, robot.kin.tcp_index, :3, 3]
    for tgt, sel in zip(named, windows(traj, [t["kind"] for t in named])):
        miss = float(np.min(np.linalg.norm(tcp[sel] - tgt["xyz"] if tgt["kind"] == "move" else tcp[sel] - grasp_point(traj, tgt), axis=1)))
        assert miss <= max(tgt["zone"], 5e-4) + 1e-9, f"seed {seed} ({arm}): {tgt['kind']} at {tgt['xyz']} missed by {miss * 1e3:.2f} mm (zone {tgt['zone']})"
    for seg in traj.segments:  # straight descents, lifts, lowerings and retreats: vertical lines
        if seg.kind != "cartesian":
            continue
        sel = np.flatnonzero((traj.times >= seg.start - 1e-9) & (traj.times <= seg.end + 1e-9))
        point = next(grasp_point(traj, t) for t in named if t["kind"] != "move" and _near_line(tcp[sel], grasp_point(traj, t)))
        off = np.linalg.norm(tcp[sel, :2] - point[:2], axis=1)
        assert np.max(off) <= 1e-3 + 1e-9, f"seed {seed} ({arm}): '{seg.label}' leaves its line by {np.max(off) * 1e3:.2f} mm"
    assert np.all(traj.positions >= robot.lower - 1e-6) and np.all(traj.positions <= robot.upper + 1e-6), f"seed {seed} ({arm})"
    table = spec["table"]
    pose = np.eye(4)
    pose[:3, 3] = table["xyz"]
    checker = CollisionChecker(robot, Scene([SceneItem.checked_primitive("table", "table", "box", pose, tuple(table["size"]), 0.0, 0.0)]),
                               padding=0.0)
    arm_idx = robot.arm_indices
    gi = robot.joint_index(robot.gripper.joint) if robot.gripper else None
    bad = checker.first_invalid(traj.positions[:, arm_idx], **({} if gi is None else {"gripper": traj.positions[:, gi]}))
    assert bad is None, f"seed {seed} ({arm}): sample {bad} at {traj.times[bad]:.2f} s touches the table"
    return True


def grasp_point(traj, tgt: dict) -> np.ndarray:
    """Where the TCP grasps or releases: the event's recorded target (the object's centre, for these plans)."""
    kind = tgt["kind"]
    events = [np.asarray(e.position) for e in traj.events if e.kind == kind and e.position is not None]
    return min(events, key=lambda p: float(np.linalg.norm(p[:2] - tgt["xyz"][:2])))


def _near_line(points: np.ndarray, p: np.ndarray) -> bool:
    return float(np.min(np.linalg.norm(points[:, :2] - p[:2], axis=1))) < 0.01


def sweep(arm: str, seeds: range) -> None:
    planned = sum(check(arm, s) for s in seeds)
    assert planned >= 0.5 * len(seeds), f"{arm}: only {planned} of {len(seeds)} draws planned (seeds {seeds})"


@pytest.mark.slow  # plans and times generated plans on three arms: 10-30 s each idle (97 s for xarm6 at load 20)
@pytest.mark.parametrize("arm", list(ARMS))
def test_a_few_generated_plans_reach_their_targets(arm):
    sweep(arm, range(3))


# 40 draws on the UR5e and the xArm6, 80 on the RoArm (100 each before: 29 s of CPU for the three arms). A planner
# whose blends round a corner within 4x the named zone (blending.zone_limits given 4 * zone) fails draws 31, 73, 80,
# 95, 97 (RoArm), 4, 10, 64, 71, 79, 89 (UR5e) and 13, 17, 73 (xArm6) of seeds 3-102: seeds 3-42 catch it twice on
# the UR5e and the xArm6 but once on the RoArm (31), whose sweep therefore goes on to seed 82 (31, 73, 80).
SWEEP = {"roarm_m3_pro": range(3, 83), "ur5e": range(3, 43), "xarm6": range(3, 43)}


@pytest.mark.slow
@pytest.mark.parametrize("arm", list(ARMS))
def test_generated_plans_reach_their_targets(arm):
    sweep(arm, SWEEP[arm])
