"""The robot description: plain dataclasses, no file formats and no maths beyond transforms.

Units everywhere: metres, radians, seconds, kilograms. A configuration vector ``q`` holds every
actuated joint in ``Robot.joint_names`` order; where the robot has a gripper, it is last.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.robot.kinematics import Kinematics

if TYPE_CHECKING:
    from roarmctl.robot.meshes import MeshGeometry

JointKind = Literal["revolute", "prismatic", "fixed"]
ShapeKind = Literal["box", "cylinder", "sphere", "capsule", "mesh"]


def transform(xyz: Iterable[float] = (0.0, 0.0, 0.0), rpy: Iterable[float] = (0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from a translation (m) and URDF roll-pitch-yaw (rad).

    URDF convention: R = Rz(yaw) @ Ry(pitch) @ Rx(roll).
    """
    r, p, y = (float(v) for v in rpy)
    if r == p == y == 0.0 and math.copysign(1.0, r) + math.copysign(1.0, p) + math.copysign(1.0, y) == 3.0:
        # most scene items (+0.0 everywhere): the matrix below, bit for bit (-sin 0 is -0.0)
        t = np.eye(4)
        t[2, 0] = -0.0
        t[:3, 3] = [float(v) for v in xyz]
        return t
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    t = np.eye(4)
    t[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    t[:3, 3] = [float(v) for v in xyz]
    return t


def axis_angle(axis: npt.ArrayLike, angle: float) -> np.ndarray:
    """4x4 rotation by ``angle`` (rad) about the unit 3-vector ``axis`` (Rodrigues' formula)."""
    k = np.asarray(axis, dtype=float)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    t = np.eye(4)
    t[:3, :3] = np.eye(3) + np.sin(angle) * kx + (1.0 - np.cos(angle)) * (kx @ kx)
    return t


def rpy_from_matrix(rot: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (rad, shape (3,)) of a 3x3 rotation; inverse of ``transform``'s rotation."""
    pitch = np.arctan2(-rot[2, 0], np.hypot(rot[0, 0], rot[1, 0]))
    if abs(np.cos(pitch)) < 1e-9:  # gimbal lock: put everything in yaw
        return np.array([0.0, pitch, np.arctan2(-rot[0, 1], rot[1, 1])])
    return np.array([np.arctan2(rot[2, 1], rot[2, 2]), pitch, np.arctan2(rot[1, 0], rot[0, 0])])


def quaternions(rot: npt.ArrayLike) -> np.ndarray:
    """Unit quaternions (x, y, z, w), shape (..., 4), w >= 0, of rotation matrices, shape (..., 3, 3).

    Shepperd's method: each matrix takes the formula of its largest of (trace, m00, m11, m22), so the square root
    is of a number >= 1 and the division never by a small one (S. W. Shepperd, "Quaternion from rotation matrix",
    J. Guidance and Control 1(3), 1978)."""
    m = np.asarray(rot, dtype=float)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    m00, m11, m22 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    tr = m00 + m11 + m22
    q = np.empty((len(m), 4))
    cases = [tr > 0, (m00 > m11) & (m00 > m22), m11 > m22, np.ones(len(m), dtype=bool)]
    taken = np.zeros(len(m), dtype=bool)
    for k, case in enumerate(cases):
        i = case & ~taken
        taken |= i
        if not i.any():
            continue
        a = m[i]
        d = [a[:, 0, 0], a[:, 1, 1], a[:, 2, 2]]
        if k == 0:
            s = 2.0 * np.sqrt(d[0] + d[1] + d[2] + 1.0)
            q[i] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) / s, (a[:, 0, 2] - a[:, 2, 0]) / s,
                             (a[:, 1, 0] - a[:, 0, 1]) / s, 0.25 * s], axis=1)
        elif k == 1:
            s = 2.0 * np.sqrt(1.0 + d[0] - d[1] - d[2])
            q[i] = np.stack([0.25 * s, (a[:, 0, 1] + a[:, 1, 0]) / s, (a[:, 0, 2] + a[:, 2, 0]) / s,
                             (a[:, 2, 1] - a[:, 1, 2]) / s], axis=1)
        elif k == 2:
            s = 2.0 * np.sqrt(1.0 + d[1] - d[0] - d[2])
            q[i] = np.stack([(a[:, 0, 1] + a[:, 1, 0]) / s, 0.25 * s, (a[:, 1, 2] + a[:, 2, 1]) / s,
                             (a[:, 0, 2] - a[:, 2, 0]) / s], axis=1)
        else:
            s = 2.0 * np.sqrt(1.0 + d[2] - d[0] - d[1])
            q[i] = np.stack([(a[:, 0, 2] + a[:, 2, 0]) / s, (a[:, 1, 2] + a[:, 2, 1]) / s, 0.25 * s,
                             (a[:, 1, 0] - a[:, 0, 1]) / s], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 3] < 0] *= -1.0
    return q.reshape(*shape, 4)


def rigid_inverse(t: npt.ArrayLike) -> np.ndarray:
    """Inverse of rigid 4x4 transforms, shape (..., 4, 4): rotation transposed, translation -R^T p."""
    t = np.asarray(t, dtype=float)
    out = np.zeros_like(t)
    rt = np.swapaxes(t[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, t[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


@dataclass(frozen=True)
class Joint:
    """One joint: child frame = parent frame @ origin @ motion(multiplier * q + offset) @ post.

    ``origin`` and ``post`` are fixed 4x4 transforms (``post`` is identity for URDF joints and
    carries d/a/alpha for standard DH). ``axis`` is a unit 3-vector in the frame after ``origin``.
    """

    name: str
    kind: JointKind
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    post: np.ndarray = field(default_factory=lambda: np.eye(4))
    lower: float = -np.pi
    upper: float = np.pi
    offset: float = 0.0
    #: URDF ``<mimic>``: the joint moves with this actuated joint's value, its own value being
    #: ``multiplier * q[mimic] + offset`` (rad or m); not itself an actuated joint.
    mimic: str | None = None
    #: 1 for every joint that is not a mimic joint.
    multiplier: float = 1.0


@dataclass(frozen=True)
class Inertial:
    """Rigid-body data of a link: mass (kg), centre of mass (m, link frame), inertia about the COM (kg m^2, link axes)."""

    mass: float
    com: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class CollisionShape:
    """A primitive attached to a link. ``origin`` places the shape in the link frame.

    Sizes (m): box ``size`` = (x, y, z); cylinder and capsule ``radius``, ``length`` along the
    shape's local z (capsule length excludes the end caps); sphere ``radius``; mesh: ``mesh``
    (``roarmctl.robot.meshes.MeshGeometry``, centred on ``origin``).
    """

    link: str
    kind: ShapeKind
    origin: np.ndarray
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    name: str = ""
    mesh: MeshGeometry | None = None


#: The joint fields of the RoArm firmware's ``T:102`` command, in its joint order (Waveshare RoArm-M3 example
#: firmware 0.84, json_cmd.h): the names a description's ``wire`` map may give its joints (the M2 uses four).
WIRE_FIELDS = ("base", "shoulder", "elbow", "wrist", "roll", "hand")


@dataclass(frozen=True)
class WireField:
    """How one joint appears on the device's wire: ``wire = offset + sign * q``, clamped to [lower, upper]."""

    joint: str
    field: str
    sign: float = 1.0
    offset: float = 0.0
    lower: float = -np.inf
    upper: float = np.inf

    def to_wire(self, q: float) -> float:
        """Joint value (rad) -> wire value (rad), clamped to the firmware's range."""
        return float(np.clip(self.offset + self.sign * q, self.lower, self.upper))

    def from_wire(self, w: float) -> float:
        """Wire value (rad) -> joint value (rad)."""
        return float((w - self.offset) / self.sign)


@dataclass(frozen=True)
class FixedJaw:
    """The face of a gripper's fixed jaw: the plane through ``point`` (m) with unit ``normal`` pointing
    toward the moving jaw, both in ``link``'s frame. A grasped object rests against this face, so its
    centre lies half its width along ``normal`` from the plane (``roarmctl.motion.planning.fixed_jaw``)."""

    link: str
    point: tuple[float, float, float]
    normal: tuple[float, float, float]


@dataclass(frozen=True)
class JawMesh:
    """A jaw's own geometry, the one its gripper's ``jaw_width`` table was measured on, in ``link``'s frame: the mesh
    file ``file`` (checked to lie inside ``roots``, the description's folders), its vertices times ``scale`` in m, or
    (``pieces``, then ``file`` is empty) a file of that mesh's convex pieces already made (``roarmctl.robot.
    jaw_pieces``' format). Read only when asked (``roarmctl.robot.jaw_meshes.jaw_triangles``): picks close by the
    convex pieces (``roarmctl.robot.jaw_pieces``, ``roarmctl.motion.planning.jaw_reach``) and the physics' jaws are
    those pieces."""

    link: str
    file: str
    scale: float = 1.0
    roots: Any = field(default=None, compare=False, repr=False)
    pieces: str | None = None
    #: the pieces themselves (each (V, 3) m), read already: a description carried in a trajectory is loaded from a
    #: temporary folder that is gone when they are asked for (``roarmctl.robot.jaw_pieces.keep_jaw_pieces``)
    kept: tuple[Any, ...] | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class Gripper:
    """Which actuated joint is the gripper, and its open and closed values (rad).

    ``jaw_q`` (K,) rad increasing and ``jaw_width`` (K,) m: the opening between the jaws at those
    joint values (interpolated linearly, monotonic), when the description gives it. ``squeeze`` (m):
    how far below an object's width a pick closes by default; ``clearance`` (m): how much wider than
    the object the open jaws must be. ``fixed_jaw``: the face of a jaw that does not move (a claw
    gripper such as the RoArm's), when the description gives it: picks then put the object against it.
    ``jaw_meshes``: the jaws' own meshes (``JawMesh``), when the description gives them.
    """

    joint: str
    open: float
    closed: float
    jaw_q: tuple[float, ...] = ()
    jaw_width: tuple[float, ...] = ()
    squeeze: float = 0.002
    clearance: float = 0.004
    fixed_jaw: FixedJaw | None = None
    jaw_meshes: tuple[JawMesh, ...] = field(default=(), compare=False)

    @property
    def has_widths(self) -> bool:
        """Whether the gripper has a joint-value-to-jaw-width table."""
        return len(self.jaw_q) >= 2

    def width(self, q: float) -> float:
        """Jaw opening (m) at gripper joint value ``q`` (rad)."""
        return float(np.interp(q, self.jaw_q, self.jaw_width))

    def q_for_width(self, width: float) -> float:
        """Gripper joint value (rad) that opens the jaws to ``width`` (m), clamped to the table."""
        return float(np.interp(width, self.jaw_width, self.jaw_q))


@dataclass
class Robot:
    """A loaded robot description.

    ``joints`` are in topological order (a parent link is always placed before its children).
    ``joint_names`` lists the actuated joints in configuration-vector order (gripper last).
    ``tcp_link`` is the frame the TCP pose, Jacobian and IK refer to.
    """

    name: str
    source: str
    root: str
    joints: list[Joint]
    joint_names: list[str]
    tcp_link: str
    lower: np.ndarray
    upper: np.ndarray
    velocity_limits: np.ndarray
    acceleration_limits: np.ndarray
    jerk_limits: np.ndarray | None = None  # rad/s^3 (m/s^3), (dof,); None: no jerk bound
    effort_limits: np.ndarray | None = None  # N m (N), (dof,); inf: unlimited; the torques timing may use
    inertials: dict[str, Inertial] = field(default_factory=dict)
    collision: list[CollisionShape] = field(default_factory=list)
    allowed_collisions: set[frozenset[str]] = field(default_factory=set)
    named_poses: dict[str, np.ndarray] = field(default_factory=dict)
    gripper: Gripper | None = None
    wire: list[WireField] = field(default_factory=list)
    singularity_model: str | None = None
    description: str = ""
    frames: dict = field(default_factory=dict)  # name -> roarmctl.robot.frames.Frame
    #: Analytic IK family ("roarm5", "roarm3", "ur6"; None: numerical). Defaults to ``singularity_model``.
    ik: str | None = None
    #: Links that may touch the object being grasped (the jaws and the link that carries them).
    jaw_links: tuple[str, ...] = ()
    #: Links that sit on the table and are never checked against items of role "table".
    base_links: tuple[str, ...] = ()
    #: The DH table the robot was built from: (convention, rows of {a, alpha, d, offset}), SI units.
    dh: tuple[str, list[dict[str, float]]] | None = None
    #: values derived from the description once per loaded robot (IK solvers, reach bounds, memos)
    derived: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    #: The URDF's ``<visual>`` elements, read only for pictures (``roarmctl.robot.visuals``); None without any.
    visual_source: Any = field(default=None, repr=False, compare=False)
    #: How it was loaded: a bundled name, or the description file's absolute path (what a trajectory names).
    spec: str = ""
    #: Movable joints of the description that nothing drives (not in ``joint_names``), held at these
    #: values (rad / m); the loader made them fixed joints.
    held_joints: dict[str, float] = field(default_factory=dict)
    #: Link -> its own collision padding (m) against the scene, instead of the plan's (sidecar ``padding``).
    padding: dict[str, float] = field(default_factory=dict)
    #: Limit kind ("velocity", "acceleration", "jerk") -> joints whose limit is roarmctl's default
    #: because the description gives none (said once by the CLI, written into the trajectory).
    defaults: dict[str, list[str]] = field(default_factory=dict)
    #: What the loader chose or left out, one line each (held joints, massless links, SRDF parts
    #: not used, defaults); the CLI prints them once.
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.kin = Kinematics(self)

    @property
    def dof(self) -> int:
        """Number of actuated joints (gripper included)."""
        return len(self.joint_names)

    @property
    def arm_indices(self) -> list[int]:
        """Indices in ``q`` of the joints that move the TCP (the arm proper, gripper excluded)."""
        return self.kin.tcp_chain_indices

    @property
    def arm_dof(self) -> int:
        """Number of arm joints (actuated, gripper excluded)."""
        return len(self.arm_indices)

    @property
    def link_names(self) -> list[str]:
        """Every link: the root, then each joint's child, in joint order."""
        return [self.root] + [j.child for j in self.joints]

    def joints_moved_by(self, name: str) -> list[Joint]:
        """Actuated joint ``name`` and every joint that mimics it (e.g. both fingers of a gripper)."""
        return [j for j in self.joints if name in (j.name, j.mimic)]

    @property
    def prismatic(self) -> np.ndarray:
        """(dof,) bool: which actuated joints are prismatic (their values in m, m/s, ...; the others in rad)."""
        kinds = {j.name: j.kind for j in self.joints}
        return np.array([kinds.get(n) == "prismatic" for n in self.joint_names])

    def joint_unit(self, index: int, power: int = 0, deg: bool = False, kind: str = "position") -> str:
        """The unit of joint ``index``'s value (power 0), velocity (1), acceleration (2) or jerk (3):
        "rad", "deg/s^2", "m/s", ...; ``deg`` turns radians into degrees (never metres). ``kind``
        "effort" gives "N m" (revolute) or "N" (prismatic)."""
        name = self.joint_names[index]  # its kind alone (``prismatic`` makes the whole mask: 24 calls a plan report)
        prismatic = any(j.kind == "prismatic" for j in self.joints if j.name == name)
        if kind == "effort":
            return "N" if prismatic else "N m"
        base = "m" if prismatic else ("deg" if deg else "rad")
        return base + ("" if power == 0 else "/s" if power == 1 else f"/s^{power}")

    def to_user(self, values: npt.ArrayLike, deg: bool, columns: npt.ArrayLike | None = None) -> np.ndarray:
        """Joint values (rad / m) -> what the user asked for: degrees for revolute joints when ``deg``,
        metres stay metres. ``values``: (..., n) with n = dof, or the joints ``columns`` (indices) name."""
        arr = np.asarray(values, dtype=float)
        if not deg:
            return arr
        mask = self.prismatic if columns is None else self.prismatic[np.asarray(columns)]
        return np.where(mask, arr, np.degrees(arr))

    def from_user(self, values: npt.ArrayLike, deg: bool) -> np.ndarray:
        """User joint values (dof or arm_dof of them; degrees for revolute joints when ``deg``) -> rad / m."""
        arr = np.asarray(values, dtype=float)
        if not deg:
            return arr
        cols = None if arr.shape[-1] == self.dof else self.arm_indices if arr.shape[-1] == self.arm_dof else None
        if cols is None and arr.shape[-1] != self.dof:
            return np.radians(arr)  # the wrong count: full_q says so with the count
        mask = self.prismatic if cols is None else self.prismatic[np.asarray(cols)]
        return np.where(mask, arr, np.radians(arr))

    def joint_states(self, q: npt.ArrayLike,
                     qd: npt.ArrayLike | None = None) -> tuple[list[str], np.ndarray, np.ndarray | None]:
        """Every movable joint of the description with its value, for a complete ``sensor_msgs/JointState``:
        the actuated joints (``q`` (N, dof), ``qd`` (N, dof) or None), then each mimic joint (its leader's
        value times its multiplier plus its offset; velocity times the multiplier), then the held joints (their
        held value, velocity 0). Returns (names, positions (N, K), velocities (N, K) or None)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        names = list(self.joint_names)
        cols, vcols = [q], [] if qd is None else [np.atleast_2d(np.asarray(qd, dtype=float))]
        for j in self.joints:
            if j.mimic is not None:
                k = self.joint_names.index(j.mimic)
                names.append(j.name)
                cols.append(j.multiplier * q[:, k:k + 1] + j.offset)
                if qd is not None:
                    vcols.append(j.multiplier * vcols[0][:, k:k + 1])
        for name, value in self.held_joints.items():
            names.append(name)
            cols.append(np.full((len(q), 1), value))
            if qd is not None:
                vcols.append(np.zeros((len(q), 1)))
        return names, np.hstack(cols), (None if qd is None else np.hstack(vcols))

    def joint_index(self, name: str) -> int:
        """Index of the actuated joint ``name`` in ``joint_names``."""
        return self.joint_names.index(name)

    def full_q(self, q: npt.ArrayLike) -> np.ndarray:
        """Accept either an arm-only vector (arm_dof) or a full one (dof); return the full vector.

        The gripper, when not given, takes its closed value.
        """
        q = np.asarray(q, dtype=float)
        if q.shape[-1] == self.dof:
            return q
        if q.shape[-1] == self.arm_dof:
            full = np.zeros(q.shape[:-1] + (self.dof,))
            if self.gripper is not None:
                full[..., self.joint_index(self.gripper.joint)] = self.gripper.closed
            full[..., self.arm_indices] = q
            return full

        raise InputError(
            f"{self.name} takes {self.arm_dof} arm joint values"
            + (f" or {self.dof} with the gripper" if self.dof != self.arm_dof else "")
            + f", got {q.shape[-1]}"
        )

    def within_limits(self, q: npt.ArrayLike, tol: float = 1e-9) -> bool:
        """Whether ``q`` (arm or full joint vector, rad) is within the joint limits, up to ``tol``."""
        q = self.full_q(q)
        return bool(np.all(q >= self.lower - tol) and np.all(q <= self.upper + tol))
