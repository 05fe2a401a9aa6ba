"""The jaws as the convex pieces of the description's jaw meshes, by CoACD: what picks close by and the physics squeezes with.

A gripper's jaw table (``Gripper.jaw_width``) was measured on the jaws' own meshes (``Gripper.jaw_meshes``); a
description's collision shapes are coarser (the RoArm-M3's finger box stands 2-30 mm nearer the fixed jaw than the
table), so physics built from them squeezed an object a plan closed short of. FCL and MuJoCo collide a mesh as its
convex hull, which would fill a jaw's concave side; here each jaw mesh is cut into convex pieces by CoACD (Wei et
al., "Approximate Convex Decomposition for 3D Meshes with Collision-Aware Concavity and Tree Search", SIGGRAPH 2022;
the ``coacd`` package). ``roarmctl.motion.planning.jaw_reach`` closes a pick on them where the object sits, and
``roarmctl.physics.mjcf`` lets objects meet the jaw links through them only.

Deterministic and cached: CoACD runs with a fixed seed and the fixed ``PARAMETERS`` (its work is bounded by them
and by ``MAX_TRIANGLES``: no clock); a piece is its vertices rounded to a micrometre (MuJoCo collides a mesh as the
convex hull of its vertices), kept as JSON under a key of the mesh's exact vertices and faces, the parameters and
CoACD's version: the same input gives the same file, byte for byte. A description may name such a file instead of
its mesh (``JawMesh.pieces``): the bundled descriptions ship their pieces (``BUNDLED``, made from the vendor's
published meshes and checked against a fresh decomposition of them by the tests), not the meshes; the pieces of a
mesh are made once (~15-60 s of CPU per jaw mesh) and kept in ``cache_folder()``.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import replace
from importlib import metadata
from pathlib import Path

import numpy as np

from roarmctl.errors import DescriptionError, InputError
from roarmctl.fileio import atomic_write_text, read_bytes
from roarmctl.kept import Kept
from roarmctl.robot.jaw_meshes import jaw_triangles
from roarmctl.robot.model import JawMesh, Robot

#: CoACD's settings (its own names): concavity ``threshold`` (a fraction of the mesh's bounding-box diagonal) 0.02,
#: where its default 0.05 left pieces up to 3.5 mm outside the M3's moving jaw and 0.02 leaves them within 1.5 mm;
#: at most ``max_convex_hull`` pieces; ``seed`` fixed so that the same mesh gives the same pieces.
#: The tree search is shallower than CoACD's defaults (60 iterations, depth 2, 1000 samples: 193 s -> ~30 s of CPU
#: for the M3's two jaws, at the same number of pieces).
PARAMETERS: dict[str, object] = {"threshold": 0.02, "max_convex_hull": 32, "preprocess_mode": "auto",
                                 "preprocess_resolution": 50, "resolution": 1000, "mcts_nodes": 20,
                                 "mcts_iterations": 60, "mcts_max_depth": 2, "merge": True, "max_ch_vertex": 256,
                                 "seed": 0}
#: Triangles of one jaw mesh CoACD is given (its work grows with them; a CAD export of a jaw has ~10,000).
MAX_TRIANGLES = 50_000
#: Bytes of one cache file read back (32 pieces of at most 256 vertices are ~0.7 MB as JSON).
CACHE_BYTES = 4 * 1024 * 1024
CACHE_FORMAT = "roarmctl.jaw_pieces/1"
#: The pieces of the bundled descriptions' jaw meshes, shipped (named by their sidecars' ``jaw_meshes``).
BUNDLED = Path(__file__).resolve().parent.parent / "robots" / "jaw_pieces"

Piece = np.ndarray  # the vertices (V, 3) m of one convex piece (MuJoCo and FCL take their convex hull)
_READ: Kept[list[Piece]] = Kept(64)  # key -> pieces, read once per process


def cache_folder() -> Path:
    """Where decompositions are kept: ``$ROARMCTL_CACHE/jaw_pieces``, else ``$XDG_CACHE_HOME/roarmctl/jaw_pieces``,
    else ``~/.cache/roarmctl/jaw_pieces``."""
    if os.environ.get("ROARMCTL_CACHE"):
        return Path(os.environ["ROARMCTL_CACHE"]) / "jaw_pieces"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "roarmctl" / "jaw_pieces"


def cache_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """The hex SHA-256 of what the pieces of a mesh depend on: its ``vertices`` (V, 3) m (float64) and ``faces``
    (F, 3) (int64) as bytes, the parameters and CoACD's version."""
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(vertices, dtype="<f8").tobytes())
    h.update(np.ascontiguousarray(faces, dtype="<i8").tobytes())
    h.update(json.dumps(PARAMETERS, sort_keys=True).encode())
    h.update(metadata.version("coacd").encode())
    return h.hexdigest()


def convex_pieces(mesh: JawMesh) -> list[Piece]:
    """The convex pieces of ``mesh`` (vertices in its link's frame, m): the pieces file it names, cached, or made by
    CoACD (then cached; a cache folder that cannot be written is passed over). Raises DescriptionError for a mesh
    over ``MAX_TRIANGLES`` or a pieces file that is not one."""
    if mesh.kept is not None:
        return list(mesh.kept)
    if mesh.pieces is not None:
        return _named(mesh)
    vertices, faces = jaw_triangles(mesh)
    if len(faces) > MAX_TRIANGLES:
        raise DescriptionError(f"gripper.jaw_meshes: '{mesh.file}' has {len(faces)} triangles, more than "
                               f"{MAX_TRIANGLES} for its convex decomposition", "simplify the jaw mesh")
    key = cache_key(vertices, faces)
    if (key,) in _READ:  # every pick of a plan asks again
        return _READ[(key,)]
    cached = _read_cache(cache_folder() / f"{key}.json", key)
    if cached is not None:
        return _READ.keep((key,), cached)
    text = cache_text(key, decompose(vertices, faces))
    path = cache_folder() / f"{key}.json"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, text)
    except OSError:
        pass  # no cache (a read-only home): the next run decomposes again, to the same pieces
    return _READ.keep((key,), _parse(json.loads(text)))


def _named(mesh: JawMesh) -> list[Piece]:
    """The pieces in the file a description names (``JawMesh.pieces``), read once per process, bounded in size."""
    path = str(mesh.pieces)
    if (path,) in _READ:
        return _READ[(path,)]
    where = f"gripper.jaw_meshes ({mesh.link}): pieces"
    raw = read_bytes(path, where, CACHE_BYTES, roots=mesh.roots, error=DescriptionError)
    try:
        data = json.loads(raw)
        if not isinstance(data, dict) or data.get("format") != CACHE_FORMAT:
            raise ValueError(f"not a {CACHE_FORMAT} file")
        pieces = _parse(data)
    except (TypeError, ValueError, KeyError, RecursionError) as exc:  # RecursionError: nested deeper than json goes
        raise DescriptionError(f"{where}: '{path}' is not a file of convex pieces ({type(exc).__name__}: {exc})"[:400],
                               "name the mesh itself (file:), or a pieces file roarmctl wrote") from None
    return _READ.keep((path,), pieces)


def keep_jaw_pieces(robot: Robot) -> None:
    """Read the pieces of ``robot``'s jaws now and keep them in its ``JawMesh``es (``kept``): its files are about to
    go (a description carried in a trajectory, loaded from a temporary folder)."""
    if robot.gripper is None or not robot.gripper.jaw_meshes:
        return
    kept = tuple(replace(m, kept=tuple(convex_pieces(m))) for m in robot.gripper.jaw_meshes)
    robot.gripper = replace(robot.gripper, jaw_meshes=kept)


def jaw_pieces(robot: Robot) -> dict[str, list[Piece]]:
    """Link name -> the convex pieces of its jaw meshes (``Gripper.jaw_meshes``), in the link's frame; empty
    when the description gives no jaw meshes."""
    out: dict[str, list[Piece]] = {}
    if robot.gripper is None:
        return out
    for mesh in robot.gripper.jaw_meshes:
        out.setdefault(mesh.link, []).extend(convex_pieces(mesh))
    return out


def decompose(vertices: np.ndarray, faces: np.ndarray) -> list[Piece]:
    """CoACD's convex pieces of the mesh (``vertices`` (V, 3) m, ``faces`` (F, 3)) with ``PARAMETERS``: each piece's
    vertices rounded to a micrometre; flat pieces (no volume to collide with) left out."""
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(np.asarray(vertices, dtype=float), np.asarray(faces, dtype=np.int64)),
                            **PARAMETERS)
    pieces = [np.round(np.asarray(v, dtype=float), 6) + 0.0 for v, _ in parts]
    return [v for v in pieces if len(v) >= 4 and np.linalg.matrix_rank(v - v[0], tol=1e-9) == 3]


def cache_text(key: str, pieces: list[Piece]) -> str:
    """The cache file of ``pieces`` made for ``key``: JSON, one line, vertices in m to a micrometre."""
    return json.dumps({"format": CACHE_FORMAT, "key": key, "parameters": PARAMETERS,
                       "pieces": [[[round(float(x), 6) + 0.0 for x in row] for row in v] for v in pieces]},
                      separators=(",", ":")) + "\n"


def _read_cache(path: Path, key: str) -> list[Piece] | None:
    """The pieces of a cache file written for ``key``; None when there is none or it is not one (it is then made
    again)."""
    try:
        data = json.loads(read_bytes(path, "jaw pieces cache", CACHE_BYTES))
    except (InputError, ValueError, RecursionError):  # missing, too large, not JSON: decomposed again
        return None
    if not isinstance(data, dict) or data.get("format") != CACHE_FORMAT or data.get("key") != key:
        return None
    try:
        return _parse(data)
    except (TypeError, ValueError, KeyError):
        return None


def _parse(data: dict) -> list[Piece]:
    pieces = []
    for p in data["pieces"]:
        v = np.asarray(p, dtype=float).reshape(-1, 3)
        if len(v) < 4 or not np.all(np.isfinite(v)):
            raise ValueError("not a convex piece")
        pieces.append(v)
    if not pieces:
        raise ValueError("no pieces")
    return pieces
