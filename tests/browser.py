"""Driving the system's Chromium with Playwright for the browser-view tests and bench/bench_view.py.

The browser is Debian's ``chromium`` (``make browser`` installs it; ``ROARMCTL_CHROMIUM`` names another
binary); Playwright only drives it (``executable_path``): nothing is downloaded. The flags keep a headless
Chromium off the network (no background services) and allow running as root.

Screen checks: the page draws the TCP at the cursor as a magenta dot of fixed pixel size over everything
(``view.js``); ``tcp_dot`` finds its centre in a screenshot, and ``project`` maps a world point to page
pixels with the camera the page reports, so a test compares the drawn TCP with the FK of the trajectory.
"""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path

import numpy as np

FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--disable-extensions", "--mute-audio"]
VIEWPORT = {"width": 1200, "height": 760}
MAGENTA = np.array([255, 0, 255])
READY = "() => window.roarmView && window.roarmView.ready"


def chromium_path() -> str | None:
    """The Chromium binary to drive: ``$ROARMCTL_CHROMIUM``, else ``chromium`` / ``chromium-browser`` on PATH."""
    env = os.environ.get("ROARMCTL_CHROMIUM")
    if env:
        return env if Path(env).is_file() else None
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


def launch(playwright):
    """A headless Chromium (the system's) under ``playwright`` (a ``sync_playwright()`` instance)."""
    return playwright.chromium.launch(executable_path=chromium_path(), args=FLAGS, headless=True)


class Watch:
    """What a page did while loading: console errors, uncaught exceptions, and every request it made."""

    def __init__(self, page) -> None:
        self.errors: list[str] = []
        self.requests: list[str] = []
        page.on("console", lambda m: self.errors.append(f"console.{m.type}: {m.text}") if m.type == "error" else None)
        page.on("pageerror", lambda e: self.errors.append(f"pageerror: {e}"))
        page.on("request", lambda r: self.requests.append(r.url))

    def remote(self) -> list[str]:
        """Requests that would leave the machine or the file (anything but file:, data: and blob: URLs)."""
        return [u for u in self.requests if not u.startswith(("file:", "data:", "blob:"))]


def open_page(browser, url: str, viewport: dict | None = None):
    """A new page at ``url``, waited on until the view says it is ready; returns (page, Watch)."""
    page = browser.new_page(viewport=viewport or VIEWPORT)
    watch = Watch(page)
    page.goto(url, timeout=180_000)  # a shared 2-core machine under load takes its time; a timeout is not a check
    page.wait_for_function(READY, timeout=180_000)
    return page, watch


def project(state: dict, xyz) -> np.ndarray:
    """Page pixel (x, y) of world point ``xyz`` (m) through the camera in ``state`` (``roarmView.state()``)."""
    proj = np.array(state["projection"]).reshape(4, 4).T  # three.js keeps matrices column-major
    view = np.array(state["view"]).reshape(4, 4).T
    clip = proj @ view @ np.append(np.asarray(xyz, dtype=float), 1.0)
    ndc = clip[:3] / clip[3]
    c = state["canvas"]
    return np.array([c["left"] + (ndc[0] + 1) / 2 * c["width"], c["top"] + (1 - ndc[1]) / 2 * c["height"]])


def screenshot(page) -> np.ndarray:
    """The page as an (H, W, 3) uint8 RGB array."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot())).convert("RGB"))


def tcp_dot(image: np.ndarray, canvas: dict) -> tuple[np.ndarray, int]:
    """Centre (x, y) in page pixels of the magenta TCP dot inside the canvas, and its pixel count."""
    x0, y0 = int(canvas["left"]), int(canvas["top"])
    sub = image[y0:y0 + int(canvas["height"]), x0:x0 + int(canvas["width"])].astype(int)
    mask = np.all(np.abs(sub - MAGENTA) <= 40, axis=-1)
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return np.array([np.nan, np.nan]), 0
    return np.array([xs.mean() + x0 + 0.5, ys.mean() + y0 + 0.5]), len(xs)
