"""The trajectory writer: a zero's sign never reaches the file."""

from __future__ import annotations

import numpy as np

from roarmctl.motion.trajectory import Event, Segment, Trajectory
from roarmctl.motion.validate import load_trajectory


def _traj(sign: float) -> Trajectory:
    """A small trajectory whose zeros carry ``sign`` (and values that round to a signed zero)."""
    z = sign * 0.0
    t = np.array([0.0, 0.01, 0.02])
    q = np.array([[z, 0.5, sign * 1e-12], [0.1, z, -0.25], [0.2, 0.5, z]])
    v = np.array([[z, z, z], [sign * 4e-10, 1.0, -2.0], [z, z, z]])
    return Trajectory("roarm_m3_pro", ["a", "b", "c"], t, q, v, v[::-1].copy(),
                      events=[Event(0.01, "grasp", "g", [z, 0.25, sign * 1e-13])],
                      segments=[Segment(z, 0.02, "free", "s")], blends=[0.01],
                      payloads=[{"start": 0.01, "end": 0.02, "link": "x", "mass": 0.1, "com": [z, 0.0, 0.01],
                                 "inertia": [[1e-5, z, z], [z, 1e-5, z], [z, z, 1e-5]], "label": "w"}],
                      scene={"items": [{"name": "b", "role": "obstacle", "shape": "box", "size": [0.1, 0.1, 0.1],
                                        "xyz": [0.2, z, 0.05], "rpy": [z, z, z]}]})


def test_written_file_has_no_negative_zero_and_reads_back_equal(tmp_path):
    neg, pos = tmp_path / "neg.json", tmp_path / "pos.json"
    _traj(-1.0).save(neg)
    _traj(1.0).save(pos)
    text = neg.read_text()
    assert "-0.0," not in text and "-0.0]" not in text and "-0.0}" not in text
    assert neg.read_bytes() == pos.read_bytes()  # flipping the sign of the zeros changes no byte
    back = load_trajectory(neg)
    src = _traj(-1.0)
    assert np.array_equal(back.times, src.times)
    assert np.array_equal(back.positions, np.round(src.positions, 9))
    assert np.array_equal(back.velocities, np.round(src.velocities, 9))
    assert np.array_equal(back.accelerations, np.round(src.accelerations, 9))
    assert "-0.25" in text and "-2.0" in text  # other negative numbers keep their sign


def test_a_file_that_is_no_trajectory_says_which_file_to_give(tmp_path):
    """'format: expected roarmctl.trajectory/1, got null' named the cause but no fix (an execution log, any JSON)."""
    import json

    import pytest

    from roarmctl.errors import TrajectoryFileError

    for doc in ({"a": 1}, {"format": "roarmctl.execlog/1"}):
        p = tmp_path / "x.json"
        p.write_text(json.dumps(doc))
        with pytest.raises(TrajectoryFileError, match="format") as info:
            load_trajectory(p)
        assert info.value.hint and "roarmctl plan" in info.value.hint
