"""The one YAML reader (``roarmctl.validation.parse_yaml``) against PyYAML's own safe loader, the reference for
what a YAML 1.1 document means: on generated documents in every style PyYAML writes, on scalars whose tag the
resolver decides (numbers in every YAML 1.1 form, booleans, nulls, strings that look like them), and on every
YAML file the project ships. The reader's own speed-ups (its resolver, its scalar builders, its nesting scan)
must give the same values; its refusals (tags, duplicate keys, aliases past the budget) are tested in
tests/test_trust.py and tests/test_fuzz.py."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from roarmctl.errors import PlanFileError
from roarmctl.validation import MAX_DEPTH, _flow_depth_line, parse_yaml

ROOT = Path(__file__).resolve().parents[1]


def same(a, b) -> bool:
    """Equal values, NaN equal to NaN, and the same types (1 is not 1.0 here, True is not 1)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    if type(a) is not type(b) and not (isinstance(a, dict) and isinstance(b, dict)) \
            and not (isinstance(a, list) and isinstance(b, list)):
        return False
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and a == 0.0:
        return math.copysign(1, a) == math.copysign(1, b)
    return a == b


#: Scalars written plain, whose type only the resolver decides: YAML 1.1's numbers (signs, exponents, ``_``
#: separators, sexagesimal, octal, hex, binary, ``.inf``/``.nan`` spellings), its booleans and nulls, and words
#: that look like them but are strings (``1e3`` has no dot: a string in YAML 1.1).
PLAIN = ["0", "-0", "+1", "12", "1_000", "0o17", "017", "0x1F", "0b101", "1:30", "-1:30:00", "3.5", "-0.0", "+.5",
         "1.", "1.5e3", "1.5E-3", "-2.5e+10", "1_000.000_1", "190:20:30.15", ".inf", "-.Inf", "+.INF", ".nan",
         ".NaN", "1e3", "inf", "nan", "true", "True", "FALSE", "yes", "No", "on", "OFF", "y", "n", "~", "null", "Null",
         "", "=", "abc", "1.2.3", "0x", "-", "--1", "12:60", "2001-12-14", "2001-12-14t21:59:43.10-05:00", "3.14.15"]


@pytest.mark.parametrize("text", PLAIN)
def test_every_plain_scalar_means_what_pyyaml_says(text):
    doc = f"a: {text}\nb: [{text or '~'}, x]\n"
    try:
        expected = yaml.safe_load(doc)
    except yaml.YAMLError:  # PyYAML itself refuses it ('=': YAML 1.1's value key, no constructor): so do we
        with pytest.raises(PlanFileError):
            parse_yaml(doc, "s.yaml")
        return
    try:
        got = parse_yaml(doc, "s.yaml")
    except PlanFileError as exc:  # refused by a documented bound (integers beyond 2**53), never a different value
        assert "too large" in str(exc), exc
        return
    assert same(got, expected), (doc, got, expected)


scalars = st.one_of(st.none(), st.booleans(), st.integers(-2 ** 53, 2 ** 53),
                    st.floats(allow_nan=False, width=64), st.text(max_size=12), st.sampled_from(PLAIN))
keys = st.text(min_size=1, max_size=8)
documents = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                          st.dictionaries(keys, inner, max_size=5)), max_leaves=40)


@pytest.mark.slow
@settings(max_examples=300, deadline=None)
@given(documents, st.sampled_from([None, True, False]), st.booleans())
def test_generated_documents_read_as_pyyaml_reads_them(doc, flow, canonical):
    """Any document PyYAML writes (block, flow or mixed; canonical or not) reads to the same values."""
    text = yaml.safe_dump({"doc": doc}, default_flow_style=flow, canonical=canonical, allow_unicode=True)
    assert same(parse_yaml(text, "g.yaml"), yaml.safe_load(text)), text


def shipped_yaml() -> list[Path]:
    return sorted(p for p in ROOT.glob("**/*.yaml") if ".venv" not in p.parts and "out" not in p.parts)


@pytest.mark.slow
def test_every_shipped_yaml_file_reads_as_pyyaml_reads_it():
    files = shipped_yaml()
    assert len(files) > 20, files
    for path in files:
        text = path.read_text()
        try:
            expected = yaml.safe_load(text)
        except yaml.YAMLError:
            continue  # a test's deliberately broken file
        try:
            got = parse_yaml(text, str(path))
        except PlanFileError:
            continue  # refused by a bound (tests/test_trust.py and test_fuzz.py check those refusals)
        assert same(got, expected), path


@pytest.mark.parametrize("depth", [MAX_DEPTH - 5, MAX_DEPTH - 1, MAX_DEPTH, MAX_DEPTH + 1])
@pytest.mark.parametrize("wrap, extra, line", [("{}", 0, 2), ("[{}]", 1, 2), ("# [[[[ \n{}", 0, 3), ("'[[[[[': {}", 0, 2),
                                               ("\"[[[[[[\": {}", 0, 2), ("a#[[[[[: {}", 5, 2)])
def test_the_nesting_scan_counts_brackets_outside_quotes_and_comments(depth, wrap, extra, line):
    """The scan before the parser: brackets in quotes and in comments do not count; one level past the limit is
    found on its line; a ``#`` inside a word starts no comment (its brackets count: stricter than YAML, never
    laxer)."""
    body = "[" * depth + "1" + "]" * depth
    text = "x: 1\n" + wrap.replace("{}", body) + "\n"
    assert _flow_depth_line(text) == (line if depth + extra > MAX_DEPTH else 0), text
