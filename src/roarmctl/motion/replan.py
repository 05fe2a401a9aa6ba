"""Plan from where the arm is: a trajectory's start reached, or its first free motion re-planned,
from a measured configuration, with the trajectory's own scene, limits, singularity margin and
planner (the same ``Planner`` as ``roarmctl plan``: OMPL + FCL, TOPP-RA, the same re-checks).

Three cases, one code path (``plan_between`` then a splice):

* ``"gripper"``: the arm stands at the start but the gripper does not: open/close it first.
* ``"move_to_start"``: a planned, checked, timed motion from the measured pose to the start, then
  the whole trajectory.
* ``"from_current"``: the first free motion is planned again from the measured pose. When the
  trajectory's plan file is still there unchanged (same sha256), the plan is planned again from the
  measured pose (same seed: the first free motion starts here, blending included); otherwise the
  first free motion is replaced by one planned to where it ended, if the trajectory is at rest there.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import InfeasibleError, InputError
from roarmctl.fileio import read_bytes
from roarmctl.motion.options import LIMITS_BOUNDS, Limits, PlannerConfig
from roarmctl.motion.scene import Scene
from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.plan.types import ItemSpec, MoveTask, Plan
from roarmctl.validation import MAX_BYTES

if TYPE_CHECKING:
    from roarmctl.robot.model import Robot

MODES = ("gripper", "move_to_start", "from_current")


def _plan_for(traj: Trajectory, robot: Robot, q_from: np.ndarray, q_to: np.ndarray) -> Plan:
    """A ``Plan`` with the trajectory's scene, limits and planner: one move from ``q_from`` to ``q_to``."""

    items = Scene.from_dict(traj.scene or {"items": []}).items
    specs = [ItemSpec(name=i.name, role=i.role, shape=i.shape, pose=i.pose.copy(), size=(i.size[0], i.size[1], i.size[2]),
                      radius=i.radius, length=i.length, data=i.mesh or i.cloud) for i in items]
    lim = traj.limits or {}
    tcp = lim.get("max_tcp_speed")
    hi = LIMITS_BOUNDS["max_tcp_speed"].hi  # older Planner versions recorded up to 100 m/s: no cap on these arms either
    limits = Limits(velocity_scale=float(lim.get("velocity_scale", 0.5)),
                    acceleration_scale=float(lim.get("acceleration_scale", 0.5)),
                    max_tcp_speed=None if tcp is None else min(float(tcp), hi))
    meta = traj.plan or {}
    margin = (traj.singularity_margin or {}).get("min_singular_value")
    cfg = PlannerConfig(name=str(meta.get("planner", PlannerConfig.name)), seed=int(meta.get("seed", 0) or 0),
                        padding=float(meta.get("padding", PlannerConfig.padding)),
                        singularity_margin=float(margin) if margin else 0.0)
    gi = robot.joint_index(robot.gripper.joint) if robot.gripper else None
    task = MoveTask(joints=np.asarray(q_to, dtype=float).copy(), gripper=None if gi is None else float(q_to[gi]), line=0)
    path = Path(str(meta.get("path", "trajectory")))
    return Plan(path=path, sha256=str(meta.get("sha256", "")), robot=traj.robot, start=np.asarray(q_from, dtype=float).copy(),
                scene=[s for s in specs if s.role != "object"], objects=[s for s in specs if s.role == "object"],
                tasks=[task], limits=limits, planner=cfg)


def plan_between(traj: Trajectory, robot: Robot, q_from: np.ndarray, q_to: np.ndarray, label: str) -> Trajectory:
    """Plan ``q_from`` -> ``q_to`` (full configurations, rad): a free motion (if the arm must move),
    then the gripper (if it must move), in the trajectory's scene; segments labelled ``label``."""
    from roarmctl.motion.pipeline import Planner, load_planning_libraries

    load_planning_libraries()
    plan = _plan_for(traj, robot, q_from, q_to)
    out = Planner(plan, robot).run().trajectory
    for s in out.segments:
        s.label = f"{label}: {s.label.split(': ', 1)[-1]}"
    out.positions[-1] = q_to  # the planner ends there to 1e-9; make the splice exact
    return out


def concat(a: Trajectory, b: Trajectory) -> Trajectory:
    """``a`` then ``b`` (``b`` starts where ``a`` ends); metadata (scene, limits, plan) from ``b``."""
    off = a.duration
    return Trajectory(
        robot=b.robot, joint_names=list(b.joint_names),
        times=np.concatenate([a.times, b.times[1:] + off]),
        positions=np.concatenate([a.positions, b.positions[1:]]),
        velocities=np.concatenate([a.velocities, b.velocities[1:]]),
        accelerations=np.concatenate([a.accelerations, b.accelerations[1:]]),
        events=list(a.events) + [Event(e.time + off, e.kind, e.label, e.position) for e in b.events],
        segments=list(a.segments) + [Segment(s.start + off, s.end + off, s.kind, s.label) for s in b.segments],
        limits=b.limits, singularity_margin=b.singularity_margin, scene=b.scene, plan=b.plan, sample_rate=b.sample_rate)


def tail(traj: Trajectory, t: float) -> Trajectory:
    """The part of ``traj`` from the sample at time ``t`` (s) on, shifted to start at 0."""
    k = int(np.argmin(np.abs(traj.times - t)))
    t0 = float(traj.times[k])
    return Trajectory(
        robot=traj.robot, joint_names=list(traj.joint_names), times=traj.times[k:] - t0,
        positions=traj.positions[k:].copy(), velocities=traj.velocities[k:].copy(),
        accelerations=traj.accelerations[k:].copy(),
        events=[Event(e.time - t0, e.kind, e.label, e.position) for e in traj.events if e.time >= t0 - 1e-9],
        segments=[Segment(s.start - t0, s.end - t0, s.kind, s.label) for s in traj.segments if s.start >= t0 - 1e-9],
        limits=traj.limits, singularity_margin=traj.singularity_margin, scene=traj.scene, plan=traj.plan,
        sample_rate=traj.sample_rate)


def _plan_again(traj: Trajectory, q: np.ndarray) -> Trajectory | None:
    """The trajectory's plan planned again from ``q`` (same seed), or None when its file is gone or changed."""
    meta = traj.plan or {}
    path = Path(str(meta.get("path", "")))
    if not meta.get("sha256") or not path.is_file():
        return None
    try:  # the trajectory names this file: read it like a plan (bounded), and only if its hash matches
        data = read_bytes(path, None, MAX_BYTES)
    except InputError:
        return None
    if hashlib.sha256(data).hexdigest() != meta["sha256"]:
        return None
    from roarmctl.motion.pipeline import plan_file

    return plan_file(path, seed=meta.get("seed"), current=lambda robot: q, start_here=True).trajectory


def replan_start(traj: Trajectory, robot: Robot, q_measured: np.ndarray, mode: str) -> tuple[Trajectory, str]:
    """The trajectory to run from ``q_measured`` (dof,) rad, and one sentence saying what was planned.

    ``mode`` is one of ``MODES``. Raises InfeasibleError/PlanningError like ``roarmctl plan``.
    """
    q = np.asarray(q_measured, dtype=float)
    if mode in ("gripper", "move_to_start"):
        q0 = traj.positions[0].copy()
        label = "open/close the gripper first" if mode == "gripper" else "move to the trajectory's start"
        first = plan_between(traj, robot, q, q0, label)
        what = ("the gripper differs from the trajectory's start: planned and checked a "
                f"{first.duration:.2f} s gripper motion first" if mode == "gripper" else
                f"planned a {first.duration:.2f} s collision-checked motion from the measured pose to the start")
        return concat(first, traj), what
    if mode != "from_current":
        raise ValueError(f"mode must be one of {MODES}")
    again = _plan_again(traj, q)
    if again is not None:
        return again, (f"planned '{Path((traj.plan or {})['path']).name}' again from the measured pose: {again.duration:.2f} s "
                       f"(was {traj.duration:.2f} s from its start)")
    free = next((s for s in traj.segments if s.kind == "free"), None)
    if free is None:
        raise InfeasibleError("the trajectory has no free motion to plan again", "use move_to_start instead",
                              option="from_current")
    before = [s for s in traj.segments if s.end <= free.start + 1e-9]
    if any(s.kind == "cartesian" for s in before):
        raise InfeasibleError("the trajectory starts with a straight-line motion before its first free one",
                              "use move_to_start instead", option="from_current")
    if any(e.time <= free.end + 1e-9 for e in traj.events):
        raise InfeasibleError("the trajectory grasps or releases before its first free motion ends",
                              "use move_to_start instead", option="from_current")
    rest = tail(traj, free.end)
    if np.max(np.abs(rest.velocities[0])) > 1e-6:
        raise InfeasibleError("the first free motion blends into the next one and the trajectory's plan "
                              f"file ({(traj.plan or {}).get('path')}) is not there unchanged to plan it again",
                              "use move_to_start, or plan again with start: current", option="from_current")
    first = plan_between(traj, robot, q, rest.positions[0].copy(), f"{free.label} (planned again from the measured pose)")
    what = (f"re-planned the first free motion from the measured pose: {first.duration:.2f} s instead of "
            f"{free.end:.2f} s to reach '{free.label}''s end")
    return concat(first, rest), what
