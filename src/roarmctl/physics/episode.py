"""One datagen episode: sample a scene from a template, plan it, run it in physics, keep it or say why not,
and render what the cameras saw.

``run_episode(template, robot, try_index, seed, options)`` is a pure function of its arguments: the scene
is drawn from ``numpy.random.default_rng([seed, try_index])`` and everything after it counts work, not
time (the planner's seed comes from the same stream), so a try gives the same episode in any process, on
any worker count. An episode is kept only if every picked object is placed within the tolerance and
nothing unintended was touched (``roarmctl.physics.report.measure``); otherwise its cause is one of
``CAUSES``. A kept episode carries, at each frame time ``k / fps`` (the physics step nearest it):

* ``state``: the joint values measured in physics (F, dof) rad (m for prismatic joints);
* ``action``: the joint goals ``execute`` had sent by then (F, dof): the streamer's schedule (the same
  rate, strategy and sag compensation), decoded from its firmware commands back to joint values; a robot
  without a wire protocol: the planned position;
* ``images``: camera -> (F, height, width, 3) uint8 (``roarmctl.physics.render``).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from roarmctl.checks import Bound, check_options
from roarmctl.device.protocol import M3_FIELDS, WireMap
from roarmctl.device.schedule import sample
from roarmctl.errors import InfeasibleError, PlanFileError, UnreachableError
from roarmctl.physics.render import CAMERAS, Cameras, FrameBuffers, offscreen
from roarmctl.physics.setup import build
from roarmctl.plan.template import Range, Template

if TYPE_CHECKING:
    from roarmctl.motion.trajectory import Trajectory
    from roarmctl.physics.run import Recording
    from roarmctl.robot.model import Robot

#: Why a try was not kept, in the order they are checked.
CAUSES = ("crowded", "unreachable", "no path", "not lifted", "not placed", "contact")
CLEARANCE = 0.01  # m between the footprints of two sampled items (and a place target and the others)
MAX_RESAMPLE = 50  # scenes drawn for one try before it counts as "crowded"


#: The side of a camera image (pixels): what datagen's options take too.
IMAGE_SIDE = Bound(16, 4096, whole=True)

#: EpisodeOptions' bounds (``roarmctl.checks.check_options``).
EPISODE_BOUNDS = {
    "width": IMAGE_SIDE,
    "height": IMAGE_SIDE,
    "fps": Bound(1, 120, whole=True),
    "cameras": Bound(choices=CAMERAS, many=True),
    "settle": Bound(0.0, 10.0),  # s
    "tolerance": Bound(1e-4, 1.0),  # m
}


@dataclass
class EpisodeOptions:
    """``width`` x ``height`` pixels per camera (``cameras``; none: no images), ``fps`` frames per second of
    simulated time, ``settle`` s simulated after the last command, ``tolerance`` m of a placement; checked on
    creation (``EPISODE_BOUNDS``)."""

    width: int = 640
    height: int = 480
    fps: int = 30
    cameras: tuple[str, ...] = CAMERAS
    settle: float = 0.5
    tolerance: float = 0.010

    def __post_init__(self) -> None:
        check_options(self, EPISODE_BOUNDS)


@dataclass
class EpisodeResult:
    """One try: ``kept`` or the ``cause`` (one of ``CAUSES``) and its ``detail``; for a kept one the frames
    (``state``/``action`` (F, dof), ``images``); ``timings``: CPU s of this process per stage (sample, plan,
    physics, render; the renderer's llvmpipe threads included), a figure a busy machine does not inflate."""

    try_index: int
    kept: bool
    cause: str | None = None
    detail: str = ""
    state: np.ndarray | None = None
    action: np.ndarray | None = None
    images: dict[str, np.ndarray] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)


def _table_top(doc: dict[str, Any]) -> float:
    table = (doc.get("scene") or {}).get("table")
    if not table or table.get("shape") != "box":
        return 0.0
    return float(table["xyz"][2]) + float(table["size"][2]) / 2


def _height(item: dict[str, Any]) -> float:
    shape = item.get("shape")
    if shape == "box":
        return float(item["size"][2])
    if shape == "cylinder":
        return float(item["length"])
    return 2.0 * float(item.get("radius", 0.0))


def _footprint(item: dict[str, Any]) -> float:
    """Radius (m) of a circle about the item's centre that holds its footprint."""
    if item.get("shape") == "box":
        return 0.5 * math.hypot(float(item["size"][0]), float(item["size"][1]))
    return float(item.get("radius", 0.0))


def _scaled(item: dict[str, Any], s: float) -> None:
    for k in ("size",):
        if k in item:
            item[k] = [float(v) * s for v in item[k]]
    for k in ("radius", "length"):
        if k in item:
            item[k] = float(item[k]) * s


def sample_plan(template: Template, robot: Robot, rng: np.random.Generator) -> tuple[dict[str, Any], dict[str, tuple]] | None:
    """A plan dict drawn from ``template`` and the colours of its objects, or None when ``MAX_RESAMPLE``
    scenes in a row put two items (or a place target and an item) closer than ``CLEARANCE``."""
    for _ in range(MAX_RESAMPLE):
        drawn = _draw(template, robot, rng)
        if drawn is not None:
            return drawn
    return None


def _draw(template: Template, robot: Robot, rng: np.random.Generator) -> tuple[dict[str, Any], dict[str, tuple]] | None:
    doc = copy.deepcopy(template.document)
    top = _table_top(doc)
    colors: dict[str, tuple] = {}
    rise: dict[str, float] = {}  # object -> how much its centre rose with its scale (m)
    circles: list[tuple[float, float, float, str]] = []  # x, y, radius, name
    for obj in doc.get("objects") or []:
        r = template.objects.get(obj["name"])
        xyz = [float(v) for v in obj["xyz"]]
        if r is not None:
            if r.x is not None:
                xyz[0] = r.x.sample(rng)
            if r.y is not None:
                xyz[1] = r.y.sample(rng)
            if r.yaw is not None:
                rpy = [float(v) for v in obj.get("rpy") or [0.0, 0.0, 0.0]]
                rpy[2] = r.yaw.sample(rng)
                obj["rpy"] = rpy
            if r.scale is not None:
                h0 = _height(obj)
                _scaled(obj, r.scale.sample(rng))
                rise[obj["name"]] = (_height(obj) - h0) / 2
                xyz[2] += rise[obj["name"]]
            if r.mass is not None:
                obj["mass"] = r.mass.sample(rng)
            if r.colors:
                colors[obj["name"]] = r.colors[int(rng.integers(len(r.colors)))]
        obj["xyz"] = xyz
        circles.append((xyz[0], xyz[1], _footprint(obj), obj["name"]))
    held: str | None = None
    k = 0
    targets: list[tuple[float, float, float, str]] = []
    for task in doc["tasks"]:
        if "pick" in task:
            held = task["pick"]["object"]
        elif "place" in task:
            place = task["place"]
            if isinstance(place.get("xyz"), list):
                goal = [float(v) for v in place["xyz"]]
                if k < len(template.places):
                    goal[0] = template.places[k].x.sample(rng)
                    goal[1] = template.places[k].y.sample(rng)
                goal[2] += rise.get(held or "", 0.0)
                place["xyz"] = goal
                radius = next((c[2] for c in circles if c[3] == held), 0.0)
                targets.append((goal[0], goal[1], radius, held or ""))
            k += 1
            held = None
    scene = doc.setdefault("scene", {})
    for kind, clutter in (("distractor", template.distractors), ("obstacle", template.obstacles)):
        if clutter is None:
            continue
        n = int(rng.integers(clutter.count[0], clutter.count[1] + 1))
        for i in range(n):
            s = clutter.size.sample(rng)
            h = (clutter.height or Range(s, s)).sample(rng) if kind == "obstacle" else s
            at = [clutter.x.sample(rng), clutter.y.sample(rng), top + h / 2]
            item: dict[str, Any] = {"name": f"{kind}_{i}", "shape": "box", "size": [s, s, h], "xyz": at,
                                    "rpy": [0.0, 0.0, float(rng.uniform(-math.pi / 4, math.pi / 4))]}
            circles.append((at[0], at[1], _footprint(item), item["name"]))
            if kind == "distractor":
                item["mass"] = (clutter.mass or Range(0.02, 0.02)).sample(rng)
                doc.setdefault("objects", []).append(item)
            else:
                scene.setdefault("obstacles", []).append(item)
    for i, a in enumerate(circles):
        for b in circles[i + 1:] + [t for t in targets if t[3] != a[3]]:
            if math.hypot(a[0] - b[0], a[1] - b[1]) < a[2] + b[2] + CLEARANCE:
                return None
    start = doc.get("start", "home")
    if template.start_jitter > 0 and isinstance(start, str) and start in robot.named_poses:
        q = np.array(robot.named_poses[start], dtype=float)
        arm = robot.arm_indices
        q[arm] += rng.uniform(-template.start_jitter, template.start_jitter, len(arm))
        q = np.clip(q, robot.lower, robot.upper)
        doc["start"] = [float(v) for v in q]
    return doc, colors


def goals_at(traj: Trajectory, robot: Robot, rec: Recording, times: np.ndarray) -> np.ndarray:
    """The joint goals (len(times), dof) that had been sent at each time (s from the start of the motion):
    the last firmware command of each joint decoded to joint values; the planned position for a robot
    that is not streamed (no commands)."""
    if not rec.commands:
        return np.asarray(sample(traj, np.clip(times, 0.0, traj.duration)), dtype=float)
    wm = WireMap(robot)
    wire = dict(zip(wm.field_names, (float(v) for v in wm.to_wire_array(traj.positions[:1])[0])))
    out = np.empty((len(times), robot.dof))
    k = 0
    for i, t in enumerate(times):
        while k < len(rec.commands) and rec.commands[k][0] <= t + 1e-9:
            cmd = rec.commands[k][1]
            if cmd.get("T") == 102:
                wire.update({f: float(cmd[f]) for f in wm.field_names if f in cmd})
            elif cmd.get("T") == 101:
                wire[M3_FIELDS[int(cmd["joint"]) - 1]] = float(cmd["rad"])
            k += 1
        out[i] = wm.from_wire(wire)
    return out


def run_episode(template: Template, robot: Robot, try_index: int, seed: int, options: EpisodeOptions,
                buffers: FrameBuffers | None = None) -> EpisodeResult:
    """Try ``try_index`` of the run with ``seed`` (see the module doc); the images in arrays lent by ``buffers``
    when given (valid until its next episode), else new ones."""
    from roarmctl.motion.pipeline import plan_file
    from roarmctl.physics.report import measure
    from roarmctl.physics.run import Options, simulate

    if options.cameras:
        offscreen()
    out = EpisodeResult(try_index, kept=False)
    rng = np.random.default_rng([seed, try_index])
    t0 = time.process_time()
    drawn = sample_plan(template, robot, rng)
    out.timings["sample"] = time.process_time() - t0
    if drawn is None:
        out.cause, out.detail = "crowded", f"no scene without overlaps in {MAX_RESAMPLE} draws"
        return out
    doc, colors = drawn
    t0 = time.process_time()
    try:
        result = plan_file(doc, seed=int(rng.integers(2**31 - 1)), base_dir=template.path.parent)
    except UnreachableError as exc:
        out.cause, out.detail = "unreachable", exc.message
    except (InfeasibleError, PlanFileError) as exc:  # a sampled item off the table or in an obstacle: no path either
        out.cause, out.detail = "no path", exc.message
    out.timings["plan"] = time.process_time() - t0
    if out.cause is not None:
        return out
    traj = result.trajectory
    t0 = time.process_time()
    sim_options = Options(settle=options.settle, tolerance=options.tolerance, frame_rate=float(options.fps))
    setup = build(traj, robot)
    setup, rec = simulate(traj, robot, sim_options, setup=setup)
    report = measure(traj, robot, setup, rec, sim_options)
    out.timings["physics"] = time.process_time() - t0
    objects = report["objects"]
    if any(not o["lifted"] for o in objects):
        out.cause = "not lifted"
        out.detail = ", ".join(o["name"] for o in objects if not o["lifted"])
    elif any(not o["placed"] for o in objects):
        out.cause = "not placed"
        out.detail = ", ".join(f"{o['name']} {o['error_mm']:.1f} mm off" for o in objects if not o["placed"])
    elif report["contacts"]:
        c = report["contacts"][0]
        out.cause, out.detail = "contact", f"{c.get('link') or c.get('item')} with {c['with']} at {c['start_s']:.2f} s"
    if out.cause is not None:
        return out
    assert rec.frame_t is not None and rec.frame_qpos is not None  # frame_rate > 0
    w = setup.world
    out.state = (rec.frame_qpos[:, w.qpos_adr] - w.offset).astype(np.float32)
    nominal = np.arange(len(rec.frame_t)) / options.fps  # the frames' timestamps (the dataset's k / fps)
    out.action = goals_at(traj, robot, rec, nominal).astype(np.float32)
    if options.cameras:
        t0 = time.process_time()
        out.images = Cameras(w, options.width, options.height, colors).render(rec.frame_qpos, options.cameras, buffers)
        out.timings["render"] = time.process_time() - t0
    out.kept = True
    return out
