"""One self-contained HTML page from a view document: the page's own script and style (``static/``), the
data as JSON, and three.js inlined from the installed ``jupyter-threejs-sage`` package, so the file opens
by double click with no server and no network (its Content-Security-Policy forbids any fetch).

three.js: the UMD build r130 that SageMath packages (https://github.com/sagemath/threejs-sage, MIT, with
OrbitControls and the fat-line classes compiled in), pinned in pyproject.toml; nothing of it is kept in
this repository.
"""

from __future__ import annotations

import html
import json
from importlib import resources
from pathlib import Path
from string import Template
from typing import Any

from roarmctl import __version__
from roarmctl.errors import InputError
from roarmctl.fileio import atomic_write_bytes

THREE_PACKAGE = "jupyter_threejs_sage"
THREE_RELEASE = "r130"
APP_SCRIPTS = ("camera.js", "strip.js", "view.js")  # the page's own script, in this order (view.js uses the others)


def _static(name: str) -> str:
    return resources.files("roarmctl.viz.web").joinpath("static", name).read_text(encoding="utf-8")


def three_js() -> str:
    """The text of three.min.js from the installed package; a missing package is an input error with the fix."""
    try:
        return resources.files(THREE_PACKAGE).joinpath("static", THREE_RELEASE, "three.min.js").read_text(encoding="utf-8")
    except (ModuleNotFoundError, FileNotFoundError):
        raise InputError(f"the 3D library for the browser view is not installed (package {THREE_PACKAGE}, three.js {THREE_RELEASE})",
                         f"pip install '{THREE_PACKAGE}==130'") from None


def data_json(doc: dict[str, Any]) -> str:
    """``doc`` as JSON that is safe inside a ``<script>`` element: every '<' escaped, so no text from a file
    (an item name, a label) can close the element or open a comment."""
    text = json.dumps(doc, separators=(",", ":"), allow_nan=False, ensure_ascii=False)
    return text.replace("<", "\\u003c").replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")


def render_page(doc: dict[str, Any]) -> str:
    """The whole page as text (UTF-8 when written)."""
    return Template(_static("page.html")).substitute(
        version=html.escape(__version__), title=html.escape(str(doc.get("title", "roarmctl view"))),
        css=_static("view.css"), data=data_json(doc), three=three_js(),
        app="\n".join(_static(name) for name in APP_SCRIPTS))


def write_page(doc: dict[str, Any], path: str | Path) -> Path:
    """Write the page atomically (temporary file, then rename); returns the path written."""
    return atomic_write_bytes(path, render_page(doc).encode("utf-8"))
