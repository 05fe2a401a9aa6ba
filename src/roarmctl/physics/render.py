"""Camera images of a physics run: MuJoCo's offscreen renderer on the CPU (Mesa's EGL with llvmpipe, or OSMesa).

``Cameras`` compiles a copy of a ``World``'s model with two cameras added (the physics model itself is left
as it is): ``front``, fixed in the world in front of the arm and looking back at the workspace, and
``wrist``, on the TCP link, looking along the tool's approach axis (TCP +x). Objects can be given their own
colours. ``render(qpos)`` draws every camera for each recorded state (``Recording.frame_qpos``): uint8 RGB
(F, height, width, 3) per camera.

MuJoCo picks its GL back end from ``MUJOCO_GL`` when it is first imported: ``offscreen()`` sets ``egl`` when none
is set (a headless machine has no display for GLFW), and must run before anything imports ``mujoco``. Debian's packages: ``libegl1 libegl-mesa0
libgl1-mesa-dri`` (``make render``).
"""

from __future__ import annotations

import os
import sys
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from roarmctl.errors import RoarmError
from roarmctl.physics.mjcf import body_name

if TYPE_CHECKING:
    from roarmctl.physics.world import World

CAMERAS = ("front", "wrist")
FRONT_EYE = (0.72, 0.0, 0.42)  # m, world: in front of the arm, above the table
FRONT_TARGET = (0.20, 0.0, 0.04)  # m, world: the middle of the workspace
FRONT_FOVY = 50.0  # deg
WRIST_OFFSET = (-0.04, 0.0, 0.0)  # m, TCP frame: a little behind the TCP, on the approach axis
WRIST_FOVY = 80.0  # deg


class RenderError(RoarmError):
    """No OpenGL context for offscreen rendering (exit 4: the machine lacks the GL libraries)."""

    exit_code = 4


def offscreen() -> None:
    """Choose EGL for MuJoCo's renderer unless ``MUJOCO_GL`` says otherwise; call before ``mujoco`` is imported.

    When ``mujoco`` was imported earlier in the process with no ``MUJOCO_GL``, it renders through GLFW, whose context
    aborts the whole process (not an exception) where there is no display: refused here with a ``RenderError``."""
    if "mujoco" not in sys.modules:
        os.environ.setdefault("MUJOCO_GL", "egl")
    elif os.environ.get("MUJOCO_GL", "glfw").strip().lower() == "glfw" and not (
            os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise RenderError("MuJoCo was imported in this process before roarmctl could choose an offscreen GL back end, "
                          "and GLFW needs a display", "set MUJOCO_GL=egl (or osmesa) before Python starts")


def _xyaxes(eye: Sequence[float], target: Sequence[float]) -> str:
    """MuJoCo's camera ``xyaxes`` (image right, image up) for a camera at ``eye`` looking at ``target``."""
    f = np.asarray(target, dtype=float) - np.asarray(eye, dtype=float)
    f /= np.linalg.norm(f)
    right = np.cross(f, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    return " ".join(f"{v:.6f}" for v in (*right, *up))


def _tcp_body(world: World) -> str:
    """The MuJoCo body the TCP rides on: the TCP link's, else the nearest ancestor link that has a body."""
    robot = world.robot
    parent = {j.child: j.parent for j in robot.joints}
    link: str | None = robot.tcp_link
    while link is not None and link not in world.link_body:
        link = parent.get(link)
    if link is None:
        raise RoarmError(f"{robot.name}: no body carries the TCP link {robot.tcp_link}")
    return body_name(link)


class Cameras:
    """The front and wrist cameras of ``world`` at ``width`` x ``height`` pixels; ``colors``: object name ->
    RGB (0-1) for the scene items drawn in their own colour."""

    def __init__(self, world: World, width: int, height: int, colors: Mapping[str, Sequence[float]] | None = None) -> None:
        offscreen()
        import mujoco

        root = ET.fromstring(world.doc.xml)
        visual = root.find("visual")
        visual = ET.SubElement(root, "visual") if visual is None else visual
        glob = visual.find("global")
        glob = ET.SubElement(visual, "global") if glob is None else glob
        glob.set("offwidth", str(max(width, 64)))
        glob.set("offheight", str(max(height, 64)))
        # no shadow map and no multisampling: on llvmpipe they cost 30x the rest of a frame (145 ms against 5 ms
        # an image at 96 x 96; bench/bench_datagen.py)
        quality = visual.find("quality")
        quality = ET.SubElement(visual, "quality") if quality is None else quality
        quality.set("shadowsize", "0")
        quality.set("offsamples", "0")
        # the clipping planes scale with the model's extent, which MuJoCo takes from the bodies (the arm, about
        # 0.3 m): the table's far edge fell behind the far plane. A metre covers a desk scene.
        stat = root.find("statistic")
        stat = ET.SubElement(root, "statistic") if stat is None else stat
        stat.set("extent", "1.0")
        stat.set("center", " ".join(map(str, FRONT_TARGET)))
        worldbody = root.find("worldbody")
        assert worldbody is not None  # build_document always writes one
        ET.SubElement(worldbody, "light", name="render:key", pos="0.4 -0.4 1.2", dir="-0.3 0.3 -1", directional="true",
                      diffuse="0.6 0.6 0.6")
        ET.SubElement(worldbody, "camera", name="front", pos=" ".join(map(str, FRONT_EYE)),
                      xyaxes=_xyaxes(FRONT_EYE, FRONT_TARGET), fovy=str(FRONT_FOVY))
        tcp = _tcp_body(world)
        body = next((b for b in root.iter("body") if b.get("name") == tcp), None)
        if body is None:
            raise RoarmError(f"{world.robot.name}: the physics model has no body {tcp}")
        # looking along the body's +x: camera -z = body +x, image right = body +y, image up = body -z
        ET.SubElement(body, "camera", name="wrist", pos=" ".join(map(str, WRIST_OFFSET)), xyaxes="0 1 0 0 0 -1",
                      fovy=str(WRIST_FOVY))
        self.model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
        for name, rgb in (colors or {}).items():
            g = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_GEOM, f"item:{name}")
            if g >= 0:
                self.model.geom_rgba[g] = (*[float(v) for v in rgb], 1.0)
        self.data = mujoco.MjData(self.model)
        try:
            self.renderer = mujoco.Renderer(self.model, height, width)
        except Exception as exc:  # noqa: BLE001  (GL back ends raise their own types)
            raise RenderError(f"cannot render offscreen with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {exc}".splitlines()[0],
                              "install Debian's libegl1 libegl-mesa0 libgl1-mesa-dri (make render), or set MUJOCO_GL=osmesa "
                              "with libosmesa6") from None
        self._mujoco = mujoco
        self.width, self.height = width, height

    def render(self, qpos: np.ndarray, cameras: Sequence[str] = CAMERAS) -> dict[str, np.ndarray]:
        """Images (F, height, width, 3) uint8 per camera, one per state of ``qpos`` (F, nq)."""
        out = {c: np.empty((len(qpos), self.height, self.width, 3), dtype=np.uint8) for c in cameras}
        for k, q in enumerate(qpos):
            self.data.qpos[:] = q
            self._mujoco.mj_kinematics(self.model, self.data)
            self._mujoco.mj_comPos(self.model, self.data)
            self._mujoco.mj_camlight(self.model, self.data)  # the cameras' poses (mj_kinematics leaves them)
            for c in cameras:
                self.renderer.update_scene(self.data, camera=c)
                self.renderer.render(out=out[c][k])  # read into the frame itself, not into a new image then copied
        return out

    def close(self) -> None:
        """Free the GL context."""
        self.renderer.close()
