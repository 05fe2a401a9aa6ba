"""The library's errors speak its own words, the CLI its flags: no error the library raises names a command-line flag
(an API user has none to pass), and the CLI prints the option at fault and the options a hint names as its flags."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from roarmctl.cli.common import cli_hint, cli_words
from roarmctl.errors import DeviceError, InfeasibleError, InputError, OptionError, RoarmError

PKG = Path(__file__).resolve().parents[1] / "src" / "roarmctl"
FLAG = re.compile(r"(?:^|[\s'(/])(--[a-z][a-z-]*|-[a-z]\s)")


def _raised_texts(path: Path) -> list[tuple[int, str]]:
    """(line, text) of every string constant (f-string parts too) in the arguments of a raise statement's call."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            for arg in [*node.exc.args, *(k.value for k in node.exc.keywords)]:
                for sub in ast.walk(arg):
                    if isinstance(sub, ast.Constant) and isinstance(sub.value, str):
                        out.append((sub.lineno, sub.value))
    return out


@pytest.mark.slow
def test_no_library_error_names_a_command_line_flag():
    found = [f"{p.relative_to(PKG)}:{line}: {text!r}" for p in sorted(PKG.rglob("*.py")) if "cli" not in p.relative_to(PKG).parts
             for line, text in _raised_texts(p) if FLAG.search(text)]
    assert not found, "library errors naming CLI flags (give option= and neutral words):\n" + "\n".join(found)


def test_the_scan_finds_a_flag_where_there_is_one(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text('raise InputError(f"--port {p}: in use", "pick another")\nraise ValueError("x", hint="or -o out/x")\n')
    assert [line for line, text in _raised_texts(bad) if FLAG.search(text)] == [1, 2]


@pytest.mark.parametrize("exc, line, hint", [
    (OptionError("speed_scale", "2 is outside [0.001, 1]"), "--speed-scale: 2 is outside [0.001, 1]", None),
    (InfeasibleError("no free motion", "use move_to_start instead", option="from_current"),
     "--from-current: no free motion", "use --move-to-start instead"),
    (DeviceError("local: Ray did not start", "leave Ray out", option="ray"), "--ray: local: Ray did not start", "leave Ray out"),
    (InputError("x.yaml: the folder is not empty", "or resume a killed run (max_tries 5)"), "x.yaml: the folder is not empty",
     "or --resume a killed run (--max-tries 5)"),
])
def test_the_cli_names_the_option_and_the_hints_options_by_their_flags(exc: RoarmError, line, hint):
    assert cli_words(exc) == line and cli_hint(exc) == hint
    if exc.option:  # the library's own message: the option's name, no flag
        assert str(exc).startswith(f"{exc.option}: ") and "--" not in exc.message
