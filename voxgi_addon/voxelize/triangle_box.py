"""Exact triangle / axis-aligned box overlap (separating axis theorem).

This is the plain, readable reference (Akenine-Möller 2001): it tests one triangle against
many unit cells of the voxel lattice and is used by the tests as the brute-force oracle for
``voxelize.voxelize_triangles``, which evaluates the same 13 axes in a restructured,
vectorised form.

Everything here is in **grid units**: coordinates divided by the voxel span (see
``voxelize.to_grid_units``). Cell ``c`` (integer 3-vector) is the closed box ``[c, c + 1]``.
A triangle that only touches a box (shares a point with its boundary) overlaps it.
"""
from __future__ import annotations

import numpy as np

_UNIT_AXES = np.eye(3)

# A triangle whose |normal| (twice its area) is below this fraction of its longest edge squared
# is a segment or point for the overlap test: its plane is rounding noise and the plane axis is
# skipped (the edge axes then decide exactly). ``mesh_checks`` drops such triangles as zero-area.
DEGENERATE_RATIO = 2e-12


def plane_is_meaningful(normal_length: np.ndarray, longest_edge_sq: np.ndarray) -> np.ndarray:
    """True where a triangle's plane normal is not rounding noise (see DEGENERATE_RATIO)."""
    return normal_length > DEGENERATE_RATIO * longest_edge_sq


def triangle_overlaps_cells(triangle: np.ndarray, cells: np.ndarray, half: float = 0.5) -> np.ndarray:
    """Which closed unit cells a triangle touches.

    Parameters
    ----------
    triangle : (3, 3) float64, the three vertices in grid units.
    cells : (M, 3) integer cell indices.
    half : half edge of the tested box around each cell centre (0.5 = the cell itself; tests
        use 0.5 ± δ to tell rounding ties from real differences).

    Returns
    -------
    (M,) bool, True where the triangle and the cell ``[c, c+1]³`` share at least one point.
    """
    tri = np.asarray(triangle, dtype=np.float64)
    centres = np.asarray(cells, dtype=np.float64) + 0.5
    v = tri[None, :, :] - centres[:, None, :]  # (M, 3 vertices, 3 coords), box at the origin
    overlap = np.ones(len(centres), dtype=bool)

    # 1) the three box face normals: the triangle's AABB against the box.
    overlap &= (v.min(axis=1) <= half).all(axis=1) & (v.max(axis=1) >= -half).all(axis=1)

    # 2) the triangle's plane.
    edges = np.array([tri[1] - tri[0], tri[2] - tri[1], tri[0] - tri[2]])
    normal = np.cross(edges[0], edges[1])
    if plane_is_meaningful(np.linalg.norm(normal), (edges**2).sum(axis=1).max()):
        radius = half * np.abs(normal).sum()
        overlap &= np.abs(v[:, 0, :] @ normal) <= radius

    # 3) the nine cross products of box axes and triangle edges.
    for unit in _UNIT_AXES:
        for edge in edges:
            axis = np.cross(unit, edge)
            proj = v @ axis  # (M, 3)
            radius = half * np.abs(axis).sum()
            overlap &= (proj.min(axis=1) <= radius) & (proj.max(axis=1) >= -radius)
    return overlap


def brute_force_cells(triangles: np.ndarray) -> np.ndarray:
    """Every cell any of the triangles touches, by testing every cell of their bounding box.

    Parameters
    ----------
    triangles : (T, 3, 3) float64 vertices in grid units.

    Returns
    -------
    (N, 3) int64 unique cells, sorted lexicographically (x, then y, then z).
    """
    tris = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    if len(tris) == 0:
        return np.zeros((0, 3), dtype=np.int64)
    lo = np.floor(tris.min(axis=(0, 1))).astype(np.int64) - 1
    hi = np.floor(tris.max(axis=(0, 1))).astype(np.int64)
    axes = [np.arange(lo[i], hi[i] + 1) for i in range(3)]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    hit = np.zeros(len(cells), dtype=bool)
    for tri in tris:
        hit |= triangle_overlaps_cells(tri, cells)
    return cells[hit]
