"""Reading a plan file: roarmctl's bounded YAML reader against PyYAML's own C loader and ``json.loads`` of the same
document, on plans/obstacle.yaml with 0 and 200 boxes off the path (bench/scenes.py), interleaved in one process.

Run: .venv/bin/python bench/bench_yaml.py [--rounds 40]

Printed per document: its size, the median CPU time of ``roarmctl.validation.parse_yaml`` (libyaml's C parser and
composer, then our constructor: line numbers, bounds, refusals), of ``yaml.load(..., CSafeLoader)`` (the same C
parser with PyYAML's constructor, no bounds) and of ``json.loads`` of the same values; and the ratio of ours to
PyYAML's. CPU time (``time.process_time``), so the figure holds on a busy machine better than wall time does.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import boxes_off_path  # noqa: E402

from roarmctl.validation import parse_yaml  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def documents() -> dict[str, str]:
    """Name -> YAML text: the bundled obstacle plan as it is, and with 200 boxes (block and flow style)."""
    plain = (ROOT / "plans" / "obstacle.yaml").read_text()
    doc = yaml.safe_load(plain)
    doc["scene"]["obstacles"] = list(doc["scene"].get("obstacles") or []) + boxes_off_path(200)
    return {"obstacle.yaml": plain, "200 boxes, block": yaml.safe_dump(doc, sort_keys=False),
            "200 boxes, flow lists": yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)}


def cpu_ms(fn, rounds: int) -> float:
    """Median CPU time (ms) of ``fn()`` over ``rounds`` calls."""
    times = []
    for _ in range(rounds):
        c0 = time.process_time()
        fn()
        times.append(time.process_time() - c0)
    return statistics.median(times) * 1e3


def main() -> None:
    """Time the three readers on each document, interleaved, and print the medians."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=40)
    args = ap.parse_args()
    print(f"{'document':<24}{'bytes':>8}{'roarmctl ms':>13}{'CSafeLoader ms':>16}{'json ms':>9}{'ratio':>7}")
    for name, text in documents().items():
        js = json.dumps(yaml.safe_load(text))
        ours = cpu_ms(lambda t=text, n=name: parse_yaml(t, n), args.rounds)
        theirs = cpu_ms(lambda t=text: yaml.load(t, Loader=yaml.CSafeLoader), args.rounds)
        plain = cpu_ms(lambda j=js: json.loads(j), args.rounds)
        print(f"{name:<24}{len(text):>8}{ours:>13.2f}{theirs:>16.2f}{plain:>9.2f}{ours / theirs:>7.2f}")


if __name__ == "__main__":
    main()
