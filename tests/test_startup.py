"""Start-up: what the CLI does NOT load (import graphs, not clocks: the figures are in bench/bench_startup.py)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest


def _imported(code: str) -> set[str]:
    """Modules imported by running ``code`` in a fresh interpreter (from -X importtime)."""
    proc = subprocess.run([sys.executable, "-X", "importtime", "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return {line.rsplit("|", 1)[-1].strip() for line in proc.stderr.splitlines() if line.startswith("import time:")}


def test_help_loads_no_numeric_or_planning_library():
    mods = _imported("import sys; sys.argv = ['roarmctl', '--help']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit:\n    pass")
    assert "roarmctl.cli" in mods
    assert not mods & {"numpy", "ompl", "fcl", "toppra", "matplotlib", "scipy", "mujoco", "yaml", "rich"}
    # nor the standard library's costly modules that only some commands use (tests/test_layers.py, START_UP_STDLIB):
    # http.server (view: ssl, email, socket), hashlib (OpenSSL), tempfile, the web page's html and resources
    assert not mods & {"http.server", "ssl", "email", "hashlib", "secrets", "tempfile", "html", "ctypes", "importlib.resources",
                       "webbrowser"}


def test_help_imports_a_bounded_number_of_modules():
    """A count of work rather than a clock (which the machine's load moves): `--help` imported 236 modules before issue
    25's cuts and 175 after (``python -c pass`` 64), most of them Python's and typer's. A command module that imports
    something costly at its top shows here; 190 leaves room for a few small modules."""
    mods = _imported("import sys; sys.argv = ['roarmctl', '--help']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit:\n    pass")
    assert len(mods) <= 190, len(mods)


@pytest.mark.slow  # fresh interpreters loading the planning libraries
def test_toppra_is_imported_as_it_is_with_no_stand_in_modules():
    """No module is replaced or deferred behind the import system's back: after import_toppra the matplotlib
    modules (toppra imports pyplot itself) are plain modules whose code has run."""
    code = ("import sys, types\nfrom roarmctl.motion.timing import import_toppra\nta = import_toppra()\n"
            "assert ta.algorithm.TOPPRA and ta.SplineInterpolator\n"
            "odd = [n for n, m in sys.modules.items() if n.split('.')[0] in ('matplotlib', 'toppra', 'scipy')\n"
            "       and type(m) is not types.ModuleType]\n"
            "assert not odd, odd\n"
            "assert 'figure' in vars(sys.modules['matplotlib.pyplot'])")
    mods = _imported(code)
    assert "toppra" in mods and "scipy.interpolate" in mods


@pytest.mark.slow
def test_help_and_a_command_load_neither_rich_markdown_nor_pydantic(tmp_path):
    """``--help`` is click's plain help (typer's rich panels load rich's markdown renderer); a command's options
    are parsed without pydantic (typer 0.28 and later build a TypeAdapter per parameter)."""
    mods = _imported("import sys; sys.argv = ['roarmctl', '--help']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit:\n    pass")
    assert not mods & {"rich.markdown", "typer.rich_utils", "pydantic"}
    mods = _imported("import sys; sys.argv = ['roarmctl', 'robots', '--json']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit:\n    pass")
    assert "roarmctl.robot.loader" in mods and "pydantic" not in mods


def test_a_stop_that_python_discards_during_the_imports_still_stops(tmp_path):
    """A SIGINT whose KeyboardInterrupt is raised where Python prints and discards exceptions (here, as seen in
    a busy test run, inside a weakref callback while the CLI is being imported) still stops the program: one
    line (no "Exception ignored" report), exit 130, and the command never runs. The CLI module is replaced by
    one that provokes exactly that. The old entry point ran the command (exit 0) after printing the report."""
    marker, finished = tmp_path / "the command ran", tmp_path / "the callback finished"
    code = f"""
import importlib.abc, importlib.util, os, signal, sys, weakref

class Fake(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path, target=None):
        return importlib.util.spec_from_loader(name, self) if name == "roarmctl.cli" else None
    def create_module(self, spec):
        return None
    def exec_module(self, module):
        class Thing:
            pass
        def callback(ref):  # the interrupt is raised in here, and Python discards it
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(100000):
                pass
            open({str(finished)!r}, "w").close()
        thing = Thing()
        ref = weakref.ref(thing, callback)
        del thing
        module.main = lambda: open({str(marker)!r}, "w").close()

sys.meta_path.insert(0, Fake())
from roarmctl.launch import main
main()
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert not finished.exists()  # the interrupt did land inside the callback (which Python then discards)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: interrupted (nothing was written)"]
    assert not marker.exists()


def test_a_stop_that_python_wraps_during_the_imports_still_stops(tmp_path):
    """A SIGINT whose KeyboardInterrupt is raised while a class is created (a descriptor's __set_name__: seen in a
    test-fast run inside platform's uname_result, which typer's import creates) reaches the entry point as Python
    3.11's "RuntimeError: Error calling __set_name__" caused by it: still one line, exit 130, the command never run
    (it was a traceback and exit 1). The CLI module is replaced by one that provokes exactly that."""
    marker = tmp_path / "the command ran"
    code = f"""
import importlib.abc, importlib.util, os, signal, sys

class Fake(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, name, path, target=None):
        return importlib.util.spec_from_loader(name, self) if name == "roarmctl.cli" else None
    def create_module(self, spec):
        return None
    def exec_module(self, module):
        class Named:
            def __set_name__(self, owner, name):  # the interrupt is raised in here
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(100000):
                    pass
        class Owner:
            attribute = Named()
        module.main = lambda: open({str(marker)!r}, "w").close()

sys.meta_path.insert(0, Fake())
from roarmctl.launch import main
main()
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 130, proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: interrupted (nothing was written)"]
    assert not marker.exists()


@pytest.mark.slow  # fresh interpreters loading the planning libraries
def test_a_stop_while_the_planning_libraries_load_waits_until_they_have_loaded(tmp_path):
    """A stop signal that arrives while load_planning_libraries imports the native modules is delivered once
    they have loaded (a Python handler raising inside a nanobind module's initialisation, OMPL's or Ruckig's,
    makes it call C++ terminate: the process aborted instead of stopping). Here the signal is sent from inside
    the toppra import step, which then runs to its end; the interrupt comes out of load_planning_libraries."""
    finished = tmp_path / "the import step finished"
    code = f"""
import os, signal
signal.signal(signal.SIGINT, signal.default_int_handler)  # as in a terminal, also when started with SIGINT ignored
import roarmctl.motion.timing as timing
from roarmctl.motion.pipeline import load_planning_libraries

real = timing.import_toppra

def import_toppra():
    os.kill(os.getpid(), signal.SIGINT)
    for _ in range(100000):  # a Python handler would run (and raise) during these
        pass
    out = real()
    open({str(finished)!r}, "w").close()
    return out

timing.import_toppra = import_toppra
try:
    load_planning_libraries()
except KeyboardInterrupt:
    import ompl.geometric
    print("interrupted after the imports")
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "interrupted after the imports"
    assert finished.exists()


def test_the_commands_annotations_are_not_strings():
    """typer reads every command's signature in every run, also for ``--help`` (inspect.signature(eval_str=True), then
    get_type_hints): an annotation kept as a string (``from __future__ import annotations``) is compiled and evaluated
    twice per parameter and run, about a tenth of ``--help``. So the command modules evaluate them once, at import."""
    import typer

    from roarmctl.cli import app

    def callbacks(t: typer.Typer):
        if t.registered_callback is not None:
            yield t.registered_callback.callback
        for info in t.registered_commands:
            yield info.callback
        for group in t.registered_groups:
            yield from callbacks(group.typer_instance)

    seen = [f for f in callbacks(app) if f is not None]
    assert len(seen) >= 15  # every command is walked
    stringly = [f"{f.__module__}.{f.__qualname__}: {name}" for f in seen for name, a in f.__annotations__.items() if isinstance(a, str)]
    assert not stringly, stringly


@pytest.mark.slow  # a fresh interpreter loading the planning libraries
def test_plan_loads_what_planning_needs_and_nothing_of_the_other_commands(tmp_path):
    """``roarmctl plan ... --json`` in a fresh process: the planning libraries load (toppra with scipy.interpolate and
    matplotlib.pyplot, which toppra's package __init__ imports: docs/benchmarks.md, start-up), but nothing that only
    other commands use: no physics (MuJoCo), no table rendering (rich, with --json), no web view (http.server), no
    meshes (trimesh: the plan has only primitive shapes), no device session's serial port."""
    out, plan = tmp_path / "p.traj.json", Path(__file__).resolve().parents[1] / "plans" / "pick_place.yaml"
    mods = _imported(f"import sys; sys.argv = ['roarmctl', 'plan', {str(plan)!r}, '-o', {str(out)!r}, '--json']\n"
                     "from roarmctl.launch import main\ntry:\n    main()\nexcept SystemExit as e:\n    assert not e.code, e.code")
    assert {"toppra", "ompl", "fcl", "numpy", "scipy.interpolate", "matplotlib.pyplot"} <= mods
    assert out.is_file()
    assert not mods & {"mujoco", "rich", "http.server", "trimesh", "serial", "pydantic", "roarmctl.physics", "roarmctl.viz.web.page",
                       "roarmctl.viz.path_figure", "roarmctl.api"}
