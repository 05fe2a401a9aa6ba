"""Which contacts a plan intends, and the episodes of those it does not.

The trajectory says what touches what and when: the jaws (``robot.jaw_links``) may touch an object
from the start of the descent to it until the end of the retreat after its release; an object may
rest on the table except while it is carried (from the end of its lift to the start of its lowering);
objects may rest on each other unless one of them is carried. Everything else is unintended: a link
against the table or an obstacle, a link that is not a jaw against an object, two links of the arm
(MuJoCo already leaves out the pairs the description allows), a carried object against anything but
the jaws. ``LAG`` extends each window at its end: the servos follow the plan tens of milliseconds late.

``Episodes`` turns per-step contacts into episodes (a pair in contact over consecutive physics steps):
which link or item, which item, from when to when, how deep at most.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Segment, Trajectory
    from roarmctl.physics.world import Contact

LAG = 0.3  # s a window stays open after its planned end (the servos' lag, settling of a released object)
GAP = 0.02  # s: contacts of one pair less than this apart are one episode


@dataclass
class Hold:
    """One pick and place of object ``name`` in trajectory time (s): ``reach`` (descent starts), ``grasp``
    (jaws closed), ``carry`` (lift ends), ``lower`` (lowering starts), ``release`` (jaws open) and
    ``leave`` (retreat ends)."""

    name: str
    reach: float
    grasp: float
    carry: float
    lower: float
    release: float
    leave: float


@dataclass
class Episode:
    """Unintended contact between ``a`` and ``b`` (each ("link"|"item", name)) from ``start`` to ``end``
    (s of physics time), ``depth`` m the deepest overlap, ``point`` (3,) m where it was deepest."""

    a: tuple[str, str]
    b: tuple[str, str]
    start: float
    end: float
    depth: float
    point: np.ndarray

    def to_dict(self) -> dict:
        """The report's form: the link (or item), what it touched, when (s), how deep (mm), where (m)."""
        link, item = (self.a, self.b) if self.a[0] == "link" else (self.b, self.a)
        return {"link" if link[0] == "link" else "item": link[1], "with": item[1], "with_kind": item[0],
                "start_s": round(self.start, 4), "end_s": round(self.end, 4), "depth_mm": round(self.depth * 1e3, 3),
                "point_m": [round(float(v), 4) for v in self.point]}


def holds_from(traj: Trajectory, object_of_payload: list[str | None]) -> list[Hold]:
    """The holds of a trajectory: one per payload (grasp to release) whose object is known
    (``object_of_payload[k]`` names payload k's object or is None). Times from the trajectory's segments:
    the segment before the grasp's gripper segment is the descent, the one after it the lift; likewise
    the lowering and the retreat around the release."""
    segs = list(traj.segments)
    out = []
    for p, name in zip(traj.payloads, object_of_payload):
        if name is None:
            continue
        tg, tr = float(p["start"]), float(p["end"])
        ig = _segment_ending(segs, tg)
        ir = _segment_ending(segs, tr)
        reach = segs[ig - 1].start if ig is not None and ig > 0 else tg - 1.0
        carry = segs[ig + 1].end if ig is not None and ig + 1 < len(segs) else tg
        lower = segs[ir - 1].start if ir is not None and ir > 0 else tr
        leave = segs[ir + 1].end if ir is not None and ir + 1 < len(segs) else tr + 1.0
        out.append(Hold(name, reach, tg, max(carry, tg), min(lower, tr), tr, max(leave, tr)))
    return out


def _segment_ending(segs: Sequence[Segment], t: float) -> int | None:
    """Index of the gripper segment that ends at ``t`` (or contains it)."""
    best = None
    for i, s in enumerate(segs):
        if s.kind == "gripper" and s.start - 1e-6 <= t <= s.end + 1e-6:
            best = i
    return best


class Policy:
    """Decides whether a contact at time ``t`` (trajectory time, s) is intended.

    ``jaw_links``: links that may touch the object they grasp; ``roles``: item name -> role;
    ``holds``: the trajectory's holds; ``time_scale``: physics seconds per trajectory second (1/speed_scale).
    """

    def __init__(self, jaw_links: Iterable[str], roles: dict[str, str], holds: list[Hold],
                 time_scale: float = 1.0) -> None:
        self.jaw_links = set(jaw_links)
        self.roles = roles
        self.holds = holds
        self.scale = time_scale

    def _carried(self, name: str, t: float) -> bool:
        """Lifted and not yet lowered (the lift's end taken ``LAG`` late: the servos follow late)."""
        return any(h.name == name and h.carry + LAG <= t <= h.lower for h in self.holds)

    def _gripping(self, name: str, t: float) -> bool:
        return any(h.name == name and h.reach <= t <= h.leave + LAG for h in self.holds)

    def intended(self, a: tuple[str, str], b: tuple[str, str], t_physics: float) -> bool:
        """Whether the plan means ``a`` and ``b`` (("link"|"item", name)) to touch at physics time ``t_physics`` (s)."""
        t = t_physics / self.scale
        if a[0] == "link" and b[0] == "link":
            return False
        if a[0] == "item" and b[0] == "link":
            a, b = b, a
        if a[0] == "link":  # a link and an item
            return self.roles.get(b[1]) == "object" and a[1] in self.jaw_links and self._gripping(b[1], t)
        ra, rb = self.roles.get(a[1]), self.roles.get(b[1])
        if ra != "object" and rb != "object":
            return True  # two fixed items (MuJoCo does not report these)
        objects = [n for n, r in ((a[1], ra), (b[1], rb)) if r == "object"]
        if any(self._carried(n, t) for n in objects):
            return False
        if len(objects) == 1:
            other_role = rb if ra == "object" else ra
            return other_role == "table"
        return True  # two objects at rest on each other


@dataclass
class Episodes:
    """Per-step contacts in, episodes out (see the module doc)."""

    policy: Policy
    open: dict = field(default_factory=dict)
    done: list[Episode] = field(default_factory=list)

    def add(self, t: float, contacts: Iterable[Contact]) -> None:
        """Contacts (``roarmctl.physics.world.Contact``) of the step at physics time ``t`` (s)."""
        for c in contacts:
            key = (c.a, c.b) if c.a <= c.b else (c.b, c.a)
            if self.policy.intended(c.a, c.b, t):
                continue
            ep = self.open.get(key)
            if ep is not None and t - ep.end <= GAP:
                ep.end = t
                if c.depth > ep.depth:
                    ep.depth, ep.point = c.depth, c.point
            else:
                if ep is not None:
                    self.done.append(ep)
                self.open[key] = Episode(key[0], key[1], t, t, c.depth, c.point)

    def result(self) -> list[Episode]:
        """Every episode, in order of start."""
        return sorted(self.done + list(self.open.values()), key=lambda e: (e.start, e.a, e.b))
