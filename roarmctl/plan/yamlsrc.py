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
        return self.lines.get(key, self.line)


class LocatedList(list):
    """A list that knows the source line of each item (and its own)."""

    line: int = 0
    lines: list

    def line_of(self, index: int) -> int:
        return self.lines[index] if 0 <= index < len(self.lines) else self.line


MERGE_TAG = "tag:yaml.org,2002:merge"


def _construct(node: yaml.Node, loader: yaml.SafeLoader) -> Any:
    if isinstance(node, yaml.MappingNode):
        out = LocatedDict()
        out.line, out.lines = node.start_mark.line + 1, {}
        merged: dict[Any, tuple[Any, int]] = {}
        for key_node, value_node in node.value:
            if key_node.tag == MERGE_TAG:  # YAML merge key: `<<: *anchor` or `<<: [*a, *b]`
                sources = value_node.value if isinstance(value_node, yaml.SequenceNode) else [value_node]
                for src in sources:
                    if not isinstance(src, yaml.MappingNode):
                        raise PlanFileError(f"{loader.name}:{key_node.start_mark.line + 1}: '<<' merges a mapping",
                                            "write '<<: *name' where '&name' marks a mapping")
                    sub = _construct(src, loader)
                    for k, v in sub.items():
                        merged.setdefault(k, (v, sub.line_of(k)))  # the first source wins, as YAML specifies
                continue
            key = loader.construct_object(key_node, deep=True)
            if key in out:
                raise PlanFileError(f"{loader.name}:{key_node.start_mark.line + 1}: '{key}' is given twice")
            out[key] = _construct(value_node, loader)
            out.lines[key] = key_node.start_mark.line + 1
        for k, (v, line) in merged.items():  # keys written here override merged ones
            if k not in out:
                out[k] = v
                out.lines[k] = line
        return out
    if isinstance(node, yaml.SequenceNode):
        out = LocatedList(_construct(n, loader) for n in node.value)
        out.line, out.lines = node.start_mark.line + 1, [n.start_mark.line + 1 for n in node.value]
        return out
    return loader.construct_object(node, deep=True)


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
        text = path.read_text()
    except FileNotFoundError:
        raise PlanFileError(f"{path}: no such file", "check the path") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanFileError(f"{path}: cannot read ({exc})") from None
    loader = yaml.SafeLoader(text)
    loader.name = str(path)
    try:
        node = loader.get_single_node()
        if node is None:
            raise PlanFileError(f"{path}: the file is empty")
        return _construct(node, loader)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = f":{mark.line + 1}" if mark else ""
        raise PlanFileError(f"{path}{line}: not valid YAML ({exc.problem or exc.context})") from None
    finally:
        loader.dispose()
