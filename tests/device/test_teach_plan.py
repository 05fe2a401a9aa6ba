"""What teach judges and saves, without a device: the planner's singularity measure and its bands, and the
saved plan (read back by the plan reader, the scene of --plan kept, flags and gripper actions written)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from roarmctl.device.teach import Judge, Waypoint
from roarmctl.device.teach_plan import plan_text, save_plan
from roarmctl.motion.planning.context import scene_item
from roarmctl.plan.schema import load_plan
from roarmctl.robot.loader import load_robot

ROOT = Path(__file__).resolve().parents[2]
ROBOT = load_robot("roarm_m3_pro")
CLEAR = np.array([0.4, 0.3, 1.3, 0.3, 0.0, 1.2])
NEAR = np.array([-0.3, 0.6, 0.05, 0.2, 0.0, 0.5])
INSIDE = np.array([0.0, 0.3, 0.05, 0.0, 0.0, 0.5])  # the stretched arm, wrist in line


def sigma_by_svd(q) -> float:
    """Smallest singular value of the translational Jacobian's arm columns, from numpy's SVD."""
    jac = ROBOT.kin.jacobian(q)[:3, ROBOT.arm_indices]
    return float(np.linalg.svd(jac, compute_uv=False)[-1])


def test_judge_uses_the_planners_measure_and_bands_it():
    judge = Judge(ROBOT, 0.02)
    for q, band in ((CLEAR, "clear"), (NEAR, "near"), (INSIDE, "inside")):
        m = judge.measure(q, validity=True)
        assert m.sigma == pytest.approx(sigma_by_svd(q), abs=1e-9)
        assert m.band == band
        assert m.manipulability == pytest.approx(float(np.prod(np.linalg.svd(ROBOT.kin.jacobian(q), compute_uv=False))))
        assert ("singularity" in m.problem) == (band == "inside")


def test_saved_plan_reads_back_with_the_scene_flags_and_gripper(tmp_path):
    source = load_plan(ROOT / "plans" / "pick_place.yaml", list(ROBOT.named_poses), frames=ROBOT.frames)
    judge = Judge(ROBOT, source.planner.singularity_margin, [scene_item(s) for s in source.scene + source.objects])
    wps = []
    for t, (q, action) in enumerate([(CLEAR, None), (CLEAR * [1, 1, 1, 1, 1, 0.5], "grasp"), (NEAR, None),
                                     (INSIDE, None), (CLEAR, "release")]):
        m = judge.measure(q, validity=True)
        flags = [m.problem] if m.problem else (["within 2x the singularity margin"] if m.band == "near" else [])
        wps.append(Waypoint(q, float(t), action, m, flags))
    out = tmp_path / "taught.yaml"
    save_plan(out, ROBOT, wps, judge.margin, source)
    text = out.read_text()
    plan = load_plan(out, list(ROBOT.named_poses), frames=ROBOT.frames)
    assert plan.start == "current" and len(plan.tasks) == 5 and plan.limits.blend is False
    assert [s.name for s in plan.scene + plan.objects] == [s.name for s in source.scene + source.objects]
    assert plan.planner.singularity_margin == source.planner.singularity_margin
    for task, w in zip(plan.tasks, wps):
        assert task.kind == "move" and task.joints == pytest.approx(w.q[:5], abs=1e-6)
    # the gripper: set at the first waypoint, at each grasp/release and where it moved (0.6 -> 0.5), kept elsewhere
    assert [t.gripper for t in plan.tasks] == [pytest.approx(1.2), pytest.approx(0.6), pytest.approx(0.5), None,
                                               pytest.approx(1.2)]
    assert text.count("# FLAGGED") == 2 and "closer to a singularity than the margin" in text and "# grasp" in text
    assert "clearance" in text  # measured against --plan's scene


def test_nothing_to_save_is_refused():
    with pytest.raises(ValueError):
        plan_text(ROBOT, [], 0.02)


@pytest.mark.slow  # plans the saved plan in a fresh `roarmctl plan`: 1.1 s of CPU
def test_a_grasp_at_a_plan_object_becomes_pick_and_place_that_plan(tmp_path):
    """Taught over plans/pick_place.yaml: above the cube, grasp at its centre, carry, release 30 cm over: the saved
    plan picks the cube and places it where the hand released it; `plan` plans it (the cube carried and checked)."""
    import json

    from clirun import roarmctl

    from roarmctl.robot.ik import solve_ik_near

    source = load_plan(ROOT / "plans" / "pick_place.yaml", list(ROBOT.named_poses), frames=ROBOT.frames)
    judge = Judge(ROBOT, source.planner.singularity_margin, [scene_item(s) for s in source.scene + source.objects])
    home = ROBOT.named_poses["home"]
    cube, target = np.array([0.25, -0.15, 0.02]), np.array([0.25, 0.15, 0.02])

    def at(xyz, grip):
        q = solve_ik_near(ROBOT, xyz, home, pitch=np.pi / 2).copy()
        q[5] = grip
        return q

    taught = [(at(cube + [0, 0, 0.06], 1.0), None), (at(cube, 0.6), "grasp"), (at(target + [0, 0, 0.06], 0.6), None),
              (at(target, 1.0), "release"), (at(target + [0, 0, 0.06], 1.0), None)]
    wps = [Waypoint(q, float(t), a, judge.measure(q, validity=True)) for t, (q, a) in enumerate(taught)]
    out = tmp_path / "taught.yaml"
    save_plan(out, ROBOT, wps, judge.margin, source)
    plan = load_plan(out, list(ROBOT.named_poses), frames=ROBOT.frames)
    assert [t.kind for t in plan.tasks] == ["move", "pick", "move", "place", "move"]
    pick, place = plan.tasks[1], plan.tasks[3]
    assert pick.object == "cube" and pick.gripper_closed == pytest.approx(0.6) and pick.grasp_offset == pytest.approx(0, abs=1e-4)
    assert pick.pitch == pytest.approx(np.pi / 2, abs=1e-3) and place.pitch == pytest.approx(np.pi / 2, abs=1e-3)
    assert place.xyz == pytest.approx(target, abs=1e-4)  # the cube's centre where the hand let it go
    r = roarmctl("plan", str(out), "--sim", "-o", str(tmp_path / "t.traj.json"))
    assert r.returncode == 0, r.stderr
    kinds = [e["kind"] for e in json.loads((tmp_path / "t.traj.json").read_text())["events"]]
    assert kinds == ["grasp", "release"]


def test_the_replay_reaches_every_taught_waypoint_and_says_so(tmp_path):
    """The saved plan writes what it chose (zone 0, blend false); planned from the first waypoint, the replay's
    table has every taught waypoint reached: its joints within 1 mrad, checked here on the samples themselves."""
    from roarmctl.motion.pipeline import plan_file

    taught = [np.array([0.4, 0.3, 1.3, 0.3, 0.0, 1.0]), np.array([-0.2, 0.4, 1.1, 0.5, 0.0, 1.0]),
              np.array([0.3, 0.1, 1.5, 0.2, 0.0, 1.0])]
    judge = Judge(ROBOT, 0.02)
    wps = [Waypoint(q, float(t), None, judge.measure(q, validity=True), []) for t, q in enumerate(taught)]
    out = tmp_path / "taught.yaml"
    save_plan(out, ROBOT, wps, judge.margin)
    text = out.read_text()
    assert "zone: 0.0" in text and "every taught waypoint is reached" in text
    result = plan_file(out, current=lambda robot: taught[0])
    traj = result.trajectory
    assert [row["reached"] for row in traj.targets] == [True] * 3
    arm = ROBOT.arm_indices
    for q in taught:
        assert np.min(np.max(np.abs(traj.positions[:, arm] - q[arm]), axis=1)) <= 1e-3
