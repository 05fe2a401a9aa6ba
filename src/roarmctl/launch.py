"""The program's first instructions: stop signals are handled before the CLI is even imported.

Loading the CLI (typer, rich, numpy) takes a few hundred ms, more on a busy machine. A Ctrl-C in
that window used to meet Python's default handler and print a traceback from deep inside an
import. Here the three stop signals are caught from the start; a stop while loading gives the CLI's
usual one line and 128 + N (nothing has been started, so nothing can be half-written). Once loaded,
``roarmctl.cli.main`` installs its own handlers for the command.
"""

from __future__ import annotations

import os
import signal
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from types import FrameType


def main() -> None:
    """Console entry point (``roarmctl`` and ``python -m roarmctl``)."""
    received: list[int] = []

    def early(signum: int, frame: FrameType | None) -> None:
        received.append(signum)
        if len(received) == 1:
            raise KeyboardInterrupt

    # Where Python discards exceptions (a weakref callback or __del__ running during the imports) the
    # KeyboardInterrupt is printed as "Exception ignored" and lost: the stop is still a stop (checked after
    # the imports), and it is not printed.
    previous_hook = sys.unraisablehook

    def unraisable(info: sys.UnraisableHookArgs) -> None:
        if not (received and info.exc_type is not None and issubclass(info.exc_type, KeyboardInterrupt)):
            previous_hook(info)

    sys.unraisablehook = unraisable
    previous = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        s = getattr(signal, name, None)
        if s is not None:
            previous[s] = signal.signal(s, early)
    try:
        from roarmctl.cli import main as cli_main

        for s, h in previous.items():
            signal.signal(s, h)
        if received:  # raised where Python discarded it
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        _stopped(received)
    except Exception as exc:
        if not (received and _caused_by_stop(exc)):
            raise
        _stopped(received)
    finally:
        sys.unraisablehook = previous_hook
    cli_main()


def _caused_by_stop(exc: BaseException) -> bool:
    """Whether ``exc`` is, or was caused by, a KeyboardInterrupt: Python 3.11 turns one raised while a class is being
    created (a descriptor's ``__set_name__``, such as platform's ``uname_result`` that typer's import creates) into
    "RuntimeError: Error calling __set_name__" with the interrupt as its cause."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, KeyboardInterrupt):
            return True
        seen = seen.__cause__
    return False


def _stopped(received: list[int]) -> None:
    """The stop while loading: the CLI's one line and 128 + N, at once (nothing has been started)."""
    signum = received[0] if received else signal.SIGINT
    what = "interrupted" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
    sys.stderr.write(f"error: {what} (nothing was written)\n")
    sys.stderr.flush()
    os._exit(128 + int(signum))
