"""The package's imports point down the layers written in docs/design.md, and no modules import each other in a circle.

Every import statement of roarmctl is read with ``ast`` (module level, inside functions, under ``TYPE_CHECKING``);
each one that names a roarmctl module is an edge. The layer order is parsed from the table under "Layers and their
order" in docs/design.md, so the document and this test cannot disagree.
"""

from __future__ import annotations

import ast
import functools
import re
import sys
import tokenize
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest

pytestmark = pytest.mark.xdist_group("layers")  # one worker reads the package's imports, once

ROOT = Path(__file__).resolve().parents[1]
PKG = ROOT / "src" / "roarmctl"


def layer_table() -> list[list[str]]:
    """The modules of each layer, lowest first, from docs/design.md."""
    text = (ROOT / "docs" / "design.md").read_text()
    section = text.split("## Layers and their order", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in section.splitlines() if re.match(r"\|\s*\d+\s*\|", line)]
    return [re.findall(r"`(roarmctl(?:\.\w+)*)`", row.split("|")[2]) for row in rows]


LAYERS = layer_table()


def layer_of(module: str) -> int:
    """The index of the layer a module belongs to (its own entry, or its closest package's)."""
    parts = module.split(".")
    for depth in range(len(parts), 0, -1):
        name = ".".join(parts[:depth])
        for i, names in enumerate(LAYERS):
            if name in names:
                return i
    raise AssertionError(f"{module}: in no layer of docs/design.md's table")


def module_name(path: Path) -> str:
    """Dotted name of a file of the package."""
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


MODULES = {module_name(p): p for p in sorted(PKG.rglob("*.py"))}
EXTENSIONS = {module_name(p).split(".cpython")[0] for p in PKG.rglob("*.c")}


@dataclass(frozen=True)
class ImportSite:
    """One import statement of a module and where it sits."""

    node: ast.Import | ast.ImportFrom
    in_function: bool  # inside a def (runs when the function is called)
    typing_only: bool  # inside ``if TYPE_CHECKING:`` (no run-time dependency)
    fallback: bool  # inside a ``try: ... except ImportError:``


def _sites(node: ast.AST, in_function: bool, typing_only: bool, fallback: bool, out: list[ImportSite]) -> None:
    """Collect the import statements under ``node`` (one recursive pass, flags carried down)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, (ast.Import, ast.ImportFrom)):
            out.append(ImportSite(child, in_function, typing_only, fallback))
        elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
            _sites(child, True, typing_only, fallback, out)
        elif isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
            for stmt in child.body:
                _sites(ast.Module(body=[stmt], type_ignores=[]), in_function, True, fallback, out)
            for stmt in child.orelse:
                _sites(ast.Module(body=[stmt], type_ignores=[]), in_function, typing_only, fallback, out)
        elif isinstance(child, ast.Try) and any("ImportError" in ast.unparse(h.type or ast.Name(""))
                                                for h in child.handlers):
            _sites(child, in_function, typing_only, True, out)
        elif isinstance(child, (ast.stmt, ast.excepthandler, ast.match_case)):
            _sites(child, in_function, typing_only, fallback, out)


@functools.cache
def import_sites() -> dict[str, list[ImportSite]]:
    """Every import statement of every module of the package, read once per test process (each file parsed once;
    computed on first use, not at collection, so a worker that runs none of these tests pays nothing)."""
    out: dict[str, list[ImportSite]] = {}
    for name, path in MODULES.items():
        sites: list[ImportSite] = []
        _sites(ast.parse(path.read_text(), str(path)), False, False, False, sites)
        out[name] = sites
    return out


def targets_of(node: ast.Import | ast.ImportFrom, package: str) -> list[str]:
    """The modules an import statement in ``package`` imports: ``from pkg import sub`` the module pkg.sub,
    ``from mod import name`` the module mod; relative imports resolved."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    if node.level:
        base = package.split(".")[: len(package.split(".")) - node.level + 1]
        mod = ".".join(base + ([node.module] if node.module else []))
    else:
        mod = node.module or ""
    subs = [f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in MODULES or f"{mod}.{a.name}" in EXTENSIONS]
    return subs if len(subs) == len(node.names) else [mod, *subs]


@functools.cache
def imports() -> list[tuple[str, str, int, bool, bool]]:
    """(importer, imported module, line, inside a function, run time) for every import of a roarmctl module."""
    edges = []
    for name, path in MODULES.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for site in import_sites()[name]:
            for t in targets_of(site.node, package):
                if t == "roarmctl" or t.startswith("roarmctl."):
                    edges.append((name, t, site.node.lineno, site.in_function, not site.typing_only))
    return edges


# Upward imports being removed by a change in flight, each with who removes it. Strict: an entry whose import
# has gone fails the test, so the list only shrinks.
PENDING: set[tuple[str, str]] = set()


def test_the_layer_table_is_read_and_covers_every_module():
    assert len(LAYERS) >= 10 and ["roarmctl.errors"] in LAYERS
    for name in MODULES:
        if name != "roarmctl":
            layer_of(name)  # raises for a module the table does not place


def test_no_import_points_up():
    found = [(a, b, line, f) for a, b, line, f, _ in imports() if b != "roarmctl" and layer_of(b) > layer_of(a)]
    up = [f"{a}:{line} imports {b} ({'in a function' if f else 'at module level'}): layer {layer_of(a) + 1} -> {layer_of(b) + 1}"
          for a, b, line, f in found if (a, b) not in PENDING]
    assert not up, "imports that point up the layers of docs/design.md:\n" + "\n".join(up)
    gone = PENDING - {(a, b) for a, b, _, _ in found}
    assert not gone, f"no longer imported, remove from PENDING: {sorted(gone)}"


def test_no_import_circles():
    graph: dict[str, set[str]] = {}
    for a, b, _, _, run_time in imports():
        if run_time and b in MODULES and b != a:
            graph.setdefault(a, set()).add(b)
    cycles = []
    state: dict[str, int] = {}  # 1: on the stack, 2: done
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                cycles.append(" -> ".join(stack[stack.index(n):] + [n]))
            elif n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not cycles, "modules that import each other in a circle:\n" + "\n".join(cycles)


@pytest.mark.parametrize("snippet, package, expected", [
    ("from roarmctl.robot import ik", "roarmctl.cli", ["roarmctl.robot.ik"]),
    ("from roarmctl.motion.planning import blending, tasks", "roarmctl.motion",
     ["roarmctl.motion.planning.blending", "roarmctl.motion.planning.tasks"]),
    ("from roarmctl.errors import InputError", "roarmctl.cli", ["roarmctl.errors"]),
    ("from roarmctl import _kernel", "roarmctl.robot", ["roarmctl._kernel"]),
    ("from .common import wrap_angle", "roarmctl.robot.ik", ["roarmctl.robot.ik.common"]),
    ("from .. import errors", "roarmctl.robot", ["roarmctl.errors"]),
    ("import roarmctl.viz.data", "roarmctl.export", ["roarmctl.viz.data"]),
])
def test_the_walk_resolves_imports_to_modules(snippet, package, expected):
    assert targets_of(ast.parse(snippet).body[0], package) == expected


def test_an_upward_import_inside_a_function_is_found():
    """The walk sees imports inside functions: a known upward import written into a scratch module is reported."""
    tree = ast.parse("def f():\n    from roarmctl.cli import common\n")
    node = tree.body[0].body[0]
    (target,) = targets_of(node, "roarmctl.robot")
    assert layer_of(target) > layer_of("roarmctl.robot.model")


STDLIB = set(sys.stdlib_module_names) | {"__future__"}
# Standard-library modules that count as libraries here: each costs a noticeable share of `roarmctl --help`
# (about 120 ms in all on an idle 2-core machine), so a command that needs one imports it (or the roarmctl
# module that does) inside a function. Costs measured with the typer-based CLI already loaded
# (bench/bench_startup.py's machine; docs/benchmarks.md, start-up): http.server ~25 ms (ssl, email, socket),
# hashlib ~5 ms (OpenSSL's libcrypto), tempfile ~2.5 ms (random), html ~2.5 ms (html.entities),
# ctypes, importlib.resources and webbrowser ~1.5-2 ms each.
START_UP_STDLIB = {"http", "hashlib", "hmac", "secrets", "tempfile", "html", "ctypes", "importlib.resources", "webbrowser"}


def _library(module: str) -> str | None:
    """The library an imported module counts as: its top-level package for a third-party one, the START_UP_STDLIB
    entry it falls under for a standard-library one, None for the rest of the standard library and roarmctl."""
    top = module.split(".")[0]
    if top == "roarmctl":
        return None
    if top not in STDLIB:
        return top
    return next((s for s in START_UP_STDLIB if module == s or module.startswith(s + ".")), None)


def _imported_names(node: ast.Import | ast.ImportFrom) -> list[str]:
    """The dotted names an import statement may load: ``from importlib import resources`` -> importlib and
    importlib.resources (which of them is a module is not known without importing)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names]
    return [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]


def _module_level_libraries() -> dict[str, set[str]]:
    """The third-party libraries each module imports at module level (run time), directly."""
    out = {}
    for name, _path in MODULES.items():
        libs = set()
        for site in import_sites()[name]:
            node = site.node
            if site.in_function or site.typing_only or getattr(node, "level", 0):
                continue
            for m in _imported_names(node):
                lib = _library(m)
                if lib is not None:
                    libs.add(lib)
        out[name] = libs
    return out


def libraries_loaded() -> dict[str, set[str]]:
    """The third-party libraries importing each module loads: its own module-level ones, its packages' and those
    of every roarmctl module it imports at module level, transitively."""
    direct = _module_level_libraries()
    graph = {m: set() for m in MODULES}
    for a, b, _, in_function, run_time in imports():
        if not in_function and run_time:
            graph[a] |= {t for t in [b] + [".".join(b.split(".")[:i]) for i in range(2, b.count(".") + 1)] if t in MODULES and t != a}

    def closure(m: str, seen: set[str]) -> set[str]:
        if m in seen:
            return set()
        seen.add(m)
        parts = m.split(".")
        out = set(direct.get(m, ()))
        for n in [".".join(parts[:i]) for i in range(2, len(parts))] + sorted(graph.get(m, ())):
            out |= closure(n, seen)
        return out

    return {m: closure(m, set()) for m in MODULES}


@pytest.mark.parametrize("module, library", [
    ("numpy.linalg", "numpy"), ("http.server", "http"), ("importlib.resources", "importlib.resources"),
    ("importlib.util", None), ("json", None), ("roarmctl.fileio", None),
])
def test_what_counts_as_a_library_for_start_up(module, library):
    assert _library(module) == library


def test_imports_inside_functions_are_there_for_start_up_time():
    """An import sits inside a function only to keep a library out of start-up: it loads a third-party library or
    a costly standard-library module (START_UP_STDLIB; directly, or through the roarmctl module it names) that its
    module does not load at module level."""
    loaded = libraries_loaded()
    needless = []
    for name, path in MODULES.items():
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for site in import_sites()[name]:
            node = site.node
            if not site.in_function or site.fallback:
                continue
            new = set()
            for t in targets_of(node, package):
                if t.split(".")[0] == "roarmctl":
                    new |= loaded.get(t, {"(extension)"} if t in EXTENSIONS else set()) - loaded[name]
            if not getattr(node, "level", 0):
                new |= {lib for m in _imported_names(node) if (lib := _library(m)) is not None} - loaded[name]
            if not new:
                needless.append(f"{name}:{node.lineno} {ast.unparse(node)}")
    assert not needless, "imports inside functions that load no library their module lacks (move them up):\n" + "\n".join(needless)


def logical_lines(path: Path) -> int:
    """Statements of a module as Python's tokenizer counts them (NEWLINE tokens): a call or signature written over
    several lines is one, comments and blank lines are none, so shortening a comment or joining lines changes nothing."""
    with path.open("rb") as f:
        return sum(1 for tok in tokenize.tokenize(f.readline) if tok.type == tokenize.NEWLINE)


WARN_LINES, MAX_LINES = 600, 800  # logical lines: near the first a module is split by job; past the second the test fails


def test_logical_lines_count_statements_not_layout(tmp_path):
    one = tmp_path / "one.py"
    one.write_text("x = f(\n    1,\n    2,\n)  # a comment\n\n# only a comment\n")
    two = tmp_path / "two.py"
    two.write_text("x = f(1, 2)\ny = 3\n")
    assert (logical_lines(one), logical_lines(two)) == (1, 2)


def test_no_module_is_over_800_logical_lines():
    """Small modules with one job: a module that grows past 800 logical lines is split along its jobs (and one past
    600 is told it is near)."""
    counts = {name: logical_lines(path) for name, path in MODULES.items()}
    near = {name: n for name, n in counts.items() if WARN_LINES < n <= MAX_LINES}
    if near:
        warnings.warn(f"modules near the size cap ({MAX_LINES} logical lines): split them by job: {near}", stacklevel=1)
    long = {name: n for name, n in counts.items() if n > MAX_LINES}
    assert not long, long
