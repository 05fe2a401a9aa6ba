"""The stages of planning one plan (``roarmctl.motion.pipeline`` runs them in order).

- ``context``: what every stage shares (plan, robot, checker, scaled limits, the world as it is so far);
- ``pieces``: the three forms a motion takes (a task's step, its untimed path, a timed piece) and path helpers;
- ``tasks``: tasks to steps, with the IK choice of every target;
- ``motions``: one free or straight motion: its path (OMPL + FCL, or IK along the line), timing and re-check;
- ``grasp``: the gripper and its jaws: grip width, gripper actions, the jaws during the motions beside them;
- ``blending``: joining timed motions without a stop (overlap in time, or a Ruckig corner move);
- ``payloads``: a held object's mass in the torque limits;
- ``assembly``: the timed pieces as one ``Trajectory``.
"""
