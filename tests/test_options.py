"""Every options object checks its own fields (``roarmctl.checks.check_options``): NaN, infinities, negative,
huge and wrong-typed values are refused with an ``OptionError`` naming the field, in the library's words (no file,
no flag); the defaults and the ends of each range are taken. Every field of every options object is walked, so a
field added without a bound fails here."""

from __future__ import annotations

import dataclasses
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import roarmctl.api as rc
from roarmctl.device.follow import FOLLOW_BOUNDS, FollowConfig
from roarmctl.device.follow_guard import GUARD_BOUNDS, GuardLimits
from roarmctl.device.options import STREAM_BOUNDS, StreamConfig
from roarmctl.errors import OptionError
from roarmctl.export import EXPORT_BOUNDS, ExportOptions
from roarmctl.export.lerobot.datagen import DATAGEN_BOUNDS, DatagenOptions
from roarmctl.export.lerobot.dataset import LAYOUT_BOUNDS, DatasetSpec
from roarmctl.motion.options import LIMITS_BOUNDS, PLANNER_BOUNDS, Limits, PlannerConfig
from roarmctl.physics.episode import EPISODE_BOUNDS, EpisodeOptions
from roarmctl.physics.run import SIMULATE_BOUNDS
from roarmctl.physics.run import Options as SimulateOptions
from roarmctl.viz.web.server import VIEW_BOUNDS, ViewOptions

#: every options object of the library and the bounds it checks against
OPTIONS: list[tuple[type, dict]] = [
    (Limits, LIMITS_BOUNDS), (PlannerConfig, PLANNER_BOUNDS), (StreamConfig, STREAM_BOUNDS), (ExportOptions, EXPORT_BOUNDS),
    (ViewOptions, VIEW_BOUNDS), (SimulateOptions, SIMULATE_BOUNDS), (FollowConfig, FOLLOW_BOUNDS), (GuardLimits, GUARD_BOUNDS),
    (EpisodeOptions, EPISODE_BOUNDS), (DatagenOptions, DATAGEN_BOUNDS)]
#: the fields an object needs besides the one a test sets (a datagen run's episodes; a dataset's fps, robot, joints)
REQUIRED: dict[type, dict] = {DatagenOptions: {"episodes": 1},
                              DatasetSpec: {"fps": 30, "robot_type": "arm", "joint_names": ["j1"]}}
FIELDS = [(cls, f.name, bounds[f.name] if f.name in bounds else None) for cls, bounds in OPTIONS
          for f in dataclasses.fields(cls)]
# a dataset's spec: only where its files roll over is an option (the rest comes from the run or the file)
FIELDS += [(DatasetSpec, name, bound) for name, bound in LAYOUT_BOUNDS.items()]
BAD_NUMBERS = [math.nan, math.inf, -math.inf, -1.0, 1e300, -1e300, "1", True, [1.0]]


def make(cls: type, **values: object) -> object:
    """``cls`` with ``values`` and the fields it cannot do without."""
    return cls(**(REQUIRED.get(cls, {}) | values))


@pytest.mark.parametrize(("cls", "name", "bound"), FIELDS, ids=[f"{c.__name__}.{n}" for c, n, _ in FIELDS])
def test_every_field_has_a_bound(cls, name, bound):
    assert bound is not None, f"{cls.__name__}.{name} has no bound: add it to the object's bounds"


@pytest.mark.parametrize(("cls", "name", "bound"), FIELDS, ids=[f"{c.__name__}.{n}" for c, n, _ in FIELDS])
def test_bad_values_are_refused_naming_the_field(cls, name, bound):
    bad = [v for v in BAD_NUMBERS if not (bound.optional and v is None)]
    if bound.choices and bound.many:
        bad = [("nope",), (bound.choices[0], bound.choices[0]), [bound.choices[0]], "front", None, ("",)]
    elif bound.choices:
        bad = ["", "nope", 3] + ([] if bound.optional else [None])
    elif bound.flag:
        bad = [1, "yes", None, math.nan]
    elif bound.text:
        bad = [3, math.nan, b"host", "x" * 256] + ([] if bound.optional else [None])
    elif bound.instance is not None:
        bad = [None, {}, 1.0, "guard"]
    for value in bad:
        if not bound.flag and not bound.choices and isinstance(value, float) and bound.lo <= value <= bound.hi:
            continue  # inside the range (a field whose range takes -1)
        with pytest.raises(OptionError) as err:
            make(cls, **{name: value})
        assert err.value.field == name and err.value.message.startswith(f"{name}: ") and "\n" not in err.value.message


def numeric(bound: object) -> bool:
    """Whether a bound is a range of numbers."""
    return not (bound.flag or bound.choices or bound.text or bound.instance)  # type: ignore[attr-defined]


@pytest.mark.parametrize(("cls", "name", "bound"), [f for f in FIELDS if numeric(f[2])],
                         ids=[f"{c.__name__}.{n}" for c, n, b in FIELDS if numeric(b)])
def test_the_ends_of_each_range_are_taken(cls, name, bound):
    for end in (bound.lo, bound.hi):
        if end == bound.lo and bound.strict_lo:
            continue
        value = int(end) if bound.whole else end
        if name in ("width", "height") and value % 2:
            continue  # a datagen image's sides are even (its videos' pixel format)
        assert getattr(make(cls, **{name: value}), name) == value


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_any_number_is_taken_exactly_when_inside_its_bound(data):
    cls, name, bound = data.draw(st.sampled_from([f for f in FIELDS if numeric(f[2]) and not f[2].whole]))
    value = data.draw(st.floats(allow_nan=True, allow_infinity=True) | st.floats(min_value=bound.lo, max_value=bound.hi))
    inside = math.isfinite(value) and bound.lo <= value <= bound.hi and not (bound.strict_lo and value == bound.lo)
    if inside:
        assert getattr(make(cls, **{name: value}), name) == value
    else:
        with pytest.raises(OptionError):
            make(cls, **{name: value})


def test_options_objects_do_not_change_and_a_copy_is_checked_again():
    limits = Limits()
    with pytest.raises(dataclasses.FrozenInstanceError):
        limits.velocity_scale = 2.0  # type: ignore[misc]
    with pytest.raises(OptionError, match="velocity_scale"):
        dataclasses.replace(limits, velocity_scale=math.nan)


def test_the_api_planner_takes_the_options_objects_and_refuses_nan():
    limits, config = Limits(velocity_scale=0.3), PlannerConfig(padding=0.01, seed=7)
    planner = rc.Planner("roarm_m3_pro", limits=limits, config=config)
    assert planner._limits is limits and planner._config is config
    with pytest.raises(rc.OptionError, match=r"^singularity_margin: expected a finite number, got nan"):
        rc.Planner("roarm_m3_pro", singularity_margin=math.nan)
    with pytest.raises(rc.InputError, match="velocity_scale given beside limits="):
        rc.Planner("roarm_m3_pro", limits=limits, velocity_scale=0.2)


def test_execute_refuses_a_nan_tracking_bound_before_it_opens_anything():
    """The safety gap of issue 37: ``rc.execute(traj, sim=True, max_error=nan)`` ran to the end with the tracking stop
    off (no comparison with NaN is true); the options object refuses it before the simulator starts."""
    from viz_fixtures import pick_place_trajectory

    traj = pick_place_trajectory()
    for value in (math.nan, math.inf, -0.01, 0.0):
        with pytest.raises(rc.OptionError, match=r"^max_error: "):
            rc.execute(traj, sim=True, max_error=value)
    with pytest.raises(rc.OptionError, match=r"^speed_scale: "):
        rc.execute(traj, sim=True, speed_scale=2)


def test_the_cli_names_the_flag_of_a_field(tmp_path):
    from clirun import roarmctl
    from viz_fixtures import pick_place_trajectory

    path = pick_place_trajectory().save(tmp_path / "t.traj.json")
    res = roarmctl("execute", str(path), "--output", str(tmp_path / "c.jsonl"), "--rate", "nan")
    assert res.returncode == 2 and "--rate: expected a finite number, got nan" in res.stderr, res.stderr


def test_every_options_object_of_the_package_is_walked_here():
    """Each dataclass of the package whose ``__post_init__`` checks itself with ``check_options`` is in ``OPTIONS``
    (or, for a dataset's spec, its layout's bounds): an options object added later is walked by the tests above, and a
    ``__post_init__`` that checks numbers by hand (``isfinite``) in place of ``check_options`` fails here."""
    import ast
    from pathlib import Path

    import roarmctl

    walked = {cls.__name__ for cls, _ in OPTIONS} | {"DatasetSpec"}
    found, by_hand = set(), []
    for path in Path(roarmctl.__file__).parent.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ClassDef):
                continue
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name == "__post_init__":
                    text = ast.unparse(item)
                    if "check_options(" in text:
                        found.add(node.name)
                    elif "isfinite" in text and node.name != "Pose":  # a pose is a value, not an option
                        by_hand.append(f"{path.name}:{node.name}")
    assert found - walked == set() and not by_hand, (found - walked, by_hand)
    assert walked - found == set(), walked - found  # and each one walked here does use it
