"""The roarmctl command line: parse, call the library, render with rich, map errors to exit codes.

Only this package prints or exits. Heavy imports (ompl, fcl, toppra, matplotlib) happen inside
the commands that need them so that ``roarmctl --help`` answers at once. The command modules do not use
``from __future__ import annotations``: typer reads every command's signature in every run and would
compile and evaluate each string annotation twice (about a tenth of ``--help``).
"""

import functools
import os
import sys
import traceback
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from roarmctl import __version__
from roarmctl.cli import (
    common,
    datagen_cmd,
    execute_cmd,
    export_cmd,
    follow_cmd,
    kin,
    plan_cmd,
    robots_cmd,
    signals,
    simulate_cmd,
    teach_cmd,
    view_cmd,
    viz_cmd,
)
from roarmctl.cli.signals import exit_code
from roarmctl.errors import InputError, RoarmError, signal_name
from roarmctl.fileio import interrupted_write_state
from roarmctl.robot import xacro_input

if TYPE_CHECKING:
    from collections.abc import Callable

    import click

app = typer.Typer(
    name="roarmctl",
    help="Plan, check and execute pick-and-place trajectories for small robot arms (Waveshare RoArm-M3 Pro first).",
    no_args_is_help=True,
    add_completion=True,  # --install-completion / --show-completion for bash, zsh, fish, PowerShell
    pretty_exceptions_enable=False,
    # Plain help and usage errors (click's formatter): typer's rich panels import rich's markdown renderer and
    # more, about 80 ms of a `roarmctl --help` that otherwise takes about as long
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        print(f"roarmctl {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    debug: bool = typer.Option(False, "--debug", help="Show full tracebacks on errors."),
    version: bool = typer.Option(False, "--version", "-V", help="Print the version and exit.", callback=_version, is_eager=True),
    package_path: list[str] = typer.Option(
        [], "--package-path", metavar="NAME=DIR",
        help="Folder of ROS package NAME for package://NAME/... mesh paths in a URDF (repeatable)."),
    trust_xacro: bool = typer.Option(
        False, "--trust-xacro",
        help="Let xacro evaluate the robot description's expressions itself (runs its Python: only for files you trust)."),
) -> None:
    common.STATE.debug = debug

    xacro_input.TRUST_ALL = trust_xacro
    if package_path:
        from roarmctl.robot.meshes import PACKAGE_PATHS

        for item in package_path:
            name, sep, folder = item.partition("=")
            if not sep or not name or not folder:
                raise InputError(f"--package-path: expected NAME=DIR, got '{item}'")
            if not Path(folder).expanduser().is_dir():
                raise InputError(f"--package-path {name}: folder '{folder}' not found")
            PACKAGE_PATHS[name] = Path(folder).expanduser().resolve()


robots_cmd.register(app)
kin.register(app)
plan_cmd.register(app)
execute_cmd.register(app)
viz_cmd.register(app)
view_cmd.register(app)
export_cmd.register(app)
simulate_cmd.register(app)
teach_cmd.register(app)
datagen_cmd.register(app)
follow_cmd.register(app)


def _click_exceptions() -> tuple[type, ...]:
    """The ClickException classes a usage error may be: typer >= 0.2x vendors click as ``typer._click`` (its
    errors are those), and a ``click`` that another package installs beside it is a different class."""
    found: list[type] = []
    for module in ("typer._click.exceptions", "click"):
        try:
            found.append(__import__(module, fromlist=["ClickException"]).ClickException)
        except (ImportError, AttributeError):
            pass
    return tuple(found)


def run(argv: list[str] | None = None) -> int:
    """Run one command line in this process and return its exit code (no ``sys.exit``).

    ``argv`` is the argument list without the program name (``["plan", "p.yaml"]``); ``None``
    reads ``sys.argv``. Errors become one line on stderr (and a JSON object with ``--json``), as
    for the console script. SIGINT, SIGTERM and SIGHUP stop a command cleanly
    (``roarmctl.cli.signals``): exit 130, 143, 129.
    """
    # run as the program (no argv): once stopping, stay deaf to further signals until the exit
    with signals.installed(keep_after_stop=argv is None) as guard:
        code = _run(argv, guard)
    sys.stdout.flush()
    sys.stderr.flush()
    return code


def main(argv: list[str] | None = None) -> None:
    """Console entry point: :func:`run`, then exit with its code."""
    code = run(argv)
    if "ompl" in sys.modules and argv is None:
        # OMPL's nanobind bindings print leak warnings at interpreter exit; skip the teardown
        # (only as the console script: a caller passing argv, such as a test, keeps its process).
        os._exit(code)
    sys.exit(code)


def _stop_line(signum: int) -> str:
    return "interrupted" if signum == 2 else f"terminated by {signal_name(signum)}"


def _stop_inside(exc: BaseException) -> BaseException | None:
    """The ``KeyboardInterrupt`` (a stop signal) that ``exc`` wraps as its cause or context, if any."""
    seen = 0
    cur: BaseException | None = exc
    while cur is not None and seen < 20:
        if isinstance(cur, KeyboardInterrupt):
            return cur
        cur = cur.__cause__ or cur.__context__
        seen += 1
    return None


def _on_disk() -> str | None:
    """What an output interrupted while it replaced a folder left on disk (``fileio``), else None."""
    return interrupted_write_state()


@functools.cache
def command() -> "click.Command":
    """The click command behind ``app``, with boolean flags shown as flags in ``--help`` (typer
    would print ``--json <bool>``, which reads as if it took a value). Built once per process (click makes a new
    context for every call; a process that runs many command lines, a test worker or a notebook, pays it once)."""
    cmd = typer.main.get_command(app)

    def fix(c: "click.Command") -> None:
        for param in getattr(c, "params", []):
            if getattr(param, "is_flag", False) and param.metavar is None:
                param.metavar = ""
            elif param.param_type_name == "argument" and param.metavar is None:
                param.metavar = param.name.upper()  # "plan PLAN", not "plan {plan}"
        help_option = c.get_help_option

        def get_help_option(ctx: "click.Context", _orig: "Callable[[click.Context], click.Option | None]" = help_option,
                            ) -> "click.Option | None":
            opt = _orig(ctx)
            if opt is not None:
                opt.metavar = ""
            return opt

        c.get_help_option = get_help_option
        for sub in getattr(c, "commands", {}).values():
            fix(sub)

    fix(cmd)
    return cmd


def _json_requested(argv: list[str] | None) -> bool:
    """Whether the command line asks for JSON output (then a failure is a JSON object on stdout too)."""
    args = sys.argv[1:] if argv is None else argv
    return "--json" in args[: args.index("--")] if "--" in args else "--json" in args


def _run(argv: list[str] | None, guard: "signals.Guard") -> int:
    common.STATE.json_printed, common.STATE.last_error = False, None  # main() may run more than once in a process
    _on_disk()  # forget an earlier command's interrupted output
    code = _run_command(argv, guard)
    if code != 0 and _json_requested(argv) and not common.STATE.json_printed:
        message, hint = common.STATE.last_error or ("failed", None)
        common.print_json({"ok": False, "error": message, "hint": hint, "exit_code": code})
    return code


def _run_command(argv: list[str] | None, guard: "signals.Guard") -> int:
    code = 0
    try:
        # Without standalone mode typer *returns* the exit code of typer.Exit, and turns Ctrl-C
        # (KeyboardInterrupt) into Exit(130) that is returned too: keep both.
        returned = command()(args=argv, standalone_mode=False, prog_name="roarmctl")
        guard.live = False
        if isinstance(returned, int) and not isinstance(returned, bool):
            code = returned
            if code == 130:
                signum = guard.first or 2
                common.error(_stop_line(signum), _on_disk() or "nothing was written")
                code = exit_code(signum)
    except RoarmError as exc:
        guard.live = False
        if common.STATE.debug:
            traceback.print_exc()
        common.error(common.cli_words(exc), common.cli_hint(exc))
        code = exc.exit_code
    except KeyboardInterrupt as exc:  # before the command started (typer turns one inside it into Exit(130))
        guard.live = False
        signum = getattr(exc, "signum", None) or guard.first or 2
        common.error(_stop_line(signum), _on_disk() or "nothing was written")
        code = exit_code(signum)
    except SystemExit as exc:  # typer.Exit raised inside a command
        guard.live = False
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except Exception as exc:  # noqa: BLE001 - the last line of defence: a bug
        guard.live = False
        if isinstance(exc, typer.Exit):
            code = exc.exit_code
        elif isinstance(exc, _click_exceptions()):
            usage: Any = exc
            usage.show()
            common.STATE.last_error = (usage.format_message(), "see 'roarmctl COMMAND --help'")
            code = 2
        elif isinstance(exc, typer.Abort):
            common.error("aborted")
            code = 130
        elif _stop_inside(exc) is not None:
            # the stop signal's exception raised where Python wraps it (e.g. __set_name__ during an import
            # turns it into a RuntimeError): a stop, not a bug
            signum = getattr(_stop_inside(exc), "signum", None) or guard.first or 2
            common.error(_stop_line(signum), _on_disk())
            code = exit_code(signum)
        else:
            import tempfile  # only for a bug's traceback file: ~2.5 ms of every start-up otherwise

            fd, log = tempfile.mkstemp(prefix="roarmctl-traceback-", suffix=".txt")
            with os.fdopen(fd, "w") as f:
                traceback.print_exc(file=f)
            if common.STATE.debug:
                traceback.print_exc()
            common.error(f"internal error: {type(exc).__name__}: {exc}", f"this is a bug; the traceback is in {log}")
            code = 1
    if code == 0 and guard.received and guard.first is not None and not guard.raised:
        # a signal arrived while the command was finishing its cleanup: it finished, but say so
        code = exit_code(guard.first)
        common.error(_stop_line(guard.first), "the command had finished its work")
    return code
