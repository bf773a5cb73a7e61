"""Exact clipping against a voxel cube: triangles clipped to their cells (area, centroid) and
planes clipped to a cube (the "voxel fraction" patches that cached voxels become at runtime).

Used by ``voxel_attributes`` (where the surface sits in each voxel) and by ``cascades`` /
``voxel_cache`` (patches transformed and re-voxelized into the cascade grid).
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import norm3

# Struct-of-arrays style: a vector is a list of three (N,) component arrays, so nothing reduces
# over a length-3 axis (slow in numpy).

_ETA = 1e-9  # clip_to_cells uses a cube of half edge ½ + _ETA (see there)
MAX_PATCH_VERTICES = 6  # a plane cuts a cube in at most a hexagon
_PLANE_CLAMP = 1 - 2.0**-9  # clamped planes keep cutting the cube by this fraction of its reach
# Runtime patches stay this many voxels inside their voxel's cube: more than the voxelizer's
# lattice shift (2⁻¹⁶), so a patch moved by a lattice-preserving transform (a 90° rotation, a
# whole-voxel move) never touches a neighbouring cell.
PATCH_SHRINK = 2.0**-10


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _interval(lo, hi, x, d, h, own_boundary=True):
    """Narrow the parameter interval [lo, hi] to the s with ``|x + s·d| <= h``.

    For d = 0 (parallel) the whole line is in or out; a line lying on the boundary
    (|x| = h up to rounding) counts as in only if ``own_boundary``.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-h - x) / d
        t2 = (h - x) / d
    zero = d == 0
    lo = np.maximum(lo, np.where(zero, -np.inf, np.minimum(t1, t2)))
    hi = np.minimum(hi, np.where(zero, np.inf, np.maximum(t1, t2)))
    ax = np.abs(x)
    inside = (ax < h * (1 - 1e-9)) | (own_boundary & (ax <= h * (1 + 1e-9)))
    return lo, np.where(zero & ~inside, -np.inf, hi)


def _face_lines(n, r, h):
    """The plane ``n·x = r`` (n unit) met with each face of the cube [-h, h]³.

    Yields, per face (axis a, side σ), the line ``x0 + s·d`` with d = n × (outward face normal) —
    so walking it keeps the plane's part inside the cube on the left around n — and the interval
    [lo, hi] of s inside the face square (empty when hi <= lo, or when the plane is parallel
    to the face). A plane through a cube edge meets both faces at that edge: only the face
    with the lower axis keeps it, so the side is counted once.
    """
    size = len(r)
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        den = 1.0 - n[a] * n[a]
        good = den > 1e-12
        inv_den = np.divide(1.0, den, out=np.zeros_like(den), where=good)
        for sigma in (-1.0, 1.0):
            d = [None] * 3
            d[a], d[b], d[c] = np.zeros(size), sigma * n[c], -sigma * n[b]  # σ·(n × e_a)
            lam = (r - n[a] * sigma * h) * inv_den  # x0 = σh·e_a + λ·(n − n_a·e_a)
            x0 = [None] * 3
            x0[a], x0[b], x0[c] = np.full(size, sigma * h), lam * n[b], lam * n[c]
            lo, hi = _interval(np.full(size, -np.inf), np.where(good, np.inf, -np.inf),
                               x0[b], d[b], h, own_boundary=a < b)
            lo, hi = _interval(lo, hi, x0[c], d[c], h, own_boundary=a < c)
            yield x0, d, lo, hi


def _add_segment(area2, moment, n, start, direction, lo, hi):
    """Green's theorem: the directed segment start + s·direction, s ∈ [lo, hi] (skipped if
    empty) adds (p × q)·n to twice the area and (p + q)·(p × q)·n to six times the moment."""
    seg = hi > lo
    with np.errstate(invalid="ignore"):
        c = np.where(seg, (hi - lo) * _dot(_cross(start, direction), n), 0.0)
        both = np.where(seg, lo + hi, 0.0)
    area2 += c
    for k in range(3):
        moment[k] += (2.0 * start[k] + both * direction[k]) * c


def clip_to_cells(tri: np.ndarray, cells: np.ndarray):
    """Area and centroid of each triangle clipped to its unit cell, exactly.

    tri : (P, 3, 3) grid units; cells : (P, 3) int, cell ``c`` = ``[c, c+1]³``. Returns area (P,)
    in grid units² and centroid (P, 3) relative to the cell's minimum corner (NaN where the
    piece has no area).

    No polygon is built: by Green's theorem the area and first moment of a planar region are
    sums over the directed segments of its boundary, in any order. The boundary of
    triangle ∩ cube is the triangle's edges clipped to the cube plus the lines (triangle plane
    ∩ cube face) clipped to the face and to the triangle — each a parametric interval, so all
    of it is fixed-size vectorised arithmetic. The cube is taken ``_ETA`` larger so that a
    triangle edge lying exactly in a face is counted once (as the side of a tiny sliver).
    """
    t = np.asarray(tri, np.float64)
    centre = np.asarray(cells, np.float64) + 0.5
    v = [[t[:, i, k] - centre[:, k] for k in range(3)] for i in range(3)]  # cube at the origin
    h = 0.5 + _ETA
    e = [[v[(i + 1) % 3][k] - v[i][k] for k in range(3)] for i in range(3)]
    nr = _cross(e[0], e[1])
    length = np.sqrt(_dot(nr, nr))
    inv = np.divide(1.0, length, out=np.zeros_like(length), where=length > 0)
    n = [x * inv for x in nr]  # triangles are counter-clockwise around their own normal
    r = _dot(n, v[0])
    area2 = np.zeros(len(t))
    moment = [np.zeros(len(t)) for _ in range(3)]
    for i in range(3):  # the triangle's edges inside the cube
        lo, hi = np.zeros(len(t)), np.ones(len(t))
        for k in range(3):
            lo, hi = _interval(lo, hi, v[i][k], e[i][k], h)
        _add_segment(area2, moment, n, v[i], e[i], lo, hi)
    m = [_cross(n, e[i]) for i in range(3)]  # in-plane inward normals of the triangle's edges
    mv = [_dot(m[i], v[i]) for i in range(3)]
    for x0, d, lo, hi in _face_lines(n, r, h):  # the cube's faces inside the triangle
        hi = np.where(length > 0, hi, -np.inf)
        for i in range(3):  # m_i·(x0 + s·d − v_i) >= 0
            g = _dot(m[i], x0) - mv[i]
            k = _dot(m[i], d)
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -g / k
            lo = np.where(k > 0, np.maximum(lo, s), lo)
            hi = np.where(k < 0, np.minimum(hi, s), hi)
            hi = np.where((k == 0) & (g < 0), -np.inf, hi)
        _add_segment(area2, moment, n, x0, d, lo, hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = [mk / (3.0 * area2) for mk in moment]
    # the boundary sums give the centroid's in-plane part; its height along n is the plane's
    height = _dot(g, n) - r
    centroid = np.stack([g[k] - height * n[k] + 0.5 for k in range(3)], axis=1)
    area = 0.5 * area2
    centroid[~(area > 0)] = np.nan
    return np.maximum(area, 0.0), centroid


def _plane_in_cube(normals, offsets, half):
    """Normals as components and offsets clamped so each plane still cuts the cube [-h, h]³
    (quantisation can push a plane through a corner out of it); NaN offsets stay NaN."""
    nn = np.asarray(normals, np.float64).reshape(-1, 3)
    n = [np.ascontiguousarray(nn[:, k]) for k in range(3)]
    reach = half * (np.abs(n[0]) + np.abs(n[1]) + np.abs(n[2]))  # the plane leaves beyond
    d = np.asarray(offsets, np.float64).reshape(-1)
    return n, np.clip(d, -_PLANE_CLAMP * reach, _PLANE_CLAMP * reach)


def patch_areas(normals: np.ndarray, offsets: np.ndarray, half: float) -> np.ndarray:
    """(N,) area of each plane ``n·x = d`` (n unit, d clamped into the cube) ∩ the cube
    [-half, half]³; 0 for a NaN offset."""
    n, d = _plane_in_cube(normals, offsets, half)
    area2 = np.zeros(len(d))
    moment = [np.zeros(len(d)) for _ in range(3)]
    for x0, direction, lo, hi in _face_lines(n, np.nan_to_num(d), half):
        _add_segment(area2, moment, n, x0, direction, lo, hi)
    return np.where(np.isnan(d), 0.0, 0.5 * area2)


def voxel_patches(normals: np.ndarray, offsets: np.ndarray, half: float):
    """Each voxel's plane clipped to its cube, as a convex polygon relative to the voxel centre.

    normals : (N, 3) unit; offsets : (N,) signed distance of the plane ``n·x = d`` from the
    centre; half : half edge of the cube (same units). Offsets beyond the cube are clamped so
    the plane still cuts it a little; a NaN offset (no plane: the surface only grazes the
    voxel) gives count 0. A patch is what a voxel's plane stands for at runtime (``cascades``).

    Each face the plane crosses holds one side of the polygon; the sides' start points, ordered
    by a pseudo-angle around the sides' mean midpoint, are its corners.
    Returns vertices (N, 6, 3) (unused slots 0) and count (N,) in 0..6; a count < 3 means the
    polygon degenerated (use the voxel centre instead).
    """
    n, d = _plane_in_cube(normals, offsets, half)
    starts, mids, valid = [[], [], []], [[], [], []], []
    for x0, direction, lo, hi in _face_lines(n, np.nan_to_num(d), half):
        ok = (hi > lo) & ~np.isnan(d)
        lo = np.where(ok, lo, 0.0)
        both = np.where(ok, lo + np.where(ok, hi, 0.0), 0.0)
        for k in range(3):
            starts[k].append(x0[k] + lo * direction[k])
            mids[k].append(x0[k] + 0.5 * both * direction[k])
        valid.append(ok)
    valid = np.stack(valid, axis=1)  # (N, 6)
    starts = [np.stack(c, axis=1) for c in starts]
    count = valid.sum(axis=1)
    scale = 1.0 / np.maximum(count, 1)
    rel = [np.stack(c, axis=1) for c in mids]
    rel = [c - np.where(valid, c, 0.0).sum(axis=1, keepdims=True) * scale[:, None] for c in rel]
    # a basis (u, v) of the plane: u = n × (the axis n is least along), v = n × u
    nn = np.stack(n, axis=1)
    u = np.cross(nn, np.eye(3)[np.argmin(np.abs(nn), axis=1)])
    u /= np.maximum(norm3(u)[:, None], 1e-30)
    w = np.cross(nn, u)
    x = rel[0] * u[:, 0, None] + rel[1] * u[:, 1, None] + rel[2] * u[:, 2, None]
    y = rel[0] * w[:, 0, None] + rel[1] * w[:, 1, None] + rel[2] * w[:, 2, None]
    norm1 = np.abs(x) + np.abs(y)
    c = np.divide(x, norm1, out=np.zeros_like(x), where=norm1 > 0)
    angle = np.where(y >= 0, 1.0 - c, 3.0 + c)  # monotone in the angle, in [0, 4)
    order = np.argsort(np.where(valid, angle, np.inf), axis=1)
    out = np.stack([np.take_along_axis(p, order, axis=1) for p in starts], axis=2)
    out[np.arange(MAX_PATCH_VERTICES) >= count[:, None]] = 0.0
    return out, count
