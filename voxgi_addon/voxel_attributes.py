"""Per-voxel surface attributes averaged from the triangles that touch each voxel.

Each (triangle, voxel) contact is weighted by the triangle's area shared evenly over the
voxels it touches — a cheap stand-in for the clipped area, matching the thesis' averaging of
rasterised fragments.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .voxelize import VoxelizedSurface


@dataclass(frozen=True)
class VoxelAttributes:
    """Float attributes of N voxels.

    albedo : (N, 3) float32 linear RGB; normal : (N, 3) float32 unit; specular : (N,) float32.
    weights : (N, 4) float32 summing to 1, bone_indices : (N, 4) uint8 — or None if unskinned.
    """

    albedo: np.ndarray
    normal: np.ndarray
    specular: np.ndarray
    weights: np.ndarray | None = None
    bone_indices: np.ndarray | None = None


def face_normals_and_areas(positions: np.ndarray, triangles: np.ndarray):
    """(T, 3) unit face normals (zero for degenerate faces) and (T,) areas."""
    p = np.asarray(positions, np.float64)[triangles]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    length = np.linalg.norm(cross, axis=1)
    normals = np.divide(cross, length[:, None], out=np.zeros_like(cross), where=length[:, None] > 0)
    return normals, 0.5 * length


def _weighted_mean(values, pair_tri, pair_cell, weight, count):
    """Per-voxel weighted mean of per-triangle values (T, k) → (N, k)."""
    total = np.bincount(pair_cell, weights=weight, minlength=count)
    out = np.empty((count, values.shape[1]))
    for c in range(values.shape[1]):
        out[:, c] = np.bincount(pair_cell, weights=weight * values[pair_tri, c], minlength=count)
    return out / np.maximum(total, 1e-300)[:, None]


def average_attributes(surface: VoxelizedSurface, positions, triangles, tri_albedo, tri_specular,
                       skin_weights=None, skin_indices=None) -> VoxelAttributes:
    """Average triangle attributes into the voxels of ``surface``.

    positions : (V, 3) object space; triangles : (T, 3) the ones passed to the voxelizer.
    tri_albedo : (T, 3), tri_specular : (T,). skin_weights (V, 4) / skin_indices (V, 4):
    each voxel takes the weights of the nearest vertex among the triangles touching it.
    """
    n = surface.voxel_count
    pt, pc = surface.triangle_of_pair, surface.cell_of_pair
    normals, areas = face_normals_and_areas(positions, triangles)
    per_tri = np.bincount(pt, minlength=len(triangles))
    weight = areas[pt] / np.maximum(per_tri[pt], 1) + 1e-30
    albedo = _weighted_mean(np.asarray(tri_albedo, np.float64), pt, pc, weight, n)
    spec = _weighted_mean(np.asarray(tri_specular, np.float64)[:, None], pt, pc, weight, n)[:, 0]
    normal = _weighted_mean(normals, pt, pc, weight, n)
    length = np.linalg.norm(normal, axis=1)
    # Opposite faces in one voxel (a thin wall) cancel: keep the heaviest face's normal there.
    flat = length < 1e-3
    if flat.any():
        order = np.lexsort((-weight, pc))
        first = order[np.r_[True, pc[order][1:] != pc[order][:-1]]]
        normal[flat] = normals[pt[first]][flat]
        length = np.linalg.norm(normal, axis=1)
    normal /= np.maximum(length, 1e-30)[:, None]
    w = idx = None
    if skin_weights is not None:
        vert = nearest_contact_vertex(surface, positions, triangles)
        w, idx = np.asarray(skin_weights)[vert], np.asarray(skin_indices)[vert]
    return VoxelAttributes(albedo.astype(np.float32), normal.astype(np.float32),
                           spec.astype(np.float32), w, idx)


def nearest_contact_vertex(surface: VoxelizedSurface, positions, triangles) -> np.ndarray:
    """Per voxel, the index of the vertex nearest its centre among the touching triangles.

    Restricting to touching triangles follows the surface: a voxel on an arm never takes the
    weights of a torso vertex that is closer through empty space. Returns (N,) int64.
    """
    corners = np.asarray(triangles)[surface.triangle_of_pair]  # (P, 3) vertex ids
    cell = np.repeat(surface.cell_of_pair, 3)
    vert = corners.ravel()
    centres = (surface.cells.astype(np.float64) + 0.5) * surface.span
    d = ((np.asarray(positions, np.float64)[vert] - centres[cell]) ** 2).sum(axis=1)
    order = np.lexsort((vert, d, cell))  # ties → lowest vertex id, deterministic
    first = order[np.r_[True, cell[order][1:] != cell[order][:-1]]]
    return vert[first]
