"""Wire protocol: exact bytes, mapping, feedback parsing, firmware identification."""

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.device import protocol as P
from roarmctl.robot.loader import load_robot


def test_encode_is_compact_and_newline_terminated():
    assert P.encode({"T": 0}) == b'{"T":0}\n'  # the 2026 firmware's fast stop matches these bytes
    assert P.encode(P.quiet_command()) == b'{"T":605,"cmd":0}\n'
    assert P.encode(P.feedback_request()) == b'{"T":105}\n'


def test_t102_has_all_fields_rounded_and_clamped():
    cmd = P.joints_command({"base": 0.123456, "shoulder": 2.0, "elbow": 1.5708, "wrist": -0.00001, "roll": math.pi,
                            "hand": 3.14159}, 120, 0)
    assert list(cmd) == ["T", "base", "shoulder", "elbow", "wrist", "roll", "hand", "spd", "acc"]
    assert cmd["base"] == 0.1235 and cmd["shoulder"] == 1.5708 and cmd["wrist"] == 0.0
    assert cmd["roll"] < math.pi and round(cmd["roll"] / (2 * math.pi) * 4096) <= 2047  # +pi would be step -1
    line = P.encode(cmd)
    assert line == b'{"T":102,"base":0.1235,"shoulder":1.5708,"elbow":1.5708,"wrist":0.0,"roll":3.1393,"hand":3.1416,"spd":120,"acc":0}\n'
    assert len(line) < 125
    with pytest.raises(ValueError):
        P.joints_command({"base": 0.0}, 0, 0)


def test_registers():
    assert P.spd_register(1.0) == math.ceil(4096 / (2 * math.pi))  # 652 steps/s
    assert P.spd_register(0.0) == 1  # never 0: 0 means full speed
    assert P.acc_register(math.pi) == math.ceil(2048 / 100)  # pi rad/s^2 = 2048 steps/s^2 = 20.48 units
    assert P.acc_register(1e6) == 254


def test_wire_map_hand_is_pi_minus_q_and_round_trips():
    wm = P.WireMap(load_robot("roarm_m3_pro"))
    q = np.array([0.3, -0.4, 1.2, 0.5, -1.0, 1.5])
    w = wm.to_wire(q)
    assert w["hand"] == pytest.approx(math.pi - 1.5) and w["base"] == pytest.approx(0.3)
    assert np.allclose(wm.from_wire(w), q)


FB = '{"T":1051,"x":346.16,"y":0,"z":223.13,"tit":0,"b":0,"s":0,"e":1.570796,"t":0,"r":0,"g":3.141593,"tB":0,"tS":0,"tE":0,"tT":0,"tR":0,"tG":0}'


def test_parse_feedback_and_identify():
    fb = P.parse_feedback((FB + "\r\n").encode())
    assert fb.firmware == "m3-0.84" and fb.joints["elbow"] == 1.570796 and fb.xyz == (346.16, 0.0, 223.13)
    new = json.loads(FB) | {"torswitchB": 1, "v": 1203}
    assert P.parse_feedback(json.dumps(new)).firmware == "m3-2026"
    m2 = '{"T":1051,"x":1,"y":2,"z":3,"b":0,"s":0,"e":1.57,"t":3.14,"torB":0,"torS":0,"torE":0,"torH":0}'
    assert P.parse_feedback(m2).firmware == "m2"
    for junk in ["version: 0.84", FB[:40], '{"T":105}', '{"error":"Queue full"}', "{not json}", "", '{"T":1051,"b":"x"}']:
        fb = P.parse_feedback(junk)
        assert fb is None or fb.firmware == "unknown"


def test_line_buffer_handles_partial_lines_and_crlf():
    lb = P.LineBuffer()
    assert lb.feed(FB[:30].encode()) == []
    lines = lb.feed((FB[30:] + "\r\nboot text\r\n{\"T\":10").encode())
    assert lines == [FB.encode(), b"boot text"]
    assert lb.feed(b"51}\n") == [b'{"T":1051}']


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300), st.lists(st.integers(1, 50), max_size=20))
def test_garbage_never_raises_and_chunking_does_not_matter(junk, cuts):
    data = junk + b"\n" + (FB + "\r\n").encode()
    whole = P.LineBuffer().feed(data)
    lb, got, i = P.LineBuffer(), [], 0
    for c in cuts + [len(data)]:
        got += lb.feed(data[i:i + c])
        i += c
    assert got == whole
    parsed = [P.parse_feedback(x) for x in whole]  # never raises
    assert parsed[-1] is not None and parsed[-1].firmware == "m3-0.84"
