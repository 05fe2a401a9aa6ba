"""Fuzz suite (issue 13, Deliver 6): generated plan files, trajectory files and robot descriptions
through the real CLI, in-process (``roarmctl.cli.main``), asserting what a user relies on:

* the exit code is 0, 2 or 3 (never 1, an internal error, and never a crash);
* on failure stderr is exactly one ``error:`` line (warnings aside), no traceback;
* nothing partial: no output file unless exit 0, no temporary ``.*.tmp`` file left;
* no hang: every case finishes within a generous alarm (60 s; most take milliseconds).

Inputs are valid documents mutated at random (a value replaced by a random one, a key dropped or
added, the text cut or given control characters, aliases or deep nesting), mostly invalid or short
so each case is cheap. Profiles: ``ROARMCTL_FUZZ=full`` (``make fuzz``, run by ``.ci/run``) runs
1,000 plans, 500 trajectories and 300 descriptions; the default ``make test`` runs a tenth of that.
Hypothesis is derandomized: the same cases every run.
"""

from __future__ import annotations

import contextlib
import copy
import io
import itertools
import json
import os
import signal
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roarmctl.cli import main
from roarmctl.robot.loader import bundled_dir

pytestmark = pytest.mark.fuzz

FULL = os.environ.get("ROARMCTL_FUZZ", "") == "full"
COUNTS = {"plans": 1000, "trajectories": 500, "descriptions": 300} if FULL else \
    {"plans": 100, "trajectories": 50, "descriptions": 30}
CASE_ALARM = 60  # s, a hang detector only

SETTINGS = dict(deadline=None, derandomize=True, database=None, print_blob=True,
                suppress_health_check=list(HealthCheck))

_counter = itertools.count()
TALLY: dict[str, dict[int, int]] = {}  # command -> exit code -> cases (printed at the end with -s)


@pytest.fixture(scope="module", autouse=True)
def _print_tally():
    yield
    for cmd, codes in TALLY.items():
        print(f"\nfuzz {cmd}: " + ", ".join(f"exit {c}: {n}" for c, n in sorted(codes.items())))


# ------------------------------------------------------------------ running one case
class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang()


def run_case(args: list[str], out: Path | None, workdir: Path) -> tuple[int, str]:
    """Run the CLI in-process; check the exit code, the one error line and that nothing partial is left."""
    err, stdout = io.StringIO(), io.StringIO()
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(CASE_ALARM)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(stdout):
            try:
                main(args)
                code = 0
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except _Hang:
        pytest.fail(f"no answer within {CASE_ALARM} s: {args}")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    text = err.getvalue()
    lines = [x for x in text.splitlines() if x.strip() and not x.startswith("warning:")]
    assert code in (0, 2, 3), f"exit {code}: {text}"
    assert "Traceback" not in text, text
    if code != 0:
        assert len(lines) == 1 and lines[0].startswith("error:"), text
        if out is not None:
            assert not out.exists(), f"partial output after exit {code}"
    assert not list(workdir.glob(".*.tmp")), "temporary file left"
    tally = TALLY.setdefault(" ".join(args[:2 if args[0] == "kin" else 1]), {})
    tally[code] = tally.get(code, 0) + 1
    return code, text


# ------------------------------------------------------------------ random values and mutations
NUMBERS = st.one_of(
    st.sampled_from([0, 1, -1, 2, 0.5, -0.5, 1e-9, 1e-6, 3600, 3601, 1e6, 1e8, 1e308, -1e308, 10 ** 30, 2 ** 63]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-10 ** 6, 10 ** 6),
)
SCALARS = st.one_of(st.none(), st.booleans(), NUMBERS, st.text(max_size=8),
                    st.sampled_from(["home", "deg", "box", "cube", "pick", "wait", "x" * 300, "", "NaN", "1e400"]))
VALUES = st.recursive(SCALARS, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6), c, max_size=3),
                      max_leaves=8)


def _paths(doc, prefix=()):
    """Every (container, key) position in a JSON-like document."""
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, prefix + (i,))


def mutate(doc, data, keys: list[str], rounds: int = 3):
    """Apply 1..rounds random edits to a deep copy of ``doc``."""
    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, rounds))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        path = data.draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        op = data.draw(st.sampled_from(["replace", "replace", "replace", "delete", "add", "wrap", "number"]))
        last = path[-1]
        if op == "replace":
            parent[last] = data.draw(VALUES)
        elif op == "number":
            parent[last] = data.draw(NUMBERS)
        elif op == "delete":
            if isinstance(parent, dict):
                del parent[last]
            else:
                parent.pop(last)
        elif op == "add" and isinstance(parent, dict):
            parent[data.draw(st.sampled_from(keys) | st.text(max_size=6))] = data.draw(VALUES)
        elif op == "wrap":
            parent[last] = [parent[last]]
    return doc


TEXT_EDITS = st.sampled_from(["none", "none", "none", "truncate", "control", "alias", "deep", "bytes"])


def text_edit(text: str, data) -> bytes:
    how = data.draw(TEXT_EDITS)
    raw = text.encode()
    if how == "truncate":
        return raw[: data.draw(st.integers(0, len(raw)))]
    if how == "control":
        at = data.draw(st.integers(0, len(raw)))
        return raw[:at] + data.draw(st.sampled_from([b"\x01", b"\x00", b"\x1b[0m", b"\t", b"\r"])) + raw[at:]
    if how == "alias":
        return raw + b"\nx_a: &a [1, 1, 1, 1, 1, 1, 1, 1]\nx_b: &b [*a, *a, *a, *a, *a, *a, *a, *a]\n" \
                     b"x_c: &c [*b, *b, *b, *b, *b, *b, *b, *b]\nx_d: [*c, *c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
    if how == "deep":
        n = data.draw(st.sampled_from([20, 40, 500]))
        return raw + b"\nx_deep: " + b"[" * n + b"]" * n + b"\n"
    if how == "bytes":
        at = data.draw(st.integers(0, len(raw)))
        return raw[:at] + data.draw(st.binary(min_size=1, max_size=4)) + raw[at:]
    return raw


# ------------------------------------------------------------------ plans
PLAN_KEYS = ["robot", "start", "scene", "objects", "tasks", "cycles", "limits", "planner", "wait", "move", "pick",
             "place", "joints", "xyz", "pitch", "seconds", "object", "velocity_scale", "max_tcp_speed", "gripper_open"]
BASE_PLANS = [
    {"robot": "roarm_m3_pro", "tasks": [{"wait": 0.3}]},
    {"robot": "roarm_m3_pro", "start": "home", "tasks": [{"wait": 0.2}, {"wait": {"seconds": 0.1}}],
     "limits": {"velocity_scale": 0.5, "gripper_time": 0.5}, "planner": {"seed": 1}},
    {"robot": "roarm_m3_pro", "tasks": [{"move": {"joints": [0.2, 0.1, 1.6, 0.0, 0.0]}}]},
    {"robot": "scara_2r", "start": [0.3, 0.5], "tasks": [{"move": {"joints": [0.5, 0.7]}}]},
    {"robot": "roarm_m3_pro", "scene": {"table": {"shape": "box", "size": [0.8, 0.6, 0.02], "xyz": [0.15, 0, -0.01]}},
     "objects": [{"name": "cube", "shape": "box", "size": [0.04, 0.04, 0.04], "xyz": [0.25, -0.15, 0.02]}],
     "tasks": [{"pick": {"object": "cube"}}, {"place": {"xyz": [0.25, 0.15, 0.02]}}]},
]


@settings(max_examples=COUNTS["plans"], **SETTINGS)
@given(data=st.data())
def test_fuzz_plan_files(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("plan", numbered=True)
    # the pick-and-place base plans for real (about a second): drawn rarely and mutated at least once
    base = BASE_PLANS[data.draw(st.sampled_from([0, 0, 1, 1, 2, 3, 4]))]
    doc = mutate(base, data, PLAN_KEYS, rounds=4)
    text = yaml.safe_dump(doc, allow_unicode=True)
    p = work / f"plan{next(_counter)}.yaml"
    p.write_bytes(text_edit(text, data))
    out = work / "out.traj.json"
    code, err = run_case(["plan", str(p), "-o", str(out)], out, work)
    if code == 0:
        assert out.exists()


# ------------------------------------------------------------------ trajectories
def _base_trajectory() -> dict:
    import numpy as np

    q0 = np.array([0.0, 0.0, 1.5708, 0.0, 0.0, 0.0])
    q1 = np.array([0.2, 0.1, 1.7, 0.0, 0.1, 0.2])
    dur, n = 0.6, 60  # within the M3 Pro's velocity and acceleration limits
    pts = []
    for k in range(n + 1):
        u = k / n
        s, ds = 10 * u ** 3 - 15 * u ** 4 + 6 * u ** 5, (30 * u ** 2 - 60 * u ** 3 + 30 * u ** 4) / dur
        dds = (60 * u - 180 * u ** 2 + 120 * u ** 3) / dur ** 2
        pts.append({"time_from_start": round(u * dur, 9), "positions": list(q0 + s * (q1 - q0)),
                    "velocities": list(ds * (q1 - q0)), "accelerations": list(dds * (q1 - q0))})
    from roarmctl.robot.loader import load_robot

    return {"format": "roarmctl.trajectory/1", "robot": "roarm_m3_pro", "joint_names": load_robot("roarm_m3_pro").joint_names,
            "sample_rate": 100.0, "points": pts,
            "events": [{"time_from_start": 0.6, "kind": "grasp", "label": "cube", "position": [0.2, 0.0, 0.05]}],
            "segments": [{"start": 0.0, "end": 0.6, "kind": "free", "label": "move"}],
            "limits": {"velocity": [2.0] * 6, "acceleration": [5.0] * 6, "velocity_scale": 0.5, "max_tcp_speed": None},
            "scene": {"items": [{"name": "cube", "role": "object", "shape": "box", "size": [0.04, 0.04, 0.04],
                                 "xyz": [0.25, -0.15, 0.02], "rpy": [0, 0, 0]}]},
            "plan": None, "singularity_margin": None}


TRAJ_KEYS = ["format", "robot", "joint_names", "sample_rate", "points", "events", "segments", "limits", "scene",
             "time_from_start", "positions", "velocities", "accelerations", "items", "size", "radius", "kind"]


@settings(max_examples=COUNTS["trajectories"], **SETTINGS)
@given(data=st.data())
def test_fuzz_trajectory_files(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("traj", numbered=True)
    base = _base_trajectory()
    doc = mutate(base, data, TRAJ_KEYS, rounds=3)
    if data.draw(st.integers(0, 9)) == 0:  # times scaled far out, or squeezed
        scale = data.draw(st.sampled_from([1e-6, 1e9, -1.0, 0.0]))
        for pt in doc.get("points") or []:
            if isinstance(pt, dict) and isinstance(pt.get("time_from_start"), (int, float)):
                pt["time_from_start"] *= scale
    text = json.dumps(doc, allow_nan=True)
    how = data.draw(st.sampled_from(["none", "none", "none", "truncate", "nest", "bytes"]))
    raw = text.encode()
    if how == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    elif how == "nest":
        raw = b"[" * 5000 + raw + b"]" * 5000
    elif how == "bytes":
        at = data.draw(st.integers(0, len(raw)))
        raw = raw[:at] + data.draw(st.binary(min_size=1, max_size=3)) + raw[at:]
    p = work / f"t{next(_counter)}.traj.json"
    p.write_bytes(raw)
    out = work / "cmds.jsonl"
    code, _ = run_case(["execute", str(p), "--output", str(out)], out, work)
    if code == 0:
        assert out.exists()


# ------------------------------------------------------------------ robot descriptions
DESC_KEYS = ["name", "joints", "tcp_link", "limits", "gripper", "named_poses", "wire", "allowed_collisions", "dh",
             "convention", "length_unit", "angle_unit", "a", "alpha", "d", "lower", "upper", "field", "sign", "clamp",
             "inertials", "mass", "base", "tool", "urdf"]
URDF_ATTRS = ["xyz", "rpy", "lower", "upper", "velocity", "effort", "value", "ixx", "iyy", "size", "radius", "length",
              "link", "name", "type"]


def _urdf_mutation(text: str, data) -> str:
    import re

    spots = [m for m in re.finditer(r'(\w+)="([^"]*)"', text)]
    for _ in range(data.draw(st.integers(1, 3))):
        m = data.draw(st.sampled_from(spots))
        new = data.draw(st.sampled_from(["nan", "inf", "-1", "0", "0 0 0", "1 2", "abc", "", "1e400", "0 0 2",
                                         "base_link", "link1", "world", "continuous", "fixed", "planar"]))
        text = text[: m.start(2)] + new + text[m.end(2):]
        spots = [s for s in re.finditer(r'(\w+)="([^"]*)"', text)]
    if data.draw(st.integers(0, 5)) == 0:
        text = text.replace("<robot", "<robto", 1).replace("</robot>", "</robto>")
    return text


@settings(max_examples=COUNTS["descriptions"], **SETTINGS)
@given(data=st.data())
def test_fuzz_robot_descriptions(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("desc", numbered=True)
    n = next(_counter)  # a new file name each case: the loader caches by path
    kind = data.draw(st.sampled_from(["dh", "dh", "sidecar", "urdf"]))
    if kind == "urdf":
        p = work / f"arm{n}.urdf"
        p.write_text(_urdf_mutation((bundled_dir() / "roarm_m3_pro.urdf").read_text(), data))
        q = ["0", "0", "1.57", "0", "0", "0"]
    else:
        src = "scara_2r.yaml" if kind == "dh" else "roarm_m3_pro.yaml"
        doc = yaml.safe_load((bundled_dir() / src).read_text())
        if kind == "sidecar":
            (work / "roarm_m3_pro.urdf").write_text((bundled_dir() / "roarm_m3_pro.urdf").read_text())
        doc = mutate(doc, data, DESC_KEYS, rounds=3)
        p = work / f"arm{n}.yaml"
        p.write_bytes(text_edit(yaml.safe_dump(doc, allow_unicode=True), data))
        q = ["0.1", "0.2"] if kind == "dh" else ["0", "0", "1.57", "0", "0"]
    run_case(["kin", "fk", str(p), *q], None, work)
