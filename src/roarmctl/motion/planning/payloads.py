"""A held object's mass, centre of mass and inertia in the torque limits, from grasp to release."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from roarmctl.motion.timing import TorqueModel, check_holding
from roarmctl.robot.dynamics import inverse_dynamics, solid_inertia
from roarmctl.robot.model import Inertial

if TYPE_CHECKING:
    from roarmctl.motion.planning.context import PlanContext
    from roarmctl.motion.timing import TorqueModel


def torque_model(ctx: PlanContext, base: np.ndarray, idx: list[int]) -> TorqueModel | None:
    """Torque limits of the joints ``idx`` for TOPP-RA (RNEA with the held payload, the other joints held at
    ``base`` (dof,) rad); None without limits."""
    if ctx.effort is None or not np.any(np.isfinite(ctx.effort[idx])) or not ctx.robot.inertials:
        return None
    robot, payload = ctx.robot, ctx.payload

    def inv_dyn(qa: np.ndarray, qda: np.ndarray, qdda: np.ndarray) -> np.ndarray:
        full = np.repeat(base[None, :], len(qa), axis=0)
        full[:, idx] = qa
        zd = np.zeros_like(full)
        fd, fdd = zd.copy(), zd.copy()
        fd[:, idx], fdd[:, idx] = qda, qdda
        return inverse_dynamics(robot, full, fd, fdd, payload=payload)[:, idx]

    return TorqueModel(inv_dyn, ctx.effort[idx], [robot.joint_names[i] for i in idx], ctx.payload_label)


def attach_payload(ctx: PlanContext, name: str, q: np.ndarray, label: str) -> None:
    """The held object ``name``'s mass, COM and inertia become part of the TCP link (from grasp to release);
    a load the arm cannot hold at ``q`` even at rest raises InfeasibleError."""
    spec = next(o for o in ctx.objects if o.name == name)
    if not spec.mass:
        return
    tcp = ctx.robot.kin.fk(q)
    rel = np.linalg.inv(tcp) @ ctx.object_pose[name]  # object frame in the TCP link frame
    com_obj = spec.com if spec.com is not None else np.zeros(3)
    inertia = spec.inertia if spec.inertia is not None else solid_inertia(spec.shape, spec.mass, spec.size, spec.radius, spec.length)
    rot = rel[:3, :3]
    ctx.payload = {ctx.robot.tcp_link: Inertial(float(spec.mass), rot @ com_obj + rel[:3, 3], rot @ inertia @ rot.T)}
    ctx.payload_label = f"'{name}' ({spec.mass:.2f} kg)"
    model = torque_model(ctx, q, ctx.arm)
    if model is not None:
        check_holding(model, q[None, ctx.arm], label)


def payload_entry(start: float, end: float, body: dict) -> dict:
    """A trajectory-file ``payloads`` entry for a held object: {link: Inertial} from ``start`` to ``end`` (s)."""
    (link, inertial), = body.items()
    r = lambda a: [round(float(v), 9) for v in a]  # noqa: E731
    return {"start": round(start, 9), "end": round(end, 9), "link": link, "mass": round(float(inertial.mass), 9),
            "com": r(inertial.com), "inertia": [r(row) for row in np.asarray(inertial.inertia)]}
