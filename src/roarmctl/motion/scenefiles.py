"""The data of mesh and point-cloud scene items (``MeshData``, ``CloudData``) and their readers: triangle meshes
(STL, OBJ, PLY, DAE) and point clouds (PLY, PCD, .npy), from files or arrays.

Meshes are read by the same code as a robot's collision meshes (``roarmctl.robot.meshes.read_triangles``,
trimesh inside) and kept as convex pieces (the convex hull of each connected part of the mesh, by qhull) or as
the triangles themselves (``exact``). Point clouds are read by trimesh (PLY), pypcd4 (PCD: ascii, binary and
binary_compressed) or numpy (``.npy``, no pickles), and become the occupied cells of ``resolution``
(``roarmctl.motion.octree``). Every file goes through the one bounded reader (``fileio.read_bytes``: a regular
file, at most ``MAX_CLOUD_BYTES`` / ``meshes.SCENE_MESH_BYTES``); what a file made is kept for the process (keyed by path,
modification time and size, and the options), so planning the same scene again does not read it again.
"""

from __future__ import annotations

import functools
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from roarmctl.errors import InputError
from roarmctl.fileio import read_bytes
from roarmctl.motion.octree import cells_of, in_range
from roarmctl.robot.meshes import SCENE_MESH_BYTES, check_extent, convex_hull, read_triangles


@dataclass(frozen=True, eq=False)
class MeshData:
    """The triangles of a mesh item in its own frame (m): ``pieces``, each (vertices (V, 3), faces (F, 3) int64),
    every piece convex (``exact`` False: the convex hull of one connected part of the file's mesh) or the file's
    triangles as they are (``exact`` True: one piece, checked by FCL as a BVH). ``source`` names the file.
    Arrays are shared between copies of an item, never written."""

    pieces: tuple[tuple[np.ndarray, np.ndarray], ...]
    exact: bool
    source: str = ""

    @functools.cached_property
    def as_lists(self) -> list[dict]:
        """The pieces as the trajectory file writes them (made once; shared by every ``to_dict``, never modified)."""
        return [{"vertices": v.tolist(), "faces": f.tolist()} for v, f in self.pieces]

    def local_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(centre (3,), half extents (3,)) of the box in the item frame that holds every vertex."""
        v = np.vstack([p[0] for p in self.pieces])
        lo, hi = v.min(axis=0), v.max(axis=0)
        return (lo + hi) / 2, (hi - lo) / 2


@dataclass(frozen=True, eq=False)
class CloudData:
    """The occupied cells of a point cloud: ``cells`` (K, 3) int64, sorted and unique, cubes of edge
    ``resolution`` (m) in the item frame (cell (i, j, k) spans [i r, (i + 1) r) x [j r, (j + 1) r) x
    [k r, (k + 1) r)); ``points`` how many points made them; ``source`` names the file."""

    cells: np.ndarray
    resolution: float
    points: int = 0
    source: str = ""

    @functools.cached_property
    def as_lists(self) -> list[list[int]]:
        """The cells as the trajectory file writes them (made once, about 1 us per cell; shared, never modified)."""
        return self.cells.tolist()

    def local_box(self) -> tuple[np.ndarray, np.ndarray]:
        """(centre (3,), half extents (3,)) of the box in the item frame that holds every cell."""
        lo = self.cells.min(axis=0) * self.resolution
        hi = (self.cells.max(axis=0) + 1) * self.resolution
        return (lo + hi) / 2, (hi - lo) / 2


MAX_CLOUD_BYTES = 512 * 1024 * 1024
MAX_POINTS = 20_000_000
MAX_CELLS = 2_000_000  # occupied cells of one cloud (a 1 m^2 desk at 1 mm is a million)
MAX_PIECES = 256  # convex pieces of one mesh: more parts than that want ``exact``
CLOUD_SUFFIXES = (".ply", ".pcd", ".npy")
_CACHE: dict[tuple, MeshData | CloudData] = {}
_CACHE_MAX = 32


def _key(path: Path, *options: object) -> tuple:
    st = path.stat()
    return (str(path.resolve()), st.st_mtime_ns, st.st_size) + options


_T = TypeVar("_T", "MeshData", "CloudData")


def _remember(key: tuple, value: _T) -> _T:
    if len(_CACHE) >= _CACHE_MAX:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[key] = value
    return value


def mesh_data(vertices: npt.ArrayLike, faces: npt.ArrayLike, exact: bool, source: str, where: str,
              error: type[InputError] = InputError) -> MeshData:
    """``MeshData`` of triangles ``vertices`` (V, 3) m, ``faces`` (F, 3): the triangles as they are when ``exact``,
    else the convex hull of each connected part (at most ``MAX_PIECES``)."""
    v = np.asarray(vertices, dtype=float)
    f = np.asarray(faces, dtype=np.int64)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
        raise error(f"{where}: a mesh needs vertices (V, 3) and faces (F, 3), got {v.shape} and {f.shape}")
    if not np.all(np.isfinite(v)) or f.min() < 0 or f.max() >= len(v):
        raise error(f"{where}: the mesh has non-finite vertices or faces that name missing vertices")
    check_extent(v, where, error)
    v.setflags(write=False)
    f.setflags(write=False)
    if exact:
        return MeshData(((v, f),), True, source)
    import trimesh

    n_parts = fewest_parts(v, f)  # before trimesh merges and splits: seconds a million parts (it makes a mesh each)
    if n_parts > MAX_PIECES:
        raise error(f"{where}: the mesh has {n_parts} separate parts or more, more than {MAX_PIECES} convex pieces",
                    "give collision: exact (its triangles as they are)")
    whole = trimesh.Trimesh(v, f, process=False)
    whole.merge_vertices()  # an STL repeats each vertex per triangle: parts are found through shared vertices
    parts = whole.split(only_watertight=False)
    if len(parts) > MAX_PIECES:
        raise error(f"{where}: the mesh has {len(parts)} separate parts, more than {MAX_PIECES} convex pieces",
                    "give collision: exact (its triangles as they are)")
    pieces = []
    for part in parts or [whole]:
        hv, hf = convex_hull(np.asarray(part.vertices, dtype=float), f"{where} ({source or 'mesh'})", error)
        hv.setflags(write=False)
        hf.setflags(write=False)
        pieces.append((hv, hf))
    return MeshData(tuple(pieces), False, source)


def fewest_parts(vertices: np.ndarray, faces: np.ndarray) -> int:
    """At most as many parts as ``Trimesh.merge_vertices`` then ``split`` make of the triangles ``faces`` (F, 3) over
    ``vertices`` (V, 3), in linear work (a hash and one sparse-graph walk, scipy) and without making a mesh for
    each part: vertices that trimesh merges (equal at 1e-8, its ``tol.merge``) get one key here too (keys of
    different vertices may collide: fewer parts), and triangles count as connected through a shared vertex
    where ``split`` needs a shared edge (fewer parts again)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return 0
    with np.errstate(all="ignore"):  # a huge coordinate casts to an arbitrary key: only fewer parts
        k = np.round(np.asarray(vertices, dtype=float) * 1e8).astype(np.int64)
    key = (k[:, 0] * 73856093) ^ (k[:, 1] * 19349663) ^ (k[:, 2] * 83492791)  # wraps: a hash
    _, merged = np.unique(key, return_inverse=True)
    tri = merged.reshape(-1)[faces]
    n = int(merged.max()) + 1
    rows = np.concatenate([tri[:, 0], tri[:, 1]])
    cols = np.concatenate([tri[:, 1], tri[:, 2]])
    graph = coo_matrix((np.ones(len(rows), dtype=np.int8), (rows, cols)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    return int(np.count_nonzero(np.bincount(labels[tri[:, 0]])))


def read_mesh_item(path: str | Path, scale: npt.ArrayLike, exact: bool, where: str,
                   error: type[InputError] = InputError) -> MeshData:
    """``MeshData`` of the mesh file ``path`` (its units times ``scale``, a number or (3,)), see ``mesh_data``."""
    path = Path(path)
    scale3 = tuple(float(s) for s in np.broadcast_to(np.asarray(scale, dtype=float), 3))
    if not all(np.isfinite(scale3)) or min(abs(s) for s in scale3) == 0:
        raise error(f"{where}: scale must be finite and not 0, got {scale3}")
    v, f = read_triangles(path, scale3, where, error=error, limit=SCENE_MESH_BYTES)
    key = _key(path, "mesh", scale3, bool(exact))
    hit = _CACHE.get(key)
    if isinstance(hit, MeshData):
        return hit
    return _remember(key, mesh_data(v, f, exact, str(path), where, error))


def cloud_data(points: npt.ArrayLike, resolution: float, source: str, where: str,
               error: type[InputError] = InputError) -> CloudData:
    """``CloudData`` of ``points`` (N, 3) m at cells of edge ``resolution`` (m); points with a NaN or infinite
    coordinate (a depth camera's missing returns) are dropped."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] < 3:
        raise error(f"{where}: a point cloud is an array (N, 3) of x, y, z in m, got shape {p.shape}")
    if len(p) > MAX_POINTS:
        raise error(f"{where}: {len(p)} points are more than {MAX_POINTS}", "downsample the cloud")
    if not (np.isfinite(resolution) and 1e-4 <= resolution <= 1.0):
        raise error(f"{where}: resolution {resolution!r} m is outside 0.0001 .. 1 m")
    p = p[:, :3]
    p = p[np.all(np.isfinite(p), axis=1)]
    if len(p) == 0:
        raise error(f"{where}: the point cloud has no finite point")
    cells = cells_of(p, resolution)
    if not in_range(cells):
        raise error(f"{where}: the cloud reaches more than {2 ** 15} cells of {resolution} m from its frame's origin",
                    "use a coarser resolution or crop the cloud")
    if len(cells) > MAX_CELLS:
        raise error(f"{where}: {len(cells)} occupied cells are more than {MAX_CELLS}", "use a coarser resolution")
    cells.setflags(write=False)
    return CloudData(cells, float(resolution), len(p), source)


def read_points(path: str | Path, where: str, error: type[InputError] = InputError) -> np.ndarray:
    """Points (N, 3) m of a PLY (vertices, with or without faces), PCD (fields x, y, z) or .npy (N, 3) file."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise error(f"{where}: '{path}': a point cloud file is {', '.join(CLOUD_SUFFIXES)}, not '{suffix or 'no suffix'}'")
    data = read_bytes(path, where, MAX_CLOUD_BYTES, error=error, hint="give a PLY, PCD or .npy file of x, y, z in m")
    try:
        if suffix == ".npy":
            pts = np.load(io.BytesIO(data), allow_pickle=False)
        elif suffix == ".pcd":
            from pypcd4 import PointCloud

            pc = PointCloud.from_fileobj(io.BufferedReader(io.BytesIO(data)))  # typed as taking a BufferedReader
            missing = [c for c in "xyz" if c not in pc.fields]
            if missing:
                raise ValueError(f"no field {', '.join(missing)} (fields: {', '.join(pc.fields)})")
            pts = pc.numpy(("x", "y", "z"))
        else:
            import trimesh

            loaded = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
            pts = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))))
    except InputError:
        raise
    except Exception as exc:  # the readers raise many kinds for a malformed file
        raise error(f"{where}: cannot read '{path}' as a point cloud ({type(exc).__name__}: {str(exc)[:200]})",
                    "give a PLY, PCD or .npy file of x, y, z in m") from None
    pts = np.asarray(pts)
    if pts.dtype.kind not in "fiu" or pts.ndim != 2 or pts.shape[1] < 3:
        raise error(f"{where}: '{path}' holds no (N, 3) array of x, y, z (shape {pts.shape}, type {pts.dtype})")
    return pts[:, :3].astype(float)


def read_cloud_item(path: str | Path, resolution: float, where: str, error: type[InputError] = InputError) -> CloudData:
    """``CloudData`` of the point cloud file ``path`` at ``resolution`` (m); see ``cloud_data``."""
    path = Path(path)
    try:
        key = _key(path, "cloud", float(resolution))
    except OSError:
        key = None  # the reader names the problem
    hit = _CACHE.get(key) if key else None
    if isinstance(hit, CloudData):
        return hit
    value = cloud_data(read_points(path, where, error), resolution, str(path), where, error)
    return _remember(key, value) if key else value

