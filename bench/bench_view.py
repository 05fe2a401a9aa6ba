"""The browser view's page per bundled plan: its size, the time to build it, and its load time in headless Chromium.

    .venv/bin/python bench/bench_view.py [--loads N] [--screenshot docs/view.png]

Each bundled plan is planned once (not timed). "build" is ``view_document`` + ``render_page`` in this process
(median of 3; the speed colours' matplotlib import is paid before). "load" opens the written file
(``file://``, no server, no network) in the system's Chromium (``make browser``) driven by Playwright, one
browser for the whole run and a new page per load, and reports the median over ``--loads`` of: "ready" =
navigation start to the end of the page's own script (data decoded, scene built, first frame drawn, from
``roarmView.timing``), and "load event" = navigation start to the window's load event (the browser has
finished with the page, its first frame rendered by the GPU process, here SwiftShader's software GL).
The machine's load average is printed: on a shared 2-core machine the figures move with it.

Where the time goes (medians, ms, from the page's ``roarmView.timing``): "parse" = navigation start to the data's
JSON parsed (the HTML and three.js read), "context" = the WebGL context made, "build" = the scene and the panel made
(data decoded, geometry built), "frame" = the first frame handed to GL (shader compiles). "fps" = frames per second
while playing in a 1400 x 900 window (the issue's size): each animation frame moves to the next sample and draws,
counted over 3 s; "calls" = draw calls of one frame (three.js counts them); "GL" says whether the page found
software GL (then it draws without multisampling).

``--screenshot PATH`` also writes the README's picture: pick_place at its grasp, 1200 x 760 px.

``--fps-of A.html B.html ...``: only frames/s (as above) of the given page files, each in turn for 3 rounds in one
browser, so that two builds of one page (e.g. written by ``visualize-path`` before and after a change) meet the same
load; prints each round and the medians.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the Chromium driver shared with the browser tests

import browser as br  # noqa: E402

PLAY = """() => new Promise((done) => {
  let n = 0; const t0 = performance.now();
  function frame() {
    window.roarmView.setIndex(n % window.roarmView.data.n); n++;
    if (performance.now() - t0 < 3000) requestAnimationFrame(frame); else done([n, performance.now() - t0]);
  }
  requestAnimationFrame(frame);
})"""


def frames_per_second(chromium, url: str) -> tuple[float, int, bool]:
    """Frames per second while stepping through the samples in a 1400 x 900 window, the draw calls of a frame, and
    whether the page drew with software GL."""
    page, _ = br.open_page(chromium, url, {"width": 1400, "height": 900})
    try:
        frames, ms = page.evaluate(PLAY)
        return frames / ms * 1000.0, int(page.evaluate("window.roarmView.stats().calls")), bool(page.evaluate("window.roarmView.softwareGL"))
    finally:
        page.close()


def fps_of(pages: list[Path], rounds: int = 3) -> None:
    """Frames/s of each page file in turn, ``rounds`` times, in one browser (see the module doc)."""
    from playwright.sync_api import sync_playwright

    print(f"load average {os.getloadavg()[0]:.2f} (2 cores); frames/s at 1400 x 900, {rounds} rounds in turn")
    seen: list[list[float]] = [[] for _ in pages]
    with sync_playwright() as pw:
        chromium = br.launch(pw)
        for r in range(rounds):
            for k, p in enumerate(pages):
                seen[k].append(frames_per_second(chromium, p.resolve().as_uri())[0])
            print(f"round {r + 1}: " + "  ".join(f"{p.name} {f[-1]:.1f}" for p, f in zip(pages, seen)), flush=True)
        chromium.close()
    print(f"medians (load average now {os.getloadavg()[0]:.2f}): " + "  ".join(f"{p.name} {statistics.median(f):.1f}" for p, f in zip(pages, seen)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loads", type=int, default=5)
    ap.add_argument("--screenshot", type=Path, default=None)
    ap.add_argument("--fps-of", type=Path, nargs="+", default=None, metavar="PAGE")
    args = ap.parse_args()
    if br.chromium_path() is None:
        sys.exit("bench_view: Chromium not found (make browser, or set ROARMCTL_CHROMIUM)")
    if args.fps_of:
        fps_of(args.fps_of)
        return

    import matplotlib  # noqa: F401  (paid once, not per page)

    from roarmctl.errors import InputError
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.viz.web.document import view_document
    from roarmctl.viz.web.page import render_page, write_page

    plans = sorted((ROOT / "plans").glob("*.yaml"))
    print(f"load average {os.getloadavg()[0]:.2f} (2 cores); {args.loads} loads per page, medians")
    print(f"{'plan':<16} {'samples':>7} {'page MB':>8} {'build s':>8} {'ready ms':>9} {'load event ms':>14} "
          f"{'parse':>6} {'context':>8} {'build':>6} {'frame':>6} {'fps':>5} {'calls':>6} GL")
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        chromium = br.launch(pw)
        for p in plans:
            try:
                traj = plan_file(p, seed=None).trajectory
            except InputError as exc:  # a plans/ file that is not a plan by itself (e.g. a datagen template)
                print(f"{p.stem:<16} skipped: {exc.message}")
                continue
            builds = []
            for _ in range(3):
                t0 = time.perf_counter()
                doc = view_document(traj, name=p.name)
                render_page(doc)
                builds.append(time.perf_counter() - t0)
            out = write_page(doc, Path(tmp) / f"{p.stem}.html")
            ready, loaded, phases = [], [], []
            for _ in range(args.loads):
                page, watch = br.open_page(chromium, out.as_uri())
                page.wait_for_function("() => document.readyState === 'complete'")
                ready.append(page.evaluate("window.roarmView.timing.ready"))
                t = page.evaluate("window.roarmView.timing")
                phases.append([t["parsed"], t["context"] - t["parsed"], t["built"] - t["context"], t["drawn"] - t["built"]])
                loaded.append(page.evaluate("performance.timing.loadEventEnd - performance.timing.navigationStart"))
                if watch.errors:
                    sys.exit(f"bench_view: {p.name}: errors on the page: {watch.errors}")
                if args.screenshot is not None and p.stem == "pick_place" and len(ready) == 1:
                    page.click(".tick.event[data-kind=grasp]")
                    args.screenshot.parent.mkdir(parents=True, exist_ok=True)
                    page.screenshot(path=str(args.screenshot))
                page.close()
            fps, calls, soft = frames_per_second(chromium, out.as_uri())
            ph = [statistics.median(col) for col in zip(*phases)]
            print(f"{p.stem:<16} {doc['n']:>7} {out.stat().st_size / 1e6:>8.2f} {statistics.median(builds):>8.2f} "
                  f"{statistics.median(ready):>9.0f} {statistics.median(loaded):>14.0f} "
                  f"{ph[0]:>6.0f} {ph[1]:>8.0f} {ph[2]:>6.0f} {ph[3]:>6.0f} {fps:>5.1f} {calls:>6} {'software' if soft else 'GPU'}")
        chromium.close()
    if args.screenshot is not None:
        print(f"wrote {args.screenshot}")


if __name__ == "__main__":
    main()
