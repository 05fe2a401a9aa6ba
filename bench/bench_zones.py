"""What zones cost and save in motion time (issue 32): plans/pick_place.yaml and the issue's six moves (down to 4 cm
above the table and up again, on both sides of the RoArm), each at limits.zone 0 (every target reached), 1 cm and
3 cm, and with blending off; and the six moves as planned before zones (blends not bounded by the targets).

Run: .venv/bin/python bench/bench_zones.py

Printed per plan and zone: the trajectory's duration (s; a function of the plan and seed, not of the machine) and the
table's largest miss (mm). The durations are the same on an idle or a busy machine.
"""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import yaml

import roarmctl.api as rc

ROOT = Path(__file__).resolve().parents[1]
SIX = [(0.25, -0.15, 0.12), (0.25, -0.15, 0.04), (0.25, -0.15, 0.12), (0.25, 0.15, 0.12), (0.25, 0.15, 0.04), (0.25, 0.15, 0.12)]


def six_moves() -> dict:
    return {"robot": "roarm_m3_pro", "start": "home",
            "scene": {"table": {"shape": "box", "size": [0.80, 0.60, 0.02], "xyz": [0.15, 0.0, -0.01]}},
            "tasks": [{"move": {"xyz": list(p)}} for p in SIX]}


def variants(plan: dict) -> list[tuple[str, dict]]:
    out = []
    for label, limits in (("zone 0 (reached)", {"zone": 0.0}), ("zone 1 cm", {"zone": 0.01}), ("zone 3 cm", {"zone": 0.03}),
                          ("blend: false", {"blend": False})):
        p = copy.deepcopy(plan)
        p["limits"] = {**p.get("limits", {}), **limits}
        out.append((label, p))
    return out


def main() -> int:
    pick_place = yaml.safe_load((ROOT / "plans" / "pick_place.yaml").read_text())
    for name, plan in (("plans/pick_place.yaml", pick_place), ("the issue's six moves", six_moves())):
        print(name)
        for label, p in variants(plan):
            traj = rc.plan(p, base_dir=ROOT / "plans").trajectory
            worst = max(t["distance"] for t in traj.targets)
            print(f"  {label:18s} {traj.duration:6.2f} s   {len(traj.targets)} targets, largest miss {worst * 1e3:5.1f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
