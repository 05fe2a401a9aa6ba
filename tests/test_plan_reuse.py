"""A plan of many cycles reuses what it computed (IK, straight lines, timed chains), and reuse changes nothing.

The plan: pick_place.yaml's cube carried to its place and back, 3 cycles of pick, place, pick, place (as
bench/bench_vs_mplib.py's 20-task plan, shorter). Checked against a second planning of the same plan with
every kept result thrown away (each lookup misses): the same trajectory, byte for byte; and by counting the
TOPP-RA runs per cycle: the first two cycles time their motions, the third, which meets the world of the
second bit for bit (a released object's pose and the fixed jaw's targets are rounded to a micrometre),
times none.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

import roarmctl.motion.planning.context as context
from roarmctl.kept import Kept
from roarmctl.motion.pipeline import plan_file
from roarmctl.motion.timing import import_toppra

PLANS = Path(__file__).resolve().parents[1] / "plans"


def cycles_plan(cycles: int) -> dict:
    doc = yaml.safe_load((PLANS / "pick_place.yaml").read_text())
    pick, place, _home = doc["tasks"]
    back = {"place": {**place["place"], "xyz": doc["objects"][0]["xyz"]}}
    doc["tasks"], doc["cycles"] = [pick, place, {"pick": dict(pick["pick"])}, back], cycles
    return doc


class _Forgetful(Kept):
    """A store whose lookups always miss: nothing kept is ever reused."""

    def get(self, key, default=None):
        return None


@pytest.mark.slow  # CPU: a 12-task plan planned twice
def test_reuse_gives_the_same_bytes_as_planning_everything_afresh(monkeypatch):
    doc = cycles_plan(3)
    kept = plan_file(copy.deepcopy(doc), seed=7, base_dir=PLANS)
    init = context.PlanContext.__init__

    def forgetful(self, *args, **kwargs):
        init(self, *args, **kwargs)
        for name in ("timed", "chains", "iks", "lines", "jaw_targets"):
            setattr(self, name, _Forgetful(256))

    monkeypatch.setattr(context.PlanContext, "__init__", forgetful)
    afresh = plan_file(copy.deepcopy(doc), seed=7, base_dir=PLANS)
    assert json.dumps(kept.trajectory.to_dict(), sort_keys=True) == json.dumps(afresh.trajectory.to_dict(), sort_keys=True)
    assert kept.warnings == afresh.warnings and kept.notes == afresh.notes
    # the work it saved: the same plan timed far less (TOPP-RA wall time is noisy; the stage exists in both)
    assert set(kept.timings) == set(afresh.timings)


def test_the_third_cycle_meets_the_second_ones_world_and_times_nothing(monkeypatch):
    import roarmctl.motion.pipeline as pipeline

    algorithm = import_toppra().algorithm
    runs: list[int] = []  # the task index (from 0) being expanded at every TOPP-RA run
    task = [0]
    solve, expand = algorithm.TOPPRA.compute_parameterization, pipeline.tasks.expand

    def counted(self, *args, **kwargs):
        runs.append(task[0])
        return solve(self, *args, **kwargs)

    def tracked(ctx, t, q, index):
        task[0] = index
        return expand(ctx, t, q, index)

    monkeypatch.setattr(algorithm.TOPPRA, "compute_parameterization", counted)
    monkeypatch.setattr(pipeline.tasks, "expand", tracked)
    result = plan_file(cycles_plan(3), seed=7, base_dir=PLANS)
    per_cycle = np.bincount(np.asarray(runs) // 4, minlength=3)
    assert per_cycle[0] > 0 and per_cycle[2] == 0, runs  # the first cycle starts at home; the third repeats the second
    # the cycles repeat: every segment of the third lasts as long as the second's (the very last retreat aside: it
    # comes to rest instead of blending into a next transit)
    lengths = {s.label: s.end - s.start for s in result.trajectory.segments}
    second = [(label, n) for label, n in lengths.items() if label.startswith(("task 5 ", "task 6 ", "task 7 ", "task 8 "))]
    assert len(second) == 16
    for label, n in second[:-1]:
        number = int(label.split()[1])
        again = lengths[label.replace(f"task {number} ", f"task {number + 4} ", 1)]
        assert abs(again - n) < 1e-9, (label, n, again)
