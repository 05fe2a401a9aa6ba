"""Time a joint path (TOPP-RA under the joint limits), then save it like a planned trajectory.

    python examples/09_time_path.py [OUT_DIR]

As mplib's ``planner.TOPP(path, step)``: ``Planner.time(path)`` returns a ``Trajectory`` sampled at
100 Hz, every sample checked again; ``save_trajectory``, ``draw``, ``export`` and ``execute`` take it.
"""

import sys
from pathlib import Path

import roarmctl.api as rc

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "out")
robot = rc.load_robot("roarm_m3_pro")
planner = rc.Planner(robot, velocity_scale=0.5, acceleration_scale=0.5, seed=1)

path = planner.plan_to_joints(robot.named_poses["home"], robot.named_poses["ready"])
traj = planner.time(path)
print(f"{traj.duration:.2f} s, {len(traj.times)} samples")
rc.save_trajectory(traj, out_dir / "timed.traj.json")
