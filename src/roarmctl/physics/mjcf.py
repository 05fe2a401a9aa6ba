"""The MJCF document of a robot description and a scene, built from the project's own robot model.

Nothing is read from another project's MJCF: every body, joint, inertia and collision shape comes
from the loaded ``Robot`` (URDF, xacro, MoveIt package or DH table) and every scene item from the
trajectory's ``Scene``.

* Bodies: one per link, placed by its joint's origin (a DH ``post`` transform is a welded child body).
  Revolute joints are hinges, prismatic joints slides, about the description's axis; a mimic joint is
  a hinge/slide held to the joint it follows by an equality constraint. Joint values in MuJoCo are
  ``q + offset`` (the description's motion is ``motion(q + offset)``).
* Inertias: the description's ``<inertial>`` (mass, centre of mass, full tensor about it). A moving
  link without one gets the mass of its collision shapes at ``DEFAULT_DENSITY`` (MuJoCo computes it
  from the geoms), or, without shapes, ``FALLBACK_MASS`` as a small sphere; every such case is a note.
* Collision: the description's primitives as they are, meshes as their convex hulls (the collision
  checker's default; MuJoCo collides every mesh as its hull, so ``exact`` meshes are hulls here too and
  a note says so). Pairs the description allows to touch (SRDF ``disable_collisions``) are excluded,
  and so are the links on the table (``base_links``) against items of role ``table``. Where the description
  gives its jaws' meshes (``Gripper.jaw_meshes``), objects meet those links only through the meshes' convex pieces
  (``roarmctl.robot.jaw_pieces``: the geometry the planner closes by), the links' own shapes everything else.
* Scene: tables and obstacles are fixed; objects are free bodies with the plan's masses (payloads of
  the trajectory), other objects at ``DEFAULT_OBJECT_DENSITY``. A mesh item is its convex pieces (the
  checker's: the hull of each connected part), one mesh geom each; a point-cloud item is its occupied cells
  (the checker's octree leaves) as boxes, runs of cells merged (``cell_boxes``), not a height field: the
  cells are what the checker saw, overhangs included.
* Contact: friction ``FRICTION`` (sliding, torsional, rolling) on every geom, elliptic friction cones
  with ``IMPRATIO``, contact stiffness ``SOLREF``; gravity 9.81 m/s^2 along -z of the world.

Units: m, kg, s, rad (MuJoCo's own).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.robot.jaw_pieces import Piece, jaw_pieces
from roarmctl.robot.model import Robot, quaternions

if TYPE_CHECKING:
    from roarmctl.motion.scene import Scene, SceneItem

GRAVITY = 9.81  # m/s^2, the same value as roarmctl.robot.dynamics.GRAVITY
TIMESTEP = 0.001  # s: the servos' control loop and the contacts both need about 1 ms
#: Coulomb friction of every contact: sliding 0.6, torsional 5 mm, rolling 0.1 mm. Assumed: printed or
#: aluminium jaws on wooden or plastic blocks are quoted at 0.3-0.8 dry; 0.6 is a middle value.
FRICTION = (0.6, 0.005, 0.0001)
#: Contact stiffness: MuJoCo's (time constant s, damping ratio); 4 ms = 4 time steps, stiffer than the
#: default 20 ms so that a squeezed 30 g cube sinks less than 0.1 mm into the jaws.
SOLREF = (0.002, 1.0)
IMPRATIO = 10.0  # elliptic cones: friction as hard as the normal force (less creep of a held object)
#: MuJoCo's soft contacts let a squeezed object creep down the jaws (millimetres per second); the no-slip
#: pass removes that creep, as dry friction below its limit does not slide.
NOSLIP_ITERATIONS = 3
DEFAULT_DENSITY = 1000.0  # kg/m^3, a link without <inertial> (MuJoCo's own default)
DEFAULT_OBJECT_DENSITY = 500.0  # kg/m^3, an object whose mass the trajectory does not give (wood)
FALLBACK_MASS = 0.001  # kg, a moving link with neither <inertial> nor collision shapes
MIN_MASS = 1e-6  # kg: an <inertial> below this counts as missing
#: Boxes of one point-cloud item (its merged occupied cells): more would slow every physics step down.
MAX_CLOUD_BOXES = 20_000
#: Contact bits (MuJoCo: two geoms collide when one's contype shares a bit with the other's conaffinity):
#: every geom has both bits; a point-cloud table's boxes only TABLE_BIT, the base links' geoms only the other.
EVERY_BIT, TABLE_BIT = 3, 2
#: (contype, conaffinity) where the jaws meet objects through the convex pieces of their meshes
#: (``roarmctl.robot.jaw_pieces``): objects carry bit 4 and accept every bit; a piece carries bit 4 only and accepts
#: none (it meets objects alone); a jaw link's collision shapes carry none and accept bits 1-2 (the table, obstacles
#: and the arm, not objects).
OBJECT_BITS, PIECE_BITS, JAW_BITS = (4, 7), (4, 0), (0, EVERY_BIT)


def body_name(link: str) -> str:
    """The MJCF body name of a link."""
    return f"link:{link}"


def item_body_name(item: str) -> str:
    """The MJCF body name of a scene item."""
    return f"item:{item}"


def joint_name(joint: str) -> str:
    """The MJCF joint name of a description joint."""
    return f"joint:{joint}"


@dataclass
class JointDynamics:
    """What the actuator adds to a joint: reflected rotor inertia (kg m^2), viscous damping (N m s/rad)
    and dry friction (N m)."""

    armature: float = 0.0
    damping: float = 0.0
    frictionloss: float = 0.0


@dataclass
class BuiltDocument:
    """The MJCF text and what it took to make it.

    ``geom_owner``: geom name -> ("link", link name) or ("item", item name); ``objects``: names of the
    free scene items; ``masses``: object name -> kg used; ``notes``: one sentence per assumption made
    for this description (links without inertia, exact meshes as hulls).
    """

    xml: str
    geom_owner: dict[str, tuple[str, str]] = field(default_factory=dict)
    objects: list[str] = field(default_factory=list)
    masses: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def quat(rot: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z), MuJoCo's order, of a 3x3 rotation matrix (``robot.model.quaternions``)."""
    x, y, z, w = quaternions(rot)
    return float(w), float(x), float(y), float(z)


def _f(values: Iterable[float]) -> str:
    return " ".join(repr(float(v) + 0.0) for v in values)


def _place(el: ET.Element, pose: np.ndarray) -> None:
    """Set ``pos``/``quat`` of ``el`` from a 4x4 transform (omitted when identity)."""
    p = pose[:3, 3]
    if np.any(p != 0):
        el.set("pos", _f(p))
    if not np.allclose(pose[:3, :3], np.eye(3), atol=1e-15):
        el.set("quat", _f(quat(pose[:3, :3])))


def _geom_shape(el: ET.Element, kind: str, size: npt.ArrayLike = (0.0, 0.0, 0.0), radius: float = 0.0,
                length: float = 0.0) -> None:
    if kind == "box":
        el.set("type", "box")
        el.set("size", _f(np.asarray(size, dtype=float) / 2))
    elif kind == "cylinder":
        el.set("type", "cylinder")
        el.set("size", _f((radius, length / 2)))
    elif kind == "capsule":
        el.set("type", "capsule")
        el.set("size", _f((radius, length / 2)))
    elif kind == "sphere":
        el.set("type", "sphere")
        el.set("size", _f((radius,)))
    else:
        raise InputError(f"physics: a '{kind}' shape has no physics model yet", "use boxes, cylinders, spheres or meshes")


def build_document(robot: Robot, scene: Scene, masses: dict[str, float] | None = None,
                   dynamics: dict[str, JointDynamics] | None = None, *, timestep: float = TIMESTEP,
                   friction: tuple[float, float, float] = FRICTION) -> BuiltDocument:
    """The MJCF of ``robot`` in ``scene`` (a ``roarmctl.motion.scene.Scene``).

    ``masses``: object name -> kg (the trajectory's payloads); ``dynamics``: joint name -> what its
    actuator adds (``roarmctl.physics.actuation``).
    """
    masses = dict(masses or {})
    dynamics = dynamics or {}
    doc = BuiltDocument(xml="")
    root = ET.Element("mujoco", model=f"roarmctl:{robot.name}")
    ET.SubElement(root, "compiler", angle="radian", autolimits="true", inertiafromgeom="auto",
                  balanceinertia="true", boundinertia="1e-12")
    opt = ET.SubElement(root, "option", timestep=repr(timestep), gravity=_f((0, 0, -GRAVITY)), integrator="implicitfast",
                  cone="elliptic", impratio=repr(IMPRATIO), noslip_iterations=str(NOSLIP_ITERATIONS))
    # several contact points between two convex shapes (a jaw's face on a cylinder is a line, not a point)
    ET.SubElement(opt, "flag", multiccd="enable")
    ET.SubElement(root, "size", memory="64M")
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "geom", friction=_f(friction), solref=_f(SOLREF), condim="4", contype=str(EVERY_BIT),
                  conaffinity=str(EVERY_BIT),
                  density=repr(DEFAULT_DENSITY), rgba="0.7 0.7 0.7 1")
    asset = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    contact = ET.SubElement(root, "contact")
    equality = ET.SubElement(root, "equality")

    # the root link is a static body of its own (not the world body): its contacts can then be excluded per pair
    root_body = ET.SubElement(world, "body", name=body_name(robot.root))
    bodies: dict[str, ET.Element] = {robot.root: root_body}
    shapes_of: dict[str, list] = {}
    for s in robot.collision:
        shapes_of.setdefault(s.link, []).append(s)
    eye = np.eye(4)
    for j in robot.joints:
        parent = bodies[j.parent]
        jb = ET.SubElement(parent, "body", name=body_name(j.child) if np.allclose(j.post, eye) else f"joint-frame:{j.name}")
        _place(jb, j.origin)
        if j.kind in ("revolute", "prismatic"):
            jel = ET.SubElement(jb, "joint", name=joint_name(j.name), type="hinge" if j.kind == "revolute" else "slide",
                                axis=_f(np.asarray(j.axis, dtype=float)))
            if math.isfinite(j.lower) and math.isfinite(j.upper) and j.lower < j.upper:
                # the description's limits are the joint's ends: a real arm stops there, whatever its servo is told
                jel.set("range", _f((j.lower, j.upper)))
            dyn = dynamics.get(j.name)
            if dyn is not None:
                for key in ("armature", "damping", "frictionloss"):
                    if getattr(dyn, key):
                        jel.set(key, repr(float(getattr(dyn, key))))
            if j.mimic is not None:
                master = next(m for m in robot.joints if m.name == j.mimic)
                ET.SubElement(equality, "joint", joint1=joint_name(j.name), joint2=joint_name(j.mimic),
                              polycoef=_f((j.offset - master.offset, 1, 0, 0, 0)))
        link_body = jb
        if not np.allclose(j.post, eye):
            link_body = ET.SubElement(jb, "body", name=body_name(j.child))
            _place(link_body, j.post)
        bodies[j.child] = link_body
        _inertial(doc, robot, j.child, link_body, bool(shapes_of.get(j.child)), j.kind != "fixed")
    for link, shapes in shapes_of.items():
        if link not in bodies:
            continue
        for k, s in enumerate(shapes):
            name = f"robot:{link}:{k}"
            g = ET.SubElement(bodies[link], "geom", name=name)
            _place(g, s.origin)
            if s.kind == "mesh":
                mesh = s.mesh
                mname = f"mesh:{link}:{k}"
                ET.SubElement(asset, "mesh", name=mname, vertex=_f(np.asarray(mesh.vertices).ravel()),
                              face=" ".join(str(int(v)) for v in np.asarray(mesh.faces).ravel()))
                g.set("type", "mesh")
                g.set("mesh", mname)
                note = f"link {link}: its 'exact' mesh collides as its convex hull in MuJoCo"
                if getattr(mesh, "exact", False) and note not in doc.notes:
                    doc.notes.append(note)
            else:
                _geom_shape(g, s.kind, s.size, s.radius, s.length)
            if robot.inertials.get(link) is not None and robot.inertials[link].mass > MIN_MASS:
                g.set("density", "0")  # the description's inertial is the body's mass
            doc.geom_owner[name] = ("link", link)
    for pair in sorted(tuple(sorted(p)) for p in robot.allowed_collisions):
        a, b = pair
        if a in bodies and b in bodies and a != b:
            ET.SubElement(contact, "exclude", body1=body_name(a), body2=body_name(b))
    pieces = {link: p for link, p in jaw_pieces(robot).items() if link in bodies}
    for link, link_pieces in pieces.items():
        _jaw_pieces(doc, link, link_pieces, bodies[link], asset)
    _scene(doc, robot, scene, world, contact, asset, bodies, masses, bool(pieces))
    if not len(equality):
        root.remove(equality)
    if not len(contact):
        root.remove(contact)
    if not len(asset):
        root.remove(asset)
    doc.xml = ET.tostring(root, encoding="unicode")
    return doc


def _jaw_pieces(doc: BuiltDocument, link: str, pieces: list[Piece], link_body: ET.Element, asset: ET.Element) -> None:
    """A jaw link meets objects through the convex pieces of its jaw mesh (``roarmctl.robot.jaw_pieces``), one
    mesh geom each that touches objects only (``PIECE_BITS``), while the link's collision shapes touch everything but
    objects (``JAW_BITS``; an ``exclude`` of the link's body would leave out the pieces too)."""
    for g in link_body.findall("geom"):
        g.set("contype", str(JAW_BITS[0]))
        g.set("conaffinity", str(JAW_BITS[1]))
    for k, v in enumerate(pieces):
        mname, gname = f"mesh:jaw:{link}:{k}", f"robot:{link}:jaw{k}"
        ET.SubElement(asset, "mesh", name=mname, vertex=_f(np.asarray(v).ravel()))  # MuJoCo: their convex hull
        ET.SubElement(link_body, "geom", name=gname, type="mesh", mesh=mname, density="0", rgba="0.2 0.6 0.9 1",
                      contype=str(PIECE_BITS[0]), conaffinity=str(PIECE_BITS[1]))
        doc.geom_owner[gname] = ("link", link)
    doc.notes.append(f"link {link} meets objects through the {len(pieces)} convex pieces of its jaw mesh (CoACD), "
                     f"the geometry of the gripper's jaw table, not through its collision shapes")


def _inertial(doc: BuiltDocument, robot: Robot, link: str, body: ET.Element, has_shapes: bool, jointed: bool) -> None:
    """The link's inertial; a link on a joint of its own needs mass (a welded frame such as a TCP does not)."""
    inertial = robot.inertials.get(link)
    if inertial is not None and inertial.mass > MIN_MASS:
        i = np.asarray(inertial.inertia, dtype=float)
        ET.SubElement(body, "inertial", pos=_f(inertial.com), mass=repr(float(inertial.mass)),
                      fullinertia=_f((i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])))
        return
    if not jointed:
        return
    if has_shapes:
        doc.notes.append(f"link {link} has no inertia in the description: its mass is that of its collision shapes "
                         f"at {DEFAULT_DENSITY:g} kg/m^3 (assumed)")
        return
    r = 0.01
    ET.SubElement(body, "inertial", pos="0 0 0", mass=repr(FALLBACK_MASS), diaginertia=_f([0.4 * FALLBACK_MASS * r * r] * 3))
    doc.notes.append(f"link {link} has neither inertia nor collision shapes: it gets {FALLBACK_MASS * 1e3:g} g as a "
                     f"{r * 1e3:g} mm sphere (assumed)")


def _scene(doc: BuiltDocument, robot: Robot, scene: Scene, world: ET.Element, contact: ET.Element, asset: ET.Element,
           bodies: dict[str, ET.Element], masses: dict[str, float], jaws_from_meshes: bool = False) -> None:
    base = [link for link in robot.base_links if link in bodies]
    for item in scene.items:
        if item.role == "object":
            body = ET.SubElement(world, "body", name=item_body_name(item.name))
            _place(body, item.pose)
            ET.SubElement(body, "freejoint", name=f"free:{item.name}")
            g = ET.SubElement(body, "geom", name=f"item:{item.name}", rgba="0.9 0.5 0.1 1")
            if jaws_from_meshes:  # jaws built from their meshes: objects meet the jaw links through those pieces only
                g.set("contype", str(OBJECT_BITS[0]))
                g.set("conaffinity", str(OBJECT_BITS[1]))
            _geom_shape(g, item.shape, item.size, item.radius, item.length)
            volume = _volume(item)
            mass = masses.get(item.name)
            if mass is None:
                mass = DEFAULT_OBJECT_DENSITY * volume
                doc.notes.append(f"object {item.name}: the trajectory gives no mass; {mass * 1e3:.1f} g at "
                                 f"{DEFAULT_OBJECT_DENSITY:g} kg/m^3 (assumed)")
            g.set("density", repr(mass / volume))
            doc.masses[item.name] = float(mass)
            doc.objects.append(item.name)
            doc.geom_owner[f"item:{item.name}"] = ("item", item.name)
        else:  # fixed: a static body of its own, so that contacts can be excluded per item
            body = ET.SubElement(world, "body", name=item_body_name(item.name))
            _place(body, item.pose)
            rgba = "0.5 0.5 0.5 1" if item.role == "table" else "0.6 0.2 0.2 1"
            if item.shape == "mesh":
                _mesh_item(doc, item, body, asset, rgba)
            elif item.shape == "cloud":
                world.remove(body)
                _cloud_item(doc, item, world, rgba, item.role == "table")
                if item.role == "table":
                    _off_cloud_tables(robot, base, bodies)
                continue
            else:
                g = ET.SubElement(body, "geom", name=f"item:{item.name}", density="0", rgba=rgba)
                _geom_shape(g, item.shape, item.size, item.radius, item.length)
                doc.geom_owner[f"item:{item.name}"] = ("item", item.name)
            if item.role == "table":
                for link in base:
                    ET.SubElement(contact, "exclude", body1=body_name(link), body2=item_body_name(item.name))


def _mesh_item(doc: BuiltDocument, item: SceneItem, body: ET.Element, asset: ET.Element, rgba: str) -> None:
    """A mesh scene item: one mesh geom per convex piece (the checker's pieces); an ``exact`` mesh (FCL checks
    its triangles) collides as its convex hull in MuJoCo, as a robot's exact mesh does, and a note says so."""
    assert item.mesh is not None  # a mesh item carries its MeshData
    for k, (v, f) in enumerate(item.mesh.pieces):
        mname, gname = f"mesh:item:{item.name}:{k}", f"item:{item.name}:{k}"
        ET.SubElement(asset, "mesh", name=mname, vertex=_f(np.asarray(v).ravel()),
                      face=" ".join(str(int(i)) for i in np.asarray(f).ravel()))
        ET.SubElement(body, "geom", name=gname, type="mesh", mesh=mname, density="0", rgba=rgba)
        doc.geom_owner[gname] = ("item", item.name)
    if item.mesh.exact:
        doc.notes.append(f"scene item {item.name}: its 'exact' mesh collides as its convex hull in MuJoCo "
                         "(a concave part is filled)")


def _cloud_item(doc: BuiltDocument, item: SceneItem, world: ET.Element, rgba: str, table: bool) -> None:
    """A point-cloud scene item: its occupied cells (the checker's octree leaves) as boxes, runs of cells
    merged into one box each (``cell_boxes``: the same volume, far fewer geoms). The boxes are geoms of the
    world body itself: MuJoCo's broad phase then passes over them (hundreds of boxes in a static body of their
    own cost every step 40 us). A table's boxes touch no geom of a base link (``TABLE_BIT``)."""
    assert item.cloud is not None  # a cloud item carries its CloudData
    r = item.cloud.resolution
    lo, hi = cell_boxes(item.cloud.cells)
    if len(lo) > MAX_CLOUD_BOXES:
        raise InputError(f"physics: scene item '{item.name}': its {len(item.cloud.cells)} cells make {len(lo)} boxes, "
                         f"more than {MAX_CLOUD_BOXES}", "give the cloud a coarser resolution")
    rot, t = item.pose[:3, :3], item.pose[:3, 3]
    q = None if np.allclose(rot, np.eye(3), atol=1e-15) else _f(quat(rot))
    centres = ((lo + hi) * r / 2) @ rot.T + t
    for k, (a, b) in enumerate(zip(lo, hi)):
        gname = f"item:{item.name}:{k}"
        g = ET.SubElement(world, "geom", name=gname, type="box", size=_f((b - a) * r / 2), pos=_f(centres[k]),
                          density="0", rgba=rgba)
        if q is not None:
            g.set("quat", q)
        if table:
            g.set("contype", str(TABLE_BIT))
            g.set("conaffinity", str(TABLE_BIT))
        doc.geom_owner[gname] = ("item", item.name)
    doc.notes.append(f"scene item {item.name}: {len(item.cloud.cells)} occupied cells of {r * 1e3:g} mm as "
                     f"{len(lo)} box{'es' if len(lo) != 1 else ''}")


def _off_cloud_tables(robot: Robot, base: list[str], bodies: dict[str, ET.Element]) -> None:
    """The base links' geoms leave out ``TABLE_BIT``: they never touch a table made of a cloud's boxes (which
    are world geoms, not a body that an ``exclude`` could name)."""
    for link in base:
        for g in bodies[link].findall("geom"):
            g.set("contype", str(EVERY_BIT & ~TABLE_BIT))
            g.set("conaffinity", str(EVERY_BIT & ~TABLE_BIT))


def cell_boxes(cells: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Boxes whose union is exactly the occupied cells ``cells`` (K, 3) int (unique): cells merged into runs
    along x, runs of equal extent into rectangles along y, rectangles into blocks along z. Returns
    (lo (B, 3), hi (B, 3)) int: box b spans cells lo[b] .. hi[b] - 1 (multiply by the resolution for m)."""
    c = np.unique(np.asarray(cells, dtype=np.int64).reshape(-1, 3), axis=0)
    lo, hi = c.copy(), c + 1
    for axis in range(3):  # merge along x, then y, then z: boxes equal in every other extent and touching
        others = [a for a in range(3) if a != axis]
        keys = np.column_stack([lo[:, a] for a in others] + [hi[:, a] for a in others])
        order = np.lexsort((lo[:, axis],) + tuple(keys[:, i] for i in reversed(range(keys.shape[1]))))
        lo, hi, keys = lo[order], hi[order], keys[order]
        # a run continues while the next box starts where this one ends
        new = np.ones(len(lo), dtype=bool)
        new[1:] = np.any(keys[1:] != keys[:-1], axis=1) | (lo[1:, axis] != hi[:-1, axis])
        start = np.flatnonzero(new)
        last = np.r_[start[1:], len(lo)] - 1
        top = hi[last, axis]
        lo, hi = lo[start], hi[start]
        hi[:, axis] = top
    return lo, hi


def _volume(item: SceneItem) -> float:
    if item.shape == "box":
        return float(np.prod(item.size))
    if item.shape == "cylinder":
        return math.pi * item.radius ** 2 * item.length
    return 4.0 / 3.0 * math.pi * item.radius ** 3
