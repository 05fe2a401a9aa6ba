"""Inspect a trajectory: duration, events, how close it comes to each target, joint positions at chosen times, the
TCP path and speed.

    python examples/02_inspect_trajectory.py [TRAJ]     (default: plans the bundled pick_place.yaml)
"""

import sys
from pathlib import Path

import numpy as np

import roarmctl.api as rc

if len(sys.argv) > 1:
    traj = rc.load_trajectory(sys.argv[1])  # checked against the robot's limits
else:
    traj = rc.plan(Path(__file__).resolve().parents[1] / "plans" / "pick_place.yaml").trajectory

robot = rc.load_robot(traj.robot)
print(f"{traj.robot}: {len(traj.joint_names)} joints, {traj.duration:.2f} s, {len(traj.times)} samples")
for e in traj.events:
    print(f"  {e.kind:8s} at {e.time:5.2f} s  {e.label}")
for row in traj.targets:  # every target the plan names: reached (zone 0) or passed within its zone
    print(f"  {row['kind']:8s} target of {row['name']}: {row['distance'] * 1e3:.1f} mm at {row['time']:.2f} s "
          f"(zone {row['zone'] * 1e3:.0f} mm, {'reached' if row['reached'] else 'OUTSIDE'})")

t = np.linspace(0.0, traj.duration, 5)
q = rc.sample(traj, t)  # (5, dof) rad
tcp = robot.kin.fk(q)[:, :3, 3]  # (5, 3) m
for ti, p in zip(t, tcp):
    print(f"  t = {ti:5.2f} s  TCP = ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m")

speed = np.linalg.norm(robot.kin.tcp_velocity(traj.positions, traj.velocities[:, robot.arm_indices]), axis=1)
print(f"peak TCP speed {speed.max():.3f} m/s at {traj.times[speed.argmax()]:.2f} s")

msg = rc.to_joint_trajectory(traj)  # a trajectory_msgs/JointTrajectory-shaped dict
print(f"JointTrajectory: {len(msg['points'])} points, last at {msg['points'][-1]['time_from_start']}")
