"""Conservative surface voxelization: every lattice cell a triangle touches, and no other.

The lattice is object space divided by the voxel span. Cell ``c`` covers
``[(c - ε)·span, (c + 1 - ε)·span]`` per axis with ``ε = LATTICE_OFFSET`` = 2⁻¹⁶ voxel: the tiny
shift makes a face lying exactly on a lattice plane (a default cube at span 0.25, a Cornell box
wall at x = -1) produce one layer of voxels — the cell above the plane — instead of two.
Overlap itself is exact and closed (touching counts); ``triangle_box.triangle_overlaps_cells``
is the readable reference of the same test.

How it is fast without leaving numpy: triangles are grouped by the shape (ex, ey, ez) of their
candidate cell range, so each group is a dense (triangles, ex, ey, ez) block evaluated with
broadcasting and no gathers. A triangle whose range is one cell thick in two axes touches every
candidate (it is a connected set spanning the third axis), so those groups skip the test.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .triangle_box import plane_is_meaningful

LATTICE_OFFSET = 2.0**-16
MAX_DENSE_KEYS = 1 << 26  # above this many cells, dedupe by sorting instead of a bitmap
_BLOCK_ELEMENTS = 1 << 15  # candidate cells evaluated per numpy block (stays in cache)


@dataclass(frozen=True)
class VoxelizedSurface:
    """The cells a set of triangles touches and which triangle touches which cell.

    cells : (N, 3) int32 lattice cells, sorted by (x, y, z).
    triangle_of_pair : (P,) int32 triangle index of each (triangle, cell) contact.
    cell_of_pair : (P,) int32 row of ``cells`` of each contact.
    span : voxel edge length in object-space units (metres).
    """

    cells: np.ndarray
    triangle_of_pair: np.ndarray
    cell_of_pair: np.ndarray
    span: float

    @property
    def voxel_count(self) -> int:
        return len(self.cells)


def to_grid_units(positions: np.ndarray, span: float) -> np.ndarray:
    """(V, 3) object-space positions → float64 grid units (cell c is ``[c, c+1]``)."""
    return np.asarray(positions, dtype=np.float64) / float(span) + LATTICE_OFFSET


def _vertex_min_max(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-triangle AABB of (T, 3, 3) vertices → (T, 3) min and max (no slow small-axis reduce)."""
    lo = np.minimum(np.minimum(tri[:, 0], tri[:, 1]), tri[:, 2])
    hi = np.maximum(np.maximum(tri[:, 0], tri[:, 1]), tri[:, 2])
    return lo, hi


def candidate_ranges(tri_grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last cell each triangle's closed AABB touches.

    tri_grid : (T, 3, 3) float64 vertices in grid units.
    Returns lo, hi : (T, 3) int64 with ``lo <= hi``; cells ``[lo, hi]`` inclusive.
    """
    vmin, vmax = _vertex_min_max(tri_grid)
    return np.ceil(vmin).astype(np.int64) - 1, np.floor(vmax).astype(np.int64)


def lattice_bounds(positions: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """The cell range covering a mesh's AABB at a span: what its cache is relative to.

    positions : (V, 3) object space. Returns lo (3,) int64 first cell and dims (3,) int64
    cells per axis. Every cell ``voxelize_triangles`` can return lies in ``[lo, lo + dims)``.
    """
    q = to_grid_units(positions, span)
    qmin, qmax = q.min(axis=0), q.max(axis=0)
    lo = np.ceil(qmin).astype(np.int64) - 1
    hi = np.floor(qmax).astype(np.int64)
    return lo, hi - lo + 1


ALL_AXES = tuple(range(10))


def _separating_intervals(tri: np.ndarray, lo: np.ndarray, axes=ALL_AXES):
    """Non-box SAT axes of each triangle and where its candidate cells must project.

    tri : (T, 3, 3) grid units; lo : (T, 3) first candidate cell; axes : which of the 10 axes
    (0 = the plane normal, 1 + 3u + j = unit_u × edge_j). Returns the axes as three (T, K)
    component arrays ax, ay, az and the intervals low, high (T, K): candidate ``lo + o``
    passes axis k iff ``low[k] <= axis_k · o <= high[k]`` (the first cell's centre is already
    subtracted).
    """
    v = tri - (lo + 0.5)[:, None, :]  # vertices relative to the first candidate's centre
    e = [v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]]
    zero = np.zeros(len(tri))
    n = np.cross(e[0], e[1]) if 0 in axes else None
    components = []
    for k in axes:
        if k == 0:
            components.append((n[:, 0], n[:, 1], n[:, 2]))
            continue
        u, ej = divmod(k - 1, 3)
        edge = e[ej]
        # unit_x × e = (0, -ez, ey); unit_y × e = (ez, 0, -ex); unit_z × e = (-ey, ex, 0)
        components.append(((zero, -edge[:, 2], edge[:, 1]), (edge[:, 2], zero, -edge[:, 0]),
                           (-edge[:, 1], edge[:, 0], zero))[u])
    ax, ay, az = (np.stack([c[a] for c in components], 1) for a in range(3))
    proj = [ax * v[:, i, 0, None] + ay * v[:, i, 1, None] + az * v[:, i, 2, None] for i in range(3)]
    pmin = np.minimum(np.minimum(proj[0], proj[1]), proj[2])
    pmax = np.maximum(np.maximum(proj[0], proj[1]), proj[2])
    radius = 0.5 * (np.abs(ax) + np.abs(ay) + np.abs(az))
    if 0 in axes:
        k = list(axes).index(0)
        pmin[:, k] = pmax[:, k] = proj[0][:, k]  # the plane axis uses vertex 0, like the reference
    low, high = pmin - radius, pmax + radius
    if 0 in axes:
        sq = [ej[:, 0] ** 2 + ej[:, 1] ** 2 + ej[:, 2] ** 2 for ej in e]
        longest_sq = np.maximum(np.maximum(sq[0], sq[1]), sq[2])
        normal_len = np.sqrt(n[:, 0] ** 2 + n[:, 1] ** 2 + n[:, 2] ** 2)
        flat = ~plane_is_meaningful(normal_len, longest_sq)
        low[flat, k], high[flat, k] = -1e300, 1e300  # a segment/point: the edge axes decide
    return ax, ay, az, low, high


def _axes_to_test(shape) -> tuple[int, ...]:
    """SAT axes that can still separate a candidate block of this shape.

    A triangle one cell thick along axis u lies inside that slab, so it overlaps a candidate
    iff its projection across u overlaps the cell's square: only the three axes u × edge_j
    can separate (2D SAT). Otherwise the plane and all nine edge axes are needed.
    """
    thin = [u for u in range(3) if shape[u] == 1]
    if thin:
        return tuple(1 + 3 * thin[0] + j for j in range(3))
    return ALL_AXES


def _test_block(ax, ay, az, low, high, shape):
    """Exact test of a block of triangles sharing one candidate shape (ex, ey, ez).

    ax, ay, az, low, high : (T, K) axes and intervals from ``_separating_intervals``.
    Returns mask (T, ex, ey, ez) bool of touched candidate cells. Each axis costs four
    full-size passes: ``|a·o - mid| <= half`` with the small per-axis terms broadcast.
    """
    ox, oy, oz = (np.arange(n, dtype=np.float64) for n in shape)
    full = (len(ax),) + tuple(int(n) for n in shape)
    mask = np.empty(full, dtype=bool)
    dist = np.empty(full)
    passed = np.empty(full, dtype=bool)
    mid = 0.5 * (low + high)
    half = 0.5 * (high - low)
    for k in range(ax.shape[1]):
        yz = (ay[:, k, None] * oy)[:, :, None] + (az[:, k, None] * oz)[:, None, :]
        x = ax[:, k, None] * ox - mid[:, k, None]
        np.add(x[:, :, None, None], yz[:, None, :, :], out=dist)
        np.abs(dist, out=dist)
        np.less_equal(dist, half[:, k, None, None, None], out=mask if k == 0 else passed)
        if k:
            mask &= passed
    return mask


class _KeySpace:
    """Linear keys of the cells in the box [lo, lo + dims): key = ((x·dy) + y)·dz + z."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray):
        self.lo = lo
        self.dims = hi - lo + 1
        self.strides = np.array([self.dims[1] * self.dims[2], self.dims[2], 1], dtype=np.int64)

    def keys(self, cells: np.ndarray) -> np.ndarray:
        return (cells - self.lo) @ self.strides

    def cells(self, keys: np.ndarray) -> np.ndarray:
        x, rem = np.divmod(keys, self.strides[0])
        y, z = np.divmod(rem, self.strides[1])
        return np.stack([x, y, z], axis=1) + self.lo


def _column_contacts(lo, ext, column, space):
    """Contacts of triangles one cell thick in two axes: all their candidates are touched."""
    counts = ext[column].prod(axis=1)
    tri_idx = np.repeat(column, counts)
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    step = np.arange(len(tri_idx)) - starts  # 0..count-1 along the one long axis
    stride = space.strides[np.argmax(ext[column], axis=1)]
    return tri_idx, space.keys(lo[column]).repeat(counts) + step * stride.repeat(counts)


def _tested_contacts(tri, lo, ext, rest, space):
    """Contacts of the other triangles, tested block by block per candidate shape.

    Triangles are sorted by shape; each run of one shape computes only the SAT axes that can
    separate it (``_axes_to_test``), so slab-thin triangles pay for 3 axes instead of 10.
    """
    e = ext[rest]
    m = int(e.max()) + 1
    shape_key = (e[:, 0] * m + e[:, 1]) * m + e[:, 2]
    order = np.argsort(shape_key, kind="stable")
    rest, e, shape_key = rest[order], e[order], shape_key[order]  # grouped by shape
    base = space.keys(lo[rest])
    starts = np.flatnonzero(np.r_[True, shape_key[1:] != shape_key[:-1]])
    ends = np.r_[starts[1:], len(rest)]
    tris_out, keys_out = [], []
    for s0, s1 in zip(starts, ends):
        shape = e[s0]
        size = int(shape.prod())
        members = rest[s0:s1]
        ax, ay, az, low, high = _separating_intervals(tri[members], lo[members], _axes_to_test(shape))
        # key offset of each candidate of this shape, in the block's flattened (i, j, k) order
        grid = np.indices(shape).reshape(3, -1).T
        local = grid @ space.strides
        per_block = max(1, _BLOCK_ELEMENTS // size)
        for b in range(0, s1 - s0, per_block):
            sel = slice(b, min(b + per_block, s1 - s0))
            mask = _test_block(ax[sel], ay[sel], az[sel], low[sel], high[sel], shape)
            t, c = np.divmod(np.flatnonzero(mask), size)
            t += s0 + b
            tris_out.append(rest[t])
            keys_out.append(base[t] + local[c])
    return tris_out, keys_out


def _contacts(tri: np.ndarray):
    """All (triangle, cell) contacts of (T, 3, 3) grid-unit triangles.

    Returns tri_idx (P,) int64, keys (P,) int64 and the _KeySpace the keys live in.
    """
    lo, hi = candidate_ranges(tri)
    space = _KeySpace(lo.min(axis=0), hi.max(axis=0))
    ext = hi - lo + 1
    thin_axes = (ext == 1).sum(axis=1)
    tris_out, keys_out = [], []
    column = np.flatnonzero(thin_axes >= 2)
    if len(column):
        t, k = _column_contacts(lo, ext, column, space)
        tris_out.append(t)
        keys_out.append(k)
    rest = np.flatnonzero(thin_axes < 2)
    if len(rest):
        t, k = _tested_contacts(tri, lo, ext, rest, space)
        tris_out += t
        keys_out += k
    return np.concatenate(tris_out), np.concatenate(keys_out), space


def _dedupe(keys: np.ndarray, total: int) -> tuple[np.ndarray, np.ndarray]:
    """Sorted unique keys and, per input key, its row in them (int32)."""
    if total <= MAX_DENSE_KEYS:
        present = np.zeros(total, dtype=bool)
        present[keys] = True
        unique_keys = np.flatnonzero(present)
        lookup = np.empty(total, dtype=np.int32)
        lookup[unique_keys] = np.arange(len(unique_keys), dtype=np.int32)
        return unique_keys, lookup[keys]
    unique_keys, inverse = np.unique(keys, return_inverse=True)
    return unique_keys, inverse.astype(np.int32)


def voxelize_triangles(positions: np.ndarray, triangles: np.ndarray, span: float) -> VoxelizedSurface:
    """Every lattice cell the triangles touch (exact), with the contact pairs.

    Parameters
    ----------
    positions : (V, 3) float, object space. Must be finite (see ``mesh_checks``).
    triangles : (T, 3) int vertex indices.
    span : voxel edge length, same units as ``positions``; > 0.

    Returns
    -------
    VoxelizedSurface with cells in the lattice described in the module docstring.
    """
    if not span > 0 or not np.isfinite(span):
        raise ValueError(f"voxel span must be a positive finite number, got {span!r}")
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(tris) == 0:
        empty = np.zeros(0, np.int32)
        return VoxelizedSurface(np.zeros((0, 3), np.int32), empty, empty, float(span))
    tri_grid = to_grid_units(positions, span)[tris]
    tri_idx, keys, space = _contacts(tri_grid)
    unique_keys, inverse = _dedupe(keys, int(space.dims.prod()))
    cells = space.cells(unique_keys).astype(np.int32)
    return VoxelizedSurface(cells, tri_idx.astype(np.int32), inverse, float(span))
