"""How much each link is padded against the scene, and which parts are too thin for it.

The plan's ``planner.padding`` (m) pads every arm shape; a description's sidecar may give some links
their own value (``padding: {LINK: m}``), e.g. thin fingers that would otherwise be doubled. A shape
is "thin" when the padding is more than half its thickness (its smallest width: a box's smallest
side, a cylinder's or sphere's diameter, a mesh hull's width across its thinnest face direction): the
padded part is then more than twice as thick as the part itself, and a plan near it is refused for a
clearance the real part has. Such parts are named in one warning with the fix; the base links (they never
move: their padding only keeps obstacles off the base, the RoArm's 6 mm base plate among them) are not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from roarmctl.errors import DescriptionError

if TYPE_CHECKING:
    from roarmctl.robot.model import CollisionShape, Robot


def thickness(shape: CollisionShape) -> float:
    """The shape's smallest width (m)."""
    if shape.kind == "mesh":
        from roarmctl.robot.meshes import MeshGeometry

        assert isinstance(shape.mesh, MeshGeometry)
        return shape.mesh.thickness()
    if shape.kind == "box":
        return float(min(shape.size))
    return 2.0 * float(shape.radius)  # sphere, cylinder, capsule


def link_padding(robot: Robot, padding: float) -> dict[str, float]:
    """Padding (m) of every link of ``robot``: the description's own value where it gives one, else ``padding``."""
    return {link: float(robot.padding.get(link, padding)) for link in robot.link_names}


def thin_parts(robot: Robot, padding: float) -> str | None:
    """One warning naming the links whose padding is more than half their thinnest shape's thickness
    (with the thickness and the fix), or None."""
    per_link = link_padding(robot, padding)
    thin: dict[str, float] = {}
    for shape in robot.collision:
        if shape.link in robot.base_links:  # never moves: its padding only keeps obstacles off the base plate
            continue
        pad = per_link[shape.link]
        t = thickness(shape)
        if pad > t / 2 and t < thin.get(shape.link, float("inf")):
            thin[shape.link] = t
    if not thin:
        return None
    parts = ", ".join(f"{link} ({t * 1000:.1f} mm thick, padded {per_link[link] * 1000:g} mm)" for link, t in thin.items())
    first = next(iter(thin))
    return (f"{robot.name}: padding more than half the thickness of {parts}: the padded part is more than twice as "
            f"thick, and a grasp or a pass near it may be refused although the part itself clears; give such links "
            f"their own padding in the description's sidecar, e.g. padding: {{{first}: {thin[first] / 4:.4f}}}")


def sidecar_padding(side: dict, where: str, links: set[str]) -> dict[str, float]:
    """The sidecar's ``padding: {LINK: m}`` (each in [0, 0.1] m)."""
    raw = side.get("padding")
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise DescriptionError(f"{where}: padding: expected a mapping link -> metres, e.g. {{left_finger: 0.002}}")
    out = {}
    for link, value in raw.items():
        if link not in links:
            raise DescriptionError(f"{where}: padding.{link}: not a link of the URDF")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise DescriptionError(f"{where}: padding.{link}: expected a number (m), got {value!r}")
        v = float(value)
        if not 0.0 <= v <= 0.1:
            raise DescriptionError(f"{where}: padding.{link}: {v:g} m is outside [0, 0.1] m")
        out[str(link)] = v
    return out
