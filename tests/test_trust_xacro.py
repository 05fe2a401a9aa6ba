"""Trust no file, part 3 (issue 40), xacro: work an allowed function does that the budget does not count, include
patterns that look outside the roots, and xacro's own symbols seen through an include's namespace. The shared
corpus (hostile arguments for every allowed function) is in tests/hostile.py; tests/test_fuzz.py runs it too."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import hostile
import pytest
from test_trust import cli, refused

from roarmctl.robot.xacro_eval import FUNCTIONS, STR_METHODS, Budget, Evaluator, Refused

TESTS = Path(__file__).parent


# --------------------------------------------------------------------------- allowed functions, hostile arguments
@pytest.mark.slow  # CPU: about 30,000 evaluations (4 s on an idle core)
def test_every_allowed_function_with_hostile_arguments_answers_as_python_or_is_refused():
    """The generated table (every allowed function and string method, a hostile argument at each place, every
    pair of numeric extremes) in a child process: one C call such as ``round(1, -10**9)`` (10**(10**9) made
    before it answers) cannot be interrupted by an alarm, so the child's time-out is the hang detector. Every
    call is refused (Refused, exit 2 through the CLI) or answers what Python answers; nothing else is raised."""
    calls = hostile.hostile_calls()
    names = {c.split("(")[0].split(".")[-1] for c in calls}
    assert set(FUNCTIONS) | set(STR_METHODS) <= names  # every allowed name is in the table
    assert "round(1, -10**9)" in calls and "round(1, -big_i)" in calls
    code = (f"import json, sys; sys.path.insert(0, {str(TESTS)!r}); import hostile; "
            "print(json.dumps(hostile.evaluate_calls(hostile.hostile_calls())))")
    try:
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    except subprocess.TimeoutExpired:
        pytest.fail("an allowed function with a hostile argument did not answer within 600 s")
    assert run.returncode == 0, run.stderr[-2000:]
    tally = json.loads(run.stdout)
    assert tally["other"] == [] and tally["differs"] == [], (tally["other"][:10], tally["differs"][:10])
    assert tally["refused"] + tally["answered"] == len(calls)
    assert tally["answered"] > 3000  # the bounds refuse the extremes (and Python the mistyped calls), not the ordinary ones


@pytest.mark.parametrize("expr, value", [
    ("round(1234.5678, 2)", 1234.57), ("round(1250, -2)", 1200), ("round(-2.5)", -2), ("round(1e308, -308)", 1e308),
    ("round(2**255, -70)", round(2 ** 255, -70)), ("round(7, -400)", 0), ("round(0.5, 400)", 0.5),
    ("'a b  c'.split()", ["a", "b", "c"]), ("'a,b'.split(',', 0)", ["a,b"]), ("'a,b,c'.rsplit(',', 1)", ["a,b", "c"]),
])
def test_bounded_functions_answer_as_python_within_their_bounds(expr, value):
    assert Evaluator(lambda n: {}[n], Budget())(expr) == value


@pytest.mark.parametrize("expr, needle", [
    ("round(1, -10**9)", "round() to more than 400 digits"), ("round(1.5, 10**9)", "round() to more than 400 digits"),
    ("round(1, -401)", "round() to more than 400 digits"),
    ("(' ' + 'a ' * 150000).split()", "a list of more than 100,000 items"),
    ("(',' * 200000).split(',')", "a list of more than 100,000 items"),
])
def test_an_allowed_call_whose_work_is_unbounded_is_refused_before_it_runs(expr, needle):
    with pytest.raises(Refused, match=needle.replace("(", r"\(").replace(")", r"\)")):
        Evaluator(lambda n: {}[n], Budget())(expr)


def test_round_of_a_huge_exponent_is_exit_2_through_the_cli(tmp_path):
    refused(["kin", "fk", str(hostile.m3_xacro(tmp_path, "str(round(1, -10**9))")), *hostile.M3_Q],
            "arm.xacro", "round() to more than 400 digits")


# --------------------------------------------------------------------------- include patterns
@pytest.fixture
def outside(tmp_path) -> Path:
    """A folder beside the description's with a file whose NAME must never appear in any output."""
    o = tmp_path / "home"
    (o / "Documents").mkdir(parents=True)
    (o / "Documents" / "tax-return-OUTSIDE-NAME.xacro").write_text(f'<robot {hostile.XACRO_NS}><link name="x"/></robot>')
    (o / "OUTSIDE-NAME-2.xacro").write_text(f'<robot {hostile.XACRO_NS}><link name="x"/></robot>')
    return o


def _desc(tmp_path: Path) -> Path:
    d = tmp_path / "desc" / "robot"
    (d / "sub").mkdir(parents=True)
    (d / "sub" / "part.xacro").write_text(f'<robot {hostile.XACRO_NS}><xacro:property name="from_part" value="p"/></robot>')
    return d


def _include(d: Path, spec: str) -> list[str]:
    arm = hostile.m3_xacro(d, "'a'", f'<xacro:include filename="{spec}"/>')
    return ["kin", "fk", str(arm), *hostile.M3_Q]


@pytest.mark.parametrize("spec, needle", [
    ("$(dirname)/s*/../../../home/*/*.xacro", "'..' after a wildcard"),
    ("$(dirname)/s*/../../../home/*.xacro", "'..' after a wildcard"),
    ("$(dirname)/*/../../../home/Documents/*", "'..' after a wildcard"),
    ("$(dirname)/../../home/*/*.xacro", "lies outside the folders"),
    ("$(dirname)/../../home/Doc*/tax*", "lies outside the folders"),
    ("/proc/*/root/*.xacro", "lies outside the folders"),
    ("$(dirname)/../../../../../../../../../proc/*/root/*/*/*", "lies outside the folders"),
])
def test_an_include_pattern_never_lists_outside_nor_names_what_it_found_there(tmp_path, outside, spec, needle):
    err = refused(_include(_desc(tmp_path), spec), needle)
    assert "OUTSIDE-NAME" not in err and ("Documents" not in err or "Documents" in spec), err


def test_a_pattern_through_a_symlink_out_is_refused_naming_the_link_not_what_is_beyond(tmp_path, outside):
    d = _desc(tmp_path)
    (d / "shared").symlink_to(outside)
    (d / "root").symlink_to("/")
    for spec in ("$(dirname)/sh*/*.xacro", "$(dirname)/sh*/*/*.xacro", "$(dirname)/ro*/proc/*/root/*", "$(dirname)/*/*"):
        err = refused(_include(d, spec), "lies outside the folders")
        assert "OUTSIDE-NAME" not in err and "Documents" not in err, err
        assert f"{d}/shared" in err or f"{d}/root" in err, err
    (d / "sub" / "evil.xacro").symlink_to(outside / "OUTSIDE-NAME-2.xacro")
    err = refused(_include(d, "$(dirname)/s?b/*.xacro"), "lies outside the folders", "sub/evil.xacro")
    assert "OUTSIDE-NAME" not in err, err


@pytest.mark.slow
def test_a_pattern_that_looks_at_too_many_entries_is_refused(tmp_path):
    d = _desc(tmp_path)
    many = d / "many"
    many.mkdir()
    for k in range(10_001):
        (many / f"f{k}").mkdir() if k < 3 else (many / f"f{k}").touch()
    refused(_include(d, "$(dirname)/many/*/x.xacro"), "looks at more than 10,000")


def test_a_pattern_inside_the_roots_includes_what_glob_finds(tmp_path):
    d = _desc(tmp_path)
    (d / "sub" / ".hidden.xacro").write_text("<robot/>")  # glob skips hidden names unless the pattern starts with '.'
    for spec in ("$(dirname)/s*/*.xacro", "$(dirname)/sub/p?rt.xacro", "$(dirname)/[s]ub/part.xacro"):
        arm = hostile.m3_xacro(d, "from_part", f'<xacro:include filename="{spec}"/>')
        code, out, err = cli(["kin", "fk", str(arm), *hostile.M3_Q, "--json"])
        assert code == 0 and json.loads(out)["robot"] == "p", (spec, err)


def test_include_glob_finds_what_python_s_glob_finds_inside_the_roots(tmp_path):
    """Differential: the walk inside the roots gives glob.glob's answer (hidden names, folders, literals)."""
    import glob

    from roarmctl.fileio import Roots
    from roarmctl.robot.xacro_glob import include_glob

    d = _desc(tmp_path)
    for name in ("a.xacro", "b.urdf", ".h.xacro", "sub2/c.xacro", "sub2/d/e.xacro", "x[1].xacro"):
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text("<robot/>")
    roots = Roots([d])
    for pat in ("*", "*.xacro", ".*", "*/*", "*/*.xacro", "sub*/d/*", "s?b2/*", "[ab].*", "*/d", "**/*.xacro", "nothing*"):
        assert include_glob(f"{d}/{pat}", roots, "t") == sorted(glob.glob(f"{d}/{pat}")), pat


# --------------------------------------------------------------------------- xacro's own symbols
@pytest.mark.parametrize("expr", ["str(n['python'])", "str(n['math'])", "n['xacro']", "str(n['python']['type'])"])
def test_an_include_namespace_shows_no_xacro_internals(tmp_path, expr):
    d = _desc(tmp_path)
    arm = hostile.m3_xacro(d, expr, '<xacro:include filename="$(dirname)/sub/part.xacro" ns="n"/>')
    err = refused(["kin", "fk", str(arm), *hostile.M3_Q], "no property")
    assert "builtin" not in err and "function" not in err, err
    arm = hostile.m3_xacro(d, "n['from_part'] + n.from_part", '<xacro:include filename="$(dirname)/sub/part.xacro" ns="n"/>')
    code, out, err = cli(["kin", "fk", str(arm), *hostile.M3_Q, "--json"])
    assert code == 0 and json.loads(out)["robot"] == "pp", err


def test_xacro_s_builtins_table_is_not_reachable_through_a_namespace_by_any_key(tmp_path):
    """Every name of xacro's global symbols, indexed through an include namespace: refused, each."""
    import xacro

    d = _desc(tmp_path)
    keys = sorted(k for k in xacro._global_symbols if k.isidentifier())
    extra = '<xacro:include filename="$(dirname)/sub/part.xacro" ns="n"/>'
    for key in keys[:: max(1, len(keys) // 12)]:
        refused(["kin", "fk", str(hostile.m3_xacro(d, f"str(n[{key!r}])", extra)), *hostile.M3_Q], "no property")
    assert os.path.exists(d)
