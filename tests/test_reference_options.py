"""docs/reference.md documents every option of every command: each option the command line takes (read from the
click commands behind the typer app, so nothing is listed by hand here) appears in the table of its command under
"Options", and every option a table names exists. A new option without a line in the reference fails here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from roarmctl.cli import command

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = (ROOT / "docs" / "reference.md").read_text()
HELP = ("-h", "--help")  # the app's help_option_names, on every command


def commands() -> dict[str, object]:
    """Every command of the app by its name on the command line ("" for the options before the command)."""
    out: dict[str, object] = {}

    def walk(cmd, path: str) -> None:
        out[path] = cmd
        for name, sub in getattr(cmd, "commands", {}).items():
            walk(sub, f"{path} {name}".strip())

    walk(command(), "")
    return out


def options(cmd) -> list[str]:
    """Every spelling of every option of ``cmd`` (``-o``, ``--output``, ``--no-sag`` ...)."""
    return [o for p in cmd.params if p.param_type_name == "option" for o in (*p.opts, *p.secondary_opts)]


def sections(text: str) -> dict[str, str]:
    """The "### ..." subsections of the "## Options" section, keyed by each command their heading names
    (``### kin fk, kin ik`` -> "kin fk", "kin ik"; ``### Before the command`` -> "")."""
    part = text.split("\n## Options\n", 1)[1].split("\n## ", 1)[0]
    out = {}
    for heading, body in re.findall(r"^### ([^\n]+)\n(.*?)(?=^### |\Z)", part, re.M | re.S):
        names = [""] if heading.strip() == "Before the command" else [n.strip() for n in heading.split(",")]
        for name in names:
            out[name] = body
    return out


def undocumented(text: str) -> list[str]:
    """``"COMMAND --option"`` for every option of every command that its section of ``text`` does not show."""
    docs = sections(text)
    missing = []
    for name, cmd in commands().items():
        opts = options(cmd)
        if not opts:  # a group without options of its own (kin)
            continue
        body = docs.get(name, "")
        missing += [f"{name} {o}".strip() for o in opts if f"`{o}`" not in body]
    return missing


def test_every_option_of_every_command_is_in_the_reference():
    assert undocumented(REFERENCE) == []


def test_every_option_the_reference_lists_exists():
    """The first cell of each table row names options of that section's commands (or -h/--help)."""
    cmds = commands()
    for heading_names, body in _grouped(REFERENCE):
        known = set(HELP) | {o for n in heading_names for o in options(cmds[n])}
        for row in re.findall(r"^\| (`-[^|]*)\|", body, re.M):
            for opt in re.findall(r"`(-[-\w]*)`", row):
                assert opt in known, f"reference.md lists {opt} under {', '.join(heading_names) or 'Before the command'}"


def _grouped(text: str) -> list[tuple[list[str], str]]:
    by_body: dict[str, list[str]] = {}
    for name, body in sections(text).items():
        by_body.setdefault(body, []).append(name)
    return [(names, body) for body, names in by_body.items()]


@pytest.mark.parametrize("row", ["| `--samples` |", "| `--sag`, `--no-sag` |", "| `--fail-reads` |"])
def test_the_check_sees_a_missing_row(row):
    """The check is not vacuous: the reference with one option's row taken out is reported, by command and option."""
    assert row in REFERENCE
    lines = [ln for ln in REFERENCE.splitlines() if not ln.startswith(row)]
    gone = undocumented("\n".join(lines))
    assert gone and all(g.split()[-1] in row for g in gone), gone
