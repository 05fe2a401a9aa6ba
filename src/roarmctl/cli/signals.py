"""SIGINT, SIGTERM and SIGHUP: one clean stop, whatever arrives and however often.

``installed()`` (used by ``roarmctl.cli.main`` around every command) turns the *first* of these
signals into ``StopRequested`` (a ``KeyboardInterrupt``), so every ``except KeyboardInterrupt`` /
``finally`` in the library runs: the streamer holds the arm, ``fileio`` removes its temporary file,
the execution log is written. Later signals are only recorded: a second Ctrl-C 10 ms after the first
must not cut the hold or the log short, nor kill the process by the signal.

Python discards an exception raised inside a finalizer (``__del__``), a weakref or garbage-collector callback
("Exception ignored in ..."): a first signal whose ``StopRequested`` lands there is recorded but never reaches the
command. ``installed()`` keeps Python from printing such a stop, and ``check()``, called by loops that wait (a
streamed motion's ticks, ``sim-device``, ``view``) and at the progress reports of commands that compute (``plan``,
``simulate``, ``datagen``), raises it again (seen: ``view`` and ``sim-device`` serving on
after a Ctrl-C, deaf to the next ones, on a loaded machine).
``shielded()`` marks cleanup that must finish (closing the port, writing the log): a signal arriving
inside is recorded and raised when the block ends, unless one was raised already.

Exit codes follow the shells' convention 128 + signal number: 130 (SIGINT, Ctrl-C), 143 (SIGTERM),
129 (SIGHUP).
"""

from __future__ import annotations

import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from roarmctl.errors import StopRequested

if TYPE_CHECKING:
    from types import FrameType

SIGNALS = tuple(s for s in (getattr(signal, "SIGINT", None), getattr(signal, "SIGTERM", None),
                            getattr(signal, "SIGHUP", None)) if s is not None)


class Guard:
    """State of the installed handler: which signals arrived, whether one was raised, shielding depth."""

    def __init__(self) -> None:
        self.received: list[int] = []
        self.raised = False
        self.live = True  # False once the command has finished: record only
        self.shield = 0

    def handle(self, signum: int, frame: FrameType | None) -> None:
        """The signal handler: record the signal; raise StopRequested for the first one unless shielded."""
        self.received.append(signum)
        if self.raised or not self.live or self.shield:
            return
        self.raised = True
        raise StopRequested(signum)

    @property
    def first(self) -> int | None:
        """The first signal that arrived, or None."""
        return self.received[0] if self.received else None


_GUARD: Guard | None = None


@contextmanager
def installed(keep_after_stop: bool = False) -> Iterator[Guard]:
    """Install the handlers for the duration of one command (main thread only; else a no-op guard).

    ``keep_after_stop``: when a stop signal arrived, ignore these signals on the way out, so that one
    more Ctrl-C while the process exits cannot kill it by the signal (its exit code stays 128 + N).
    """
    global _GUARD
    guard = Guard()
    if threading.current_thread() is not threading.main_thread():
        yield guard
        return
    previous = {}
    for s in SIGNALS:
        try:
            previous[s] = signal.signal(s, guard.handle)
        except (OSError, ValueError):
            pass
    outer, _GUARD = _GUARD, guard
    previous_hook = sys.unraisablehook

    def unraisable(info: sys.UnraisableHookArgs) -> None:
        if not (guard.received and info.exc_type is not None and issubclass(info.exc_type, KeyboardInterrupt)):
            previous_hook(info)  # anything else is reported as Python would

    sys.unraisablehook = unraisable
    try:
        yield guard
    finally:
        guard.live = False
        _GUARD = outer
        sys.unraisablehook = previous_hook
        for s, h in previous.items():
            # ignored at the OS level: the interpreter's own shutdown resets Python-level handlers
            signal.signal(s, signal.SIG_IGN if (keep_after_stop and guard.received) else h)


def check() -> None:
    """Raise the stop a signal asked for when it arrived while the command runs (not in a shielded block) yet the
    command goes on: its ``StopRequested`` was raised where Python discards exceptions. For a loop that waits (for
    the next tick, a request, the simulator's end) and is not itself cleanup after a stop: call it once a wait."""
    guard = _GUARD
    if guard is not None and guard.live and guard.received and not guard.shield:
        guard.raised = True
        raise StopRequested(guard.received[0])


@contextmanager
def shielded() -> Iterator[None]:
    """Run a block that must complete (hold, port close, log write); re-raise a deferred signal after it."""
    guard = _GUARD
    if guard is None:
        yield
        return
    guard.shield += 1
    before = len(guard.received)
    try:
        yield
    finally:
        guard.shield -= 1
    if not guard.shield and len(guard.received) > before and not guard.raised and guard.live:
        guard.raised = True
        raise StopRequested(guard.received[before])


def exit_code(signum: int) -> int:
    """128 + the signal number, as shells report a process stopped by that signal."""
    return 128 + int(signum)
