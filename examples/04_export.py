"""Export a trajectory for Foxglove (MCAP), ROS 2 (a bag folder) and a spreadsheet (CSV); draw it.

    python examples/04_export.py [TRAJ] [OUT_DIR]
"""

import sys
from pathlib import Path

import roarmctl.api as rc

if len(sys.argv) > 1:
    traj = rc.load_trajectory(sys.argv[1])
else:
    traj = rc.plan(Path(__file__).resolve().parents[1] / "plans" / "pick_place.yaml").trajectory
out = Path(sys.argv[2] if len(sys.argv) > 2 else "out")

for name in ("pick_place.mcap", "pick_place_bag", "pick_place.csv"):
    info = rc.export(traj, out / name)
    what = f"{info['rows']} rows" if "rows" in info else ", ".join(f"{t} x{n}" for t, n in info["topics"].items())
    print(f"{info['output']}: {what}")
print(f"drew {rc.draw(traj, out / 'pick_place.svg', dpi=50)}")
