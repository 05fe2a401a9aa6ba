"""Camera images of a physics run: MuJoCo's offscreen renderer on the CPU (Mesa's EGL with llvmpipe, or OSMesa).

``Cameras`` draws a ``World``'s compiled model (a copy of it: the physics model is left as it is) from two
cameras: ``front``, fixed in the world in front of the arm and looking back at the workspace, and ``wrist``,
on the TCP link, looking along the tool's approach axis (TCP +x), lit by MuJoCo's headlight and one
directional key light. Objects can be given their own colours. ``render(qpos)`` draws every camera for each
recorded state (``Recording.frame_qpos``): uint8 RGB (F, height, width, 3) per camera.

What a datagen worker pays for again and again is kept out of the episode (``bench/bench_datagen.py``): the
model is not compiled again with cameras in it (the cameras are placed in MuJoCo's scene each frame, the light
added to it: ~45 ms an episode), the GL context and MuJoCo's GPU-side copy of the model's meshes (``MjrContext``,
~50 ms) are kept for the next model whose meshes, textures and visual settings are the same (``_Context``:
compared by their bytes), and ``FrameBuffers`` lends the episode's frame arrays again to the next episode (fresh
ones cost the kernel ~0.25 ms an image to zero their huge pages).

MuJoCo picks its GL back end from ``MUJOCO_GL`` when it is first imported: ``offscreen()`` sets ``egl`` when none
is set (a headless machine has no display for GLFW), and must run before anything imports ``mujoco``. Debian's packages: ``libegl1 libegl-mesa0
libgl1-mesa-dri`` (``make render``).
"""

from __future__ import annotations

import copy
import hashlib
import os
import sys
from collections.abc import Mapping, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any

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


def _look_at(eye: Sequence[float], target: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Forward and up (unit vectors, world) of a camera at ``eye`` looking at ``target``, its image rows level."""
    f = np.asarray(target, dtype=float) - np.asarray(eye, dtype=float)
    f /= np.linalg.norm(f)
    right = np.cross(f, (0.0, 0.0, 1.0))
    right /= np.linalg.norm(right)
    return f, np.cross(right, f)


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


class FrameBuffers:
    """Frame arrays lent to one episode at a time: ``take(camera, shape)`` gives a uint8 array of ``shape`` (F,
    height, width, 3) in memory kept from the episode before (grown when too small). What it gave for a camera
    is overwritten by the next ``take`` for that camera: use (encode) the frames before rendering the next episode."""

    def __init__(self) -> None:
        self._kept: dict[str, np.ndarray] = {}

    def take(self, camera: str, shape: tuple[int, ...]) -> np.ndarray:
        """A uint8 array of ``shape`` for ``camera``'s frames (what was lent for it before is overwritten)."""
        n = int(np.prod(shape))
        buf = self._kept.get(camera)
        if buf is None or buf.size < n:
            buf = self._kept[camera] = np.empty(n, dtype=np.uint8)
        return buf[:n].reshape(shape)


def _assets_key(mujoco: ModuleType, model: Any) -> bytes:
    """A digest of what ``MjrContext`` copies from ``model`` to the GL side (meshes, textures, height fields,
    skins, flexes, materials' texture use, the visual settings and extent): two models with the same digest draw
    the same with one context. The meshes' collision trees (``mesh_bvh*``, ``mesh_octree*``) are left out: their
    addresses move with the scene's other geoms, and nothing of them is drawn."""
    h = hashlib.sha256()
    for name in sorted(dir(model)):
        if (name.startswith(_ASSET_PREFIXES) or name in ("nmesh", "ntex", "nhfield", "nskin", "nflex", "nmat")) and \
                "bvh" not in name and "octree" not in name:
            value = getattr(model, name)
            h.update(name.encode())
            h.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray) else repr(value).encode())
    h.update(repr(model.vis).encode())
    h.update(repr(model.stat.extent).encode())
    return h.digest()


_ASSET_PREFIXES = ("mesh_", "tex_", "hfield_", "skin_", "flex_", "mat_")


class _Context:
    """The process's GL context and ``MjrContext`` (one at a time), kept for the next model with the same
    assets (``_assets_key``) at the same image size; made anew (the old one freed) otherwise."""

    key: tuple | None = None
    gl: Any = None
    mjr: Any = None

    @classmethod
    def get(cls, mujoco: ModuleType, model: Any, width: int, height: int) -> Any:
        key = (_assets_key(mujoco, model), width, height)
        if key != cls.key:
            cls.free()
            from mujoco import gl_context

            try:
                cls.gl = gl_context.GLContext(width, height)
                cls.gl.make_current()
                cls.mjr = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150.value)
            except Exception as exc:  # noqa: BLE001  (GL back ends raise their own types)
                cls.free()
                raise RenderError(f"cannot render offscreen with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {exc}".splitlines()[0],
                                  "install Debian's libegl1 libegl-mesa0 libgl1-mesa-dri (make render), or set "
                                  "MUJOCO_GL=osmesa with libosmesa6") from None
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, cls.mjr)
            cls.key = key
        cls.gl.make_current()
        return cls.mjr

    @classmethod
    def free(cls) -> None:
        if cls.mjr is not None:
            cls.mjr.free()
        if cls.gl is not None:
            cls.gl.free()
        cls.key = cls.gl = cls.mjr = None


def _key_light(mujoco: ModuleType) -> Any:
    """The key light as MuJoCo makes it from ``KEY_LIGHT`` (a light of the model, in its scene)."""
    if "light" not in _KEPT:
        attrs = " ".join(f'{k}="{v}"' for k, v in KEY_LIGHT.items())
        m = mujoco.MjModel.from_xml_string(f"<mujoco><worldbody><light {attrs}/></worldbody></mujoco>")
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        scene = mujoco.MjvScene(m, 10)
        mujoco.mjv_updateScene(m, d, mujoco.MjvOption(), None, mujoco.MjvCamera(), mujoco.mjtCatBit.mjCAT_ALL.value, scene)
        _KEPT["light"] = {f: copy.copy(getattr(scene.lights[scene.nlight - 1], f)) for f in _LIGHT_FIELDS}
    return _KEPT["light"]


_KEPT: dict[str, Any] = {}
_LIGHT_FIELDS = ("pos", "dir", "type", "castshadow", "ambient", "diffuse", "specular", "attenuation", "cutoff",
                 "exponent", "bulbradius", "intensity", "range", "texid", "headlight")
KEY_LIGHT = {"pos": "0.4 -0.4 1.2", "dir": "-0.3 0.3 -1", "directional": "true", "diffuse": "0.6 0.6 0.6"}


class Cameras:
    """The front and wrist cameras of ``world`` at ``width`` x ``height`` pixels; ``colors``: object name ->
    RGB (0-1) for the scene items drawn in their own colour."""

    def __init__(self, world: World, width: int, height: int, colors: Mapping[str, Sequence[float]] | None = None) -> None:
        offscreen()
        import mujoco

        self._mujoco = mujoco
        self.model = copy.copy(world.model)  # the physics model's own arrays stay as they are
        m = self.model
        m.vis.global_.offwidth, m.vis.global_.offheight = max(width, 64), max(height, 64)
        # no shadow map and no multisampling: on llvmpipe they cost 30x the rest of a frame (145 ms against 5 ms
        # an image at 96 x 96; bench/bench_datagen.py)
        m.vis.quality.shadowsize, m.vis.quality.offsamples = 0, 0
        # the clipping planes scale with the model's extent, which MuJoCo takes from the bodies (the arm, about
        # 0.3 m): the table's far edge fell behind the far plane. A metre covers a desk scene.
        m.stat.extent = 1.0
        m.stat.center[:] = FRONT_TARGET
        for name, rgb in (colors or {}).items():
            g = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"item:{name}")
            if g >= 0:
                m.geom_rgba[g] = (*[float(v) for v in rgb], 1.0)
        self.tcp_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, _tcp_body(world))
        if self.tcp_body < 0:
            raise RoarmError(f"{world.robot.name}: the physics model has no body {_tcp_body(world)}")
        self.data = mujoco.MjData(m)
        self.scene = mujoco.MjvScene(m, maxgeom=max(1000, 2 * m.ngeom))
        self.option = mujoco.MjvOption()
        self.camera = mujoco.MjvCamera()
        self.camera.type = mujoco.mjtCamera.mjCAMERA_FREE
        self._fovy = float(m.vis.global_.fovy)
        self.light = _key_light(mujoco)
        _Context.get(mujoco, m, width, height)  # made now, so that a missing GL library is said before any frame
        self.rect = mujoco.MjrRect(0, 0, width, height)
        self.width, self.height = width, height
        self._front = (np.asarray(FRONT_EYE, dtype=float), *_look_at(FRONT_EYE, FRONT_TARGET))  # pos, forward, up
        self._scratch = np.empty((height, width, 3), dtype=np.uint8)

    def _pose(self, camera: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Position, forward, up (world) and vertical field of view (deg) of ``camera`` in the current state."""
        if camera == "front":
            return (*self._front, FRONT_FOVY)
        r = self.data.xmat[self.tcp_body].reshape(3, 3)
        # looking along the body's +x: image right = body +y, image up = body -z
        return self.data.xpos[self.tcp_body] + r @ np.asarray(WRIST_OFFSET), r[:, 0], -r[:, 2], WRIST_FOVY

    def render(self, qpos: np.ndarray, cameras: Sequence[str] = CAMERAS, buffers: FrameBuffers | None = None) -> dict[str, np.ndarray]:
        """Images (F, height, width, 3) uint8 per camera, one per state of ``qpos`` (F, nq); in arrays lent by
        ``buffers`` when given (valid until its next ``take``), else new ones."""
        for c in cameras:
            if c not in CAMERAS:
                raise RoarmError(f"unknown camera '{c}'")
        shape = (len(qpos), self.height, self.width, 3)
        out = {c: buffers.take(c, shape) if buffers is not None else np.empty(shape, dtype=np.uint8) for c in cameras}
        context = _Context.get(self._mujoco, self.model, self.width, self.height)  # current here, made for these assets
        try:
            self._draw(qpos, cameras, out, context)
        finally:
            self.model.vis.global_.fovy = self._fovy  # as it was (a context is kept by the model's visual settings)
        return out

    def _draw(self, qpos: np.ndarray, cameras: Sequence[str], out: dict[str, np.ndarray], context: Any) -> None:
        """Draw every camera at each state of ``qpos`` into ``out[camera][k]``."""
        mujoco, m, d, scene = self._mujoco, self.model, self.data, self.scene
        for k, q in enumerate(qpos):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            mujoco.mj_camlight(m, d)  # the model's own lights, if it has any
            for c in cameras:
                pos, forward, up, fovy = self._pose(c)
                m.vis.global_.fovy = fovy
                mujoco.mjv_updateScene(m, d, self.option, None, self.camera, mujoco.mjtCatBit.mjCAT_ALL.value, scene)
                for gl in scene.camera:  # both eyes (mono): the camera's pose in place of the free camera's
                    gl.pos[:], gl.forward[:], gl.up[:] = pos, forward, up
                if scene.nlight and scene.lights[0].headlight:  # the headlight shines from the camera
                    scene.lights[0].pos[:], scene.lights[0].dir[:] = pos, forward
                light = scene.lights[scene.nlight]
                for f, v in self.light.items():
                    setattr(light, f, v)
                scene.nlight += 1
                mujoco.mjr_render(self.rect, scene, context)
                mujoco.mjr_readPixels(self._scratch, None, self.rect, context)
                np.copyto(out[c][k], self._scratch[::-1])  # OpenGL's rows run bottom-up
