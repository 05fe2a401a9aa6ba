"""Straight TCP lines: how many samples a line gets, and that they lie on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from roarmctl.motion.cartesian import cartesian_line, line_deviation, line_steps
from roarmctl.robot.ik import solve_ik
from roarmctl.robot.loader import load_robot

ROARM = load_robot("roarm_m3_pro")


@pytest.mark.parametrize(("length", "steps"), [
    (0.06, 12), (0.06000000000000004, 12), (0.059999999999999956, 12),  # 6 cm as FK rounds it either way
    (0.05000000000000006, 10), (0.049999999999999996, 10),
    (0.0600001, 13), (0.005 * (12 + 2e-9), 13),  # really longer than 12 steps: one more
    (0.0, 1), (1e-12, 1), (0.0049, 1), (0.0051, 2),
])
def test_line_steps_counts_whole_steps_without_a_rounding_extra(length, steps):
    assert line_steps(length, 0.005) == steps


def test_a_line_whole_steps_long_gets_that_many_segments_on_the_line():
    """A 6 cm descent sampled every 5 mm: 12 equal segments (13 waypoints) whatever the last bit of the
    FK start, each waypoint's TCP on the segment (FK), the last at the goal."""
    q0 = solve_ik(ROARM, [0.25, 0.1, 0.08], pitch=math.pi / 2)[0]
    p0 = ROARM.kin.fk(q0)[:3, 3]
    for goal in (p0 + [0.0, 0.0, -0.06], p0 + [0.0, 0.06, 0.0], p0 + [0.06 / math.sqrt(2), 0.0, -0.06 / math.sqrt(2)]):
        wps = cartesian_line(ROARM, q0, goal, pitch=math.pi / 2)
        assert len(wps) == 13
        p = ROARM.kin.fk(wps)[:, :3, 3]
        assert line_deviation(ROARM, wps, p0, goal) <= 1e-6
        assert np.linalg.norm(p[-1] - goal) <= 1e-6
        seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
        assert np.all(np.abs(seg - 0.005) <= 1e-6)
