"""The physics servos behind the firmware: ``roarmctl.device``'s servo-model interface on MuJoCo.

``PhysicsServos`` answers what the firmware's servo bus asks (``roarmctl.device.servos.ServoModel``):
goals, speed and acceleration registers and torque switches go in, present positions and loads come
out, all in servo steps of the firmware's six joints (``M3_FIELDS``: base, shoulder, elbow, wrist,
roll, hand). Between two calls the model steps MuJoCo (``World``) with the servo torques of
``roarmctl.physics.servo``. A firmware joint the robot does not have (the M2's wrist and roll) is a
servo without a load: its position is its profile.

``PhysicsServos.recorder`` (optional) is called after every physics step with the backend, so a
run can record what it needs at the physics rate.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.device.fwmath import INIT_RAD
from roarmctl.device.protocol import M3_FIELDS, WireMap
from roarmctl.device.servos import servo_goal, servo_reading
from roarmctl.motion.scene import Scene
from roarmctl.physics.actuation import Actuation, for_robot
from roarmctl.physics.servo import ACC_UNIT, ST3235, ServoBank, profile_step, quantise_speed
from roarmctl.physics.setup import build
from roarmctl.physics.world import World
from roarmctl.robot.loader import load_robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

N_FIRMWARE_JOINTS = 6


class PhysicsServos:
    """Six firmware joints on a MuJoCo ``World`` driven by ``actuation`` (a streamed RoArm).

    ``t0`` is the firmware clock (s) that corresponds to the world's time 0 (None: the time of the first
    ``advance``); ``q0`` (dof,) the arm's pose at that time (torque on, at rest).
    """

    def __init__(self, world: World, actuation: Actuation, q0: npt.ArrayLike, t0: float | None = 0.0,
                 recorder: Callable[[PhysicsServos], None] | None = None) -> None:
        self.world = world
        self.act = actuation
        self.bank = actuation.bank
        self.t0 = t0  # None: the firmware clock of the first call
        self.recorder = recorder
        self.dt = float(world.model.opt.timestep)
        self.channel = np.full(N_FIRMWARE_JOINTS, -1, dtype=int)
        for c, k in enumerate(actuation.firmware_index):
            if k >= 0:
                self.channel[k] = c
        q0 = np.asarray(q0, dtype=float)
        world.set_q(q0)
        self.bank.reset(q0)
        # joints without a physical servo: the profile is the position (steps)
        self.phantom_pos = np.full(N_FIRMWARE_JOINTS, 2047.0)  # the firmware's middle step
        self.phantom_vel = np.zeros(N_FIRMWARE_JOINTS)
        self.phantom_goal = np.full(N_FIRMWARE_JOINTS, 2047.0)
        self.phantom_spd = np.zeros(N_FIRMWARE_JOINTS)
        self.phantom_acc = np.zeros(N_FIRMWARE_JOINTS)
        self.phantom_on = np.ones(N_FIRMWARE_JOINTS, dtype=bool)
        self._damping_dirty = True
        self._phantoms = [j for j in range(N_FIRMWARE_JOINTS) if self.channel[j] < 0]

    # ------------------------------------------------------------------ ServoModel
    def command(self, joints: Sequence[int], goal: Sequence[float], spd: Sequence[float], acc: Sequence[float]) -> None:
        """Goal (steps), speed and acceleration registers of firmware joints (``ServoModel.command``)."""
        ch, g, s, a = [], [], [], []
        for j, gg, ss, aa in zip(joints, goal, spd, acc):
            c = self.channel[j]
            gg = servo_goal(gg)  # the servo's own angle limits: one turn
            if c >= 0:
                ch.append(int(c))
                g.append(gg)
                s.append(ss)
                a.append(aa)
                if not self.bank.enabled[c]:
                    self.bank.set_torque(True, [int(c)], self.world.q())
                    self._damping_dirty = True
            else:
                self.phantom_goal[j], self.phantom_spd[j], self.phantom_acc[j] = gg, ss, aa
                self.phantom_on[j] = True
        if ch:
            self.bank.command(ch, g, s, a)

    def set_torque(self, on: bool, joints: Sequence[int] | None = None) -> None:
        """Torque enable of firmware joints (default all); limp joints coast (no back-EMF braking)."""
        idx = range(N_FIRMWARE_JOINTS) if joints is None else joints
        ch = [int(self.channel[j]) for j in idx if self.channel[j] >= 0]
        self.bank.set_torque(on, ch, self.world.q())
        for j in idx:
            if self.channel[j] < 0:
                self.phantom_on[j] = bool(on)
                self.phantom_vel[j] = 0.0
        self._damping_dirty = True

    def advance(self, t: float) -> None:
        """Step the physics until its time reaches ``t - t0`` (whole steps: at most one step short)."""
        if self.t0 is None:
            self.t0 = float(t)
        w = self.world
        target = t - self.t0
        while w.data.time + 0.5 * self.dt <= target:
            self.step()

    def positions(self) -> np.ndarray:
        """(6,) present positions, steps (float)."""
        out = self.phantom_pos.copy()
        steps = self.bank.steps(self.world.q())
        for c, k in enumerate(self.act.firmware_index):
            out[k] = servo_reading(steps[c])  # the encoder reads one turn
        return out

    def torque(self) -> np.ndarray:
        """(6,) torque enable, bool."""
        out = self.phantom_on.copy()
        for c, k in enumerate(self.act.firmware_index):
            out[k] = self.bank.enabled[c]
        return out

    def loads(self) -> np.ndarray:
        """(6,) present load, +-1000 (the duty in 0.1 %)."""
        out = np.zeros(N_FIRMWARE_JOINTS)
        loads = self.bank.loads()
        for c, k in enumerate(self.act.firmware_index):
            out[k] = loads[c]
        return out

    # ------------------------------------------------------------------ physics
    def step(self) -> None:
        """One physics step: servo torques from the present state, then MuJoCo."""
        w = self.world
        if self._damping_dirty:
            w.model.dof_damping[w.dof_adr[self.bank.joint]] = self.bank.joint_damping()
            self._damping_dirty = False
        physics_step(w, self.bank, self.dt)
        for j in self._phantoms:
            if self.phantom_on[j]:
                v = quantise_speed(self.phantom_spd[j], ST3235.speed_quantum)
                a = self.phantom_acc[j] * ACC_UNIT if self.phantom_acc[j] > 0 else math.inf
                self.phantom_pos[j], self.phantom_vel[j] = profile_step(
                    self.phantom_pos[j], self.phantom_vel[j], self.phantom_goal[j], v if v > 0 else math.inf, a, self.dt)
        if self.recorder is not None:
            self.recorder(self)


def physics_step(world: World, bank: ServoBank, dt: float, profile: bool = True) -> None:
    """One step of ``world``: each servo's duty torque from the present joint values (its profile advanced
    by ``dt`` s unless ``profile`` is False), applied at its joint, then ``mj_step``. The servos' back-EMF
    braking is the joints' damping (set by the caller whenever torque switches)."""
    d = world.data
    q = d.qpos[world.qpos_adr] - world.offset
    tau = bank.torques(q.tolist(), dt, profile)
    applied = d.qfrc_applied
    applied[world.dof_adr] = 0.0
    for j, t in zip(bank.joint, tau):
        applied[world.dof_adr[j]] += t
    world.step()


def desk() -> Scene:
    """The scene of an arm without a trajectory (``sim-device``): a 1 x 1 m table whose top is the base's plane, so
    that the arm meets it (and itself) as a real arm on a desk does, instead of swinging through where it stands."""
    return Scene.from_dict({"items": [{"name": "table", "role": "table", "shape": "box", "size": [1.0, 1.0, 0.02],
                                       "xyz": [0.0, 0.0, -0.01], "rpy": [0.0, 0.0, 0.0]}]})


def for_firmware(robot: Robot, traj: Trajectory | None = None) -> Callable[[], PhysicsServos]:
    """A zero-argument factory of physics servos for the firmware simulator (``roarmctl.device``'s
    ``PtySimulator(servos=...)``; called in its process): ``robot`` in ``traj``'s scene with its payload
    masses (on the ``desk()`` without ``traj``), standing at the firmware's boot pose (``INIT_RAD``: elbow
    pi/2, gripper closed), its clock starting at the firmware's first call."""

    def make() -> PhysicsServos:

        if traj is not None:

            setup = build(traj, robot)
            world, act = setup.world, setup.actuation
        else:
            act = for_robot(robot)
            world = World(robot, desk(), None, act.dynamics(robot))
        wm = WireMap(robot)
        q0 = wm.from_wire({f: INIT_RAD[M3_FIELDS.index(f)] for f in wm.field_names})
        return PhysicsServos(world, act, q0, t0=None)

    return make


def roarm_m3_pro() -> PhysicsServos:
    """Physics servos of the bundled RoArm-M3 Pro in an empty world: a zero-argument factory for
    ``bench/bench_stream.py --servos roarmctl.physics.servo_backend:roarm_m3_pro``."""
    return for_firmware(load_robot("roarm_m3_pro"))()
