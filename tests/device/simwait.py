"""Waits on the simulated firmware's own clock (``PtySimulator.state()["now"]``), for the tests that keep the real
pty: what they wait for is time of the model, however slowly a busy machine lets it run."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from roarmctl.device.simulator import PtySimulator


def until(sim: PtySimulator, done: Callable[[dict[str, Any]], bool], limit: float = 60.0) -> dict[str, Any]:
    """Poll the simulator's state until ``done(state)``; return that state. ``limit`` (wall s) detects a hang only."""
    end = time.monotonic() + limit
    while not done(st := sim.state()):
        assert time.monotonic() < end, f"the simulated firmware did not get there within {limit} s (its clock at {st['now']:.2f} s)"
        time.sleep(0.02)
    return st


def run_on(sim: PtySimulator, seconds: float, limit: float = 60.0) -> dict[str, Any]:
    """Let ``seconds`` pass on the simulated firmware's clock; return its state then."""
    start = sim.state()["now"]
    return until(sim, lambda st: st["now"] >= start + seconds, limit)
