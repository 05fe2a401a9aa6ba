"""The execution log format (``roarmctl.device.execlog``): what a writer builds is what the reader gives back,
and the reader refuses what no writer writes (times out of order or not finite, numbers out of bounds)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import hostile
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.device.execlog import FORMAT, MAX_LOG_TIME, ExecLog, is_log, parse_log, read_log, write_log
from roarmctl.errors import TrajectoryFileError

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
times = st.lists(st.floats(min_value=1 - MAX_LOG_TIME, max_value=MAX_LOG_TIME, allow_nan=False), max_size=12).map(sorted)


@st.composite
def logs(draw: st.DrawFn) -> ExecLog:
    """Any log a writer may build: entries in time order with commands and feedback of finite numbers."""
    sent = [{"t": t, "cmd": {"T": 102, "base": draw(finite), "spd": 0}} for t in draw(times)]
    received = []
    for t in draw(times):
        e: dict = {"t": t, "line": "{}"}
        if draw(st.booleans()):
            e["feedback"] = {"T": 1051, "b": draw(finite)}
            e["read_t"] = t - draw(st.floats(min_value=0.0, max_value=0.05))
        received.append(e)
    return ExecLog(robot=draw(st.sampled_from(["roarm_m3_pro", "a" * 255])), port=draw(st.none() | st.text(max_size=8)),
                   firmware=None, speed_scale=draw(st.floats(min_value=1e-3, max_value=1.0)),
                   t0_monotonic=draw(finite), sent=sent, received=received,
                   kind=draw(st.none() | st.just("teach")),
                   details=draw(st.dictionaries(st.sampled_from(["strategy", "rate", "notes"]), finite, max_size=3)))


@pytest.mark.slow
@settings(max_examples=60, deadline=None)
@given(log=logs())
def test_what_is_written_reads_back_the_same(tmp_path_factory: pytest.TempPathFactory, log: ExecLog) -> None:
    path = write_log(tmp_path_factory.mktemp("log") / "run.exec.json", log)
    doc = read_log(path)
    assert doc == json.loads(json.dumps(log.to_dict()))  # the reader gives back the writer's fields, all of them
    assert doc["format"] == FORMAT and is_log(doc)
    assert list(doc)[-2:] == ["sent", "received"]


def test_a_dict_log_is_written_as_it_is(tmp_path: Path) -> None:
    doc = hostile.execlog_doc(n=5)
    assert read_log(write_log(tmp_path / "run.exec.json", doc)) == doc


@pytest.mark.parametrize(("change", "field"), [
    (lambda d: d["sent"].reverse(), "sent[1].t"),  # out of time order
    (lambda d: d["received"][0].update(t=math.inf), "received[0].t"),
    (lambda d: d["received"][2].update(read_t=d["received"][2]["t"] + 1), "received[2].read_t"),  # read after it came
    (lambda d: d["sent"][0]["cmd"].update(base=1e7), "sent[0].cmd.base"),
    (lambda d: d.update(speed_scale=0.0), "speed_scale"),
    (lambda d: d.update(format="roarmctl.execlog/2"), "format"),
    (lambda d: d.update(sent={}), "sent"),
])
def test_the_reader_names_the_field_it_refuses(change, field: str) -> None:
    doc = hostile.execlog_doc(n=5)
    change(doc)
    with pytest.raises(TrajectoryFileError) as err:
        parse_log(doc, "run.exec.json")
    assert f"run.exec.json: {field}" in str(err.value)


def test_a_cut_short_log_is_not_told_to_be_planned_again(tmp_path: Path) -> None:
    """A truncated execution log said "the file is damaged; plan it again": a log comes from a run, not a plan."""
    p = tmp_path / "run.exec.json"
    p.write_text('{"format": "roarmctl.execlog/1", "sent": [')
    with pytest.raises(TrajectoryFileError) as info:
        read_log(p)
    assert info.value.hint is not None and "execute" in info.value.hint and "damaged" in info.value.hint
