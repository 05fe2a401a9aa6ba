"""xacro as data: what a description's ``${...}`` and ``$(...)`` may do, enforced where xacro evaluates them.

The installed ``xacro`` (2.1.1) evaluates ``${expr}`` with Python's ``eval`` behind a filter on names
that start with ``__``; a lambda or a comprehension slips past it and runs any code. roarmctl
therefore never lets xacro's ``eval`` see an expression: ``hooks(...)`` replaces, for the time of one
expansion, the functions of the ``xacro`` module where it evaluates and reads:

* ``safe_eval`` (every ``${...}``) -> ``xacro_eval.Evaluator``: an interpreter of an ALLOW-LIST of Python's
  syntax tree, the part xacro documents for properties and math: numbers, strings, ``True``/``False``,
  arithmetic (``+ - * / // % **``), comparisons, ``and``/``or``/``not``, ``a if c else b``, property
  names, lists/tuples/dicts written out, indexing, the math functions and constants xacro exposes
  (``sin``, ``radians``, ``pi``, also as ``math.sin``), ``abs min max round int float str bool len``, ``dict`` (with keyword arguments too),
  ``xacro.arg(name)`` and ``xacro.load_yaml(file)`` / ``load_yaml(file)`` (a YAML file inside the
  roots, read by ``roarmctl.validation``). Anything else (attribute access, lambda, comprehension,
  f-string, a name starting with ``_``, a call of anything not listed) is refused by name.
* ``eval_extension`` (every ``$(...)``) -> ``$(arg NAME)``, ``$(find PKG)`` (a declared package
  folder), ``$(dirname)``, ``$(eval EXPR)`` (by ``Evaluator``); ``$(optenv VAR default)`` is its
  default (the environment is not read); ``$(env VAR)`` and ``$(cwd)`` are refused.
* ``parse`` (the top file and every ``<xacro:include>``) and the include glob (``xacro_glob``): files
  inside the roots, regular, under ``MAX_FILE_BYTES`` (``roarmctl.fileio.read_bytes``).
* ``eval_all`` (every element): counted against the ``Budget``, like every expression, every step of
  an expression and every character produced, so an exponent bomb (``${9**9**9}``), a macro that
  doubles itself or a property that doubles a string stop with exit 2 after a fixed amount of WORK
  (the same verdict on any machine), long before a second has passed. Every value an operation makes
  is bounded as it is made (``xacro_eval.Evaluator._made``: its printed size too, however its parts are shared),
  and what an operation reads counts (``_operand``), so comparing or printing large values is work.
* ``QuickLexer`` and ``parse_macro_arg``: xacro's lexer is quadratic and its macro-parameter pattern
  exponential on an unclosed quote; ``_Lexer`` and ``MACRO_ARG`` do the same in linear time.

``trusted=True`` (``--trust-xacro``, or ``trust: true`` in a sidecar the user named) leaves
expressions and ``$(...)`` to xacro itself: only for files whose author you trust.
"""

from __future__ import annotations

import math
import os
import re
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from roarmctl.errors import DescriptionError
from roarmctl.fileio import UNKNOWN_PACKAGE, Roots, note_read, read_text
from roarmctl.robot.xacro_eval import Budget, Evaluator, Refused, no_properties
from roarmctl.robot.xacro_glob import include_glob

MAX_INCLUDE_DEPTH = 40  # includes within includes (a file including itself stops here)
MAX_FILE_BYTES = 8 * 1024 * 1024  # one xacro file or included file
#: Characters of a macro's ``params`` (xacro parses them one by one, copying the rest each time).
MAX_PARAMS_CHARS = 16 * 1024
#: xacro's pattern of one macro parameter (``name:=default``, ``^|`` forwarding) without its nested
#: quantifier: xacro's ``(?:'.*?'|".*?"|[^\s'"]+)+`` backtracks exponentially on an unclosed quote
#: (``params="x:=aaaa...a'"``: 2 s at 24 letters, doubling with each). Here each character of a default
#: has one way to match; a well-formed default matches as xacro's does.
MACRO_ARG = re.compile(r"^\s*([^\s:=]+?)\s*:?=\s*(\^\|?)?("
                       r"""\$\{[^}\n]*\}|\$\([^)\n]*\)|(?:'[^'\n]*'|"[^"\n]*"|[^\s'"])+|"""
                       r")(?:\s+|$)(.*)")

#: xacro's YAML unit tags (``xacro.ConstructUnits``): the scalar is an expression, times the factor.
YAML_UNITS = {"!radians": 1.0, "!degrees": math.pi / 180.0, "!meters": 1.0, "!millimeters": 0.001, "!foot": 0.3048,
              "!inches": 0.0254}


_LOCK = threading.RLock()


class _Lexer:
    """xacro's ``QuickLexer`` (the tokens of a text with ``${...}`` and ``$(...)``) in linear time: xacro's
    copies the rest of the text after each token, so an attribute of a million ``$a`` takes hours. Same
    token patterns (xacro's ``LEXER``, matched at a position instead of at the start of a copy), same tokens."""

    def __init__(self, other: Any) -> None:
        self.__dict__.update({k: v for k, v in other.__dict__.items() if k.isupper()})  # the token ids
        self.res = [re.compile(r.pattern[1:] if r.pattern.startswith("^") else r.pattern) for r in other.res]
        self.text, self.pos = "", 0
        self.top: tuple[int, str] | None = None

    def lex(self, text: str) -> None:
        """Start on ``text``."""
        self.text, self.pos, self.top = text, 0, None
        self.next()

    def peek(self) -> Any:
        """The current token (id, text), None at the end."""
        return self.top

    def next(self) -> Any:
        """The current token; moves on to the next."""
        import xacro

        result, self.top = self.top, None
        if self.pos >= len(self.text):
            return result
        for i, rx in enumerate(self.res):
            m = rx.match(self.text, self.pos)
            if m:
                self.top, self.pos = (i, m.group(0)), m.end()
                return result
        raise xacro.XacroException("invalid expression: " + self.text[self.pos:self.pos + 80])


def _xacro_lookup(symbols: Any, name: str) -> Any:
    """A property of xacro's symbol ``Table`` chain (never xacro's global symbols: Python builtins)."""
    import xacro

    t = symbols
    while isinstance(t, xacro.Table):
        if dict.__contains__(t, name):
            return t._resolve_(name)
        t = t.parent
    raise KeyError(name)


@contextmanager
def hooks(roots: Roots, where: str, trusted: bool = False) -> Iterator[Budget]:
    """Within this block the ``xacro`` module evaluates and reads only as described above (see the
    module docstring); yields the ``Budget`` of the expansion. One expansion at a time (a lock)."""
    import xacro
    from xacro import substitution_args

    budget = Budget()
    originals = {name: getattr(xacro, name) for name in ("safe_eval", "eval_extension", "parse", "eval_all", "glob",
                                                          "replace_node", "QuickLexer", "parse_macro_arg",
                                                          "abs_filename_spec")}
    orig_parse, orig_eval_all, orig_replace = originals["parse"], originals["eval_all"], originals["replace_node"]
    orig_find = substitution_args._eval_find
    orig_macro_arg = originals["parse_macro_arg"]

    class Lexer(_Lexer):
        def next(self) -> Any:
            budget.spend("tokens")
            return super().next()

    def parse_macro_arg(text: str) -> Any:
        if len(text) > MAX_PARAMS_CHARS:
            raise Refused(f"macro params of more than {MAX_PARAMS_CHARS:,} characters")
        budget.spend("steps")
        saved, xacro.re_macro_arg = xacro.re_macro_arg, MACRO_ARG
        try:
            return orig_macro_arg(text)
        finally:
            xacro.re_macro_arg = saved

    def find(pkg: str) -> str:
        folder = roots.packages.get(pkg)
        if folder is not None:
            return str(folder)
        if trusted:
            try:
                return orig_find(pkg)  # ROS's package index, when ROS is installed
            except (ImportError, LookupError):
                pass
        return f"{UNKNOWN_PACKAGE}/{pkg}"  # fails when something under it is read (Roots.check), not before

    def parse(inp: Any, filename: str | None = None) -> Any:
        from roarmctl.validation import check_markup  # PyYAML: not at start-up

        if inp is None:  # the top file, then each include
            budget.spend("includes")
            if len(xacro.filestack or ()) > MAX_INCLUDE_DEPTH:
                raise Refused(f"includes nested more than {MAX_INCLUDE_DEPTH} deep (a file that includes itself?)")
            what = f"{where}: xacro include" if budget.used["includes"] > 1 else None
            inp = read_text(os.path.join(xacro.root_dir, filename or ""), what, MAX_FILE_BYTES, roots=roots,
                            error=DescriptionError)
            check_markup(inp, str(filename), DescriptionError)  # before minidom builds its tree
        return orig_parse(inp, filename)

    def eval_all(node: Any, macros: Any, symbols: Any) -> Any:
        budget.spend("elements")
        attrs = getattr(node, "attributes", None)
        size = sum(len(v) for _, v in attrs.items()) if attrs else 0
        size += sum(len(c.data) for c in node.childNodes if c.nodeType == c.TEXT_NODE)
        budget.spend("characters", size)
        return orig_eval_all(node, macros, symbols)

    def replace_node(node: Any, by: Any, content_only: bool = False) -> Any:
        parent = node.parentNode
        siblings = len(parent.childNodes) if parent is not None else 1
        moved = 1
        for doc in (by if isinstance(by, list) else [by] if by is not None else []):
            moved += len(doc.childNodes) if content_only else 1
        budget.spend("node moves", siblings * moved)
        return orig_replace(node, by, content_only)

    class _Glob:
        @staticmethod
        def glob(pattern: str, *args: Any, **kwargs: Any) -> list[str]:
            return include_glob(pattern, roots, f"{where}: xacro include '{pattern}'")

    def load_yaml(filename: Any) -> Any:
        from roarmctl.validation import load_yaml as load

        if not isinstance(filename, str):
            raise Refused("load_yaml() takes a file name")
        path = xacro.abs_filename_spec(filename)

        def unit(factor: float) -> Callable[[str], float]:
            return lambda text: float(Evaluator(no_properties, budget)(text)) * factor

        tags = {tag: unit(factor) for tag, factor in YAML_UNITS.items()}
        return load(path, DescriptionError, what=f"{where}: xacro load_yaml", roots=roots, empty_ok=True, tags=tags,
                    last_key_wins=True)

    def abs_filename_spec(spec: Any) -> Any:
        """xacro's own, noting the file (``fileio.note_read``): trusted, xacro's ``load_yaml`` opens it itself, and
        the robot loaded depends on it."""
        path = originals["abs_filename_spec"](spec)
        try:
            note_read(path, os.stat(path))
        except (OSError, TypeError, ValueError):
            pass  # not a file (yet): xacro says so if it reads it
        return path

    def arg(name: Any) -> Any:
        try:
            return xacro.substitution_args_context["arg"][name]
        except (KeyError, TypeError):
            raise Refused(f"xacro.arg({name!r}): no such argument (give it in the sidecar's xacro_args)") from None

    def namespace(value: Any, attr: str) -> Any:
        if isinstance(value, xacro.Table):
            return _xacro_lookup(value, attr)
        if isinstance(value, dict) and attr in value:
            return value[attr]
        raise KeyError(attr)

    def safe_eval(expr: str, globals: Any, locals: Any = None) -> Any:
        return Evaluator(lambda n: _xacro_lookup(globals, n), budget, load_yaml=load_yaml, arg=arg,
                         namespace=namespace)(expr)

    def eval_extension(s: str) -> Any:
        budget.spend("expressions")
        inner = s[2:-1].strip()
        command, _, rest = inner.partition(" ")
        words = rest.split()
        if command == "arg" and len(words) == 1:
            try:
                return xacro.substitution_args_context["arg"][words[0]]
            except KeyError:
                raise Refused(f"$(arg {words[0]}): no such argument (give it in the sidecar's xacro_args, or "
                              "declare it with <xacro:arg name=... default=...>)") from None
        if command == "find" and len(words) == 1:
            return find(words[0])
        if command == "dirname" and not words:
            return os.path.abspath(os.path.dirname(xacro.filestack[-1] or "."))
        if command == "optenv" and words:
            return " ".join(words[1:])  # the environment is not read: the default, as in a clean one
        if command == "eval" and rest.strip():
            args = xacro.substitution_args_context.get("arg", {})

            def lookup(name: str) -> Any:
                return substitution_args.convert_value(args[name], "auto")

            return str(Evaluator(lookup, budget)(rest))
        if command in ("env", "optenv", "cwd"):
            raise Refused(f"$({inner[:40]}) is not allowed: a description does not read the environment or the "
                          "current folder (pass values with xacro_args in the sidecar)")
        raise Refused(f"$({inner[:40]}) is not allowed (only $(arg NAME), $(find PKG), $(dirname), $(eval EXPR))")

    with _LOCK:
        try:
            xacro.parse, xacro.eval_all, xacro.glob, xacro.replace_node = parse, eval_all, _Glob, replace_node
            xacro.QuickLexer, xacro.parse_macro_arg = Lexer, parse_macro_arg
            substitution_args._eval_find = find
            if not trusted:
                xacro.safe_eval, xacro.eval_extension = safe_eval, eval_extension
            else:
                xacro.abs_filename_spec = abs_filename_spec
            yield budget
        finally:
            for name, value in originals.items():
                setattr(xacro, name, value)
            substitution_args._eval_find = orig_find


def find_refusal(exc: BaseException | None) -> BaseException | None:
    """The ``Refused`` or ``DescriptionError`` inside the exceptions xacro wraps around it, if any."""
    seen = 0
    while exc is not None and seen < 50:
        if isinstance(exc, (Refused, DescriptionError)):
            return exc
        exc = getattr(exc, "exc", None) or exc.__cause__ or exc.__context__
        seen += 1
    return None
