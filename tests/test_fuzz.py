"""Fuzz suite (issue 13, Deliver 6): generated plan files, trajectory files and robot descriptions
through the real CLI, in-process (``roarmctl.cli.main``), asserting what a user relies on:

* the exit code is 0, 2 or 3 (never 1, an internal error, and never a crash);
* on failure stderr is exactly one ``error:`` line (warnings aside), no traceback;
* nothing partial: no output file unless exit 0, no temporary ``.*.tmp`` file left;
* no hang: every case finishes within a generous alarm (60 s; most take milliseconds).

Inputs are valid documents mutated at random (a value replaced by a random one, a key dropped or
added, the text cut or given control characters, aliases or deep nesting), mostly invalid or short
so each case is cheap, and (issue 19) hostile ones from tests/hostile.py: xacro expressions built from
allowed and forbidden syntax with code-running payloads, bombs and FIFOs; mesh paths that leave their
folder, loop or block; mutated SRDF and joint_limits.yaml; export paths onto user folders, ``.``,
``..`` and long names; damaged execution logs. No case may run code (the payload's marker file never
appears), delete a file the test made, or leave a temporary file. Profiles: ``ROARMCTL_FUZZ=full``
(``make fuzz``, run by ``.ci/run``) runs 1,000 plans, 500 trajectories, 300 descriptions, 400 xacro
files, 200 mesh paths, 200 SRDF, 200 joint_limits.yaml, 200 export paths and 300 logs; the default
``make test`` runs a tenth of that. Hypothesis is derandomized: the same cases every run. Also (issue 19
review): YAML tags in every text-edited file, the size bombs, lexer and macro-params cases of
tests/hostile.py, and 200 descriptions named by a plan or carried by a trajectory whose file fields point
outside (absolute, ``..``, symlinks, FIFOs, loops).
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
_FULL_COUNTS = {"plans": 1000, "trajectories": 500, "descriptions": 300, "xacro": 400, "meshes": 200, "srdf": 200,
                "joint_limits": 200, "export_paths": 200, "logs": 300, "named_descriptions": 200}
COUNTS = _FULL_COUNTS if FULL else {k: v // 10 for k, v in _FULL_COUNTS.items()}
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
    # warnings and notes (what a description leaves out, e.g. an SRDF element skipped as srdfdom skips it) may come
    # before the one error line
    lines = [x for x in text.splitlines() if x.strip() and not x.startswith(("warning:", "note:"))]
    assert code in (0, 2, 3), f"exit {code}: {text}"
    assert "Traceback" not in text, text
    if code != 0:
        assert len(lines) == 1 and lines[0].startswith("error:"), text
        if out is not None:
            assert not out.exists(), f"partial output after exit {code}"
    assert not list(workdir.glob(".*.tmp")), "temporary file left"
    assert not [p for p in workdir.glob(".*") if p.is_dir()], "temporary folder left"
    words = args[2:] if args[0] == "--package-path" else args  # the command, after a global option
    tally = TALLY.setdefault(" ".join(words[:2 if words[0] == "kin" else 1]), {})
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


TEXT_EDITS = st.sampled_from(["none", "none", "none", "truncate", "control", "alias", "deep", "bytes", "tag"])
#: YAML tags a file may carry that must never construct anything but plain values (issue 19 review).
YAML_TAGS = st.sampled_from(["!!python/object/apply:os.system [touch MARKER]", "!!python/name:os.system x",
                             "!!set {a, b}", "!!omap [a: 1]", "!degrees 90", "!local {a: 1}", "!!binary aGk=",
                             "!!timestamp 2001-12-14", "!!float abc", "!!int 99999999999999999999999"])


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
    if how == "tag":
        return raw + b"\nx_tag: " + data.draw(YAML_TAGS).encode() + b"\n"
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


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
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
    code, _err = run_case(["plan", str(p), "-o", str(out)], out, work)
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
            "plan": None, "singularity_margin": None,
            "payloads": [{"start": 0.1, "end": 0.5, "link": load_robot("roarm_m3_pro").tcp_link, "mass": 0.05,
                          "com": [0, 0, 0], "inertia": [[1e-5, 0, 0], [0, 1e-5, 0], [0, 0, 1e-5]]}]}


TRAJ_KEYS = ["format", "robot", "joint_names", "sample_rate", "points", "events", "segments", "limits", "scene",
             "time_from_start", "positions", "velocities", "accelerations", "items", "size", "radius", "kind",
             "payloads", "link"]
#: Links a trajectory's payload may name that the robot lacks (issue 40: simulate exited 1, export took it).
FOREIGN_LINKS = st.sampled_from(["no_such_link", "", "wrist_link_of_another_arm", "../base_link", "link\x1b[2J"]) | st.text(max_size=12)


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["trajectories"], **SETTINGS)
@given(data=st.data())
def test_fuzz_trajectory_files(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("traj", numbered=True)
    base = _base_trajectory()
    doc = mutate(base, data, TRAJ_KEYS, rounds=3)
    if data.draw(st.integers(0, 9)) == 0 and isinstance(doc.get("payloads"), list) and doc["payloads"] \
            and isinstance(doc["payloads"][0], dict):  # a payload on a link the robot may lack
        doc["payloads"][0]["link"] = data.draw(FOREIGN_LINKS)
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
    out = work / data.draw(st.sampled_from(["cmds.jsonl", "t.csv"]))
    args = ["execute", str(p), "--output", str(out)] if out.suffix == ".jsonl" else ["export", str(p), "-o", str(out)]
    code, _ = run_case(args, out, work)
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


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
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


# ------------------------------------------------------------------ xacro (issue 19)
import hostile  # noqa: E402  (the corpus of hostile inputs, shared with tests/test_trust.py)

ATOMS = st.sampled_from(["1", "0", "-1", "2.5", "1e308", "10**6", "9**9**9", "'a'", "''", "p0", "p1", "p2", "undefined",
                         "pi", "e", "True", "None", "math", "xacro", "__class__", "_p", "sin", "load_yaml",
                         "xacro.arg('a')", "$(arg a)"])
UNARY = st.sampled_from(["-{}", "not {}", "sin({})", "radians({})", "len({})", "str({})", "int({})", "float({})",
                         "abs({})", "round({})", "({}).__class__", "({}).real", "[{} for x in [1]]", "(lambda: {})()",
                         "max(x for x in [{}])", "open({})", "__import__({})", "getattr({}, 'a')", "math.{}", "[{}][0]",
                         "[{}][5]", "{}[0]", "({})[1:3]", "xacro.load_yaml({})", "python.len({})", "'%s' % {}",
                         "f'x{}'", "{{'k': {}}}['k']"])
BINARY = st.sampled_from(["({}) + ({})", "({}) - ({})", "({}) * ({})", "({}) / ({})", "({}) // ({})", "({}) % ({})",
                          "({}) ** ({})", "({}) == ({})", "({}) &lt; ({})", "({}) and ({})", "({}) or ({})",
                          "({}) if ({}) else 0", "max({}, {})", "atan2({}, {})", "({}) &lt;&lt; ({})", "({}) in ({})"])
EXPRESSIONS = st.recursive(ATOMS, lambda inner: st.one_of(
    st.tuples(UNARY, inner).map(lambda t: t[0].format(t[1])),
    st.tuples(BINARY, inner, inner).map(lambda t: t[0].format(t[1], t[2]))), max_leaves=6)
EXTENSIONS = st.sampled_from(["$(env HOME)", "$(optenv HOME dflt)", "$(cwd)", "$(find pkg)", "$(find nopkg)", "$(arg a)",
                              "$(arg nope)", "$(eval 1+1)", "$(eval __import__('os'))", "$(dirname)", "$(anon x)",
                              "$(eval 9**9**9)", "$(find pkg)/parts.xacro"])


#: Every allowed function with hostile arguments (issue 40: ``round(1, -10**9)``), those without the table's
#: large properties (tests/test_trust_xacro.py runs them all).
HOSTILE_CALLS = sorted(c for c in hostile.hostile_calls() if not any(b in c for b in ("big_", "spaces", "pairs")))
#: Include patterns that climb out after a wildcard, walk /proc, or stay inside (issue 40).
GLOB_PATTERNS = st.sampled_from(["$(dirname)/*/../../*", "$(dirname)/p*/../../../etc/*", "$(dirname)/../*",
                                 "/proc/*/root/*", "$(dirname)/../../../../../../proc/*/root/*/*", "$(dirname)/pkg/*.xacro",
                                 "$(dirname)/[p]kg/p?rts.xacro", "$(dirname)/**/*.xacro", "$(dirname)/*/*/*/*",
                                 "/etc/*", "$(dirname)/.*", "$(dirname)/pkg/*/.."])


def _xacro_case(work: Path, data) -> Path:
    """A xacro robot: generated expressions and substitutions, or one of the corpus's hostile builders."""
    from xml.sax.saxutils import escape

    marker = work / "MARKER"
    (work / "pkg").mkdir(exist_ok=True)
    (work / "pkg" / "parts.xacro").write_text(f'<robot {hostile.XACRO_NS}><link name="from_pkg"/></robot>')
    (work / "cfg.yaml").write_text("a: {b: 1}\n")
    kind = data.draw(st.sampled_from(["expr", "expr", "expr", "extension", "payload", "corpus"]))
    props = ('<xacro:arg name="a" default="1"/><xacro:property name="p0" value="0.5"/>'
             '<xacro:property name="p1" value="${p0 * 2}"/><xacro:property name="p2" value="abc"/>')
    if kind == "expr":
        return hostile.m3_xacro(work, escape(data.draw(EXPRESSIONS), {'"': "&quot;"}).replace("&amp;lt;", "&lt;"), props)
    if kind == "extension":
        return hostile.m3_xacro(work, f"'{data.draw(EXTENSIONS)}'", props)
    if kind == "payload":
        return hostile.m3_xacro(work, escape(hostile.payload(marker), {'"': "&quot;"}), props)
    corpus = {
        "pow": lambda: hostile.m3_xacro(work, hostile.POW_BOMB),
        "macros": lambda: hostile.m3_xacro(work, "'a'", hostile.macro_doubling(data.draw(st.sampled_from([5, 14, 20])))),
        "blocks": lambda: hostile.m3_xacro(work, "'a'", hostile.block_doubling(data.draw(st.sampled_from([5, 20])))),
        "strings": lambda: hostile.m3_xacro(work, "'a'", hostile.string_doubling(data.draw(st.sampled_from([10, 60])))),
        "self include": lambda: hostile.self_include(work),
        "include fifo": lambda: hostile.m3_xacro(work, "'a'", f'<xacro:include filename="{hostile.fifo(work, "p.xacro")}"/>'),
        "yaml fifo": lambda: hostile.m3_xacro(work, f"xacro.load_yaml('{hostile.fifo(work, 'p.yaml')}')"),
        "yaml outside": lambda: hostile.m3_xacro(work, "xacro.load_yaml('/etc/passwd')"),
        "yaml inside": lambda: hostile.m3_xacro(work, "str(xacro.load_yaml('cfg.yaml').a.b)"),
        "include outside": lambda: hostile.m3_xacro(work, "'a'", '<xacro:include filename="/etc/hostname"/>'),
        "include pkg": lambda: hostile.m3_xacro(work, "'a'", '<xacro:include filename="$(find pkg)/parts.xacro"/>'),
        "include glob": lambda: hostile.m3_xacro(work, "'a'", '<xacro:include filename="/etc/*.conf"/>'),
        "lexer": lambda: hostile.m3_xacro(work, "'a'", hostile.lexer_bomb(data.draw(st.sampled_from([1000, 1_000_000])))),
        "macro params": lambda: hostile.m3_xacro(work, "'a'", hostile.macro_params_redos(data.draw(st.sampled_from([5, 40])))),
        "hostile call": lambda: hostile.m3_xacro(work, escape(f"str({data.draw(st.sampled_from(HOSTILE_CALLS))})",
                                                               {'"': "&quot;"})),
        "include pattern": lambda: hostile.m3_xacro(work, "'a'", f'<xacro:include filename="{data.draw(GLOB_PATTERNS)}"/>'),
        **{f"size: {name}": (lambda e, n: lambda: hostile.m3_xacro(
            work, e, hostile.repeated_work() if n == "repeated work on a property" else ""))(expr, name)
           for name, (expr, _) in hostile.SIZE_BOMBS.items()},
    }
    return corpus[data.draw(st.sampled_from(sorted(corpus)))]()


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["xacro"], **SETTINGS)
@given(data=st.data())
def test_fuzz_xacro(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("xacro", numbered=True)
    arm = _xacro_case(work, data)
    run_case(["--package-path", f"pkg={work / 'pkg'}", "kin", "fk", str(arm), *hostile.M3_Q], None, work)
    assert not (work / "MARKER").exists(), "a xacro expression ran code"


# ------------------------------------------------------------------ mesh paths
MESH_NAMES = st.sampled_from([
    "m.stl", "pkg/m.stl", "package://pkg/m.stl", "package://pkg/../m.stl", "package://pkg/../../../../etc/hostname",
    "package://nopkg/m.stl", "package://pkg/link_out.stl", "package://pkg/loop.stl", "package://pkg/fifo.stl",
    "package://pkg/sparse.stl", "package://pkg/empty.stl", "package://pkg/garbage.stl", "package://pkg/m.obj",
    "package://pkg/mtl.obj", "file:///etc/hostname", "/etc/hostname", "http://example.com/m.stl", "m.txt", "",
    "package://", "package://pkg", "package://pkg/", "../desc/m.stl", "m.stl\x00x", "pkg/" + "a" * 300 + ".stl"])


def _mesh_folder(work: Path) -> Path:
    import trimesh

    d = work / "desc"
    (d / "pkg").mkdir(parents=True)
    box = trimesh.creation.box((0.02, 0.02, 0.02))
    box.export(d / "m.stl")
    box.export(d / "pkg" / "m.stl")
    (d / "pkg" / "m.obj").write_text(box.export(file_type="obj"))
    hostile.fifo(d / "pkg", "pipe.mtl")
    (d / "pkg" / "mtl.obj").write_text("mtllib pipe.mtl\n" + box.export(file_type="obj"))
    (work / "outside.stl").write_bytes((d / "m.stl").read_bytes())
    (d / "pkg" / "link_out.stl").symlink_to(work / "outside.stl")
    (d / "pkg" / "loop.stl").symlink_to(d / "pkg" / "loop2.stl")
    (d / "pkg" / "loop2.stl").symlink_to(d / "pkg" / "loop.stl")
    hostile.fifo(d / "pkg", "fifo.stl")
    with open(d / "pkg" / "sparse.stl", "wb") as f:
        f.truncate(3 * 2 ** 30)
    (d / "pkg" / "empty.stl").write_bytes(b"")
    (d / "pkg" / "garbage.stl").write_bytes(bytes(range(256)) * 4)
    return d


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["meshes"], **SETTINGS)
@given(data=st.data())
def test_fuzz_mesh_paths(tmp_path_factory, data):
    from xml.sax.saxutils import quoteattr

    work = tmp_path_factory.mktemp("mesh", numbered=True)
    d = _mesh_folder(work)
    name = data.draw(MESH_NAMES).replace("\x00", "")
    scale = data.draw(st.sampled_from(["", ' scale="1 1 1"', ' scale="0.001 0.001 0.001"', ' scale="1e-300 1 1"',
                                       ' scale="1e300 1 1"', ' scale="nan 1 1"', ' scale="0 1 1"', ' scale="-1 1 1"',
                                       ' scale="1 1"']))
    urdf = (bundled_dir() / "roarm_m3_pro.urdf").read_text().replace(
        '<link name="link3">', f'<link name="link3"><collision><geometry><mesh filename={quoteattr(name)}{scale}/>'
        '</geometry></collision>', 1)
    (d / "arm.urdf").write_text(urdf)
    side = hostile.sidecar(d, "arm.urdf", packages={"pkg": "pkg"},
                           mesh_collision=data.draw(st.sampled_from(["convex", "exact"])))
    run_case(["kin", "fk", str(side), *hostile.M3_Q[:5]], None, work)


# ------------------------------------------------------------------ SRDF and joint_limits.yaml
SRDF_VALUES = st.sampled_from(["nan", "inf", "-inf", "1e400", "", "abc", "0", "1.2", "-5", "base_link", "no_link",
                               "link1", "hand_tcp", "gripper", "arm", "no_group", "link5_to_gripper_link", "no_joint",
                               "fixed", "planar", "floating"])


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["srdf"], **SETTINGS)
@given(data=st.data())
def test_fuzz_srdf(tmp_path_factory, data):
    import re

    from test_moveit_xacro import SRDF

    work = tmp_path_factory.mktemp("srdf", numbered=True)
    text = SRDF % data.draw(st.sampled_from(["", '<passive_joint name="x"/>', '<virtual_joint name="v" type="planar"/>',
                                             '<group name="g2"><chain base_link="nowhere" tip_link="hand_tcp"/></group>',
                                             '<group name="loop"><group name="loop"/></group>', "<unknown/>",
                                             '<end_effector name="e" parent_link="nolink" group="gripper"/>']))
    for _ in range(data.draw(st.integers(0, 3))):
        spots = list(re.finditer(r'(\w+)="([^"]*)"', text))
        m = data.draw(st.sampled_from(spots))
        text = text[: m.start(2)] + data.draw(SRDF_VALUES) + text[m.end(2):]
    (work / "arm.srdf").write_bytes(text_edit(text, data))
    side = {"format": "roarmctl.robot/1", "urdf": "arm.urdf", "srdf": "arm.srdf", "ik": "roarm5"}
    (work / "arm.urdf").write_text((bundled_dir() / "roarm_m3_pro.urdf").read_text())
    (work / "arm.yaml").write_text(yaml.safe_dump(side))
    run_case(["kin", "fk", str(work / "arm.yaml"), *hostile.M3_Q[:5]], None, work)


JL_KEYS = ["joint_limits", "has_velocity_limits", "max_velocity", "has_acceleration_limits", "max_acceleration",
           "has_position_limits", "min_position", "max_position", "has_jerk_limits", "default_velocity_scaling_factor",
           "base_link_to_link1", "no_joint"]


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["joint_limits"], **SETTINGS)
@given(data=st.data())
def test_fuzz_joint_limits(tmp_path_factory, data):
    from test_moveit_xacro import LIMITS

    work = tmp_path_factory.mktemp("jl", numbered=True)
    doc = mutate(LIMITS, data, JL_KEYS, rounds=3)
    how = data.draw(st.sampled_from(["yaml", "yaml", "list", "deep", "fifo", "sparse"]))
    if how == "fifo":
        hostile.fifo(work, "joint_limits.yaml")
    elif how == "sparse":
        with open(work / "joint_limits.yaml", "wb") as f:
            f.truncate(2 ** 31)
    elif how == "deep":
        (work / "joint_limits.yaml").write_bytes(b"joint_limits: " + b"[" * 5000 + b"]" * 5000 + b"\n")
    else:
        body = yaml.safe_dump([doc] if how == "list" else doc, allow_unicode=True)
        (work / "joint_limits.yaml").write_bytes(text_edit(body, data))
    (work / "arm.urdf").write_text((bundled_dir() / "roarm_m3_pro.urdf").read_text())
    hostile.sidecar(work, "arm.urdf", joint_limits="joint_limits.yaml")
    run_case(["kin", "fk", str(work / "arm.yaml"), *hostile.M3_Q[:5]], None, work)


# ------------------------------------------------------------------ export paths
EXPORT_TARGETS = st.sampled_from([".", "..", "/", "", "user", "user/", "userfile", "bag", "bag.mcap", "out.csv",
                                  "x.png", "x.json", "new/deeper/bag", "a" * 300, "a" * 300 + ".mcap", "userfile/bag",
                                  "bag\nname", "-", "--force", "user/inner", "ourbag", "ourbag/", "link_to_user", "~",
                                  "fifo.mcap", "fifo"])


# ------------------------------------------------------------------ descriptions a plan or trajectory names
NAMED_FIELDS = st.sampled_from(["urdf", "srdf", "joint_limits", "packages"])
NAMED_TARGETS = st.sampled_from(["{o}/x", "../outside/x", "sub/x", "/", "link", "loop", "x", "fifo", "/etc/passwd",
                                 "{o}", "..", "."])


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["named_descriptions"], **SETTINGS)
@given(data=st.data())
def test_fuzz_descriptions_named_by_a_file(tmp_path_factory, data):
    """A sidecar a plan names, or the robot.yaml a trajectory carries, whose file fields point anywhere (outside,
    through symlinks, at a FIFO or a loop): never a read outside its folder (the outside files' marker word
    never shows), never exit 1."""
    work = tmp_path_factory.mktemp("named", numbered=True)
    o, d = work / "outside", work / "desc"
    o.mkdir(), d.mkdir()
    m3 = (bundled_dir() / "roarm_m3_pro.urdf").read_text()
    for name in ("x", "jl.yaml"):
        (o / name).write_text("joint_limits: {OUTSIDE_4711: {has_velocity_limits: true, max_velocity: 1}}\n")
    (o / "arm.urdf").write_text(m3.replace('name="roarm_m3_pro"', 'name="OUTSIDE_4711"', 1))
    (d / "arm.urdf").write_text(m3)
    (d / "sub").symlink_to(o)
    (d / "link").symlink_to(o / "x")
    (d / "loop").symlink_to(d / "loop")
    hostile.fifo(d, "fifo")
    (d / "x").write_text("joint_limits: {}\n")
    fields = {}
    for _ in range(data.draw(st.integers(1, 3))):
        key, target = data.draw(NAMED_FIELDS), data.draw(NAMED_TARGETS).replace("{o}", str(o))
        fields[key] = {"p": target} if key == "packages" else target
    if data.draw(st.booleans()):
        hostile.sidecar(d, fields.pop("urdf", "arm.urdf"), **fields)
        (d / "p.yaml").write_text("robot: arm.yaml\nstart: [0, 0, 1.57, 0, 0, 0]\ntasks: [{wait: 0.2}]\n")
        out = d / "p.traj.json"
        code, err = run_case(["plan", str(d / "p.yaml"), "-o", str(out)], out, work)
    else:
        side = yaml.safe_load((bundled_dir() / "roarm_m3_pro.yaml").read_text())
        side.update({"urdf": "robot.urdf", **fields})
        doc = hostile.trajectory_doc("custom")
        doc["robot_description"] = {"format": "roarmctl.robot-bundle/1",
                                    "files": {"robot.yaml": yaml.safe_dump(side), "robot.urdf": m3}}
        (d / "t.traj.json").write_text(json.dumps(doc))
        out = d / "t.png"
        code, err = run_case(["visualize-path", str(d / "t.traj.json"), "-o", str(out)], out, work)
    assert "OUTSIDE_4711" not in err
    if out.suffix == ".json" and code == 0:
        assert "OUTSIDE_4711" not in out.read_text()


@pytest.mark.slow  # CPU: generated cases through the CLI (make test-fast keeps the execution-log fuzz)
@settings(max_examples=COUNTS["export_paths"], **SETTINGS)
@given(data=st.data())
def test_fuzz_export_paths(tmp_path_factory, data):
    """Every output path through ``export``: never a user's file deleted or changed, exit 0 or 2."""
    work = tmp_path_factory.mktemp("export", numbered=True)
    traj = work / "t.traj.json"
    traj.write_text(json.dumps(hostile.trajectory_doc()))
    (work / "user").mkdir()
    (work / "user" / "metadata.yaml").write_text("mine: true\n")
    (work / "user" / "notes.txt").write_text("precious")
    (work / "userfile").write_text("precious file")
    (work / "link_to_user").symlink_to(work / "user")
    hostile.fifo(work, "fifo.mcap")
    hostile.fifo(work, "fifo")
    if data.draw(st.booleans()):  # a bag roarmctl wrote before: may be replaced
        assert main_code(["export", str(traj), "-o", str(work / "ourbag")]) == 0
    before = {p: p.read_bytes() for p in work.rglob("*") if p.is_file() and not p.is_symlink()
              and "ourbag" not in p.parts and p != traj}
    target = data.draw(EXPORT_TARGETS)
    old = os.getcwd()
    os.chdir(work)
    try:
        run_case(["export", str(traj), "-o", target], None, work)
    finally:
        os.chdir(old)
    for p, content in before.items():
        assert p.exists() and p.read_bytes() == content, f"export -o {target!r} changed or deleted {p}"


def main_code(args: list[str]) -> int:
    """Exit code of a CLI run in this process, its output swallowed."""
    from roarmctl.cli import run

    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        return run(args)


# ------------------------------------------------------------------ execution logs
LOG_KEYS = ["format", "robot", "speed_scale", "sent", "received", "t", "cmd", "feedback", "T", "base", "b", "line",
            "trajectory", "points", "positions", "time_from_start", "joint_names", "scene"]


@pytest.mark.slow
@settings(max_examples=COUNTS["logs"], **SETTINGS)
@given(data=st.data())
def test_fuzz_execution_logs(tmp_path_factory, data):
    work = tmp_path_factory.mktemp("log", numbered=True)
    doc = hostile.execlog_doc(n=8)
    if data.draw(st.booleans()):  # a log carries the trajectory it ran (read by export, view and visualize-path)
        doc["trajectory"] = hostile.trajectory_doc()
    doc = mutate(doc, data, LOG_KEYS, rounds=3)
    if data.draw(st.integers(0, 4)) == 0:  # times scaled far out, reversed or squeezed
        scale = data.draw(st.sampled_from([1e-300, 1e15, 1e308, -1.0, 0.0]))
        for e in (doc.get("sent") or []) if isinstance(doc.get("sent"), list) else []:
            if isinstance(e, dict) and isinstance(e.get("t"), (int, float)):
                e["t"] *= scale
    raw = json.dumps(doc, allow_nan=True).encode()
    how = data.draw(st.sampled_from(["none", "none", "truncate", "bigint", "bytes"]))
    if how == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw)))]
    elif how == "bigint":
        raw = raw.replace(b'"t": 0.0', b'"t": ' + b"9" * data.draw(st.sampled_from([40, 5000, 200_000])), 1)
    elif how == "bytes":
        at = data.draw(st.integers(0, len(raw)))
        raw = raw[:at] + data.draw(st.binary(min_size=1, max_size=3)) + raw[at:]
    log = work / f"r{next(_counter)}.exec.json"
    log.write_bytes(raw)
    out = work / data.draw(st.sampled_from(["run.mcap", "run.csv", "run_bag"]))
    code, _ = run_case(["export", str(log), "-o", str(out)], out, work)
    if code == 0:
        assert out.exists()
