"""One exception hierarchy for the whole library.

Each class carries the process exit code the CLI maps it to (see docs/reference.md, "Exit codes") and a
one-line message that names the cause and, where there is one, the fix. The library raises these;
only ``roarmctl.cli`` turns them into output and exit codes.
"""

from __future__ import annotations

import signal
from collections.abc import Iterable, Mapping
from typing import Any, Literal, cast, get_args


def describe_value(value: Any, *, json: bool = False) -> str:
    """How an unexpected value reads in an error message ("got a list of 3", "got str 'abc'").

    ``json`` names a dict "an object" and ``None`` "null", as a JSON file's reader expects; otherwise
    (YAML, URDF) "a mapping" and "nothing". Long values are cut at 40 characters so the message
    stays one line.
    """
    if isinstance(value, dict):
        return "an object" if json else "a mapping"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if value is None:
        return "null" if json else "nothing"
    text = repr(value)
    return f"{type(value).__name__} {text[:40]}{'...' if len(text) > 40 else ''}"


class RoarmError(Exception):
    """Base class. ``exit_code`` is what the CLI exits with; ``hint`` is an optional fix.

    ``option``: the input at fault in the library's own words (an argument or field name, ``"from_current"``), when
    there is one; the message is then ``"{option}: {message}"`` and ``problem`` the message alone. The CLI names
    its flag instead when it prints (``roarmctl.cli.common.cli_words``), as it does for the option names a hint
    gives (``move_to_start``)."""

    exit_code: int = 1

    def __init__(self, message: str, hint: str | None = None, *, option: str | None = None) -> None:
        text = f"{option}: {message}" if option else message
        super().__init__(text)
        self.message = text
        self.hint = hint
        self.option = option
        self.problem = message

    def __str__(self) -> str:
        return self.message if not self.hint else f"{self.message} ({self.hint})"


class InputError(RoarmError):
    """Invalid input or usage: missing file, schema error, unknown robot, out-of-range value (exit 2)."""

    exit_code = 2


class OptionError(InputError):
    """An option out of its bounds, in the library's words: ``field`` names it as the options object does
    (``speed_scale``), ``problem`` says what is wrong; the message is ``"{field}: {problem}"``. The CLI names
    its flag instead when it prints (``roarmctl.cli.common``)."""

    def __init__(self, field: str, problem: str, hint: str | None = None) -> None:
        super().__init__(problem, hint, option=field)
        self.field = field


class DescriptionError(InputError):
    """A robot description (URDF, sidecar or DH table) is wrong or incomplete (exit 2)."""


class PlanFileError(InputError):
    """A plan file is malformed: unknown key, wrong type, impossible value, dangling reference (exit 2)."""


class TrajectoryFileError(InputError):
    """A trajectory file cannot be read or does not follow the format (exit 2)."""


class InfeasibleError(RoarmError):
    """The input is well-formed but cannot be done: unreachable, no path, timing failed (exit 3)."""

    exit_code = 3
    #: set by planning: what was planned before the failure (``roarmctl.motion.pipeline.PartialPlan``), or None
    partial: Any = None


UnreachableReason = Literal["out_of_reach", "joint_limit", "orientation", "collision", "singularity", "mixed"]


class UnreachableError(InfeasibleError):
    """IK found no (valid) solution. ``reason`` is one of 'out_of_reach', 'joint_limit', 'orientation' or, when
    solutions exist but each was rejected: 'collision' (each collides; where the planner knows no more, also those
    too near a singularity), 'singularity' (each within the singularity margin), 'joint_limit' (each outside
    the limits) or 'mixed' (for different causes; the message counts each)."""

    def __init__(self, message: str, reason: UnreachableReason = "out_of_reach", hint: str | None = None) -> None:
        super().__init__(message, hint)
        self.reason = reason


#: The cause an IK candidate (a solution, or a tool pitch) was rejected for -> the words a message counts it with.
REJECTED_AS = {"joint_limit": "outside the joint limits", "collision": "in collision",
               "singularity": "within the singularity margin", "mixed": "for mixed causes"}


def rejection(causes: Iterable[str], said: Mapping[str, str] | None = None) -> tuple[UnreachableReason, str]:
    """What rejected a set of IK candidates, from the cause of each (``causes``: "collision", "singularity",
    "joint_limit", ... as ``motion.rejection.rejection_cause`` and ``Validity.kind`` say). Returns (the
    ``UnreachableError`` reason: the one cause, or "mixed" when they differ or the one is no reason; the one-line
    count of each cause in the order first seen, "3 in collision, 2 within the singularity margin", each followed
    by ``said[cause]`` when given). The counting of every "no valid IK" error (api, plans, ``kin ik``)."""
    counts: dict[str, int] = {}
    for cause in causes:
        counts[cause] = counts.get(cause, 0) + 1
    one = next(iter(counts)) if len(counts) == 1 else "mixed"
    reason = cast(UnreachableReason, one) if one in get_args(UnreachableReason) else "mixed"
    text = ", ".join(f"{n} {REJECTED_AS.get(c, c)}" + (f" {said[c]}" if said and c in said else "")
                     for c, n in counts.items())
    return reason, text


class PlanningError(InfeasibleError):
    """No collision-free path within the time budget, start in collision, or timing failed (exit 3)."""


class DeviceError(RoarmError):
    """Port missing or busy, device silent, wrong firmware, link lost (exit 4)."""

    exit_code = 4


class Interrupted(RoarmError):
    """Ctrl-C, SIGTERM or SIGHUP stopped the run; raised after the arm was told to hold.

    Exit code 128 + the signal number, as shells report it: 130 (SIGINT), 143 (SIGTERM), 129 (SIGHUP).
    """

    exit_code = 130

    def __init__(self, message: str, hint: str | None = None, signum: int = 2) -> None:
        super().__init__(message, hint)
        self.signum = signum
        self.exit_code = 128 + signum


class StopRequested(KeyboardInterrupt):
    """A stop signal turned into an exception (by ``roarmctl.cli.signals``); ``signum`` says which.

    A ``KeyboardInterrupt``, so every ``except KeyboardInterrupt``/``finally`` runs as for Ctrl-C.
    """

    def __init__(self, signum: int = 2) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def what(self) -> str:
        """'Ctrl-C', 'SIGTERM', 'SIGHUP' (for messages)."""
        return signal_name(self.signum)


def signal_name(signum: int) -> str:
    """'Ctrl-C' for SIGINT, else the signal's name ('SIGTERM', 'SIGHUP')."""
    if signum == signal.SIGINT:
        return "Ctrl-C"
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"
