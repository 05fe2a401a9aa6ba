"""Is a configuration valid? Within the limits, free of collisions, clear of singularities, and why not.

    python examples/06_is_valid.py [OUT_DIR]

As mplib's ``planner.check_for_collision(qpos)``: ``Planner.is_valid(q)`` returns a ``Validity`` that is
true in an ``if`` and carries the reason when it is not.
"""

import json
import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
scene = rc.Scene()
scene.add_box("table", (0.8, 0.6, 0.02), (0.15, 0.0, -0.01), role="table")
planner = rc.Planner(robot, scene)

answers = {}
for name, q in {"home": robot.named_poses["home"].tolist(), "into the desk": [0.0, 1.4, 1.2, 0.0, 0.0],
                "elbow past its limit": [0.0, 0.0, 3.5, 0.0, 0.0]}.items():
    v = planner.is_valid(q)
    answers[name] = [v.valid, v.reason]
    print(f"{name}: {'valid' if v else 'invalid: ' + v.reason}")
out_dir.mkdir(parents=True, exist_ok=True)
(out_dir / "is_valid.json").write_text(json.dumps(answers))
