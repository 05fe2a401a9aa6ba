"""YAML with line numbers: every mapping and list remembers where each of its entries stood.

``load_located(path)`` returns plain Python values, where mappings are ``LocatedDict`` and lists
``LocatedList``; both carry ``line_of(key_or_index)`` (1-based) so that a schema error can name
the file, the line and the field.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from roarmctl.errors import PlanFileError


class LocatedDict(dict):
    """A dict that knows the source line of each key (and its own)."""

    line: int = 0
    lines: dict

    def line_of(self, key: Any) -> int:
        """The line of ``key``'s value (the mapping's own line if unknown)."""
        return self.lines.get(key, self.line)


class LocatedList(list):
    """A list that knows the source line of each item (and its own)."""

    line: int = 0
    lines: list

    def line_of(self, index: int) -> int:
        """The line of item ``index`` (the list's own line if out of range)."""
        return self.lines[index] if 0 <= index < len(self.lines) else self.line


MERGE_TAG = "tag:yaml.org,2002:merge"

#: Limits of what a plan file may be (docs/reference.md, "The plan file"): its size in bytes, how deep its
#: mappings and lists nest, and how many values it expands to (an alias counts again each time it is
#: used, so a "billion laughs" alias bomb or a recursive alias stops here, not in memory).
MAX_BYTES = 1024 * 1024
MAX_DEPTH = 32
MAX_NODES = 100_000


class _Budget:
    def __init__(self) -> None:
        self.nodes = 0


def _construct(node: yaml.Node, loader: yaml.SafeLoader, budget: _Budget | None = None, depth: int = 0) -> Any:
    budget = budget or _Budget()
    budget.nodes += 1
    line = node.start_mark.line + 1
    if budget.nodes > MAX_NODES:
        raise PlanFileError(f"{loader.name}:{line}: the plan expands to more than {MAX_NODES} values",
                            "aliases (*name) are expanded each time they are used; write the plan out plainly")
    if depth > MAX_DEPTH:
        raise PlanFileError(f"{loader.name}:{line}: nested more than {MAX_DEPTH} levels deep (or an alias that contains itself)")
    if isinstance(node, yaml.MappingNode):
        out = LocatedDict()
        out.line, out.lines = line, {}
        merged: dict[Any, tuple[Any, int]] = {}
        for key_node, value_node in node.value:
            if key_node.tag == MERGE_TAG:  # YAML merge key: `<<: *anchor` or `<<: [*a, *b]`
                sources = value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
                for src in sources:
                    if not isinstance(src, yaml.MappingNode):
                        raise PlanFileError(f"{loader.name}:{key_node.start_mark.line + 1}: '<<' merges a mapping",
                                            "write '<<: *name' where '&name' marks a mapping")
                    sub = _construct(src, loader, budget, depth + 1)
                    for k, v in sub.items():
                        merged.setdefault(k, (v, sub.line_of(k)))  # the first source wins, as YAML specifies
                continue
            if not isinstance(key_node, yaml.ScalarNode):
                raise PlanFileError(f"{loader.name}:{key_node.start_mark.line + 1}: a key must be a plain name, not a "
                                    f"{'list' if isinstance(key_node, yaml.SequenceNode) else 'mapping'}")
            key = _scalar(key_node, loader)
            if key in out:
                raise PlanFileError(f"{loader.name}:{key_node.start_mark.line + 1}: '{key}' is given twice")
            out[key] = _construct(value_node, loader, budget, depth + 1)
            out.lines[key] = key_node.start_mark.line + 1
        for k, (v, line) in merged.items():  # keys written here override merged ones
            if k not in out:
                out[k] = v
                out.lines[k] = line
        return out
    if isinstance(node, yaml.SequenceNode):
        out = LocatedList(_construct(n, loader, budget, depth + 1) for n in node.value)
        out.line, out.lines = line, [n.start_mark.line + 1 for n in node.value]
        return out
    return _scalar(node, loader)


def _scalar(node: yaml.Node, loader: yaml.SafeLoader) -> Any:
    """One scalar; a tag whose text does not fit (``!!float abc``, ``!!int x``) is a PlanFileError."""
    try:
        value = loader.construct_object(node, deep=True)
    except yaml.MarkedYAMLError:
        raise
    except (ValueError, TypeError, OverflowError) as exc:
        raise PlanFileError(f"{loader.name}:{node.start_mark.line + 1}: '{str(node.value)[:40]}' does not fit its "
                            f"tag {node.tag} ({exc})") from None
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 2 ** 53:
        raise PlanFileError(f"{loader.name}:{node.start_mark.line + 1}: the number {str(node.value)[:24]} is too large")
    return value


def locate(value: Any) -> Any:
    """Plain Python values (from a dict built in code) -> located containers with line 0 everywhere."""
    if isinstance(value, dict):
        out = LocatedDict((k, locate(v)) for k, v in value.items())
        out.line, out.lines = 0, {}
        return out
    if isinstance(value, (list, tuple)):
        out = LocatedList(locate(v) for v in value)
        out.line, out.lines = 0, []
        return out
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return locate(value.tolist())
    return value


def load_located(path: str | Path) -> Any:
    """Parse a YAML file into located containers; syntax errors become PlanFileError with the line."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise PlanFileError(f"{path}: larger than {MAX_BYTES // 1024} KiB; that is not a plan file",
                                "split it into several plans")
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise PlanFileError(f"{path}: no such file", "check the path") from None
    except UnicodeDecodeError as exc:
        line = path.read_bytes()[: exc.start].count(b"\n") + 1
        raise PlanFileError(f"{path}:{line}: not UTF-8 text (byte {exc.start})", "save the file as UTF-8") from None
    except OSError as exc:
        raise PlanFileError(f"{path}: cannot read ({exc.strerror or exc})") from None
    loader = None
    try:
        loader = yaml.SafeLoader(text)  # the reader checks the characters here
        loader.name = str(path)
        node = loader.get_single_node()
        if node is None:
            raise PlanFileError(f"{path}: the file is empty")
        return _construct(node, loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f":{mark.line + 1}" if mark else ""
        raise PlanFileError(f"{path}{line}: not valid YAML ({exc.problem or exc.context})") from None
    except yaml.YAMLError as exc:  # the reader's errors (control characters) carry a position, not a mark
        pos = getattr(exc, "position", None)
        line = f":{text[:pos].count(chr(10)) + 1}" if isinstance(pos, int) else ""
        reason = getattr(exc, "reason", None) or str(exc).splitlines()[0]
        raise PlanFileError(f"{path}{line}: not valid YAML ({reason})", "remove control characters") from None
    except RecursionError:
        raise PlanFileError(f"{path}: nested too deeply", f"at most {MAX_DEPTH} levels") from None
    finally:
        if loader is not None:
            loader.dispose()
