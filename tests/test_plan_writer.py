"""The plan writer (``roarmctl.plan.writer``) against the plan reader: what is written reads back as written."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.plan.schema import load_plan
from roarmctl.plan.writer import TaskText, move_task, pick_task, place_task, plan_text

ROOT = Path(__file__).resolve().parents[1]
SCENE = {"table": {"shape": "box", "size": [0.8, 0.8, 0.02], "xyz": [0.2, 0.0, -0.01]}}
OBJECTS = [{"name": "cube", "shape": "box", "size": [0.03, 0.03, 0.03], "xyz": [0.25, 0.1, 0.015]}]

angle = st.floats(min_value=-3.0, max_value=3.0, allow_nan=False)
move = st.tuples(st.lists(angle, min_size=5, max_size=5), st.none() | st.floats(min_value=0.0, max_value=1.5))


@settings(max_examples=40, deadline=None)
@given(moves=st.lists(move, min_size=1, max_size=6), pitch=st.floats(min_value=-90, max_value=90),
       offset=st.floats(min_value=-0.01, max_value=0.01), xyz=st.tuples(*[st.floats(min_value=0.1, max_value=0.3)] * 3))
def test_written_tasks_read_back(tmp_path_factory: pytest.TempPathFactory, moves, pitch: float, offset: float,
                                 xyz: tuple[float, float, float]) -> None:
    tasks = [TaskText(move_task(q, g), comments=[f"move {k}"], note="a note") for k, (q, g) in enumerate(moves)]
    tasks += [TaskText(pick_task("cube", pitch, offset, 0.6)), TaskText(place_task(xyz, pitch, 1.2))]
    text = plan_text("roarm_m3_pro", tasks, header=["# written by a test"], carried={"scene": SCENE, "objects": OBJECTS},
                     limits={"blend": False}, limits_note="why", planner={"seed": 3})
    path = tmp_path_factory.mktemp("plan") / "p.yaml"
    path.write_text(text)
    plan = load_plan(path)
    assert [t.kind for t in plan.tasks] == ["move"] * len(moves) + ["pick", "place"]
    for task, (q, g) in zip(plan.tasks, moves):
        assert np.allclose(task.joints, q, atol=5e-7)  # written to 1e-6 rad
        assert (task.gripper is None) == (g is None) and (g is None or math.isclose(task.gripper, g, abs_tol=5e-7))
    pick, place = plan.tasks[-2:]
    assert pick.object == "cube" and pick.gripper_closed == pytest.approx(0.6)
    assert pick.grasp_offset == pytest.approx(offset, abs=5e-5)
    assert pick.pitch == pytest.approx(math.radians(pitch), abs=1e-4) and place.gripper_open == pytest.approx(1.2)
    assert place.xyz == pytest.approx(xyz, abs=5e-7)
    assert plan.limits.blend is False and plan.planner.seed == 3 and [o.name for o in plan.objects] == ["cube"]
