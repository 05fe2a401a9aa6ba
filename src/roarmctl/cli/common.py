"""Shared CLI helpers: output consoles, JSON printing, error lines, argument parsing."""

from __future__ import annotations

import json
import math
import os
import re
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from roarmctl.errors import InputError, RoarmError

if TYPE_CHECKING:
    import numpy as np
    from rich.console import Console

    from roarmctl.robot.model import Robot


@dataclass
class _State:
    debug: bool = False
    json_printed: bool = False  # a command printed its JSON object (no second one on failure)
    last_error: tuple[str, str | None] | None = None  # (message, hint) of the last error line


STATE = _State()


def console(stderr: bool = False) -> Console:
    """A rich console on stdout (or stderr) without highlighting: what every command renders with."""
    from rich.console import Console

    return Console(stderr=stderr, highlight=False)


def _plain(obj: Any) -> Any:
    import numpy as np  # here, not at the top: `roarmctl --help` does not load numpy

    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    return obj


def print_json(obj: Any) -> None:
    """Exactly one JSON object on stdout, nothing else; a command's result carries ``"ok": true``
    (a failure prints ``{"ok": false, "error", "hint", "exit_code"}`` instead, from ``cli.main``)."""
    if isinstance(obj, dict) and "ok" not in obj:
        obj = {"ok": True, **obj}
    sys.stdout.write(json.dumps(_plain(obj)) + "\n")
    STATE.json_printed = True


def not_the_input(output: Any, source: Any, flag: str) -> None:
    """``InputError`` (exit 2) when the file ``output`` is the file ``source`` the command reads: the atomic rename
    would replace the user's input (a plan, a trajectory) with the result."""
    try:
        same = output is not None and os.path.samefile(output, source)
    except (OSError, ValueError):  # an output that does not exist yet is not the input
        return
    if same:
        raise InputError(f"{flag} {output} is the input file {source}; writing it would replace the input",
                         "give the output another name")


def cli_words(exc: RoarmError) -> str:
    """The message of a library error as the CLI prints it: the option at fault (``speed_scale``, ``from_current``:
    the library's neutral words) named by its flag (``--speed-scale``); any other error as it is."""
    if exc.option:
        return f"--{exc.option.replace('_', '-')}: {exc.problem}"
    return exc.message


#: What a library hint says (an option as the API spells it, ``move_to_start``; a way to reach the arm) and the CLI's
#: words for it.
HINT_FLAGS = {name: "--" + name.replace("_", "-") for name in (
    "move_to_start", "from_current", "max_tries", "package_path", "max_error", "speed_scale", "resume", "force")} | {
    "connect to the arm (its port, or the simulated one)": "pass --port PORT (or --sim)"}
_HINT_WORD = re.compile("|".join(rf"\b{re.escape(k)}(?!\w)" for k in sorted(HINT_FLAGS, key=len, reverse=True)))


def cli_hint(exc: RoarmError) -> str | None:
    """The hint of a library error as the CLI prints it: the option names it gives written as flags."""
    return None if exc.hint is None else _HINT_WORD.sub(lambda m: HINT_FLAGS[m.group(0)], exc.hint)


def error(message: str, hint: str | None = None) -> None:
    """One line on stderr: the cause, and the fix where there is one."""
    STATE.last_error = (message, hint)
    text = f"error: {message}" + (f" ({hint})" if hint else "")
    sys.stderr.write(one_line(text) + "\n")


def one_line(text: str) -> str:
    """Control characters (from file names, keys or values quoted in a message) escaped, so that a
    message stays one line whatever the input held."""
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def shown(name: object) -> str:
    """A name from a file or the command line (a file name, a robot's or a plan's name) as rich prints it: control
    characters escaped (``one_line``: a terminal title sequence in a file name stays text) and rich's markup
    escaped (``[bold]`` in a name stays text). Every name the CLI prints through rich goes through here."""
    from rich.markup import escape

    return escape(one_line(str(name)))


_NOTED: set[int] = set()


def load_robot(spec: str) -> Robot:
    """The robot ``spec`` (``roarmctl.robot.loader.load_robot``), its loader notes (held joints, massless
    links, defaults used for limits the description lacks) written to stderr the first time it loads."""
    from roarmctl.robot.loader import load_robot as _load

    robot = _load(spec, trust_sidecar=True)  # the user named it on the command line
    if id(robot) not in _NOTED:
        _NOTED.add(id(robot))
        for n in robot.notes:
            sys.stderr.write(f"note: {one_line(n)}\n")
    return robot


def warn(message: str) -> None:
    """Write ``warning: MESSAGE`` to stderr on one line."""
    sys.stderr.write(f"warning: {one_line(message)}\n")


def parse_numbers(values: list[str], what: str, deg: bool = False) -> np.ndarray:
    """Numbers from the command line, as separate arguments or in one ('0,0.5,1.2', '[0, 0.5, 1.2]', as a
    Python or YAML list is typed); degrees are converted to radians when ``deg``."""
    out = []
    for v in values:
        for token in v.strip().removeprefix("[").removesuffix("]").replace(",", " ").split():
            try:
                out.append(float(token))
            except ValueError:
                raise InputError(f"{what}: '{token}' is not a number",
                                 "give numbers, separated by spaces or commas: 0 -1.57 1.57") from None
    import numpy as np

    arr = np.array(out)
    if not np.all(np.isfinite(arr)):  # float() reads 'nan' and 'inf': a NaN joint gave a NaN pose and exit 0
        bad = next(v for v in out if not math.isfinite(v))
        raise InputError(f"{what}: expected finite numbers, got {bad:g}", "give ordinary numbers: 0 -1.57 1.57")
    return np.radians(arr) if deg else arr
