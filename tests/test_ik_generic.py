"""The numerical IK for arms without a closed form: batched damped least squares, and the plan's tool
pitch/roll held on a user's 5-joint hobby arm (an SO-100-like arm built here from boxes)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

import roarmctl.api as rc
from roarmctl.errors import PlanFileError, UnreachableError
from roarmctl.robot.ik import ORI_TOL, POS_TOL, pitch_aim, solve_ik, solve_ik_near
from roarmctl.robot.ik.dls import Aim, dls_batch
from roarmctl.robot.loader import load_robot

# Pan about z, then shoulder, elbow and wrist pitch about y, wrist roll about x (the approach axis), a
# jaw; the TCP 8 cm beyond the roll joint on its axis, its +x along the fingers. Lengths of the SO-100's
# order (12 cm upper arm, 13 cm forearm); boxes for collision.
URDF = """<?xml version="1.0"?>
<robot name="hobby5">
  <link name="base"><collision><origin xyz="0 0 0.025"/><geometry><box size="0.08 0.08 0.05"/></geometry></collision></link>
  <link name="shoulder"><collision><origin xyz="0 0 0.015"/><geometry><box size="0.04 0.04 0.03"/></geometry></collision></link>
  <link name="upper_arm"><collision><origin xyz="0 0 0.06"/><geometry><box size="0.025 0.025 0.09"/></geometry></collision></link>
  <link name="forearm"><collision><origin xyz="0.065 0 0"/><geometry><box size="0.1 0.022 0.022"/></geometry></collision></link>
  <link name="wrist"><collision><origin xyz="0.025 0 0"/><geometry><box size="0.02 0.03 0.03"/></geometry></collision></link>
  <link name="hand"><collision><origin xyz="0.04 0 0"/><geometry><box size="0.04 0.03 0.015"/></geometry></collision></link>
  <link name="jaw"><collision><origin xyz="0.02 0.012 0"/><geometry><box size="0.02 0.004 0.01"/></geometry></collision></link>
  <link name="tcp"/>
  <joint name="pan" type="revolute"><parent link="base"/><child link="shoulder"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="lift" type="revolute"><parent link="shoulder"/><child link="upper_arm"/>
    <origin xyz="0 0 0.03"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper_arm"/><child link="forearm"/>
    <origin xyz="0 0 0.12"/><axis xyz="0 1 0"/><limit lower="-2.6" upper="2.6" effort="1" velocity="1"/></joint>
  <joint name="flex" type="revolute"><parent link="forearm"/><child link="wrist"/>
    <origin xyz="0.13 0 0"/><axis xyz="0 1 0"/><limit lower="-2.2" upper="2.2" effort="1" velocity="1"/></joint>
  <joint name="roll" type="revolute"><parent link="wrist"/><child link="hand"/>
    <origin xyz="0.05 0 0"/><axis xyz="1 0 0"/><limit lower="-3.14159" upper="3.14159" effort="1" velocity="1"/></joint>
  <joint name="grip" type="revolute"><parent link="hand"/><child link="jaw"/>
    <origin xyz="0.04 0 0"/><axis xyz="0 0 1"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint>
  <joint name="tcp_joint" type="fixed"><parent link="hand"/><child link="tcp"/><origin xyz="0.08 0 0"/></joint>
</robot>
"""

SIDECAR = {
    "format": "roarmctl.robot/1",
    "urdf": "hobby5.urdf",
    "joints": ["pan", "lift", "elbow", "flex", "roll", "grip"],
    "tcp_link": "tcp",
    "gripper": {"joint": "grip", "open": 1.0, "closed": 0.0},
    "limits": {"velocity": [2] * 6, "acceleration": [5] * 6},
    "named_poses": {"home": [0, 0, 0.3, 0.5, 0]},
    "allowed_collisions": [["base", "shoulder"], ["shoulder", "upper_arm"], ["upper_arm", "forearm"],
                           ["forearm", "wrist"], ["wrist", "hand"], ["hand", "jaw"]],
}


@pytest.fixture(scope="module")
def hobby(tmp_path_factory):
    d = tmp_path_factory.mktemp("hobby5")
    (d / "hobby5.urdf").write_text(URDF)
    (d / "hobby5.yaml").write_text(yaml.safe_dump(SIDECAR))
    return d / "hobby5.yaml"


def _pitch_of(robot, q, p):
    """Independent reading of the tool pitch: the angle of TCP +x below the horizontal, its horizontal
    part taken along the direction from the base axis (x = y = 0 for this arm) to ``p``."""
    a = robot.kin.fk(q)[:3, 0]
    u = np.array([p[0], p[1], 0.0]) / math.hypot(p[0], p[1])
    return math.atan2(-a[2], float(a @ u)), float(np.cross(u, [0.0, 0.0, 1.0]) @ a)


def test_batched_starts_equal_one_at_a_time(hobby):
    """A batch of starts gives each start's result as if it ran alone (position + approach axis, and
    position only on the UR10), so batching changes the cost, not the answers."""
    for robot, aimed in ((load_robot(str(hobby)), True), (load_robot("ur10"), False)):
        arm = robot.arm_indices
        rng = np.random.default_rng(4)
        starts = np.array([robot.full_q(rng.uniform(robot.lower[arm], robot.upper[arm])) for _ in range(12)])
        p = robot.kin.fk(starts[0] * 0.5)[:3, 3]
        aim = pitch_aim(robot, p, 1.2, None, None) if aimed else Aim()
        lo, hi = robot.lower[arm], robot.upper[arm]
        q, ep, eo = dls_batch(robot, starts, p, aim, lo, hi)
        for i in range(len(starts)):
            q1, ep1, eo1 = dls_batch(robot, starts[i:i + 1], p, aim, lo, hi)
            assert np.allclose(q1[0], q[i], atol=1e-9), i
            assert ep1[0] == pytest.approx(ep[i], abs=1e-12) and eo1[0] == pytest.approx(eo[i], abs=1e-9)
        assert np.sum((ep <= POS_TOL) & (eo <= ORI_TOL)) >= 2  # the batch does find solutions


def test_every_solution_hits_position_and_pitch_within_limits(hobby):
    """Targets taken from random configurations (so reachable with their own pitch): every returned
    solution is within the limits, at the position, with TCP +x at the pitch, in the vertical plane."""
    robot = load_robot(str(hobby))
    arm = robot.arm_indices
    rng = np.random.default_rng(7)
    done = 0
    while done < 12:
        qa = robot.full_q(rng.uniform(robot.lower[arm] * 0.8, robot.upper[arm] * 0.8))
        p = robot.kin.fk(qa)[:3, 3]
        if math.hypot(p[0], p[1]) < 0.03:
            continue
        pitch, lateral = _pitch_of(robot, qa, p)
        if abs(lateral) > 1e-9:  # the arm's plane holds the base axis, so its approach axis is in it too
            raise AssertionError(lateral)
        sols = solve_ik(robot, p, pitch=pitch, all_solutions=True)
        for q in sols:
            assert robot.within_limits(q)
            assert np.linalg.norm(robot.kin.fk(q)[:3, 3] - p) <= POS_TOL
            got, lat = _pitch_of(robot, q, p)
            assert abs(math.remainder(got - pitch, 2 * math.pi)) <= ORI_TOL and abs(lat) <= ORI_TOL
        done += 1
    # the same inputs give the same solutions, bit for bit
    a = solve_ik(robot, p, pitch=pitch, all_solutions=True)
    b = solve_ik(robot, p, pitch=pitch, all_solutions=True)
    assert len(a) == len(b) and all(np.array_equal(x, y) for x, y in zip(a, b))


def test_roll_turns_the_tool_about_the_approach_axis(hobby):
    """Hand-derived: straight down on the +x axis, roll 0 puts TCP +y along world +y (z_up x away),
    roll +90 deg (right-handed about the downward approach axis) along world +x."""
    robot = load_robot(str(hobby))
    p = [0.2, 0.0, 0.03]
    for roll, want_y in ((0.0, [0, 1, 0]), (math.pi / 2, [1, 0, 0])):
        (q,) = solve_ik(robot, p, pitch=math.pi / 2, roll=roll)
        t = robot.kin.fk(q)
        assert np.allclose(t[:3, 0], [0, 0, -1], atol=1e-5) and np.allclose(t[:3, 1], want_y, atol=1e-5)
        assert np.linalg.norm(t[:3, 3] - p) <= POS_TOL


def test_failure_reasons(hobby):
    robot = load_robot(str(hobby))
    with pytest.raises(UnreachableError) as ei:
        solve_ik(robot, [0.6, 0.0, 0.1], pitch=math.pi / 2)
    assert ei.value.reason == "out_of_reach"
    # pointing straight up at 5 cm height, 28 cm out, the wrist (13 cm behind the TCP) would be at
    # z = -8 cm, 0.32 m from the shoulder (z = 8 cm), beyond its 0.25 m reach: not at that pitch, yet
    # the position itself is reachable
    with pytest.raises(UnreachableError) as ei:
        solve_ik(robot, [0.28, 0.0, 0.05], pitch=-math.pi / 2)
    assert ei.value.reason == "orientation" and "tool pitch -90.0 deg" in ei.value.message
    assert solve_ik(robot, [0.28, 0.0, 0.05])


def test_straight_line_points_continue_the_previous_solution(hobby):
    """solve_ik_near from a solution 1 mm away returns the configuration a small step away (the same
    roll and elbow), not another branch."""
    robot = load_robot(str(hobby))
    (q0,) = solve_ik(robot, [0.2, 0.05, 0.06], pitch=math.pi / 2, q_ref=robot.named_poses["home"])
    q1 = solve_ik_near(robot, [0.2, 0.05, 0.059], q0, pitch=math.pi / 2)
    assert np.max(np.abs(q1 - q0)) < 0.02
    assert np.linalg.norm(robot.kin.fk(q1)[:3, 3] - [0.2, 0.05, 0.059]) <= POS_TOL


def _plan(hobby, pitch=None, roll=None):
    grip = {"approach_height": 0.05}
    if pitch is not None:
        grip["pitch"] = {"deg": pitch}
    if roll is not None:
        grip["roll"] = {"deg": roll}
    return {
        "robot": str(hobby),
        "start": "home",
        "scene": {"table": {"shape": "box", "size": [0.6, 0.6, 0.02], "xyz": [0.1, 0.0, -0.01]}},
        "objects": [{"name": "cube", "shape": "box", "size": [0.02, 0.02, 0.02], "xyz": [0.2, 0.05, 0.01]}],
        "tasks": [{"pick": {"object": "cube", **grip}},
                  {"place": {"xyz": [0.2, -0.06, 0.01], **grip}},
                  {"move": {"pose": "home"}}],
        "planner": {"seed": 1},
    }


@pytest.mark.parametrize("pitch", [90, 70])
def test_pick_and_place_hold_the_plans_pitch_on_a_5_joint_arm(hobby, pitch):
    """The trajectory's grasp and release samples have the approach axis (TCP +x) at the plan's pitch,
    in the vertical plane through the base axis, and the TCP at the object (checked by FK)."""
    res = rc.plan(_plan(hobby, pitch))
    traj = res.trajectory
    robot = load_robot(str(hobby))
    for ev, where in zip([e for e in traj.events if e.kind in ("grasp", "release")], ([0.2, 0.05, 0.01], [0.2, -0.06, 0.01])):
        q = traj.positions[int(np.argmin(np.abs(traj.times - ev.time)))]
        assert np.linalg.norm(robot.kin.fk(q)[:3, 3] - where) < 1e-4
        got, lateral = _pitch_of(robot, q, where)
        assert math.degrees(got) == pytest.approx(pitch, abs=0.01) and abs(lateral) < 1e-4
    assert not any("no pitch given" in n for n in res.notes)


def test_no_pitch_is_position_only_and_says_so(hobby):
    res = rc.plan(_plan(hobby))
    assert any("no pitch given" in n and "position only" in n for n in res.notes)


def test_a_position_only_ik_refuses_a_written_pitch():
    """The RoArm-M2-S (3 arm joints, roarm3 IK) cannot hold a pitch: a plan that writes one stops with
    exit 2 naming the task, instead of dropping it."""
    plan = {"robot": "roarm_m2_s", "objects": [{"name": "c", "shape": "box", "size": [0.03] * 3, "xyz": [0.22, -0.1, 0.015]}],
            "tasks": [{"pick": {"object": "c", "pitch": {"deg": 90}}}]}
    with pytest.raises(PlanFileError) as ei:
        rc.plan(plan)
    assert ei.value.exit_code == 2 and "task 1" in ei.value.message and "position only" in ei.value.message
