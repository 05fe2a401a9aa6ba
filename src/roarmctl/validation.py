"""Documents: the ONE place where an input's text becomes values, bounded.

Every reader (plans, trajectories, execution logs, robot descriptions, SRDF, joint_limits.yaml,
xacro's ``load_yaml``) parses through here and checks its fields with these helpers, so each input
is bounded the same way (size, nesting, number of values, digits of a number, UTF-8, finite values)
and every refusal is an ``InputError`` subclass (exit 2) naming the file, the line or field, and the
fix. The bytes come from ``roarmctl.fileio.read_bytes`` (regular files under a size cap, inside the
roots where the caller gives them).

* ``load_yaml(path, error)``: YAML with line numbers: mappings are ``LocatedDict``, lists
  ``LocatedList``; both carry ``line_of(key_or_index)`` (1-based).
* ``load_json(path, error)``: JSON; NaN/Infinity, numbers beyond a float and integers of more than
  ``MAX_DIGITS`` digits refused.
* their fields are checked by ``roarmctl.checks`` (``Checker``, ``Bound``, ``check_options``).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.parser import Parser
from yaml.reader import Reader
from yaml.resolver import Resolver
from yaml.scanner import Scanner

from roarmctl.checks import HugeNumber
from roarmctl.errors import InputError, PlanFileError
from roarmctl.fileio import Roots, read_bytes


# --------------------------------------------------------------------------- located values
class LocatedDict(dict):
    """A dict that knows the source line of each key (and its own)."""

    __slots__ = ("line", "lines")  # set by whoever makes one (no per-instance __dict__: a big scene has thousands)
    line: int
    lines: dict

    def line_of(self, key: Any) -> int:
        """1-based line of ``key`` (the mapping's own line for a key it lacks)."""
        return self.lines.get(key, self.line)


class LocatedList(list):
    """A list that knows the source line of each item (and its own)."""

    __slots__ = ("line", "lines")
    line: int
    lines: list

    def line_of(self, index: int) -> int:
        """1-based line of item ``index`` (the list's own line out of range)."""
        return self.lines[index] if 0 <= index < len(self.lines) else self.line


_PLAIN = frozenset((int, float, str, bool, type(None)))  # values locate leaves as they are


def locate(value: Any) -> Any:
    """Plain Python values (from a dict built in code) -> located containers with line 0 everywhere."""
    if isinstance(value, dict):
        out = LocatedDict(value)
        for k, v in value.items():
            if type(v) not in _PLAIN:
                out[k] = locate(v)
        out.line, out.lines = 0, {}
        return out
    if isinstance(value, (list, tuple)):
        if set(map(type, value)) <= _PLAIN:  # a list of numbers (most of a plan): as it is
            lst = LocatedList(value)
        else:
            lst = LocatedList(v if type(v) in _PLAIN else locate(v) for v in value)
        lst.line, lst.lines = 0, []
        return lst
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return locate(value.tolist())
    return value


# --------------------------------------------------------------------------- YAML
MERGE_TAG = "tag:yaml.org,2002:merge"
MAP_TAG = "tag:yaml.org,2002:map"
SEQ_TAG = "tag:yaml.org,2002:seq"

#: Limits of a YAML input (docs/reference.md; plan, sidecar, joint_limits.yaml, a file xacro loads): its size in bytes,
#: how deep its mappings and lists nest, and how many values it expands to (an alias counts again each
#: time it is used, so a "billion laughs" alias bomb or a recursive alias stops here, not in memory).
MAX_BYTES = 1024 * 1024
MAX_DEPTH = 32
MAX_NODES = 100_000
#: Integers larger than this are refused (a float carries 53 bits; a bigger integer is a mistake).
MAX_INT = 2 ** 53
#: Digits of an integer a JSON file may write (Python refuses beyond 4300 with a ValueError).
MAX_DIGITS = 30


class _Budget:
    def __init__(self, tags: dict[str, Callable[[str], Any]] | None = None, last_key_wins: bool = False) -> None:
        self.nodes = 0
        self.tags = tags or {}
        self.last_key_wins = last_key_wins


def _short_tag(tag: str) -> str:
    """``tag:yaml.org,2002:set`` -> ``!!set``, cut to 60 characters."""
    return tag.replace("tag:yaml.org,2002:", "!!")[:60]


def _refuse_size(node: yaml.Node, loader: yaml.SafeLoader, error: type[InputError], budget: _Budget) -> NoReturn:
    line = node.start_mark.line + 1
    if budget.nodes > MAX_NODES:
        raise error(f"{loader.name}:{line}: the file expands to more than {MAX_NODES} values",
                    "aliases (*name) are expanded each time they are used; write it out plainly")
    raise error(f"{loader.name}:{line}: nested more than {MAX_DEPTH} levels deep (or an alias that contains itself)")


def _construct(node: yaml.Node, loader: yaml.SafeLoader, error: type[InputError], budget: _Budget,
               depth: int = 0) -> Any:
    budget.nodes += 1
    if budget.nodes > MAX_NODES or depth > MAX_DEPTH:
        _refuse_size(node, loader, error, budget)
    kind = type(node)  # the composers make these three classes exactly
    if kind is yaml.ScalarNode:  # most nodes: first, and without the containers' bookkeeping
        if node.tag in budget.tags:
            try:
                return budget.tags[node.tag](str(node.value))
            except InputError:
                raise
            except Exception as exc:  # noqa: BLE001 - the tag's reader says what was wrong
                raise error(f"{loader.name}:{node.start_mark.line + 1}: {node.tag} {str(node.value)[:40]!r}: "
                            f"{exc}") from None
        return _scalar(node, loader, error)
    line = node.start_mark.line + 1
    if kind is yaml.MappingNode:
        if node.tag != MAP_TAG:
            raise error(f"{loader.name}:{line}: the tag {_short_tag(node.tag)} is not allowed", "remove the tag")
        out = LocatedDict()
        out.line, out.lines = line, {}
        merged: dict[Any, tuple[Any, int]] = {}
        for key_node, value_node in node.value:
            if key_node.tag == MERGE_TAG:  # YAML merge key: `<<: *anchor` or `<<: [*a, *b]`
                sources = value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
                for src in sources:
                    if not isinstance(src, yaml.MappingNode):
                        raise error(f"{loader.name}:{key_node.start_mark.line + 1}: '<<' merges a mapping",
                                    "write '<<: *name' where '&name' marks a mapping")
                    sub = _construct(src, loader, error, budget, depth + 1)
                    for k, v in sub.items():
                        merged.setdefault(k, (v, sub.line_of(k)))  # the first source wins, as YAML specifies
                continue
            if not isinstance(key_node, yaml.ScalarNode):
                raise error(f"{loader.name}:{key_node.start_mark.line + 1}: a key must be a plain name, not a "
                            f"{'list' if isinstance(key_node, yaml.SequenceNode) else 'mapping'}")
            key = _scalar(key_node, loader, error)
            if key in out and not budget.last_key_wins:
                raise error(f"{loader.name}:{key_node.start_mark.line + 1}: '{key}' is given twice")
            out[key] = _construct(value_node, loader, error, budget, depth + 1)
            out.lines[key] = key_node.start_mark.line + 1
        for k, (v, kline) in merged.items():  # keys written here override merged ones
            if k not in out:
                out[k] = v
                out.lines[k] = kline
        return out
    if node.tag != SEQ_TAG:
        raise error(f"{loader.name}:{line}: the tag {_short_tag(node.tag)} is not allowed", "remove the tag")
    items = node.value
    lst = LocatedList([_construct(n, loader, error, budget, depth + 1) for n in items])
    lst.line, lst.lines = line, [n.start_mark.line + 1 for n in items]
    return lst


def _fast_float(loader: yaml.SafeLoader, node: yaml.ScalarNode) -> Any:
    """``!!float``: Python's ``float`` for the plain decimal forms (most of a plan's numbers), PyYAML's own
    constructor for the rest (``_`` separators, ``1:30`` sexagesimal, ``.inf``, ``.nan``): the same values either way,
    since the resolver only tags as float what YAML 1.1's float pattern matches."""
    text = node.value
    if "_" not in text and ":" not in text:
        try:
            return float(text)
        except ValueError:  # .inf, .nan and their signed forms
            pass
    return SafeConstructor.construct_yaml_float(loader, node)


#: Scalar tags built without PyYAML's generic ``construct_object`` (its bookkeeping of recursive objects is for
#: mappings and lists, which ``_construct`` builds itself): tag -> function of (loader, node).
_SCALAR_BUILDERS: dict[str, Callable[[Any, Any], Any]] = {
    "tag:yaml.org,2002:str": lambda loader, node: node.value,
    "tag:yaml.org,2002:float": _fast_float,
    "tag:yaml.org,2002:int": SafeConstructor.construct_yaml_int,
    "tag:yaml.org,2002:bool": SafeConstructor.construct_yaml_bool,
    "tag:yaml.org,2002:null": SafeConstructor.construct_yaml_null,
}


def _scalar(node: yaml.Node, loader: yaml.SafeLoader, error: type[InputError]) -> Any:
    """One scalar; a tag whose text does not fit (``!!float abc``, ``!!int x``) is refused."""
    try:
        build = _SCALAR_BUILDERS.get(node.tag)
        value = build(loader, node) if build is not None else loader.construct_object(node, deep=True)
    except yaml.MarkedYAMLError:
        raise
    except (ValueError, TypeError, OverflowError) as exc:
        raise error(f"{loader.name}:{node.start_mark.line + 1}: '{str(node.value)[:40]}' does not fit its "
                    f"tag {node.tag} ({exc})") from None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_INT:
        raise error(f"{loader.name}:{node.start_mark.line + 1}: the number {str(node.value)[:24]} is too large")
    return value


#: The characters ``_flow_depth_line`` looks at; the text between them is skipped at C speed.
_FLOW_MARKS = re.compile(r"[\[\]{}\n'\"#]")


def _flow_depth_line(text: str) -> int:
    """The line (1-based) where ``[``/``{`` brackets first nest deeper than ``MAX_DEPTH``, 0 if never.

    PyYAML's scanner takes time quadratic in the flow nesting (5,000 levels: seconds), so this linear
    scan refuses such a file first. Quoted strings and comments are skipped; a bracket inside a plain
    scalar counts, which can only make the scan stricter than the parser."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:  # fewer openers than the limit cannot nest past it
        return 0
    depth, line, quote, comment = 0, 1, "", False
    for mark in _FLOW_MARKS.finditer(text):
        c = mark.group()
        if c == "\n":  # a quote or comment ends at the line's end here (stricter than YAML, never laxer)
            line, comment, quote = line + 1, False, ""
        elif comment:
            pass
        elif quote:
            if c == quote:
                quote = ""
        elif c in "'\"":
            quote = c
        elif c == "#":
            at = mark.start()
            comment = at == 0 or text[at - 1] in " \t\n"
        elif c in "[{":
            depth += 1
            if depth > MAX_DEPTH:
                return line
        else:
            depth = max(depth - 1, 0)
    return 0


#: The YAML 1.1 scalar types a document may hold (``!!str``, ``!!int``, ...); mappings and lists are built by
#: ``_construct``. Any other tag (``!!python/...``, a local ``!tag`` the reader did not ask for) is refused.
SCALAR_TAGS = ("null", "bool", "int", "float", "binary", "timestamp", "str")
_IMPLICIT_TAGS = {f"tag:yaml.org,2002:{t}" for t in ("null", "bool", "int", "float", "timestamp", "merge", "value")}


def _private_loader() -> type:
    """A loader class of our own: PyYAML's safe parser (libyaml's C one where PyYAML was built with it, about
    10x faster, else its Python one) with constructor and resolver tables COPIED at import and never shared.

    PyYAML keeps these tables on classes: whoever calls ``SafeLoader.add_constructor`` (xacro's
    ``load_yaml`` does, for ``!degrees``, with a constructor that runs xacro's ``eval``) or
    ``add_implicit_resolver`` changes every document read through ``SafeLoader``/``CSafeLoader`` in the
    process. Our class lists the safe scalar constructors by name and keeps only the standard implicit
    resolvers, so no registration elsewhere reaches a plan, and nothing we do reaches anyone else."""
    c_parser: Any = getattr(yaml, "__with_libyaml__", False) and importlib.import_module("yaml.cyaml").CParser
    parsers: tuple[type, ...] = (c_parser,) if c_parser else (Reader, Scanner, Parser, Composer)

    def __init__(self: Any, stream: str) -> None:
        if c_parser:
            c_parser.__init__(self, stream)
        else:
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)
            Composer.__init__(self)
        SafeConstructor.__init__(self)
        Resolver.__init__(self)

    constructors: dict[Any, Any] = {f"tag:yaml.org,2002:{t}": getattr(SafeConstructor, f"construct_yaml_{t}")
                                    for t in SCALAR_TAGS}
    constructors[None] = SafeConstructor.construct_undefined
    resolvers = {first: [(tag, rx) for tag, rx in pairs if tag in _IMPLICIT_TAGS]
                 for first, pairs in Resolver.yaml_implicit_resolvers.items()}
    # The tag of every scalar is asked of the resolver; with no path resolvers (our table has none) PyYAML's
    # ``resolve`` and its per-node ``descend_resolver``/``ascend_resolver`` bookkeeping reduce to this: the first
    # implicit pattern for the scalar's first character that matches a plain scalar, else the kind's default tag.
    def resolve(self: Any, kind: type, value: str, implicit: tuple[bool, bool]) -> str:
        if kind is yaml.ScalarNode:
            if implicit[0]:
                for tag, regexp in resolvers.get(value[:1], ()):
                    if regexp.match(value):
                        return tag
            return str(Resolver.DEFAULT_SCALAR_TAG)
        return str(Resolver.DEFAULT_SEQUENCE_TAG if kind is yaml.SequenceNode else Resolver.DEFAULT_MAPPING_TAG)

    def no_path(self: Any, *args: Any) -> None:
        return None

    return type("RoarmctlYAMLLoader", (*parsers, SafeConstructor, Resolver), {
        "__init__": __init__, "yaml_constructors": constructors, "yaml_multi_constructors": {},
        "yaml_implicit_resolvers": resolvers, "yaml_path_resolvers": {}, "resolve": resolve,
        "descend_resolver": no_path, "ascend_resolver": no_path})


#: The loader every YAML input is parsed with (see ``_private_loader``).
SAFE_LOADER = _private_loader()


def parse_yaml(text: str, name: str, error: type[InputError] = PlanFileError,
               tags: dict[str, Callable[[str], Any]] | None = None, last_key_wins: bool = False) -> Any:
    """YAML ``text`` (from file ``name``) -> located values within the limits; None for an empty document.

    ``tags``: readers of local tags (``"!degrees"`` -> a function of the scalar's text), for the YAML
    files xacro loads. A key given twice in one mapping is refused, unless ``last_key_wins`` (the later
    value, as PyYAML reads it: for the YAML files xacro loads, where real xacro's reading is the reference;
    Franka's published ``inertials.yaml`` repeats a key)."""
    deep = _flow_depth_line(text)
    if deep:
        raise error(f"{name}:{deep}: nested more than {MAX_DEPTH} levels deep")
    loader = None
    try:
        loader = SAFE_LOADER(text)  # the reader checks the characters here
        loader.name = name
        node = loader.get_single_node()
        if node is None:
            return None
        return _construct(node, loader, error, _Budget(tags, last_key_wins))
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f":{mark.line + 1}" if mark else ""
        raise error(f"{name}{line}: not valid YAML ({exc.problem or exc.context})") from None
    except yaml.YAMLError as exc:  # the reader's errors (control characters) carry a position, not a mark
        pos = getattr(exc, "position", None)
        line = f":{text[:pos].count(chr(10)) + 1}" if isinstance(pos, int) else ""
        reason = getattr(exc, "reason", None) or str(exc).splitlines()[0]
        raise error(f"{name}{line}: not valid YAML ({reason})", "remove control characters") from None
    except RecursionError:
        raise error(f"{name}: nested too deeply", f"at most {MAX_DEPTH} levels") from None
    finally:
        if loader is not None:
            loader.dispose()


def load_yaml(path: str | Path, error: type[InputError] = PlanFileError, *, what: str | None = None,
              limit: int = MAX_BYTES, roots: Roots | None = None, empty_ok: bool = False,
              tags: dict[str, Callable[[str], Any]] | None = None, digest: bool = False,
              last_key_wins: bool = False) -> Any:
    """A YAML file -> located values (see ``parse_yaml``), read by ``fileio.read_bytes``.

    ``what``: the field that names the file (None for a file named on the command line); ``roots``:
    where the file may lie. An empty file is refused unless ``empty_ok`` (then None). With ``digest``:
    (values, sha256 hex of the bytes parsed), the file read once. ``last_key_wins``: see ``parse_yaml``.
    """
    path = Path(path)
    data = read_bytes(path, what, limit, roots=roots, error=error)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(f"{path}:{line}: not UTF-8 text (byte {exc.start})", "save the file as UTF-8") from None
    value = parse_yaml(text, str(path), error, tags, last_key_wins)
    if value is None and not empty_ok:
        raise error(f"{path}: the file is empty")
    if digest:
        return value, hashlib.sha256(data).hexdigest()
    return value


# --------------------------------------------------------------------------- XML
#: Elements (counted by their ``<``) an XML description file (URDF, SRDF, xacro) may hold, checked before it is
#: parsed: a parser's tree costs about 200 bytes an element (a 16 MiB file of ``<a/>``: 4 million, 425 MB).
#: The largest published file of the corpus has 519.
MAX_MARKUP_TAGS = 100_000


def check_markup(text: str, name: str, error: type[InputError]) -> str:
    """``text`` if it holds at most ``MAX_MARKUP_TAGS`` elements (comments count), else ``error`` naming ``name``."""
    if text.count("<") > MAX_MARKUP_TAGS:
        raise error(f"{name}: more than {MAX_MARKUP_TAGS:,} XML elements", "is this the right file?")
    return text


# --------------------------------------------------------------------------- JSON
class _Refused(ValueError):
    pass


def _parse_int(text: str) -> int | HugeNumber:
    if len(text.lstrip("-")) > MAX_DIGITS:
        return HugeNumber(text)
    return int(text)


def _parse_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise _Refused(f"the number {text[:24]} is beyond the range of a float")
    return x


def _parse_constant(name: str) -> float:
    raise _Refused(f"'{name}' is not a number JSON allows")


def parse_json(text: str, name: str, error: type[InputError] = InputError, hint: str | None = None) -> Any:
    """JSON ``text`` (from file ``name``) -> Python values. NaN, Infinity and a number beyond a float are
    refused, as is nesting beyond the parser's stack; an integer of more than ``MAX_DIGITS`` digits
    becomes a ``HugeNumber`` that the field's check refuses by name."""
    try:
        return json.loads(text, parse_int=_parse_int, parse_float=_parse_float, parse_constant=_parse_constant)
    except json.JSONDecodeError as exc:
        raise error(f"{name}:{exc.lineno}: not valid JSON ({exc.msg})", hint) from None
    except RecursionError:
        raise error(f"{name}: nested too deeply", hint) from None
    except _Refused as exc:
        raise error(f"{name}: {exc}", "every value must be a finite number of ordinary size") from None


def load_json(path: str | Path, error: type[InputError] = InputError, *, what: str | None = None, limit: int,
              hint: str | None = None) -> Any:
    """A JSON file (``read_bytes`` within ``limit`` bytes, UTF-8) -> Python values (see ``parse_json``)."""
    path = Path(path)
    data = read_bytes(path, what, limit, error=error)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise error(f"{path}:{line}: not UTF-8 text (byte {exc.start})", hint) from None
    return parse_json(text, str(path), error, hint)
