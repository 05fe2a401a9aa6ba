"""``simulate``: a trajectory played open loop into the physics model, faster than real time.

For a RoArm the servos get exactly what ``execute`` would send: the streamer's schedule
(``roarmctl.device.streamer.build_schedule``: the same rate, strategy, speed scale and ``T:102``/``T:101``
commands), each applied at its tick time plus the link latency the schedule assumes
(``default_latency``), turned into servo goals by the firmware's own arithmetic
(``roarmctl.device.fwmath.command_to_goal``: its clamps, rounding to steps and joint signs). Other
robots' generic drives follow the planned motion itself. After the last command the model runs
``Options.settle`` seconds more, so that what the arm and the objects come to rest at is measured.

Every physics step records the joint values and speeds and each servo's duty; contacts, every
``CONTACT_EVERY`` steps, go through ``roarmctl.physics.contacts`` (only unintended ones are kept, as
episodes); objects' poses are sampled at ``Options.track_rate``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.checks import Bound, check_options
from roarmctl.device.fwmath import command_to_goal
from roarmctl.device.protocol import M3_FIELDS
from roarmctl.device.schedule import (
    DEFAULT_STRATEGY,
    MAX_LINK_RATE,
    STRATEGIES,
    build_schedule,
    default_latency,
    sample,
)
from roarmctl.errors import RoarmError
from roarmctl.formats import MIN_SPEED_SCALE
from roarmctl.physics.actuation import Actuation
from roarmctl.physics.contacts import Episode, Episodes, Policy
from roarmctl.physics.servo_backend import PhysicsServos, physics_step
from roarmctl.physics.setup import Setup, build
from roarmctl.physics.world import World
from roarmctl.robot.dynamics import inverse_dynamics
from roarmctl.robot.model import Robot

if TYPE_CHECKING:
    from roarmctl.device.schedule import Tick
    from roarmctl.motion.trajectory import Trajectory

CONTACT_EVERY = 2  # physics steps between two looks at the contacts (2 ms: an episode shorter than that is missed)


SIMULATE_BOUNDS: dict[str, Bound] = {
    "rate": Bound(0.0, MAX_LINK_RATE, strict_lo=True),  # Hz, as execute's
    "strategy": Bound(choices=tuple(STRATEGIES)),
    "speed_scale": Bound(MIN_SPEED_SCALE, 1.0),
    "settle": Bound(0.0, 60.0),  # s
    "tolerance": Bound(1e-4, 1.0),  # m
    "track_rate": Bound(0.0, 1000.0, strict_lo=True),  # Hz
    "feedback_rate": Bound(0.0, 1000.0, strict_lo=True),  # Hz
    "sag": Bound(flag=True),
    "frame_rate": Bound(0.0, 1000.0),  # Hz; 0: no frames
}


@dataclass(frozen=True)
class Options:
    """How to run: the streamer's ``rate`` (Hz), ``strategy`` and ``speed_scale``; ``settle`` (s) after the
    last command; ``tolerance`` (m) of a placement; ``track_rate`` (Hz) of the run file's tracks and
    ``feedback_rate`` (Hz) of its feedback lines. Checks its own fields when made (``SIMULATE_BOUNDS``: NaN,
    infinities, wrong types and values out of range raise ``OptionError`` naming the field), as execute's
    ``StreamConfig`` does; simulate (CLI and API) and datagen's episodes build one."""

    rate: float = 50.0  # roarmctl.device.schedule.DEFAULT_RATE
    strategy: str = DEFAULT_STRATEGY  # what execute sends by default
    speed_scale: float = 1.0
    settle: float = 1.0
    tolerance: float = 0.010
    track_rate: float = 50.0
    feedback_rate: float = 25.0
    sag: bool = True  # the schedule's sag compensation (roarmctl.device.sag), on as execute sends it by default
    frame_rate: float = 0.0  # Hz: the whole state (MuJoCo qpos) at frame k / frame_rate, for rendering (0: none)

    def __post_init__(self) -> None:
        check_options(self, SIMULATE_BOUNDS)


@dataclass
class Recording:
    """What a run recorded. Physics times (s) from the start of the motion; ``t``/``q``/``qd`` (N, dof)
    every physics step, ``duty`` (N, channels); ``track_t`` (M,) and ``objects``: name -> (xyz (M, 3) m,
    quat (M, 4) w x y z) at the track rate; ``commands``: (time, command dict, tick) applied; ``episodes``:
    unintended contacts; ``wall`` s the run took, ``cpu`` s of this thread's CPU time (the run is one thread: on
    a shared machine ``wall`` includes waiting for a core, ``cpu`` is what one free core would take)."""

    dt: float
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    duty: np.ndarray
    track_t: np.ndarray
    objects: dict[str, tuple[np.ndarray, np.ndarray]]
    commands: list[tuple[float, dict[str, Any], int]]
    episodes: list[Episode]
    wall: float = 0.0
    cpu: float = 0.0
    frame_t: np.ndarray | None = None  # (F,) s: the physics step nearest each frame time k / frame_rate
    frame_qpos: np.ndarray | None = None  # (F, nq): MuJoCo's qpos at those steps (arm, gripper, free objects)


def simulate(traj: Trajectory, robot: Robot, options: Options | None = None, *, setup: Setup | None = None,
             progress: Callable[[float, float], None] | None = None,
             schedule: list[Tick] | None = None) -> tuple[Setup, Recording]:
    """Run ``traj`` on the physics model of ``robot``; ``progress(done_s, total_s)`` is called about every
    0.1 s of simulated time. ``schedule``: the streamer's schedule of ``traj`` under ``options`` when the caller
    built it already (to refuse its input errors before the model is built), else built here. Returns the setup and
    what was recorded."""
    options = options or Options()
    setup = setup or build(traj, robot)
    world, act = setup.world, setup.actuation
    scene_roles = {o[1]: r for o, r in _roles(traj).items()}
    policy = Policy(robot.jaw_links, scene_roles, setup.holds, 1.0 / options.speed_scale)
    rec = _Recorder(world, act, policy, options)
    t_wall, t_cpu = time.perf_counter(), time.thread_time()
    if act.streamed:
        _drive_streamed(traj, robot, setup, options, rec, progress, schedule)
    else:
        _drive_generic(traj, robot, setup, options, rec, progress)
    out = rec.result()
    out.wall = time.perf_counter() - t_wall
    out.cpu = time.thread_time() - t_cpu
    setup.notes.extend(w for w in world.warnings() if w not in setup.notes)
    return setup, out


def _roles(traj: Trajectory) -> dict[tuple[str, str], str]:
    return {("item", str(i["name"])): str(i["role"]) for i in traj.scene.get("items", [])}


class _Recorder:
    """Called after every physics step: joint state, duty, contacts, object tracks."""

    def __init__(self, world: World, act: Actuation, policy: Policy, options: Options) -> None:
        self.world = world
        self.act = act
        self.episodes = Episodes(policy)
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.qd: list[np.ndarray] = []
        self.duty: list[list[float]] = []
        self.track_every = max(1, int(round(1.0 / (options.track_rate * world.model.opt.timestep))))
        self.track_t: list[float] = []
        self.tracks: dict[str, tuple[list, list]] = {n: ([], []) for n in world.objects}
        self.commands: list[tuple[float, dict[str, Any], int]] = []
        self._n = 0
        self.frame_period = 1.0 / options.frame_rate if options.frame_rate > 0 else 0.0
        self.frame_t: list[float] = []
        self.frame_qpos: list[np.ndarray] = []

    def __call__(self, _servos: object = None) -> None:
        w = self.world
        t = w.time
        self.t.append(t)
        self.q.append(w.data.qpos[w.qpos_adr] - w.offset)
        self.qd.append(w.data.qvel[w.dof_adr].copy())
        self.duty.append(list(self.act.bank.duty))
        if w.data.ncon and self._n % CONTACT_EVERY == 0:
            self.episodes.add(t, w.contacts())
        if self._n % self.track_every == 0:
            self.track_t.append(t)
            for name, (xs, qs) in self.tracks.items():
                p, r = w.object_pose(name)
                xs.append(p)
                qs.append(r)
        half = 0.5 * float(w.model.opt.timestep)
        if self.frame_period and t + half >= len(self.frame_t) * self.frame_period:  # the step nearest the frame time
            self.frame_t.append(t)
            self.frame_qpos.append(w.data.qpos.copy())
        self._n += 1

    def result(self) -> Recording:
        dof = len(self.world.robot.joint_names)
        return Recording(
            float(self.world.model.opt.timestep), np.array(self.t), np.array(self.q).reshape(-1, dof),
            np.array(self.qd).reshape(-1, dof), np.array(self.duty).reshape(len(self.t), -1), np.array(self.track_t),
            {n: (np.array(xs).reshape(-1, 3), np.array(qs).reshape(-1, 4)) for n, (xs, qs) in self.tracks.items()},
            self.commands, self.episodes.result(),
            frame_t=np.array(self.frame_t) if self.frame_period else None,
            frame_qpos=np.array(self.frame_qpos).reshape(len(self.frame_t), -1) if self.frame_period else None)


def _progress_every(total: float, progress: Callable[[float, float], None] | None, done: float,
                    last: list[float]) -> None:
    if progress is not None and done - last[0] >= 0.1:
        last[0] = done
        progress(done, total)


def _drive_streamed(traj: Trajectory, robot: Robot, setup: Setup, options: Options, rec: _Recorder,
                    progress: Callable[[float, float], None] | None, schedule: list[Tick] | None = None) -> None:

    if schedule is None:
        schedule = build_schedule(traj, robot, rate=options.rate, speed_scale=options.speed_scale,
                                  strategy=options.strategy, sag=options.sag)
    latency = default_latency(options.rate)
    servos = PhysicsServos(setup.world, setup.actuation, traj.positions[0], recorder=rec)
    rec()  # the state at time 0
    total = schedule[-1].t + latency + options.settle
    last = [0.0]
    for k, tick in enumerate(schedule):
        t_apply = tick.t + latency
        _advance(servos, t_apply, total, progress, last)
        for cmd in tick.commands:
            _apply(servos, cmd, M3_FIELDS, command_to_goal)
            rec.commands.append((tick.t, cmd, k))
    _advance(servos, total, total, progress, last)
    if progress is not None:
        progress(total, total)


def _advance(servos: PhysicsServos, t: float, total: float, progress: Callable[[float, float], None] | None,
             last: list[float]) -> None:
    """``servos.advance(t)`` in slices of 0.1 s so that progress is reported."""
    w = servos.world
    while w.time + 1e-9 < t - servos.dt * 0.5:
        servos.advance(min(t, w.time + 0.1))
        _progress_every(total, progress, w.time, last)


def _apply(servos: PhysicsServos, cmd: dict[str, Any], fields: Sequence[str],
           to_goal: Callable[[int, float], float]) -> None:
    """One T:102 (every field given) or T:101 (one joint, 1-based) as the firmware writes it to the servos."""
    code = cmd.get("T")
    if code == 102:
        ks = [k for k, f in enumerate(fields) if f in cmd]
        servos.command(ks, [float(to_goal(k, float(cmd[fields[k]]))) for k in ks], [float(cmd.get("spd", 0))] * len(ks),
                       [float(cmd.get("acc", 0))] * len(ks))
    elif code == 101:
        k = int(cmd["joint"]) - 1
        servos.command([k], [float(to_goal(k, float(cmd["rad"])))], [float(cmd.get("spd", 0))], [float(cmd.get("acc", 0))])


def _drive_generic(traj: Trajectory, robot: Robot, setup: Setup, options: Options, rec: _Recorder,
                   progress: Callable[[float, float], None] | None) -> None:
    """Generic drives: the reference is the planned position and speed at every physics step."""

    w, bank = setup.world, setup.actuation.bank
    q0 = traj.positions[0]
    w.set_q(q0)
    bank.reset(q0)
    w.model.dof_damping[w.dof_adr[bank.joint]] = bank.joint_damping()
    rec()
    dt = float(w.model.opt.timestep)
    t_end = traj.duration / options.speed_scale
    total = t_end + options.settle
    n = int(math.ceil(total / dt - 1e-9))
    times = np.minimum(np.arange(1, n + 1) * dt, t_end) * options.speed_scale
    q_ref = sample(traj, times)
    qd_ref = np.column_stack([np.interp(times, traj.times, traj.velocities[:, j]) for j in range(robot.dof)])
    qdd_ref = np.column_stack([np.interp(times, traj.times, traj.accelerations[:, j]) for j in range(robot.dof)])
    qd_ref *= options.speed_scale
    qdd_ref *= options.speed_scale ** 2
    try:  # the torque the planned motion needs, fed forward (robots without inertias: none)
        tau_ref = inverse_dynamics(robot, q_ref, qd_ref, qdd_ref)
    except RoarmError:
        tau_ref = np.zeros_like(q_ref)
    last = [0.0]
    for k in range(n):
        bank.follow(q_ref[k], qd_ref[k], tau_ref[k])
        physics_step(w, bank, dt, profile=False)
        rec()
        _progress_every(total, progress, w.time, last)
    if progress is not None:
        progress(total, total)
