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


def main() -> None:
    """Console entry point (``roarmctl`` and ``python -m roarmctl``)."""
    received: list[int] = []

    def early(signum: int, frame) -> None:
        received.append(signum)
        if len(received) == 1:
            raise KeyboardInterrupt

    previous = {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        s = getattr(signal, name, None)
        if s is not None:
            previous[s] = signal.signal(s, early)
    try:
        from roarmctl.cli import main as cli_main
    except KeyboardInterrupt:
        signum = received[0] if received else signal.SIGINT
        what = "interrupted" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
        sys.stderr.write(f"error: {what} (nothing was written)\n")
        sys.stderr.flush()
        os._exit(128 + int(signum))
    for s, h in previous.items():
        signal.signal(s, h)
    cli_main()
