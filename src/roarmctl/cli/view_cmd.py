"""``roarmctl view``: the interactive 3D view of a plan, a trajectory or a run, served on 127.0.0.1.

The page is the one ``visualize-path -o NAME.html`` writes (``roarmctl.viz.web``); the server holds it in
memory and answers only on the loopback interface. Ctrl-C is its normal end: exit 0, with how to open it again
(SIGTERM and SIGHUP stop it as every command: 143, 129).
"""

import shlex
import signal
import sys
from pathlib import Path

import typer

from roarmctl.cli import common, signals


def register(app: typer.Typer) -> None:
    """Add ``view`` to ``app``."""
    app.command("view")(view)


def view(
    source: Path = typer.Argument(..., help="Trajectory (.traj.json), plan file (.yaml, planned first) or execution log (.exec.json).",
                                  show_default=False),
    trajectory: Path | None = typer.Option(None, "--trajectory", "-t",
                                        help="With an execution log: the trajectory it ran (its scene, marks and commanded arm), for a log that carries none (an older roarmctl's)."),
    port: int = typer.Option(0, "--port", help="TCP port on 127.0.0.1 (0: a free one)."),
    open_browser: bool = typer.Option(False, "--open", help="Also open the page in the default web browser."),
) -> None:
    """Serve an interactive 3D view (robot, scene, TCP path, timeline) at http://127.0.0.1:PORT/ until Ctrl-C."""
    # here, not at the top: http.server (ssl, email, socket) and the page's modules cost ~30 ms of every --help
    import webbrowser

    from roarmctl.viz.web.page import render_page
    from roarmctl.viz.web.server import ViewOptions, ViewServer
    from roarmctl.viz.web.sources import load_view_source, source_document

    options = ViewOptions(port=port)  # checked before the page is built
    src = load_view_source(source, trajectory)
    page = render_page(source_document(src)).encode("utf-8")
    server = ViewServer(page, options)
    try:
        if src.error is not None:
            common.warn(f"{src.error.message}; the view shows the path up to the failure")
        out = common.console()
        out.print(f"view of {common.shown(source.name)} at [bold]{server.url}[/] ({len(page) / 1e6:.1f} MB page; Ctrl-C to stop)", soft_wrap=True)
        sys.stdout.flush()
        if open_browser:
            webbrowser.open(server.url)
        try:
            server.serve_forever(on_poll=signals.check)  # a Ctrl-C that Python discarded still stops the view
        except KeyboardInterrupt as exc:
            if (getattr(exc, "signum", None) or signal.SIGINT) != signal.SIGINT:
                raise  # SIGTERM, SIGHUP: stopped from outside, reported as every command is
            # Ctrl-C is how a view ends: not an error (exit 0); the page is gone with the server, so say how to get it back
            again = " ".join(shlex.quote(str(a)) for a in (["roarmctl", "view", source] + (["-t", trajectory] if trajectory else [])))
            out.print(common.one_line(f"stopped the view of {source.name}; open it again with: {again} (or write it to a file "
                                      f"that needs no server: roarmctl visualize-path {shlex.quote(str(source))} -o NAME.html)"),
                      soft_wrap=True, markup=False)
    finally:
        server.close()
