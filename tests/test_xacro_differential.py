"""roarmctl's sandboxed xacro against real xacro on published descriptions (issue 33, item 1).

tests/data/xacro/ holds the xacro files (and the YAML they load) of published robot descriptions, byte for
byte (SOURCES.yaml: repository, commit, licence, git blob id of each file; collect.py made it). Each case is
expanded twice: by real xacro in a fresh interpreter, trusted (its own ``eval``, ``$(find)`` pointed at the
stored package folders, an empty environment), and by ``roarmctl.robot.xacro_input.expand`` (the sandbox).
After XML canonicalisation (C14N 2.0, comments and whitespace-only text dropped) the two must be equal, or the
sandbox must refuse the case for a cause listed in ``REFUSED_FOR_CAUSE`` (a construct outside the documented
subset: code, the environment, files outside the roots). docs/published.md's table says which is which.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path
from xml.etree.ElementTree import canonicalize

import pytest
import yaml

from roarmctl.errors import DescriptionError
from roarmctl.robot.xacro_eval import Budget, Evaluator, Refused
from roarmctl.robot.xacro_input import expand

CORPUS = Path(__file__).parent / "data" / "xacro"
SOURCES = yaml.safe_load((CORPUS / "SOURCES.yaml").read_text())
CASES: dict[str, dict] = SOURCES["cases"]
#: case -> pattern of the sandbox's refusal, for a published file that really steps outside the subset. None.
REFUSED_FOR_CAUSE: dict[str, str] = {}
#: ``make test-fast`` expands these (one per widening of the sandbox and a plain one); ``make test`` all.
INNER = {"kinova_gen3", "franka_fr3", "fanuc_cr7ia", "ur_ur5e"}
DOCS = Path(__file__).parents[1] / "docs" / "published.md"

REAL_XACRO = r"""
import json, sys
import xacro
from xacro import substitution_args

jobs = json.load(sys.stdin)
out = {}
for name, job in jobs.items():
    substitution_args._eval_find = lambda pkg, p=job["packages"]: p[pkg]
    try:
        out[name] = {"xml": xacro.process_file(job["file"], mappings=job["args"]).toxml()}
    except Exception as exc:
        out[name] = {"error": f"{type(exc).__name__}: {exc}"}
json.dump(out, sys.stdout)
"""


def git_blob(data: bytes) -> str:
    """Git's id of a file's bytes (what ``git rev-parse COMMIT:PATH`` prints for the published file)."""
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def job(name: str) -> dict:
    """Where case ``name``'s top file is, its xacro arguments and its packages (name -> stored folder)."""
    case = CASES[name]
    repo = CORPUS / case["repository"].replace("/", "+")
    packages = {p: str((repo / d).resolve()) for p, d in SOURCES["repositories"][case["repository"]]["packages"].items()}
    return {"file": str(repo / case["file"]), "args": case["args"], "packages": packages}


def canonical(xml: str) -> str:
    """C14N 2.0 of ``xml``: attribute order, quoting, empty elements, comments and indentation no longer differ."""
    return canonicalize(xml, strip_text=True)


@pytest.fixture(scope="module")
def real(request: pytest.FixtureRequest) -> dict[str, dict]:
    """The cases this run compares (all for ``make test``, ``INNER`` for ``make test-fast``) expanded by real
    xacro, in one fresh interpreter with an empty environment: expanding all 30 took 1.3-1.7 s of each fast
    worker's CPU for the 4 it compares."""
    names = {item.callspec.params["name"] for item in request.session.items
             if getattr(item, "originalname", None) == "test_sandboxed_expansion_equals_real_xacro"}
    proc = subprocess.run([sys.executable, "-c", REAL_XACRO], input=json.dumps({n: job(n) for n in sorted(names)}),
                          capture_output=True, text=True, env={"PATH": os.defpath}, check=True, timeout=300)
    return json.loads(proc.stdout)


def test_the_corpus_is_thirty_published_descriptions_or_more_from_ten_vendors():
    assert len(CASES) >= 30
    assert len({c["repository"] for c in CASES.values()}) >= 10


@pytest.mark.parametrize("repository", sorted(SOURCES["repositories"]))
def test_stored_files_are_the_published_bytes(repository):
    entry = SOURCES["repositories"][repository]
    assert re.fullmatch(r"[0-9a-f]{40}", entry["commit"]) and entry["licence"]
    folder = CORPUS / repository.replace("/", "+")
    stored = {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}
    assert stored == set(entry["files"])  # nothing unlisted, nothing missing
    for path, blob in entry["files"].items():
        assert git_blob((folder / path).read_bytes()) == blob, path


# one xdist group: the worker that runs them expands them with real xacro once (``real``), not each worker that drew one
@pytest.mark.xdist_group("real-xacro")
@pytest.mark.parametrize("name", [pytest.param(n, marks=[] if n in INNER else [pytest.mark.slow]) for n in sorted(CASES)])
def test_sandboxed_expansion_equals_real_xacro(real, name):
    j = job(name)
    assert "xml" in real[name], f"real xacro fails on a corpus file: {real[name]}"
    try:
        ours = expand(Path(j["file"]), j["args"], name, {p: Path(f) for p, f in j["packages"].items()})
    except DescriptionError as exc:
        cause = REFUSED_FOR_CAUSE.get(name)
        assert cause and re.search(cause, str(exc)), f"refused without a listed cause: {exc}"
        return
    assert name not in REFUSED_FOR_CAUSE, "expands now: remove it from REFUSED_FOR_CAUSE (and the docs table)"
    assert canonical(ours) == canonical(real[name]["xml"])


def test_the_docs_table_lists_every_case_with_its_verdict():
    text = DOCS.read_text()
    for name in CASES:
        verdict = "refused: " if name in REFUSED_FOR_CAUSE else "equal"
        assert re.search(rf"^\| {re.escape(name)} \|[^\n]*\| {verdict}", text, re.M), name


def _no_properties(name: str):
    raise KeyError(name)


@pytest.mark.parametrize("expr, value", [
    ("dict(joint_1=0.0, joint_2=1.5)['joint_2']", 1.5),  # Kinova's gen3.xacro
    ("dict([('a', 1)], b=2)", {"a": 1, "b": 2}),
    ("len(dict(a=1, b=2, c=3))", 3),
])
def test_dict_takes_keyword_arguments_as_python_does(expr, value):
    assert Evaluator(_no_properties, Budget())(expr) == value == eval(expr)  # noqa: S307 - constant test input


@pytest.mark.parametrize("expr, refusal", [
    ("round(1.25, ndigits=1)", "keyword arguments are allowed only in dict"),
    ("dict(**{'a': 1})", r"\* or \*\* arguments"),
    ("max(*[1, 2])", r"\* or \*\* arguments"),
    ("dict(a=[0] * 10**6, b=[0] * 10**6)", "repetition"),
    ("dict('ab')", "dict"),
])
def test_keyword_arguments_stay_refused_elsewhere(expr, refusal):
    with pytest.raises(Refused, match=refusal):
        Evaluator(_no_properties, Budget())(expr)
