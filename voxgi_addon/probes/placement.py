"""Probe placement (Bowald 2016, 3.1.1; docs/probes.md "Placement").

The probe box is divided into dims[0] × dims[1] × dims[2] volumes; a volume is *active* when a
triangle touches it (the exact triangle/box test of ``voxelize.surface``); every active volume
gets probes at its 8 corners, shared with its neighbours, so a full grid has (k + 1)³ probes.

The test runs once, at the sub-volume resolution (4 per volume and axis): active volumes are the
parents of touched sub-volumes, and the same contacts give the masks their clipped triangle
areas (``masks``). A box that is not a cube is handled by mapping it to grid units per axis —
an affine map, which keeps which triangles touch which boxes (and area ratios within a plane).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import VoxGIError
from ..scene.geometry import bulk_bounds
from ..scene.short_axis import all_along, norm3
from ..voxelize.cube_clipping import clip_to_cells
from ..voxelize.surface import LATTICE_OFFSET, voxelize_triangles
from .grid import CORNER_OFFSETS

__all__ = ["SUBDIVISIONS", "ProbeLayout", "SubVolumeGeometry", "scene_box", "place_probes"]

SUBDIVISIONS = 4  # sub-volumes per volume and axis (64 per volume: one 64-bit mask)
MAX_VOLUMES_PER_AXIS = 256
BOX_MARGIN = 1e-3  # scene boxes grow by this share of their extent (and at least 0.1 mm)


@dataclass(frozen=True, eq=False)
class SubVolumeGeometry:
    """The triangles in each touched sub-volume, clipped to it (one row per contact).

    volume_row : (Q,) int64 row of the active volume (``ProbeLayout.volume_cells``).
    sub : (Q,) int64 sub-volume bit ``sx + 4·(sy + 4·sz)`` within it.
    area : (Q,) float64 world area of the triangle's piece in the sub-volume (m²).
    centroid : (Q, 3) float64 world centroid of the piece. normal : (Q, 3) unit face normal.
    """

    volume_row: np.ndarray
    sub: np.ndarray
    area: np.ndarray
    centroid: np.ndarray
    normal: np.ndarray


@dataclass(frozen=True, eq=False)
class ProbeLayout:
    """Where the probes go (before validity and baking).

    origin, volume_size : (3,) float64; dims : (3,) int64.
    volume_cells : (V,) int64 ascending linear volumes ``x + X·(y + Y·z)`` with geometry.
    volume_probes : (V, 8) int64 probe of each corner (``grid.CORNER_OFFSETS`` order).
    corners : (P,) int64 ascending linear grid corners ``x + (X+1)·(y + (Y+1)·z)`` of the probes.
    positions : (P, 3) float64 corner positions. geometry : the clipped sub-volume contacts.
    """

    origin: np.ndarray
    volume_size: np.ndarray
    dims: np.ndarray
    volume_cells: np.ndarray
    volume_probes: np.ndarray
    corners: np.ndarray
    positions: np.ndarray
    geometry: SubVolumeGeometry


def scene_box(positions) -> tuple[np.ndarray, np.ndarray]:
    """The triangles' bounding box grown by ``BOX_MARGIN`` of its extent on every side, so that
    walls on the bounds lie inside the outer volumes rather than on their faces. A triangle
    with a NaN or infinite corner (which no ray hits) is left out of it, and so are a stray
    few far from the rest (``scene.geometry.bulk_bounds``: a 5 cm helper 170 m away would
    make every volume tens of metres wide)."""
    bounds = bulk_bounds(positions)
    if bounds is None:
        raise VoxGIError("the scene has no triangles to place probes around")
    lo, hi = bounds
    margin = max(BOX_MARGIN * float((hi - lo).max()), 1e-4)
    return lo - margin, hi + margin


def place_probes(triangles, normals, lo, hi, dims) -> ProbeLayout:
    """Active volumes and corner probes of the box [lo, hi] split into ``dims`` volumes.

    triangles : (T, 3, 3) world-space corners; normals : (T, 3) unit face normals.
    dims : int k (k × k × k) or three ints.
    """
    lo = np.asarray(lo, np.float64).reshape(3)
    hi = np.asarray(hi, np.float64).reshape(3)
    dims = np.broadcast_to(np.asarray(dims, np.int64), (3,)).copy()
    if (dims < 1).any() or (dims > MAX_VOLUMES_PER_AXIS).any():
        raise VoxGIError(f"probe volumes per axis must be 1..{MAX_VOLUMES_PER_AXIS}, got {dims}")
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and (hi > lo).all()):
        raise VoxGIError(f"the probe box {lo} .. {hi} is empty")
    size = (hi - lo) / dims
    tri = np.asarray(triangles, np.float64).reshape(-1, 3, 3)
    normals = np.asarray(normals, np.float64).reshape(-1, 3)
    # Sub-volume grid units: sub-volume s covers [s, s+1) (with the voxelizer's lattice shift).
    sub_size = size / SUBDIVISIONS
    local = (tri - lo) / sub_size
    surface = voxelize_triangles(local.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), 1.0)
    sub_dims = dims * SUBDIVISIONS
    cells = surface.cells.astype(np.int64)
    inside = all_along((cells >= 0) & (cells < sub_dims))
    pair_ok = inside[surface.cell_of_pair]
    pair_tri = surface.triangle_of_pair[pair_ok].astype(np.int64)
    pair_cell = cells[surface.cell_of_pair[pair_ok]]

    volume_xyz = pair_cell // SUBDIVISIONS
    volume_lin = volume_xyz[:, 0] + dims[0] * (volume_xyz[:, 1] + dims[1] * volume_xyz[:, 2])
    volume_cells, volume_row = np.unique(volume_lin, return_inverse=True)
    vx = volume_cells % dims[0]
    vy = (volume_cells // dims[0]) % dims[1]
    vz = volume_cells // (dims[0] * dims[1])
    corner_xyz = np.stack([vx, vy, vz], axis=1)[:, None, :] + CORNER_OFFSETS[None]
    corner_lin = corner_xyz[..., 0] + (dims[0] + 1) * (corner_xyz[..., 1] + (dims[1] + 1) * corner_xyz[..., 2])
    corners, probe_of = np.unique(corner_lin.ravel(), return_inverse=True)
    x1, y1 = dims[0] + 1, dims[1] + 1
    positions = lo + np.stack([corners % x1, (corners // x1) % y1, corners // (x1 * y1)], axis=1) * size

    # Clipped piece of each contact: area and centroid in sub-grid units (the voxelizer's
    # shifted lattice), the area turned into m² through the triangle's share in that frame.
    shifted = local[pair_tri] + LATTICE_OFFSET
    piece, centroid = clip_to_cells(shifted, pair_cell)
    full = 0.5 * norm3(np.cross(shifted[:, 1] - shifted[:, 0], shifted[:, 2] - shifted[:, 0]))
    world = 0.5 * norm3(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    area = np.divide(piece, full, out=np.zeros_like(piece), where=full > 0) * world[pair_tri]
    keep = area > 0
    centroid_world = lo + (pair_cell + centroid - LATTICE_OFFSET) * sub_size
    s = pair_cell % SUBDIVISIONS
    geometry = SubVolumeGeometry(
        volume_row=volume_row[keep].astype(np.int64),
        sub=(s[:, 0] + SUBDIVISIONS * (s[:, 1] + SUBDIVISIONS * s[:, 2]))[keep],
        area=area[keep], centroid=centroid_world[keep], normal=normals[pair_tri[keep]])
    return ProbeLayout(lo, size, dims, volume_cells.astype(np.int64),
                       probe_of.reshape(-1, 8).astype(np.int64), corners, positions, geometry)
