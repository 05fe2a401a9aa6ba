"""The command line run in this process, as a shell sees it: exit code, stdout and stderr.

``roarmctl.cli.run`` is what the console script runs (``launch.main`` adds only the interpreter's start-up and
``sys.exit``), so a test of what a command prints and returns needs no new interpreter per call: this saves
about a second of imports (numpy, OMPL, TOPP-RA, matplotlib) per command. Tests of the process itself (signals,
start-up, the console script, busy cores) start a real one.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any


@dataclass
class Result:
    """What ``subprocess.run(..., capture_output=True, text=True)`` gives, for an in-process run."""

    returncode: int
    stdout: str
    stderr: str


def roarmctl(*args: str, env: dict[str, str] | None = None, cwd: str | Path | None = None) -> Result:
    """Run ``roarmctl ARGS`` in this process (80 columns wide, as the subprocess helpers set it), with ``env``
    added to the environment and ``cwd`` as the working directory for the call."""
    from roarmctl.cli import run
    from roarmctl.robot import xacro_input
    from roarmctl.robot.meshes import PACKAGE_PATHS

    extra = {"COLUMNS": "80", **(env or {})}
    saved = {k: os.environ.get(k) for k in extra}
    # what the global options set for the process (--package-path, --trust-xacro) ends with the call, as it ends
    # with a process: a later call must not find a package folder an earlier test named
    packages, trust = dict(PACKAGE_PATHS), xacro_input.TRUST_ALL
    out, err = io.StringIO(), io.StringIO()
    try:
        os.environ.update(extra)
        with contextlib.ExitStack() as stack:
            if cwd is not None:
                stack.enter_context(contextlib.chdir(cwd))
            stack.enter_context(contextlib.redirect_stdout(out))
            stack.enter_context(contextlib.redirect_stderr(err))
            code = run(list(args))
    finally:
        PACKAGE_PATHS.clear()
        PACKAGE_PATHS.update(packages)
        xacro_input.TRUST_ALL = trust
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return Result(code, out.getvalue(), err.getvalue())


@contextlib.contextmanager
def virtual_simulator(arm: Any = None) -> Iterator[list]:
    """Within the block, ``execute --sim`` in this process (and ``roarmctl.api.execute(sim=True)``) runs on a virtual
    clock: the simulator's firmware and servo models (``roarmctl.device.virtual.VirtualSimulator``, each on a clock of
    its own) behind the real ``Link``, with no pty and no real time. ``arm``: one ``VirtualSimulator`` every run
    connects to instead (the arm stays where the last run or a hand left it, as on ``sim-device``). Yields the
    simulators made, in order."""
    import pytest

    from roarmctl.device import session
    from roarmctl.device.virtual import VirtualClock, VirtualSimulator

    made: list[VirtualSimulator] = []

    def simulator(config, servos):
        made.append(arm if arm is not None else VirtualSimulator(config, VirtualClock(), servos=servos))
        return made[-1]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(session, "pty_simulator", simulator)
        yield made


def planned_and_run_on_sim(folder: Path, plan_text: str) -> tuple[Path, Path]:
    """Plan ``plan_text`` (a plan file's YAML; the default seed) into ``folder/short.traj.json`` and run it with
    ``execute --sim --yes`` (the simulated arm, on a virtual clock: ``virtual_simulator``), its log in
    ``folder/short.exec.json``: (trajectory, log). Fails the test when the run does not complete."""
    from roarmctl.motion.pipeline import plan_file

    plan = folder / "short.yaml"
    plan.write_text(plan_text)
    traj, log = folder / "short.traj.json", folder / "short.exec.json"
    plan_file(plan, seed=None).trajectory.save(traj)
    with virtual_simulator():
        run = roarmctl("execute", str(traj), "--sim", "--yes", "--log", str(log))
    assert run.returncode == 0, run.stderr
    return traj, log
