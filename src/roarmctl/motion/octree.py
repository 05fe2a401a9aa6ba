"""Occupied cells of a point cloud, and the FCL octree that holds them.

A point cloud becomes a set of occupied cubic cells of edge ``resolution`` (m) in the cloud's own frame: cell
``(i, j, k)`` spans ``[i r, (i + 1) r) x [j r, (j + 1) r) x [k r, (k + 1) r)``, the same cells OctoMap makes
(``OcTreeKey``: floor(coordinate / resolution) + 2^15, 16 levels; K. M. Wurm, A. Hornung et al., "OctoMap: an
efficient probabilistic 3D mapping framework based on octrees", Autonomous Robots 34(3), 2013). FCL checks such a
tree directly (``fcl::OcTree`` over ``octomap::OcTree``; python-fcl's ``fcl.OcTree(resolution, data)`` reads
the tree from OctoMap's binary stream, ``OcTree::readBinaryData``). ``octree_stream`` writes that stream:

* nodes in depth-first order from the root, each inner node as two bytes that give its eight children two bits
  each (child ``c`` in bits ``2c`` and ``2c + 1`` of the first byte for c < 4, of the second for c >= 4): bit
  ``2c + 1`` alone an occupied leaf, both bits an inner node (its own two bytes follow, before its next
  sibling's), neither no child (unknown space); free leaves (bit ``2c`` alone) are never written;
* child ``c`` of a node at depth d holds the keys whose bit ``15 - d`` is ``c & 1`` in x, ``c >> 1 & 1`` in y and
  ``c >> 2 & 1`` in z (OctoMap's ``computeChildIdx``).

Every cell here is an occupied leaf at the finest level (depth 16); FCL reads an inner node's occupancy as its
children's largest, so a part of the tree is occupied exactly where one of its cells is.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import fcl

TREE_DEPTH = 16  # OctoMap's (and so FCL's) fixed tree depth
KEY_OFFSET = 1 << (TREE_DEPTH - 1)  # key of cell index 0
#: Cells of one octree: a cloud of more is split (``blocks``); also bounds the stream's size (about 2 bytes per node).
BLOCK_CELLS = 16  # edge of a block in cells: a cloud becomes one octree per occupied block of 16^3 cells


def cells_of(points: np.ndarray, resolution: float) -> np.ndarray:
    """Occupied cell indices (K, 3) int64, sorted and unique, of ``points`` (N, 3) m in the cloud's frame."""
    with np.errstate(over="ignore", invalid="ignore"):  # 1e308 / 1e-4: inf, clipped below and refused by in_range
        cells = np.clip(np.floor(np.asarray(points, dtype=float) / float(resolution)), -2.0 ** 62, 2.0 ** 62)
    idx = cells.astype(np.int64)
    return np.unique(idx, axis=0) if len(idx) else idx.reshape(0, 3)


def in_range(cells: np.ndarray) -> bool:
    """True when every cell index fits OctoMap's keys (-2^15 <= i < 2^15)."""
    return bool(len(cells) == 0 or (cells.min() >= -KEY_OFFSET and cells.max() < KEY_OFFSET))


def _morton(cells: np.ndarray) -> np.ndarray:
    """Morton codes (K,) uint64 of cells (K, 3): for bit b of the keys (15 first), 3 bits z_b y_b x_b."""
    keys = (np.asarray(cells, dtype=np.int64) + KEY_OFFSET).astype(np.uint64)
    code = np.zeros(len(keys), dtype=np.uint64)
    for b in range(TREE_DEPTH):
        for axis in range(3):
            bit = (keys[:, axis] >> np.uint64(b)) & np.uint64(1)
            code |= bit << np.uint64(3 * b + axis)
    return code


def octree_stream(cells: np.ndarray) -> bytes:
    """OctoMap's binary tree stream (``readBinaryData``) of the occupied leaf cells (K, 3) (see the module doc)."""
    codes = np.unique(_morton(cells))
    if len(codes) == 0:
        return b""
    order_keys, depths, pairs = [], [], []
    for d in range(TREE_DEPTH):  # inner nodes at depth d: the distinct prefixes of 3 d bits
        shift_node = np.uint64(3 * (TREE_DEPTH - d))
        prefix = codes >> shift_node
        child = ((codes >> np.uint64(3 * (TREE_DEPTH - 1 - d))) & np.uint64(7)).astype(np.int64)
        leaf = d == TREE_DEPTH - 1
        # two bits per child: bit 2c + 1 alone an occupied leaf (the finest level), both an inner node
        bits = (np.int64(2) if leaf else np.int64(3)) << (2 * child)
        starts = np.flatnonzero(np.r_[True, prefix[1:] != prefix[:-1]])
        word = np.bitwise_or.reduceat(bits, starts)  # duplicates (cells sharing a child) OR to the same bits
        order_keys.append(prefix[starts] << shift_node)  # the node's first possible code: parents sort first
        depths.append(np.full(len(starts), d, dtype=np.int64))
        pairs.append(word)
    keys = np.concatenate(order_keys)
    depth = np.concatenate(depths)
    word = np.concatenate(pairs)
    order = np.lexsort((depth, keys))  # depth-first pre-order: by first code, a parent before its first child
    word = word[order]
    out = np.empty((len(word), 2), dtype=np.uint8)
    out[:, 0] = word & 0xFF
    out[:, 1] = (word >> 8) & 0xFF
    return out.tobytes()


def fcl_octree(cells: np.ndarray, resolution: float) -> fcl.OcTree:
    """An ``fcl.OcTree`` whose occupied leaves are ``cells`` (K, 3) of edge ``resolution`` (m)."""
    import fcl

    # python-fcl converts ``data`` to a C++ vector<char> item by item: signed values (bytes above 127 overflow)
    return fcl.OcTree(float(resolution), np.frombuffer(octree_stream(cells), dtype=np.int8).tolist())


def blocks(cells: np.ndarray, edge: int = BLOCK_CELLS) -> list[np.ndarray]:
    """The cells (K, 3) grouped by the block of ``edge``^3 cells they fall in: a list of index arrays into
    ``cells``, in a fixed order (by block). Each block becomes an octree of its own with a tight box, so the
    checker's box pre-filter clears most of a large cloud before FCL looks at it."""
    if len(cells) == 0:
        return []
    block = np.floor_divide(cells, edge)
    _, inverse = np.unique(block, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    order = np.argsort(inverse, kind="stable")
    bounds = np.flatnonzero(np.diff(inverse[order])) + 1
    return np.split(order, bounds)
