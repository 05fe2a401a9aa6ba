"""Field checks and option bounds: the ONE place where a read value, or an option given in code, is checked.

* ``Checker(error)``: ``number``, ``numbers``, ``name``, ``mapping``, ``known_keys``, ``required``: each refusal an
  ``error`` (an ``InputError`` subclass, exit 2) naming where (a file and line) and the field, with the fix.
* ``Bound`` and ``check_options``: the values one option takes; options objects check every field against their
  bounds when made, refusing NaN, infinities, wrong types and values out of range in the field's own name
  (``OptionError``; the CLI adds its flag names).

The documents these values come from are parsed by ``roarmctl.validation``.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, fields
from typing import Any, NoReturn

from roarmctl.errors import InputError, OptionError, describe_value


class HugeNumber:
    """A JSON integer of more than ``roarmctl.validation.MAX_DIGITS`` digits, kept as text so that the field checker that
    meets it can refuse it by name (``Checker.number``); no other code takes it for a number."""

    def __init__(self, text: str) -> None:
        self.text = text

    def __repr__(self) -> str:
        return f"{self.text[:12]}... ({len(self.text.lstrip('-'))} digits)"


def closest(word: str, options: Iterable[object]) -> str | None:
    """The option most like ``word`` (a typo's fix), or None."""
    match = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.6)
    return match[0] if match else None


class Checker:
    """Field checks that raise ``error`` with ``"{where}: {field}: {message}"``.

    ``json``: name values as a JSON reader expects (``an object``, ``null``) in messages. Every
    number must be finite and within ``bound`` unless a tighter range is given. ``number_word``: how
    ``number`` names what it expected (``expected a number, got ...``); ``max_name``: the longest
    ``name`` (characters) unless a call says otherwise.
    """

    def __init__(self, error: type[InputError], *, json: bool = False, bound: float = 1e6,
                 number_word: str = "a number", max_name: int = 255) -> None:
        self.error = error
        self.json = json
        self.bound = bound
        self.number_word = number_word
        self.max_name = max_name

    def kind(self, value: Any) -> str:
        """How an unexpected value reads in a message."""
        return describe_value(value, json=self.json)

    def fail(self, where: str, field: str, message: str, hint: str | None = None) -> NoReturn:
        """Raise the checker's error for ``field`` of ``where``."""
        raise self.error(f"{where}: {field}: {message}" if field else f"{where}: {message}", hint)

    def number(self, value: Any, where: str, field: str, *, lo: float | None = None, hi: float | None = None,
               strict_lo: bool = False, what: str | None = None) -> float:
        """A finite number (not a bool, not a string) within [lo, hi] (default: +-``bound``); ``what``: its
        name in the message (default: ``number_word``)."""
        what = self.number_word if what is None else what
        if isinstance(value, HugeNumber):
            self.fail(where, field, f"the number {value!r} is too large")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(where, field, f"expected {what}, got {self.kind(value)}")
        try:
            x = float(value)
        except OverflowError:
            self.fail(where, field, f"the number {str(value)[:12]}... is too large")
        if not math.isfinite(x):
            self.fail(where, field, f"expected a finite number, got {x}")
        lo = -self.bound if lo is None else lo
        hi = self.bound if hi is None else hi
        if x < lo or (strict_lo and x <= lo):
            self.fail(where, field, f"{x:g} is too small (must be {'>' if strict_lo else '>='} {lo:g})")
        if x > hi:
            self.fail(where, field, f"{x:g} is too large (must be <= {hi:g})")
        return x

    def numbers(self, value: Any, n: int | None, where: str, field: str, **bounds: Any) -> list[float]:
        """A list of ``n`` numbers (any length when None), each checked by ``number``."""
        if not isinstance(value, list) or (n is not None and len(value) != n):
            count = f"{n} " if n is not None else ""
            self.fail(where, field, f"expected a list of {count}numbers, got {self.kind(value)}")
        return [self.number(x, where, f"{field}[{i}]", **bounds) for i, x in enumerate(value)]

    def name(self, value: Any, where: str, field: str, *, empty: bool = False, max_len: int | None = None,
             choices: tuple[str, ...] | list[str] | None = None) -> str:
        """A string of at most ``max_len`` characters (default: ``max_name``; non-empty unless ``empty``), one of
        ``choices`` if given."""
        max_len = self.max_name if max_len is None else max_len
        if not isinstance(value, str) or (not value and not empty):
            self.fail(where, field, f"expected a name, got {self.kind(value)}")
        if len(value) > max_len:
            self.fail(where, field, f"longer than {max_len} characters")
        if choices is not None and value not in choices:
            close = closest(value, choices)
            self.fail(where, field, f"'{value[:40]}' is not one of {', '.join(choices)}",
                      f"did you mean '{close}'?" if close else None)
        return value

    def mapping(self, value: Any, where: str, field: str) -> dict:
        """A mapping (a JSON object)."""
        if not isinstance(value, dict):
            self.fail(where, field, f"expected {'an object' if self.json else 'a mapping'}, got {self.kind(value)}")
        return value

    def known_keys(self, value: dict, allowed: Sequence[str], where: str, field: str | None,
                   line_of: Callable[[Any], str] | None=None) -> None:
        """Refuse a key of ``value`` outside ``allowed``, suggesting the closest; ``line_of(key)`` -> the
        ``where`` of that key (a file and line), else ``where``."""
        for key in value:
            if key not in allowed:
                close = closest(str(key), allowed)
                at = f"{field}.{key}" if field else str(key)
                self.fail(line_of(key) if line_of else where, at, "unknown key",
                          f"did you mean '{close}'?" if close else f"allowed: {', '.join(allowed)}")

    def required(self, value: dict, keys: Iterable[str], where: str, field: str) -> None:
        """Refuse ``value`` if a key of ``keys`` is missing."""
        for key in keys:
            if key not in value:
                self.fail(where, field, f"'{key}' is missing")


# --------------------------------------------------------------------------- options objects
MAX_WHOLE = 2 ** 63 - 1  # the largest whole-number option (a seed): what a C long holds


@dataclass(frozen=True)
class Bound:
    """The values one option takes: a finite number in [``lo``, ``hi``] (above ``lo`` when ``strict_lo``), a whole
    number in that range (``whole``), true or false (``flag``), one of ``choices`` (with ``many``: a tuple of
    distinct names of ``choices``, perhaps none), a text of at most ``checker.max_name`` characters (``text``) or an
    instance of the options class ``instance`` (a nested options object, checked when it was made); ``optional``:
    None too."""

    lo: float = -1e6
    hi: float = 1e6
    strict_lo: bool = False
    whole: bool = False
    flag: bool = False
    choices: tuple[str, ...] | None = None
    many: bool = False
    text: bool = False
    instance: type | None = None
    optional: bool = False

    def check(self, value: Any, checker: Checker, where: str, field: str) -> Any:
        """``value`` if it is within the bound; else ``checker``'s error naming ``where`` and ``field``."""
        if value is None and self.optional:
            return None
        if self.flag:
            if not isinstance(value, bool):
                checker.fail(where, field, f"expected true or false, got {checker.kind(value)}")
            return value
        if self.instance is not None:
            if not isinstance(value, self.instance):
                checker.fail(where, field, f"expected a {self.instance.__name__}, got {checker.kind(value)}")
            return value
        if self.text:
            return checker.name(value, where, field, empty=True)
        if self.choices is not None and self.many:
            if not isinstance(value, tuple):
                checker.fail(where, field, f"expected a tuple of names, got {checker.kind(value)}")
            for name in value:
                checker.name(name, where, field, choices=self.choices)
            if len(set(value)) != len(value):
                checker.fail(where, field, "a name is given twice")
            return value
        if self.choices is not None:
            return checker.name(value, where, field, choices=self.choices)
        if self.whole:
            if isinstance(value, bool) or not isinstance(value, int) or not self.lo <= value <= self.hi:
                span = f">= {self.lo:.0f}" if self.hi >= MAX_WHOLE else f"from {self.lo:.0f} to {self.hi:.0f}"
                checker.fail(where, field, f"expected a whole number {span}, got {checker.kind(value)}")
            return value
        return checker.number(value, where, field, lo=self.lo, hi=self.hi, strict_lo=self.strict_lo)


class _OptionChecker(Checker):
    """Field checks that raise ``OptionError`` in the options object's own words (no file, no flag)."""

    def fail(self, where: str, field: str, message: str, hint: str | None = None) -> NoReturn:
        raise OptionError(field, message, hint)


OPTION_CHECK = _OptionChecker(OptionError)


def check_options(options: Any, bounds: dict[str, Bound]) -> None:
    """Check every field of the dataclass ``options`` that ``bounds`` names; raises ``OptionError`` naming the
    first field out of its bound (NaN, inf, a wrong type, out of range). Options objects call it from
    ``__post_init__``, so none exists with a value outside its bounds."""
    for f in fields(options):
        bound = bounds.get(f.name)
        if bound is not None:
            bound.check(getattr(options, f.name), OPTION_CHECK, "", f.name)
