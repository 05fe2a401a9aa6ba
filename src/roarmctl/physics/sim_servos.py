"""Which servos the simulated arm of an execute runs, for the CLI's ``execute --sim --servos`` and
``roarmctl.api.execute(sim=True, servos=...)`` alike: the physics servos (MuJoCo, ``servo_backend``) or the ideal
kinematic ones the firmware simulator has by itself. Cheap to import: MuJoCo loads only when physics servos are made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from roarmctl.device.sag import wanted
from roarmctl.errors import InputError

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.robot.model import Robot

SIM_SERVOS = ("physics", "ideal")


def check_servos(servos: str, *, sim: bool) -> None:
    """Refuse a servo model other than ``SIM_SERVOS``, or other than the default "physics" without the simulator (a
    real arm has its own servos); ``InputError`` naming the option ``servos``."""
    if servos not in SIM_SERVOS:
        raise InputError(f"'{servos}' is not physics or ideal", option="servos")
    if servos != "physics" and not sim:
        raise InputError("only with the simulator (a real arm has its own servos)", option="servos")


def sim_servos(robot: Robot, traj: Trajectory, servos: str, *, sim: bool,
               sag: bool | None) -> tuple[Callable[[], Any] | None, bool]:
    """(the servo factory for ``PtySimulator(servos=...)``: physics servos in ``traj``'s scene, None for the ideal
    ones or a real arm; whether goals are sag-compensated: ``sag``, by default on except on ideal servos), after
    ``check_servos``."""
    check_servos(servos, sim=sim)
    ideal = sim and servos == "ideal"
    if not sim or ideal:
        return None, wanted(sag, ideal=ideal)
    from roarmctl.physics.servo_backend import for_firmware  # MuJoCo: only for physics servos

    return for_firmware(robot, traj), wanted(sag)
