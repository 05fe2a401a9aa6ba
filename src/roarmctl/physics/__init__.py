"""Physics: a MuJoCo model of any robot description and its scene, servo models, and the open-loop run.

Modules (each one job):

* ``mjcf``: the MJCF document built from a ``Robot`` and a ``Scene`` (bodies, joint axes, inertias,
  collision shapes as the checker sees them, objects with masses, friction, gravity).
* ``world``: the compiled MuJoCo model and its bookkeeping (joint values in the description's
  convention, which link or scene item a contact belongs to, object poses).
* ``servo``: the servo models: the Feetech ST3235 (speed/acceleration profile in the servo's own
  units, position loop with the firmware's P gain, stall torque and torque-speed falloff) and a
  generic position servo for robots without servo data.
* ``actuation``: which servo drives which joint, and how a firmware command becomes a servo goal.
* ``servo_backend``: the physics servos behind the firmware simulator (``roarmctl.device``).
* ``sim_servos``: which servos an execute's simulated arm runs (physics or ideal), for the CLI and the API alike.
* ``run``: ``simulate``: a trajectory's commands (the streamer's schedule) played into the model.
* ``report``: what a run measured (tracking, torque, TCP, contacts, objects) and its run file.

``mujoco`` is imported only inside these modules: ``import roarmctl.physics`` is cheap.
"""
