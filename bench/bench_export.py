"""Export time and size of the demo trajectory (plans/pick_place.yaml) per format (medians over repeats).

Run: .venv/bin/python bench/bench_export.py [--repeats N]
The trajectory is planned once; each repeat builds the messages and writes the file (rosbags does
the CDR serialisation and the MCAP / sqlite3 storage). Imports are loaded before timing.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def size(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*")) if path.is_dir() else path.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    import rosbags.rosbag2  # noqa: F401 - imported before timing

    from roarmctl.api import plan
    from roarmctl.export import export

    traj = plan(ROOT / "plans" / "pick_place.yaml").trajectory
    with tempfile.TemporaryDirectory() as d:
        src = Path(d) / "pick_place.traj.json"
        traj.save(src)
        print(f"demo trajectory: {len(traj.times)} samples, {traj.duration:.2f} s")
        print(f"{'format':<8}{'median ms':>10}{'size kB':>10}  messages")
        for name in ("pick_place.mcap", "pick_place_bag", "pick_place.csv"):
            times = []
            for k in range(args.repeats):
                out = Path(d) / f"{k}_{name}"
                t0 = time.perf_counter()
                info = export(src, out)
                times.append(time.perf_counter() - t0)
            what = f"{info['rows']} rows" if "rows" in info else f"{sum(info['topics'].values())} in {len(info['topics'])} topics"
            print(f"{info['format']:<8}{statistics.median(times) * 1000:>10.0f}{size(out) / 1024:>10.0f}  {what}")


if __name__ == "__main__":
    main()
