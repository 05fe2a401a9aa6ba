"""The boot mission's listing read back: the mode its last valid T:301 step sets, the firmware's default without one,
nothing from a listing cut short. Listings are generated in the firmware's own format (``boot_mission_listing``, as
``missionContent`` prints it) and checked against the mode worked out from the steps directly."""

from __future__ import annotations

import json

from hypothesis import given
from hypothesis import strategies as st

from roarmctl.device.espnow import DEFAULT_MODE, boot_mission_listing, listing_ended, mode_from_listing

STEPS = st.one_of(
    st.builds(lambda m: json.dumps({"T": 301, "mode": m}), st.integers(-1, 5)),
    st.builds(lambda v: json.dumps({"T": 114, "led": v}), st.integers(0, 255)),
    st.just('{"T":301,"mode":"1"}'), st.just('{"T":301,"mode":1.0}'), st.just('{"T":301'), st.just("not json"),
)


def expected(steps: list[str]) -> int | None:
    """The mode of the last valid T:301 step, None without one."""
    mode = None
    for s in steps:
        try:
            d = json.loads(s)
        except ValueError:
            continue
        if d.get("T") == 301 and type(d.get("mode")) is int and 0 <= d["mode"] <= 3:
            mode = d["mode"]
    return mode


@given(st.lists(STEPS, max_size=8))
def test_the_last_valid_t301_step_sets_the_mode_else_the_default(steps):
    found = mode_from_listing(boot_mission_listing(steps), "here")
    want = expected(steps)
    assert found is not None and found.mode == (DEFAULT_MODE if want is None else want)
    assert ("sets none" in found.source) == (want is None)


@given(st.lists(STEPS, max_size=8), st.data())
def test_a_listing_cut_short_says_nothing(steps, data):
    lines = boot_mission_listing(steps)
    cut = lines[:data.draw(st.integers(0, len(lines) - 1))]
    assert not listing_ended(cut) and mode_from_listing(cut, "here") is None


def test_a_missing_boot_mission_is_the_default():
    found = mode_from_listing(["file not found."], "here")
    assert found is not None and found.mode == DEFAULT_MODE
