"""A built simulation: the physics model of a trajectory's robot and scene, its servos, the trajectory's
holds (which object each payload carries) and the notes the building made. ``run`` plays a trajectory
into it; ``servo_backend`` puts it behind the firmware simulator."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.device.schedule import sample
from roarmctl.motion.scene import Scene
from roarmctl.physics.actuation import Actuation, for_robot
from roarmctl.physics.contacts import Hold, holds_from
from roarmctl.physics.world import World
from roarmctl.robot.model import Robot

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory

MATCH_TOLERANCE = 0.005  # m: a payload's centre at its grasp names the object within this distance


@dataclass
class Setup:
    """A built simulation: the world, its servos, the holds of the trajectory and the notes made."""

    world: World
    actuation: Actuation
    holds: list[Hold]
    objects_of_payloads: list[str | None]
    notes: list[str] = field(default_factory=list)


def payload_objects(traj: Trajectory, robot: Robot, scene: Scene) -> list[str | None]:
    """The object each payload of ``traj`` carries: the scene object whose centre lies where the payload's
    centre of mass is at its grasp (planned pose), or None."""

    objects = [i for i in scene.items if i.role == "object"]
    out: list[str | None] = []
    for p in traj.payloads:
        q = sample(traj, float(p["start"]))
        t = robot.kin.fk(robot.full_q(q), p["link"])
        c = t[:3, :3] @ np.asarray(p["com"], dtype=float) + t[:3, 3]
        best = min(objects, key=lambda i: float(np.linalg.norm(i.xyz - c)), default=None)
        out.append(best.name if best is not None and np.linalg.norm(best.xyz - c) <= MATCH_TOLERANCE else None)
    return out


def build(traj: Trajectory, robot: Robot, *, masses: dict[str, float] | None = None) -> Setup:
    """The physics model of ``traj``'s robot and scene, its servos, and the trajectory's holds; ``masses``
    (object name -> kg) overrides the payloads' masses."""

    scene = Scene.from_dict(traj.scene)
    names = payload_objects(traj, robot, scene)
    given = {n: float(p["mass"]) for n, p in zip(names, traj.payloads) if n is not None}
    given.update(masses or {})
    act = for_robot(robot, traj)
    world = World(robot, scene, given, act.dynamics(robot))
    # what the description lacks or left out (a jaw mesh not found, a link without inertia), as plan says it
    notes = list(robot.notes) + [n for n in world.doc.notes if n not in robot.notes] + list(act.notes)
    for k, n in enumerate(names):
        if n is None:
            notes.append(f"payload {k + 1} (grasp at {traj.payloads[k]['start']:.2f} s) matches no object of the scene")
    return Setup(world, act, holds_from(traj, names), names, notes)
