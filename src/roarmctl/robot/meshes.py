"""Collision meshes of a description: resolve the file name, load it with trimesh, keep the convex
hull (default, conservative) or the triangles themselves (``exact``).

File names: relative to the URDF's folder, absolute, ``file://...``, or ``package://NAME/rest``
resolved through the sidecar's ``packages: {NAME: folder}`` map (folders relative to the sidecar)
or the command line's ``--package-path NAME=FOLDER`` (``PACKAGE_PATHS``; the sidecar wins).
Formats: whatever trimesh reads as one triangle mesh, STL, OBJ, DAE (COLLADA, through pycollada)
among them; a scene with several meshes is concatenated in its own frame. A COLLADA file's
``<unit meter="0.001"/>`` is honoured (its vertices are in that unit, as assimp, so RViz and Gazebo, read
them; trimesh records it and leaves the numbers as written); its ``<up_axis>`` is not applied, as RViz and MoveIt
read it (they drop the rotation assimp puts on the root of a file that is not Y_UP and keep the unit's scale:
ros-visualization/rviz#1689, moveit/geometric_shapes#52; trimesh applies none). STL, OBJ and the rest are in metres.
``scale`` multiplies the vertices after that, as in URDF. ``unit_notes``: a link whose mesh is more than
``UNIT_RATIO`` times larger or smaller than the longest joint offset at its ends, the usual sign of a mesh
in the wrong unit.

Load time: an STL of a few thousand triangles loads and gets its hull in about 2 ms, so nothing is
cached on disk; a mesh used by several links is read once per process (keyed by path, file
modification time and scale).
"""

from __future__ import annotations

import io
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from roarmctl.errors import DescriptionError, InputError
from roarmctl.fileio import Roots, note_read, read_bytes, resolved
from roarmctl.kept import Kept

#: NAME -> folder for ``package://NAME/...``, filled by the CLI's ``--package-path`` option.
PACKAGE_PATHS: dict[str, Path] = {}

MESH_MODES = ("convex", "exact")
MESH_TYPES = ("stl", "obj", "dae", "ply", "off", "glb")  # read from bytes alone (no other file opened)
MESH_BYTES = 64 * 1024 * 1024  # a mesh file may have (published arms' collision meshes: < 5 MiB)
SCENE_MESH_BYTES = 256 * 1024 * 1024  # a scene item's mesh file (a CAD export of a workcell)
MAX_TRIANGLES = 2_000_000  # triangles of one mesh file
#: A mesh this many times larger or smaller than its link's offset from the parent joint gets a note.
UNIT_RATIO = 10.0
#: Offsets below this (m) are no measure of a link's size (a frame at its parent's origin): no note.
UNIT_MIN_OFFSET = 0.01


@dataclass(frozen=True)
class MeshGeometry:
    """Triangles (m) in the collision element's frame, centred: the vertices' bounding box is
    symmetric about the origin (the loader moves the shape's origin by the offset).

    ``vertices`` (V, 3) float, ``faces`` (F, 3) int. ``exact``: FCL checks the triangles (a BVH
    model) instead of their convex hull. ``source``: the resolved file, for messages.
    """

    vertices: np.ndarray
    faces: np.ndarray
    exact: bool
    source: str
    _grown: dict = field(default_factory=dict, compare=False, repr=False)
    _thickness: list = field(default_factory=list, init=False, compare=False, repr=False)  # worked out once (every plan asks)

    @property
    def half_extents(self) -> np.ndarray:
        """Half the extent (3,) m of the vertices along each axis, about the origin."""
        return np.max(np.abs(self.vertices), axis=0)

    def thickness(self) -> float:
        """The smallest width (m) of the convex hull across one of its faces: how thick the part is at its
        thinnest (a finger plate's thickness). For an exact mesh, that of its hull."""
        if not self._thickness:
            self._thickness.append(self._hull_width())
        return self._thickness[0]

    def _hull_width(self) -> float:
        v, f = (self.vertices, self.faces) if not self.exact else convex_hull(self.vertices, self.source)
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        norm = np.linalg.norm(n, axis=1)
        n = n[norm > 1e-15] / norm[norm > 1e-15, None]
        proj = v @ n.T  # (V, F)
        return float(np.min(proj.max(axis=0) - proj.min(axis=0)))

    def grown(self, grow: float) -> tuple[np.ndarray, np.ndarray]:
        """The shape padded by ``grow`` (m): vertices (V', 3) and faces (F', 3).

        A convex mesh becomes the hull of its vertices each surrounded by a polytope that holds a ball
        of radius ``grow`` (``ball_points``): the Minkowski sum of the hull and that polytope, so every
        point within ``grow`` of the hull lies inside and no point of it lies farther than 1.071 x
        ``grow`` from the hull (moving the vertices along their normals pushed a thin finger's sharp
        corners out by up to 5 x ``grow``). An exact mesh (not convex) moves its vertices out along
        their normals (``grown_vertices``), keeping its triangles."""
        if grow <= 0:
            return self.vertices, self.faces
        key = float(grow)
        if key not in self._grown:
            if self.exact:
                self._grown[key] = (self.grown_vertices(grow), self.faces)
            else:  # the Minkowski sum of the hull and a ball of radius grow, from outside
                pts = (self.vertices[:, None, :] + grow * ball_points()[None, :, :]).reshape(-1, 3)
                self._grown[key] = convex_hull(pts, self.source)
        return self._grown[key]

    def grown_vertices(self, grow: float) -> np.ndarray:
        """Vertices (V, 3) moved outwards by ``grow`` (m) along their normals, far enough that each
        vertex leaves every face it belongs to by at least ``grow`` (the exact-mesh padding)."""
        if grow == 0:
            return self.vertices
        v, f = self.vertices, self.faces
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        area = np.linalg.norm(fn, axis=1)
        keep = area > 1e-15
        f, fn = f[keep], fn[keep] / area[keep, None]
        vn = np.zeros_like(v)
        for k in range(3):
            np.add.at(vn, f[:, k], fn)
        norm = np.linalg.norm(vn, axis=1)
        vn = np.where(norm[:, None] > 1e-12, vn / np.maximum(norm, 1e-12)[:, None], 0.0)
        worst = np.ones(len(v))
        for k in range(3):  # the smallest cosine between a vertex normal and its faces' normals
            np.minimum.at(worst, f[:, k], np.einsum("ij,ij->i", vn[f[:, k]], fn))
        return v + vn * (grow / np.clip(worst, 0.2, 1.0))[:, None]


def ball_points() -> np.ndarray:
    """42 points (42, 3) whose convex hull holds the unit ball and lies within 1.0705 of the centre: an
    icosahedron divided once (its 12 vertices and 30 edge midpoints on the unit sphere), scaled by the
    inverse of that polytope's inradius."""
    global _BALL
    if _BALL is None:
        from scipy.spatial import ConvexHull

        t = (1 + 5 ** 0.5) / 2
        ico = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                        [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=float)
        ico /= np.linalg.norm(ico, axis=1)[:, None]
        d = np.linalg.norm(ico[:, None] - ico[None], axis=2)
        edge = np.min(d[d > 0])
        mids = [ico[i] + ico[j] for i in range(12) for j in range(i + 1, 12) if abs(d[i, j] - edge) < 1e-9]
        pts = np.vstack([ico, np.array(mids)])
        pts /= np.linalg.norm(pts, axis=1)[:, None]
        inradius = float(np.min(-ConvexHull(pts).equations[:, 3]))
        _BALL = pts / inradius
    return _BALL


_BALL: np.ndarray | None = None


# Meshes read, by (path, modification time, size, scale), and convex hulls taken, by the points' bytes: a process that
# loads a description again (the API, a test suite) or two links that share a mesh pay for the file and qhull once
_LOADED: Kept[tuple[np.ndarray, np.ndarray]] = Kept(512)
_HULLS: Kept[tuple[np.ndarray, np.ndarray, np.ndarray]] = Kept(512)  # key -> (hull vertices, faces, the points)


#: Why a description named by a plan, trajectory or log may not point elsewhere, and the fix.
CONFINED_HINT = ("a description named by a plan, trajectory or execution log reads only inside its own folder and "
                 "package_path folders: keep its files there, or give the folder with package_path NAME=DIR")


def description_roots(side: dict, sidecar: Path, confined: bool = False) -> Roots:
    """The folders a description may read (``roarmctl.fileio.Roots``): the folder of ``sidecar`` (the
    YAML, or the URDF/xacro named directly), the folders of the files the sidecar names (``urdf``,
    ``srdf``, ``joint_limits``), the sidecar's ``packages`` and the command line's ``--package-path``
    folders (``PACKAGE_PATHS``; the sidecar wins). What those files refer to (meshes, includes,
    ``load_yaml``) must lie inside these folders.

    ``confined`` (a description a plan, trajectory or log named, not the user): only the sidecar's folder
    and ``--package-path`` folders; a ``urdf``, ``srdf``, ``joint_limits`` or package folder the sidecar
    names outside them (after symlinks) is refused, so such a file cannot widen what it may read."""
    if confined:
        base = Roots([Path(sidecar).parent], PACKAGE_PATHS)
        for key in ("urdf", "srdf", "joint_limits"):
            if isinstance(side.get(key), str):
                base.check(Path(sidecar).parent / str(side[key]), f"{sidecar}: {key}", DescriptionError, CONFINED_HINT)
        own = package_map(side.get("packages"), sidecar, str(sidecar))
        for name, folder in own.items():
            base.check(folder, f"{sidecar}: packages.{name}", DescriptionError, CONFINED_HINT)
        return Roots(base.folders, {**PACKAGE_PATHS, **own})
    packages = {**PACKAGE_PATHS, **package_map(side.get("packages"), sidecar, str(sidecar))}
    named = [Path(sidecar).parent / str(side[k]) for k in ("urdf", "srdf", "joint_limits") if isinstance(side.get(k), str)]
    return Roots([Path(sidecar).parent] + [p.parent for p in named], packages)


def resolve(filename: str, urdf: Path, packages: dict[str, Path], where: str, roots: Roots | None = None) -> Path:
    """The file a URDF ``<mesh filename=...>`` names; with ``roots``, refused unless it lies inside them
    (after symlinks: ``package://pkg/../..`` or a symlink out of the folder is refused)."""
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        name, _, sub = rest.partition("/")
        folder = packages.get(name) or PACKAGE_PATHS.get(name)
        if folder is None:
            raise DescriptionError(
                f"{where} mesh filename: package '{name}' of '{filename}' is unknown",
                f"map it in the sidecar (packages: {{{name}: path/to/{name}}}) or give package_path {name}=DIR")
        path = Path(folder) / sub
    elif filename.startswith("file://"):
        path = Path(filename[len("file://"):])
    elif "://" in filename:
        raise DescriptionError(f"{where} mesh filename: '{filename}': only relative paths, file:// and package:// are supported")
    else:
        p = Path(filename)
        path = p if p.is_absolute() else urdf.parent / p
    if roots is not None:
        return roots.check(path, f"{where} mesh filename", DescriptionError)
    try:
        return path.resolve()
    except (OSError, RuntimeError) as exc:
        raise DescriptionError(f"{where} mesh filename: '{filename}' cannot be resolved ({exc})") from None


def load_mesh(path: Path, scale: np.ndarray, exact: bool, where: str,
              roots: Roots | None = None) -> tuple[MeshGeometry, np.ndarray]:
    """Read ``path`` (a regular file of at most ``MESH_BYTES``, inside ``roots`` when given), scale it,
    and return (centred geometry, centre (3,) in the element's frame). trimesh reads the bytes alone: an
    OBJ's ``mtllib`` or a COLLADA file's images are never opened."""
    vertices, faces = read_triangles(path, scale, f"{where} mesh filename", roots=roots,
                                     hint="check the path (relative to the URDF) or the package folder")
    if not exact:
        vertices, faces = convex_hull(vertices, f"{where} mesh '{path}'")
    return centred(vertices, faces, exact, str(path))


def centred(vertices: np.ndarray, faces: np.ndarray, exact: bool, source: str) -> tuple[MeshGeometry, np.ndarray]:
    """(geometry centred on its bounding box, that centre (3,)) of triangles ``vertices`` (V, 3) m, ``faces`` (F, 3)."""
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    return MeshGeometry(vertices - centre, faces, exact, source), centre


def read_triangles(path: Path, scale: npt.ArrayLike, what: str, *, roots: Roots | None = None,
                   error: type[InputError] = DescriptionError, hint: str | None = None,
                   limit: int = MESH_BYTES) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of the mesh file ``path`` (``MESH_TYPES``), vertices times ``scale`` (a number or (3,)):
    (vertices (V, 3) m, faces (F, 3) int64), every mesh of the file concatenated in its frame. The one mesh
    reader of robots and scenes: through ``fileio.read_bytes`` (regular file, at most ``limit`` bytes, inside
    ``roots``), read once per process (keyed by path, modification time and scale). Errors are ``error`` naming
    ``what`` (the field that names the file)."""

    import trimesh

    kind = path.suffix.lower().lstrip(".")
    if kind not in MESH_TYPES:
        raise error(f"{what}: '{path.name}': .{kind} is not a mesh type roarmctl reads",
                    f"use one of {', '.join('.' + t for t in MESH_TYPES)}")
    given = path
    if roots is not None:  # before the lookup: a mesh read earlier under wider roots is not handed out here
        path = roots.check(path, what, error, hint)
    try:
        st: os.stat_result | None = path.stat()
    except (OSError, ValueError):
        st = None
    scale3 = tuple(float(s) for s in np.broadcast_to(np.asarray(scale, dtype=float), 3))
    key = (str(path), (st.st_mtime_ns, st.st_size) if st is not None else (0, -1), scale3)
    if st is not None and key in _LOADED:
        note_read(given, st)  # served from the store: still a file the caller's result depends on
    else:
        data = read_bytes(given, what, limit, roots=roots, error=error, hint=hint)
        try:
            loaded = trimesh.load_mesh(io.BytesIO(data), file_type=kind, process=False)
            unit = _declared_unit(loaded) if kind == "dae" else 1.0
            if isinstance(loaded, trimesh.Scene):  # several meshes (COLLADA, OBJ groups): in the file's frame
                loaded = loaded.to_mesh() if len(loaded.geometry) else None
            elif isinstance(loaded, list):
                loaded = trimesh.util.concatenate(loaded) if loaded else None
        except Exception as exc:  # trimesh raises many kinds for unreadable files
            raise error(f"{what}: cannot read '{path}' as a mesh ({type(exc).__name__}: {str(exc)[:100]})",
                        "use an STL, OBJ, PLY or DAE file") from None
        if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
            raise error(f"{what}: '{path}' contains no triangles")
        if len(loaded.faces) > MAX_TRIANGLES:
            raise error(f"{what}: '{path}' has {len(loaded.faces)} triangles, more than {MAX_TRIANGLES}",
                        "simplify the mesh (a collision model needs far fewer)")
        if not (math.isfinite(unit) and 1e-6 <= unit <= 1e6):
            raise error(f"{what}: '{path}' declares <unit meter=\"{unit:g}\"/>, not a length unit",
                        "fix the file's <unit> (0.001 for millimetres)")
        with np.errstate(over="ignore", invalid="ignore"):  # float32 1e38 times a scale: inf, refused below
            vertices = np.asarray(loaded.vertices, dtype=float) * unit * np.array(scale3)
        if not np.all(np.isfinite(vertices)):
            raise error(f"{what}: '{path}' has non-finite vertex coordinates")
        check_extent(vertices, f"{what}: '{path}'", error)
        _LOADED.keep(key, (vertices, np.asarray(loaded.faces, dtype=np.int64)))
    return _LOADED[key]


#: How far (m) a mesh's vertex may lie from its origin, after its scale: a robot or a scene fits in far less; a
#: file in the wrong units (micrometres) or with 1e30 coordinates is refused here, before any arithmetic on it.
MAX_MESH_EXTENT = 1e5


def check_extent(vertices: np.ndarray, what: str, error: type[InputError]) -> None:
    """Refuse (``error`` naming ``what``) vertices (V, 3) m farther than ``MAX_MESH_EXTENT`` from the origin."""
    far = float(np.abs(vertices).max()) if len(vertices) else 0.0
    if far > MAX_MESH_EXTENT:
        raise error(f"{what}: a vertex lies {far:.3g} m from the mesh's origin, more than {MAX_MESH_EXTENT:g} m",
                    "check the file's units and the scale")


def _declared_unit(loaded: Any) -> float:
    """Metres per unit of a COLLADA file as trimesh records its ``<unit meter=...>`` ('0.001 * meters'); 1 if none."""
    units = getattr(loaded, "metadata", {}).get("units")
    m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*\*\s*meters\s*", units) if isinstance(units, str) else None
    try:
        return float(m.group(1)) if m else 1.0
    except ValueError:
        return math.nan


def unit_notes(shapes: list[Any], joints: list[Any], kind: str = "collision") -> list[str]:
    """Notes for links whose mesh size is more than ``UNIT_RATIO`` x larger or smaller than the link's reach:
    the longest offset of a joint at either of its ends (m; a link whose reach is under ``UNIT_MIN_OFFSET`` is
    not judged). ``shapes``: objects with ``link`` and ``mesh`` (a ``MeshGeometry`` or None); ``joints``: with
    ``parent``, ``child`` and ``origin`` (4x4)."""
    offsets: dict[str, float] = {}
    for j in joints:
        d = float(np.linalg.norm(j.origin[:3, 3]))
        for link in (j.parent, j.child):
            offsets[link] = max(offsets.get(link, 0.0), d)
    sizes: dict[str, float] = {}
    for shape in shapes:
        if shape.mesh is not None and len(shape.mesh.vertices):
            v = shape.mesh.vertices
            sizes[shape.link] = max(sizes.get(shape.link, 0.0), float(np.max(v.max(axis=0) - v.min(axis=0))))
    off = [f"{link} ({size:.3g} m across, its joints {offsets[link]:.3g} m apart at most)"
           for link, size in sizes.items() if offsets.get(link, 0.0) >= UNIT_MIN_OFFSET
           and not offsets[link] / UNIT_RATIO <= size <= offsets[link] * UNIT_RATIO]
    if not off:
        return []
    return [f"{kind} mesh of {', '.join(off)}: more than {UNIT_RATIO:g}x off the link's size; a mesh in "
            "millimetres read as metres? (STL and OBJ are read as metres: give the URDF's scale=\"0.001 0.001 "
            "0.001\"; a COLLADA file's <unit> is honoured)"]


def convex_hull(vertices: np.ndarray, where: str,
                error: type[InputError] = DescriptionError) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull (vertices (H, 3), outward-wound faces (K, 3)) of a point set, by qhull (scipy). The arrays
    returned may be shared with an earlier call on the same points: read them, do not change them."""
    points = np.ascontiguousarray(vertices, dtype=float)
    key = (points.shape, hash(points.tobytes()))
    if key in _HULLS and np.array_equal(_HULLS[key][2], points):
        return _HULLS[key][0], _HULLS[key][1]
    hv, hf = _convex_hull(points, where, error)
    hv.setflags(write=False)
    hf.setflags(write=False)
    _HULLS.keep(key, (hv, hf, points))
    return hv, hf


def _convex_hull(vertices: np.ndarray, where: str, error: type[InputError]) -> tuple[np.ndarray, np.ndarray]:
    """``convex_hull`` without the store."""
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise error(f"{where}: no convex hull (flat or degenerate mesh?): {first}",
                    None if error is DescriptionError else "give collision: exact (its triangles as they are)") from None
    used = np.unique(hull.simplices)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    v, f = vertices[used], remap[hull.simplices]
    # qhull's facet normals point outwards: wind each triangle so that its normal agrees
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = np.einsum("ij,ij->i", n, hull.equations[:, :3]) < 0
    f[flip] = f[flip][:, ::-1]
    return np.asarray(v, dtype=float), np.asarray(f, dtype=np.int64)


def mesh_modes(value: Any, links: list[str], where: str) -> dict[str, str]:
    """The sidecar's ``mesh_collision``: one mode for every link, or ``{link: mode}`` (with an
    optional ``default``). Returns link -> mode for every link."""
    if value is None:
        return dict.fromkeys(links, "convex")
    if isinstance(value, str):
        if value not in MESH_MODES:
            raise DescriptionError(f"{where}: mesh_collision: '{value}' is not one of {', '.join(MESH_MODES)}")
        return dict.fromkeys(links, value)
    if not isinstance(value, dict):
        raise DescriptionError(f"{where}: mesh_collision: expected 'convex', 'exact' or a mapping link -> mode")
    default = value.get("default", "convex")
    out: dict[str, str] = {}
    for k, v in value.items():
        if k != "default" and k not in links:
            raise DescriptionError(f"{where}: mesh_collision: '{k}' is not a link")
        if v not in MESH_MODES:
            raise DescriptionError(f"{where}: mesh_collision.{k}: '{v}' is not one of {', '.join(MESH_MODES)}")
    if default not in MESH_MODES:
        raise DescriptionError(f"{where}: mesh_collision.default: '{default}' is not one of {', '.join(MESH_MODES)}")
    for link in links:
        out[link] = str(value.get(link, default))  # each value checked against MESH_MODES above
    return out


def package_map(value: Any, sidecar: Path, where: str) -> dict[str, Path]:
    """The sidecar's ``packages: {NAME: folder}``, folders relative to the sidecar."""
    if value is None:
        return {}
    if not isinstance(value, dict) or not all(isinstance(v, str) for v in value.values()):
        raise DescriptionError(f"{where}: packages: expected a mapping NAME -> folder")
    out = {}
    for name, folder in value.items():
        p = resolved(sidecar.parent / Path(folder).expanduser(), f"{where}: packages.{name}", DescriptionError)
        if not p.is_dir():
            raise DescriptionError(f"{where}: packages.{name}: folder '{folder}' not found (resolved to {p})",
                                   "the path is relative to the sidecar YAML")
        out[str(name)] = p
    return out
