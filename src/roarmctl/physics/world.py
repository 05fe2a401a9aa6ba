"""The compiled MuJoCo model of a robot in its scene, seen in the description's terms.

``World`` holds ``mujoco.MjModel``/``MjData`` and the maps between them and the project's names:
joint values in ``robot.joint_names`` order and convention (``q``; MuJoCo's hinge angle is
``q + offset``), which link or scene item each geom belongs to (for contact reports), and the pose
of each free object. Units: m, kg, s, rad.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.errors import DescriptionError
from roarmctl.physics.mjcf import (
    TIMESTEP,
    BuiltDocument,
    JointDynamics,
    body_name,
    build_document,
    item_body_name,
    joint_name,
)
from roarmctl.robot.model import Robot

if TYPE_CHECKING:
    from types import ModuleType

    from roarmctl.motion.scene import Scene

#: MuJoCo's own warning texts (it would otherwise append them to MUJOCO_LOG.TXT in the working directory).
MESSAGES: list[str] = []


def _quiet_warnings(mujoco: ModuleType) -> None:
    """Keep MuJoCo's warnings in ``MESSAGES`` instead of a file in the user's working directory."""
    if mujoco.get_mju_user_warning() is None:
        mujoco.set_mju_user_warning(lambda text: MESSAGES.append(str(text)) if len(MESSAGES) < 100 else None)


MIN_DEPTH = 5e-5  # m: shapes that overlap less than this only touch (MuJoCo's soft contacts always overlap a little)


@dataclass
class Contact:
    """One contact of one physics step: owners ``a``/``b`` as ("link"|"item", name), ``depth`` (m, >= 0:
    how far the shapes overlap) and the world point (3,)."""

    a: tuple[str, str]
    b: tuple[str, str]
    depth: float
    point: np.ndarray


class World:
    """A robot and its scene in MuJoCo.

    Build with ``World(robot, scene, masses, dynamics)``; ``doc.notes`` lists the assumptions the model
    needed. Joint order everywhere is ``robot.joint_names``.
    """

    def __init__(self, robot: Robot, scene: Scene, masses: dict[str, float] | None = None,
                 dynamics: dict[str, JointDynamics] | None = None, *, timestep: float | None = None) -> None:
        import mujoco


        self.robot = robot
        self.doc: BuiltDocument = build_document(robot, scene, masses, dynamics,
                                                 timestep=TIMESTEP if timestep is None else timestep)
        try:
            self.model = mujoco.MjModel.from_xml_string(self.doc.xml)
        except ValueError as exc:  # MuJoCo's compiler refuses the description (degenerate mesh, inertia, ...)
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise DescriptionError(f"{robot.name}: MuJoCo cannot build a physics model of it: {first}",
                                   "check the description's inertias and meshes") from None
        self.data = mujoco.MjData(self.model)
        self._mujoco = mujoco
        _quiet_warnings(mujoco)
        m = self.model
        jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint_name(n)) for n in robot.joint_names]
        self.qpos_adr = np.array([m.jnt_qposadr[j] for j in jid], dtype=int)
        self.dof_adr = np.array([m.jnt_dofadr[j] for j in jid], dtype=int)
        offsets = {j.name: j.offset for j in robot.joints}
        self.offset = np.array([offsets[n] for n in robot.joint_names])
        # geom id -> owner index into self.owners (("link", name) | ("item", name))
        self.owners: list[tuple[str, str]] = []
        index: dict[tuple[str, str], int] = {}
        self.geom_owner = np.full(m.ngeom, -1, dtype=int)
        for name, owner in self.doc.geom_owner.items():
            g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, name)
            if owner not in index:
                index[owner] = len(self.owners)
                self.owners.append(owner)
            self.geom_owner[g] = index[owner]
        self.objects = list(self.doc.objects)
        self.object_qpos = {}
        for name in self.objects:
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"free:{name}")
            self.object_qpos[name] = int(m.jnt_qposadr[j])
        self.link_body = {link: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body_name(link)) for link in robot.link_names
                          if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body_name(link)) >= 0}
        # scene item -> its body (a point cloud's boxes are geoms of the world body: no body of its own)
        self.item_body = {o[1]: b for o in self.owners if o[0] == "item"
                          if (b := mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, item_body_name(o[1]))) >= 0}
        self._mimic = [(jj, robot.joint_names.index(jj.mimic)) for jj in robot.joints if jj.mimic is not None]
        self._mimic_adr = [int(m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, joint_name(jj.name))])
                           for jj, _ in self._mimic]

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Physics time, s."""
        return float(self.data.time)

    def set_q(self, q: npt.ArrayLike, qd: npt.ArrayLike | None = None) -> None:
        """Put the arm at ``q`` (dof,) rad (velocities ``qd`` or zero), mimic joints with it; recompute positions."""
        q = np.asarray(q, dtype=float)
        d = self.data
        d.qpos[self.qpos_adr] = q + self.offset
        for (jj, master), adr in zip(self._mimic, self._mimic_adr):
            d.qpos[adr] = q[master] + jj.offset
        d.qvel[self.dof_adr] = 0.0 if qd is None else np.asarray(qd, dtype=float)
        self._mujoco.mj_forward(self.model, d)

    def q(self) -> np.ndarray:
        """Joint values (dof,) rad in the description's convention."""
        return self.data.qpos[self.qpos_adr] - self.offset

    def qd(self) -> np.ndarray:
        """Joint speeds (dof,) rad/s."""
        return self.data.qvel[self.dof_adr].copy()

    def apply(self, torque: npt.ArrayLike) -> None:
        """Joint torques (dof,) N m (N for prismatic) for the next steps."""
        self.data.qfrc_applied[self.dof_adr] = torque

    def step(self, n: int = 1) -> None:
        """``n`` physics steps."""
        self._mujoco.mj_step(self.model, self.data, nstep=n)

    def object_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """(position (3,) m, quaternion (4,) w x y z) of a free object in the world frame."""
        a = self.object_qpos[name]
        return self.data.qpos[a:a + 3].copy(), self.data.qpos[a + 3:a + 7].copy()

    def link_pose(self, link: str) -> np.ndarray:
        """4x4 world pose of a link's body (after the last step)."""
        b = self.link_body[link]
        t = np.eye(4)
        t[:3, :3] = self.data.xmat[b].reshape(3, 3)
        t[:3, 3] = self.data.xpos[b]
        return t

    def contacts(self) -> list[Contact]:
        """Every contact of the current state whose shapes overlap by more than ``MIN_DEPTH``."""
        d = self.data
        n = d.ncon
        if n == 0:
            return []
        c = d.contact
        dist = np.asarray(c.dist[:n])
        out = []
        for k in np.flatnonzero(dist < -MIN_DEPTH):
            ga, gb = int(c.geom1[k]), int(c.geom2[k])
            oa, ob = self.geom_owner[ga], self.geom_owner[gb]
            if oa < 0 or ob < 0:
                continue
            out.append(Contact(self.owners[oa], self.owners[ob], float(-dist[k]), np.array(c.pos[k])))
        return out

    def warnings(self) -> list[str]:
        """MuJoCo's warnings of this run (instability, too many contacts, ...), one sentence each."""
        out = []
        kinds = {int(v): k.removeprefix("mjWARN_") for k, v in vars(self._mujoco.mjtWarning).items() if k.startswith("mjWARN_")}
        for k, name in sorted(kinds.items()):
            stat = self.data.warning[k]
            if stat.number:
                out.append(f"MuJoCo warned {stat.number} time(s): {name} (info {stat.lastinfo})")
        return out

    def actuator_free_bias(self) -> np.ndarray:
        """Gravity and velocity forces on the robot's joints (dof,) N m: MuJoCo's ``qfrc_bias``."""
        return self.data.qfrc_bias[self.dof_adr].copy()
