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


def _separating_intervals(tri: np.ndarray, lo: np.ndarray):
    """The 10 non-box SAT axes of each triangle and where its candidate cells must project.

    tri : (T, 3, 3) grid units; lo : (T, 3) first candidate cell. Returns the axes as three
    (T, 10) component arrays ax, ay, az and the intervals low, high (T, 10): candidate
    ``lo + o`` passes axis k iff ``low[k] <= axis_k · o <= high[k]`` (the first cell's centre
    is already subtracted). Axis 0 is the plane normal, 1-9 are unit_u × edge_j.
    """
    v = tri - (lo + 0.5)[:, None, :]  # vertices relative to the first candidate's centre
    e = [v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2]]
    n = np.cross(e[0], e[1])
    zero = np.zeros(len(tri))
    # unit_x × e = (0, -ez, ey); unit_y × e = (ez, 0, -ex); unit_z × e = (-ey, ex, 0)
    ax = np.stack([n[:, 0]] + [zero] * 3 + [ej[:, 2] for ej in e] + [-ej[:, 1] for ej in e], 1)
    ay = np.stack([n[:, 1]] + [-ej[:, 2] for ej in e] + [zero] * 3 + [ej[:, 0] for ej in e], 1)
    az = np.stack([n[:, 2]] + [ej[:, 1] for ej in e] + [-ej[:, 0] for ej in e] + [zero] * 3, 1)
    proj = [ax * v[:, i, 0, None] + ay * v[:, i, 1, None] + az * v[:, i, 2, None] for i in range(3)]
    pmin = np.minimum(np.minimum(proj[0], proj[1]), proj[2])
    pmax = np.maximum(np.maximum(proj[0], proj[1]), proj[2])
    pmin[:, 0] = pmax[:, 0] = proj[0][:, 0]  # the plane axis uses vertex 0, like the reference
    radius = 0.5 * (np.abs(ax) + np.abs(ay) + np.abs(az))
    low, high = pmin - radius, pmax + radius
    longest_sq = np.maximum(np.maximum((e[0]**2).sum(1), (e[1]**2).sum(1)), (e[2]**2).sum(1))
    flat = ~plane_is_meaningful(np.linalg.norm(n, axis=1), longest_sq)
    low[flat, 0], high[flat, 0] = -1e300, 1e300  # a segment/point: the edge axes decide
    return ax, ay, az, low, high


def _test_block(ax, ay, az, low, high, shape):
    """Exact test of a block of triangles sharing one candidate shape (ex, ey, ez).

    Returns mask (T, ex, ey, ez) bool of touched candidate cells. Each axis costs four
    full-size passes: ``|a·o - mid| <= half`` with the small per-axis terms broadcast.
    """
    ox, oy, oz = (np.arange(n, dtype=np.float64) for n in shape)
    full = (len(ax),) + tuple(int(n) for n in shape)
    mask = np.ones(full, dtype=bool)
    dist = np.empty(full)
    passed = np.empty(full, dtype=bool)
    mid = 0.5 * (low + high)
    half = 0.5 * (high - low)
    for k in range(10):
        yz = (ay[:, k, None] * oy)[:, :, None] + (az[:, k, None] * oz)[:, None, :]
        x = ax[:, k, None] * ox - mid[:, k, None]
        np.add(x[:, :, None, None], yz[:, None, :, :], out=dist)
        np.abs(dist, out=dist)
        np.less_equal(dist, half[:, k, None, None, None], out=passed)
        mask &= passed
    return mask


def _column_contacts(lo, ext, column):
    """Contacts of triangles one cell thick in two axes: all their candidates are touched."""
    counts = ext[column].prod(axis=1)
    tri_idx = np.repeat(column, counts)
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    step = np.arange(len(tri_idx)) - starts  # 0..count-1 along the one long axis
    long_axis = np.repeat(np.argmax(ext[column], axis=1), counts)
    cells = lo[tri_idx]
    cells[np.arange(len(tri_idx)), long_axis] += step
    return tri_idx, cells


def _contacts(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """All (triangle, cell) contacts. tri (T, 3, 3) grid units → (P,) int64 tri, (P, 3) cells."""
    lo, hi = candidate_ranges(tri)
    ext = hi - lo + 1
    thin_axes = (ext == 1).sum(axis=1)
    tris_out, cells_out = [], []

    column = np.flatnonzero(thin_axes >= 2)
    if len(column):
        t, c = _column_contacts(lo, ext, column)
        tris_out.append(t)
        cells_out.append(c)

    rest = np.flatnonzero(thin_axes < 2)
    if len(rest):
        ax, ay, az, low, high = _separating_intervals(tri[rest], lo[rest])
        e = ext[rest]
        m = int(e.max()) + 1
        shape_key = (e[:, 0] * m + e[:, 1]) * m + e[:, 2]
        order = np.argsort(shape_key, kind="stable")
        keys_sorted = shape_key[order]
        starts = np.flatnonzero(np.r_[True, keys_sorted[1:] != keys_sorted[:-1]])
        ends = np.r_[starts[1:], len(order)]
        for s0, s1 in zip(starts, ends):
            shape = e[order[s0]]
            per_block = max(1, _BLOCK_ELEMENTS // int(shape.prod()))
            for b in range(s0, s1, per_block):
                sel = order[b:min(b + per_block, s1)]
                mask = _test_block(ax[sel], ay[sel], az[sel], low[sel], high[sel], shape)
                t, i, j, k = np.nonzero(mask)
                idx = rest[sel]
                tris_out.append(idx[t])
                cells_out.append(lo[idx[t]] + np.stack([i, j, k], axis=1))
    if not tris_out:
        return np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
    return np.concatenate(tris_out), np.concatenate(cells_out)


def _dedupe(cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique cells (sorted x, y, z) and, per input row, its row in the unique array."""
    if len(cells) == 0:
        return np.zeros((0, 3), np.int32), np.zeros(0, np.int32)
    lo = cells.min(axis=0)
    dims = cells.max(axis=0) - lo + 1
    rel = cells - lo
    keys = (rel[:, 0] * dims[1] + rel[:, 1]) * dims[2] + rel[:, 2]
    total = int(dims.prod())
    if total <= MAX_DENSE_KEYS:
        present = np.zeros(total, dtype=bool)
        present[keys] = True
        unique_keys = np.flatnonzero(present)
        lookup = np.empty(total, dtype=np.int32)
        lookup[unique_keys] = np.arange(len(unique_keys), dtype=np.int32)
        inverse = lookup[keys]
    else:
        unique_keys, inverse = np.unique(keys, return_inverse=True)
        inverse = inverse.astype(np.int32)
    x, rem = np.divmod(unique_keys, dims[1] * dims[2])
    y, z = np.divmod(rem, dims[2])
    unique = (np.stack([x, y, z], axis=1) + lo).astype(np.int32)
    return unique, inverse


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
    tri_grid = to_grid_units(positions, span)[tris]
    tri_idx, cells = _contacts(tri_grid)
    unique, inverse = _dedupe(cells)
    return VoxelizedSurface(unique, tri_idx.astype(np.int32), inverse, float(span))
