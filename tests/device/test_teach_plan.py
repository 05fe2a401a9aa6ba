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
    assert text.count("# FLAGGED") == 2 and "closer to the base-axis singularity" in text and "# grasp" in text
    assert "clearance" in text  # measured against --plan's scene


def test_nothing_to_save_is_refused():
    with pytest.raises(ValueError):
        plan_text(ROBOT, [], 0.02)
