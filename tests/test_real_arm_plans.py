"""Plans for the real arm, run after run: pitch: auto, jaw widths, move's gripper, positions in the
firmware frame, start: current. Checked with FK, the description's jaw table interpolated by hand,
and IK at the neighbouring pitch, not with the planner's own bookkeeping."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from clirun import roarmctl

from roarmctl.errors import InfeasibleError, InputError, UnreachableError
from roarmctl.motion.collision import CollisionChecker
from roarmctl.motion.options import PlannerConfig
from roarmctl.motion.pipeline import plan_file
from roarmctl.motion.scene import Scene
from roarmctl.robot.frames import from_frame, get_frame
from roarmctl.robot.ik import pitch_candidates, solve_ik, tool_pitch
from roarmctl.robot.loader import load_robot

R = load_robot("roarm_m3_pro")
GI = R.joint_index(R.gripper.joint)

HEAD = """robot: roarm_m3_pro
start: {start}
scene:
  table: {{shape: box, size: [0.80, 0.60, 0.02], xyz: [0.15, 0.0, -0.01]}}
objects:
  - {{name: cube, shape: box, size: [0.04, 0.04, 0.04], xyz: [0.25, -0.15, 0.02], mass: 0.03{extra}}}
tasks:
"""
TAIL = "planner: {name: RRTConnect, seed: 1}\n"


def write(tmp_path: Path, tasks: str, start: str = "home", extra: str = "") -> Path:
    p = tmp_path / "plan.yaml"
    p.write_text(HEAD.format(start=start, extra=extra) + tasks + TAIL)
    return p


def segment_end(traj, label_part: str) -> np.ndarray:
    seg = next(s for s in traj.segments if label_part in s.label)
    return traj.positions[int(np.argmin(np.abs(traj.times - seg.end)))]


# ---------------------------------------------------------------- pitch: auto
HIGH = [0.25, 0.1, 0.15]  # straight down fails here: link3_to_link4 would be at 91.4 deg


def test_straight_down_fails_where_pitch_auto_finds_the_nearest_valid_pitch(tmp_path):
    with pytest.raises(UnreachableError, match="link3_to_link4 would be at 9"):
        plan_file(write(tmp_path, f"  - move: {{xyz: {HIGH}, pitch: {{deg: 90}}}}\n"))
    res = plan_file(write(tmp_path, f"  - move: {{xyz: {HIGH}, pitch: auto}}\n"))
    traj = res.trajectory
    label = traj.segments[0].label
    assert "auto" in label
    chosen = float(label.split("(pitch ")[1].split(" deg")[0])
    q = traj.positions[-1]
    assert np.linalg.norm(R.kin.fk(q)[:3, 3] - HIGH) < 1e-5
    assert math.degrees(tool_pitch(R, q, HIGH)) == pytest.approx(chosen, abs=0.05)
    assert any(f"{chosen:.1f} deg" in n for n in res.notes)
    # nearest: one degree closer to straight down is not reachable within the limits
    with pytest.raises(UnreachableError):
        solve_ik(R, HIGH, pitch=math.radians(chosen + 1.0), all_solutions=True)


@pytest.mark.slow
def test_pitch_auto_with_a_preferred_angle_and_for_pick_and_place(tmp_path):
    res = plan_file(write(tmp_path, "  - pick: {object: cube, pitch: {auto: {deg: 60}}}\n"
                                    "  - place: {xyz: [0.25, 0.15, 0.02], pitch: auto}\n"))
    traj = res.trajectory
    q = segment_end(traj, "descend to 'cube'")
    assert math.degrees(tool_pitch(R, q)) == pytest.approx(60.0, abs=0.05)  # 60 deg works here: kept
    assert all("(pitch" in s.label for s in traj.segments if s.kind == "cartesian")


ON_AXIS = [0.0, 0.0, 0.3]  # above the base axis: the pitches that reach it do so only inside the margin


@pytest.mark.slow
def test_pitch_auto_on_the_base_axis_says_the_singularity_margin_rejects_it(tmp_path):
    """Every pitch that reaches a point above the base axis has its IK solutions inside the (default 0.02 m/rad)
    singularity margin, measured here by a fresh checker; plan and ``kin ik`` (the pitch chosen too) say so,
    not the preferred pitch's joint limit (the old reason) nor "collision"."""
    checker = CollisionChecker(R, Scene([]))
    sigmas = []
    for pitch in pitch_candidates(math.pi / 2):
        try:
            sols = solve_ik(R, ON_AXIS, pitch=pitch, all_solutions=True)
        except UnreachableError:
            continue
        sigmas += [float(checker.margin_measure(q[R.arm_indices])[0]) for q in sols]
    assert sigmas and max(sigmas) < PlannerConfig().singularity_margin
    with pytest.raises(UnreachableError) as ei:
        plan_file(write(tmp_path, f"  - move: {{xyz: {ON_AXIS}, pitch: auto}}\n"))
    assert ei.value.reason == "singularity" and "within the singularity margin" in ei.value.message
    assert "\n" not in ei.value.message
    proc = roarmctl("kin", "ik", "roarm_m3_pro", "--xyz", *map(str, ON_AXIS))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 3 and len(lines) == 1 and "unreachable (singularity)" in lines[0]
    assert f"{len(sigmas)} within the singularity margin" in lines[0]


# ---------------------------------------------------------------- jaw width
def test_jaws_that_do_not_clear_the_object_are_refused(tmp_path):
    # the example: gripper_open 0.05 rad around a 40 mm cube (7.3 mm of opening)
    with pytest.raises(InfeasibleError, match=r"opens the jaws 7\.3 mm.*40\.0 mm wide"):
        plan_file(write(tmp_path, "  - pick: {object: cube, gripper_open: 0.05}\n"))


def test_default_grip_closes_to_the_width_minus_the_squeeze(tmp_path):
    # a grasp_width: the jaw table, not the jaw meshes (test_physics checks those against the physics' jaws)
    res = plan_file(write(tmp_path, "  - pick: {object: cube, gripper_open: 1.0}\n", extra=", grasp_width: 0.04"))
    grip = segment_end(res.trajectory, "grasp 'cube'")[GI]
    # by hand from the description's table: 37 mm lies between 0.50 rad (34.5 mm) and 0.75 rad (46.4 mm)
    assert grip == pytest.approx(0.5 + 0.25 * (37.0 - 34.5) / (46.4 - 34.5), abs=1e-6)
    assert not res.warnings


def test_grasp_width_and_squeeze_are_used(tmp_path):
    res = plan_file(write(tmp_path, "  - pick: {object: cube, squeeze: 0.005}\n", extra=", grasp_width: 0.03"))
    grip = segment_end(res.trajectory, "grasp 'cube'")[GI]
    assert grip == pytest.approx(0.30 + 0.2 * (25.0 - 23.1) / (34.5 - 23.1), abs=1e-6)


def test_a_fully_closed_grip_on_an_object_warns(tmp_path):
    res = plan_file(write(tmp_path, "  - pick: {object: cube, gripper_closed: 0.0}\n"))
    assert any("closes the jaws fully" in w for w in res.warnings)
    res = plan_file(write(tmp_path, "  - pick: {object: cube, gripper_closed: 1.0}\n"))
    assert any("would not hold" in w for w in res.warnings)


# ---------------------------------------------------------------- chaining
def test_move_with_gripper_ends_where_it_started(tmp_path):
    res = plan_file(write(tmp_path, "  - pick: {object: cube}\n  - place: {xyz: [0.25, 0.15, 0.02]}\n"
                                    "  - move: {pose: home, gripper: closed}\n"))
    traj = res.trajectory
    assert np.abs(traj.positions[-1] - traj.positions[0]).max() < 1e-9
    # the gripper closes on the way home where its jaws are clear (blending), else at rest after the move
    last = traj.segments[-1]
    if last.kind == "gripper":
        assert "close gripper" in last.label
    else:
        sel = (traj.times > last.start) & (traj.times < last.end)
        assert last.kind == "free" and np.any(np.abs(traj.velocities[sel, GI]) > 1e-3)


def test_bundled_plans_end_where_they_start():
    root = Path(__file__).resolve().parents[1] / "plans"
    from roarmctl.plan.schema import load_plan
    from roarmctl.plan.types import MoveTask

    for p in sorted(root.glob("*.yaml")):
        plan = load_plan(p)
        last = plan.tasks[-1]
        assert isinstance(last, MoveTask) and last.pose == plan.start and last.gripper == "closed", p.name


# ---------------------------------------------------------------- frames and start: current
def test_positions_in_the_firmware_frame(tmp_path):
    target_fw = [250.0, 100.0, 30.0]
    res = plan_file(write(tmp_path, f"  - move: {{xyz: {{firmware: {target_fw}}}, pitch: auto}}\n"))
    tcp = R.kin.fk(res.trajectory.positions[-1])[:3, 3]
    assert tcp == pytest.approx([0.25, 0.10, 0.030 + 0.122059], abs=1e-5)
    assert from_frame(get_frame(R, "firmware"), target_fw) == pytest.approx(tcp, abs=1e-5)
    with pytest.raises(Exception, match="no frame 'nosuch'"):
        plan_file(write(tmp_path, "  - move: {xyz: {nosuch: [1, 2, 3]}}\n"))


def test_start_current_needs_the_arm(tmp_path):
    with pytest.raises(InputError, match="start: current"):
        plan_file(write(tmp_path, "  - move: {pose: home}\n", start="current"))
    q0 = R.full_q(np.array([0.3, 0.2, 1.2, 0.3, 0.0]))
    q0[GI] = 0.4
    res = plan_file(write(tmp_path, "  - move: {pose: home, gripper: closed}\n", start="current"), current=lambda robot: q0)
    assert res.trajectory.positions[0] == pytest.approx(q0)
    proc = roarmctl("plan", str(tmp_path / "plan.yaml"), "-o", str(tmp_path / "x.traj.json"))
    assert proc.returncode == 2 and "--port" in proc.stderr
