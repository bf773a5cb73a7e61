"""Storage of one ``VoxelOctree`` level and node-centred sampling over it (numpy, vectorised).

``DenseLevel`` (full 3D arrays) and ``SparseLevel`` (Morton-sorted node arrays) hold the node
attributes. Each also keeps a premultiplied sampling table ``table`` (4, M+1) float32 —
channels r·α, g·α, b·α, α of its M stored nodes plus a final column of zeros standing for
"absent" — and turns integer node coordinates into columns ("rows") of that table:

* dense level (2^ℓ nodes per axis): row = (x·s + y)·s + z, the flat index of ``array[x, y, z]``;
* sparse level with an index map (an int32 map over the cube of nodes the level can hold):
  one gather in that map;
* sparse level without one, and ``lookup`` always: ``np.searchsorted`` on the Morton keys.

The 8 trilinear corners of a point are built per axis and combined by broadcasting, so a
chunk of m points costs O(m) coordinate work plus 8m gathers per channel. Corner arrays are
(8, m), corner-major in octant order ``z<<2 | y<<1 | x``; the table is channel-major, so every
inner numpy loop runs over m.

Each level also keeps ``directional`` (24, M+1): the premultiplied values of its M present
nodes seen from the 6 faces ``FACES`` (row 4·f + channel, column M = absent), float32 (float16
halved the memory but was slower to gather and convert in numpy); a sparse level shares
``table``'s columns, a dense level maps them with ``directional_index``. See ``svo``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from .cascades import cells_within
from .morton import morton_encode, spread_bits

CHUNK_POINTS = 1 << 15  # points per vectorised chunk: keeps the (8, m) temporaries in cache
# Faces of the directional tables: the side of the node the viewer is on. Face 2·a + s views
# along axis a from +a (s = 0: a cone travelling −a reads it) or from −a (s = 1).
FACES = ("+x", "-x", "+y", "-y", "+z", "-z")
DIRECTIONAL_DTYPE = np.float32
TAU_ALPHA_CAP = 0.999  # face opacity at which its colour weight τ stops growing (τ ≈ 6.9)
_INVALID_KEY_BIT = np.uint64(1 << 63)  # never set in a Morton key of 21-bit coordinates


@dataclass(eq=False)
class DenseLevel:
    """Level ℓ stored as full arrays, s = 2^ℓ per axis, indexed [x, y, z].

    radiance, normal, albedo : (s, s, s, 3) float32; occlusion : (s, s, s) float32 (0 = absent);
    count : (s, s, s) int32; child_base : (s, s, s) int64 (−1 if absent) and child_mask :
    (s, s, s) uint8 only on the last dense level when sparse levels follow, else None;
    table : (4, s³ + 1) float32 premultiplied sampling channels (r·α, g·α, b·α, α), last row 0;
    directional : (24, M + 1) the same per face of ``FACES`` (row 4·face + channel) for the M
    present nodes only, last column 0; directional_index : (s³ + 1,) int32 column of
    ``directional`` per ``table`` column (M = absent). Dense levels are mostly empty, so this
    costs 4 bytes per cell + 96 per node instead of 96 per cell.
    """

    kind: ClassVar[str] = "dense"
    level: int
    radiance: np.ndarray
    occlusion: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    count: np.ndarray
    child_base: np.ndarray | None
    child_mask: np.ndarray | None
    table: np.ndarray = field(repr=False)
    directional: np.ndarray = field(repr=False)
    directional_index: np.ndarray = field(repr=False)

    @property
    def node_count(self) -> int:
        return int(np.count_nonzero(self.occlusion))

    def directional_columns(self, rows: np.ndarray) -> np.ndarray:
        """Rows of ``table`` (any shape) → columns of ``directional``."""
        return self.directional_index[rows]

    def rows(self, nodes: np.ndarray) -> np.ndarray:
        """(N, 3) int64 node coordinates → (N,) rows of ``table`` (s³ = absent or outside)."""
        s = 1 << self.level
        inside = cells_within(nodes, 0, s)
        rows = np.where(inside, (nodes[:, 0] * s + nodes[:, 1]) * s + nodes[:, 2], s ** 3)
        present = self.table[3, np.minimum(rows, s ** 3)] > 0
        return np.where(present, rows, s ** 3)

    def corner_rows(self, lower: np.ndarray) -> np.ndarray:
        """(m, 3) int64 lower trilinear corners → (8, m) rows of ``table`` (s³ = absent)."""
        return grid_rows(lower, (0, 0, 0), 1 << self.level)


@dataclass(eq=False)
class SparseLevel:
    """Level ℓ stored as M present nodes sorted by Morton key.

    keys : (M,) uint64 sorted; radiance, normal, albedo : (M, 3) float32; occlusion : (M,)
    float32 (> 0); count : (M,) int32; child_base : (M,) int64 row in the next level of the
    first present child (where it would be when there is none); child_mask : (M,) uint8.
    window_origin : (3,) int64, window_size W: the cube of nodes this level can hold (all of
    level ℓ ≤ log2(res), else the window of cascade n−1−(ℓ−log2(res))). index_map : (W³ + 1,)
    int32 row per window cell in [x, y, z] order (M = absent, last entry M) or None when the
    window is over budget. table : (4, M + 1) float32 premultiplied sampling channels, row M 0;
    directional : (24, M + 1) the same per face of ``FACES`` (row 4·face + channel), same
    columns as ``table``.
    """

    kind: ClassVar[str] = "sparse"
    level: int
    keys: np.ndarray
    radiance: np.ndarray
    occlusion: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    count: np.ndarray
    child_base: np.ndarray
    child_mask: np.ndarray
    window_origin: np.ndarray
    window_size: int
    index_map: np.ndarray | None = field(repr=False)
    table: np.ndarray = field(repr=False)
    directional: np.ndarray = field(repr=False)

    @property
    def node_count(self) -> int:
        return len(self.keys)

    def directional_columns(self, rows: np.ndarray) -> np.ndarray:
        """Rows of ``table`` (any shape) → columns of ``directional`` (the same here)."""
        return rows

    def rows(self, nodes: np.ndarray) -> np.ndarray:
        """(N, 3) int64 node coordinates → (N,) rows by searchsorted on ``keys`` (M = absent)."""
        return coordinate_rows(nodes, self.level, self.keys)

    def corner_rows(self, lower: np.ndarray) -> np.ndarray:
        """(m, 3) int64 lower trilinear corners → (8, m) rows of ``table`` (M = absent)."""
        if self.index_map is None:
            return keyed_rows(lower, self.level, self.keys)
        return self.index_map[grid_rows(lower, self.window_origin, self.window_size)]


def _axis_offsets(c0: np.ndarray, lo: int, size: int, stride: int, big: int) -> np.ndarray:
    """(m,) int64 lower corner → (2, m) int64 ``(c − lo)·stride`` for c0, c0+1; ``big`` outside."""
    rel = c0[None, :] - lo + np.array([[0], [1]], dtype=np.int64)
    return np.where((rel >= 0) & (rel < size), rel * stride, big)


def _combine_corners(px: np.ndarray, py: np.ndarray, pz: np.ndarray, op) -> np.ndarray:
    """Per-axis (2, m) parts → (8, m), corner-major in octant order z<<2 | y<<1 | x."""
    out = op(pz[:, None, None, :], py[None, :, None, :])
    return op(out, px[None, None, :, :]).reshape(8, px.shape[1])


def grid_rows(lower: np.ndarray, lo, size: int) -> np.ndarray:
    """Rows of a row-major [x, y, z] grid of ``size``³ cells whose cell 0 is node ``lo`` (3,).

    lower : (m, 3) int64 lower trilinear corners. Returns (8, m) int64 in [0, size³];
    ``size³`` marks a corner outside the grid.
    """
    n = size ** 3
    parts = [_axis_offsets(lower[:, a], int(lo[a]), size, size ** (2 - a), n) for a in range(3)]
    return np.minimum(_combine_corners(*parts, np.add), n)


def keyed_rows(lower: np.ndarray, level: int, keys: np.ndarray) -> np.ndarray:
    """Rows of the 8 corners in a sparse level found by searchsorted on its sorted ``keys``.

    lower : (m, 3) int64; keys : (M,) uint64 sorted. Returns (8, m) int64 in [0, M], M = absent.
    """
    side = 1 << level
    parts = []
    for axis in range(3):
        c = lower[None, :, axis] + np.array([[0], [1]], dtype=np.int64)
        part = spread_bits(np.clip(c, 0, side - 1)) << np.uint64(axis)
        part[(c < 0) | (c >= side)] = _INVALID_KEY_BIT
        parts.append(part)
    return rows_of_keys(keys, _combine_corners(*parts, np.bitwise_or))


def rows_of_keys(keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Any-shape uint64 ``query`` → int64 rows into sorted ``keys`` (len(keys) where absent)."""
    m = len(keys)
    if m == 0:
        return np.zeros(np.shape(query), np.int64)
    pos = np.searchsorted(keys, query)
    return np.where(keys[np.minimum(pos, m - 1)] == query, pos, m)


def coordinate_rows(nodes: np.ndarray, level: int, keys: np.ndarray) -> np.ndarray:
    """(N, 3) int64 node coordinates of a sparse level → (N,) rows (len(keys) where absent)."""
    side = 1 << level
    inside = cells_within(nodes, 0, side)
    query = np.full(len(nodes), _INVALID_KEY_BIT, dtype=np.uint64)
    query[inside] = morton_encode(nodes[inside])
    return rows_of_keys(keys, query)


def _corners(level, points: np.ndarray, root_origin: np.ndarray, node_size: float):
    """(8, m) float32 trilinear weights and (8, m) int64 table columns of the corners."""
    u = (points - root_origin) / node_size - 0.5
    lower = np.floor(u)
    f = (u - lower).T.astype(np.float32)
    lower = lower.astype(np.int64)
    weights = _combine_corners(*[np.stack([1 - f[a], f[a]]) for a in range(3)], np.multiply)
    return weights, level.corner_rows(lower)


def trilinear(level, points: np.ndarray, root_origin: np.ndarray, node_size: float) -> np.ndarray:
    """Trilinear interpolation of ``level.table`` over node centres.

    level : a ``DenseLevel`` or ``SparseLevel``; points : (m, 3) float64 world positions.
    Returns (4, m) float32: premultiplied radiance r, g, b and occlusion; absent nodes are 0.
    """
    weights, rows = _corners(level, points, root_origin, node_size)
    # Channel-major table and corner-major arrays keep every inner loop m long.
    return np.stack([np.einsum("km,km->m", weights, np.take(channel, rows))
                     for channel in level.table])


def trilinear_directional(level, points: np.ndarray, dirs: np.ndarray, root_origin: np.ndarray,
                          node_size: float, extinction: bool = True) -> np.ndarray:
    """The faces of ``level.directional`` that face a cone travelling along ``dirs`` (d_a < 0
    reads face 2a, d_a > 0 face 2a + 1), each interpolated trilinearly, combined over the axes.

    points, dirs : (m, 3) float64 (dirs unit). Returns (4, m) float32 like ``trilinear``.
    extinction : False = Σ_a d_a² × face a (all four channels; sums to 1 for a unit direction).
    True = per-axis extinction: with τ_a = −ln(1 − α_a), α = 1 − exp(−Σ_a |d_a|·τ_a), so a face
    opaque along an axis stays opaque to every cone that crosses it at an angle (a thin wall
    does not leak to slanted cones); the colour is the faces' colours weighted by the share of
    that optical depth each axis holds, |d_a|·τ_a (what a ray through such a medium hits: a
    wall opaque along x hides the edge-on faces behind it, which the d² blend let through at
    d_y² + d_z²). τ is capped at −ln(1 − TAU_ALPHA_CAP) for the weights only.
    The corners and weights are shared by the 3 axes: 12 gathers of (8, m) instead of 4
    (measured ~3–5× the isotropic ``trilinear``; a row-major (M+1, 6, 4) table gathering 4
    channels per corner was slower in numpy).
    """
    weights, rows = _corners(level, points, root_origin, node_size)
    rows = level.directional_columns(rows).astype(np.int64, copy=False)
    table = level.directional
    n = table.shape[1]
    flat = table.reshape(-1)
    m = len(points)
    faces = np.empty((3, 4, m), np.float32)  # [axis, channel, point]
    cols = np.empty_like(rows)
    for axis in range(3):
        # Column of channel c of the face facing the cone: (4·face + c)·n + row.
        base = np.where(dirs[:, axis] > 0, (2 * axis + 1) * 4 * n, 2 * axis * 4 * n)
        np.add(rows, base[None, :], out=cols)
        for c in range(4):
            if c:
                cols += n
            faces[axis, c] = np.einsum("km,km->m", weights,
                                       np.take(flat, cols).astype(np.float32, copy=False))
    if not extinction:
        d2 = (dirs * dirs).T.astype(np.float32)
        return np.einsum("am,acm->cm", d2, faces)
    along = np.abs(dirs).T  # (3, m)
    face_alpha = faces[:, 3].astype(np.float64)
    transmit = np.prod(np.power(np.clip(1.0 - face_alpha, 0.0, 1.0), along), axis=0)
    alpha = 1.0 - transmit
    # Weight of face a's premultiplied colour: |d_a|·τ_a / α_a (τ/α → 1 as α → 0).
    tau = -np.log1p(-np.clip(face_alpha, 0.0, TAU_ALPHA_CAP))
    tau_per_alpha = np.where(face_alpha > 1e-4, tau / np.maximum(face_alpha, 1e-4),
                             1.0 + 0.5 * np.maximum(face_alpha, 0.0))
    w = along * tau_per_alpha
    depth = (along * tau).sum(axis=0)
    out = np.empty((4, m), np.float32)
    out[:3] = np.einsum("am,acm->cm", w, faces[:, :3]) * (alpha / np.maximum(depth, 1e-12))
    out[3] = alpha
    return out


def sample_levels(levels, points: np.ndarray, level: np.ndarray, root_origin: np.ndarray,
                  root_size: float, dirs: np.ndarray | None = None,
                  extinction: bool = True) -> np.ndarray:
    """Trilinear within levels floor(level) and floor(level)+1, linear between them.

    levels : per-level objects 0..depth; points : (N, 3) float64; level : (N,) float, clipped
    to [0, depth]; dirs : (N, 3) unit cone directions for the anisotropic sample
    (``trilinear_directional``), None for the isotropic one.
    Returns (4, N) float32: premultiplied radiance r, g, b and occlusion.
    """
    depth = len(levels) - 1
    lev = np.clip(np.asarray(level, dtype=np.float64), 0, depth)
    lev = np.broadcast_to(lev, (len(points),))
    lo = np.floor(lev).astype(np.int64)
    t = (lev - lo).astype(np.float32)
    hi = np.minimum(lo + 1, depth)
    out = np.zeros((4, len(points)), dtype=np.float32)
    used = np.bincount(lo, minlength=depth + 1) + np.bincount(hi[t > 0], minlength=depth + 1)
    for ell in np.flatnonzero(used):
        at_lo = lo == ell
        sel = np.flatnonzero(at_lo | ((hi == ell) & (t > 0)))
        w = np.where(at_lo[sel], 1 - t[sel], t[sel])
        node_size = root_size / (1 << int(ell))
        everyone = len(sel) == len(points)  # one level for all points: slices, no scatter
        for start in range(0, len(sel), CHUNK_POINTS):
            chunk = slice(start, start + CHUNK_POINTS)
            idx = chunk if everyone else sel[chunk]
            if dirs is None:
                part = trilinear(levels[ell], points[idx], root_origin, node_size)
            else:
                part = trilinear_directional(levels[ell], points[idx], dirs[idx], root_origin,
                                             node_size, extinction=extinction)
            out[:, idx] += w[chunk] * part
    return out
