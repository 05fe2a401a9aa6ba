"""What a plan file becomes: the ``Plan`` and its parts (scene items, tasks), as ``roarmctl.plan.schema`` reads
them. Lengths in m, angles in rad, masses in kg; poses (4, 4) in the world frame."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from roarmctl.motion.options import Limits, PlannerConfig


@dataclass
class ItemSpec:
    """A scene obstacle, the table, or a graspable object, as written in the plan."""

    name: str
    role: str  # "table" | "obstacle" | "object"
    shape: str
    pose: np.ndarray  # (4, 4) world frame
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    mass: float | None = None  # kg; carried by the hand from grasp to release
    com: np.ndarray | None = None  # (3,) m, object frame, from the shape's centre; None: the centre
    inertia: np.ndarray | None = None  # (3, 3) kg m^2 about the COM, object axes; None: uniform solid
    grasp_width: float | None = None  # m across the jaws; default: the shape's narrowest horizontal extent
    line: int = 0
    file: Path | None = None  # mesh or cloud: the file, resolved (inside the plan's folder)
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)  # mesh: the file's units times this are m
    exact: bool = False  # mesh: its triangles as they are (else the convex hulls of its connected parts)
    resolution: float = 0.0  # cloud: the edge of its occupied cells (m)
    where: str = ""  # "plan.yaml:12: scene.obstacles[0]": names the item in errors about its file
    data: Any = None  # mesh or cloud already read (``motion.scene.MeshData`` / ``CloudData``): a trajectory's scene

    @property
    def height(self) -> float:
        """Extent along the item's local z (m)."""
        return {"box": self.size[2], "cylinder": self.length, "sphere": 2 * self.radius}[self.shape]


@dataclass
class PickTask:
    """A pick: grasp ``object`` from above (heights m, pitch/roll rad, gripper joint values)."""

    object: str
    approach_height: float = 0.06
    pitch: float = math.pi / 2
    roll: float | None = None
    gripper_open: float | None = None
    gripper_closed: float | None = None
    grasp_offset: float = 0.0
    squeeze: float | None = None  # m the jaws close below the grasp width (default: the robot's)
    pitch_auto: bool = False
    pitch_set: bool = False  # the plan wrote pitch (else the default applies: held by the RoArm only)
    line: int = 0
    kind: str = "pick"


@dataclass
class PlaceTask:
    """A place: put the held object's centre at ``xyz`` (m)."""

    xyz: np.ndarray
    object: str | None = None
    approach_height: float = 0.06
    pitch: float = math.pi / 2
    roll: float | None = None
    gripper_open: float | None = None
    pitch_auto: bool = False
    pitch_set: bool = False
    line: int = 0
    kind: str = "place"


@dataclass
class MoveTask:
    """A move to a named pose, joint values (rad) or a TCP position (m), optionally setting the gripper."""

    pose: str | None = None
    joints: np.ndarray | None = None
    xyz: np.ndarray | None = None
    pitch: float | None = None
    pitch_auto: bool = False
    gripper: float | str | None = None  # rad, or "open" / "closed" (the robot's values); None: keep
    zone: float | None = None  # m the path may pass the target at and flow on (0: reached); None: limits.zone
    line: int = 0
    kind: str = "move"


@dataclass
class WaitTask:
    """A pause of ``seconds`` s."""

    seconds: float
    line: int = 0
    kind: str = "wait"


@dataclass(frozen=True)
class Plan:
    """A checked plan file: its path and sha256, robot, start, scene, objects, tasks, limits and planner. Not
    changed after it is read (a caller that plans from elsewhere makes a copy: ``dataclasses.replace``)."""

    path: Path
    sha256: str
    robot: str
    start: str | np.ndarray
    scene: list[ItemSpec]
    objects: list[ItemSpec]
    tasks: list[Any]
    cycles: int = 1
    limits: Limits = field(default_factory=Limits)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    lines: dict[str, int] = field(default_factory=dict)  # top-level key -> line, for later messages
    document: Any = None  # the parsed file (located containers; a dict's obstacles may be its own): ``load_plan(..., parsed=plan)`` reads it again
    item_specs: dict = field(default_factory=dict, repr=False)  # id(raw item) -> its ItemSpec, when no frame is used
