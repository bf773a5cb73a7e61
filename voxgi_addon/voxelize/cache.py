"""VoxelCache: one mesh's packed surface voxels at one span (one cascade).

Struct-of-arrays of u32 words (see ``voxel_packing``). Cells are stored relative to
``origin_cell``, the first lattice cell of the mesh's AABB at this span, so a cache holds at
most 1024 cells per axis. Object-space centre of a voxel: ``(origin_cell + cell + 0.5) * span``;
the top byte of its normal word places the voxel's surface plane relative to that centre
(``voxel_packing``).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..scene.short_axis import norm3
from . import packing as vp
from .attributes import VoxelAttributes
from .cube_clipping import PATCH_SHRINK, voxel_patches


@dataclass(frozen=True)
class VoxelCache:
    """Packed voxels of one mesh at one cascade.

    key : mesh (cache) key; cascade : cascade index; span : voxel edge in object-space units
    (the cascade's span in metres, divided by the unit scale of a skinned mesh's key,
    ``object_scale.skin_key``).
    origin_cell : (3,) int64; dims : (3,) int64 cells of the AABB per axis (each ≤ 1024).
    positions, normals, colors : (N,) uint32; weights, bone_indices : (N,) uint32 or None.
    """

    key: str
    cascade: int
    span: float
    origin_cell: np.ndarray
    dims: np.ndarray
    positions: np.ndarray
    normals: np.ndarray
    colors: np.ndarray
    weights: np.ndarray | None = None
    bone_indices: np.ndarray | None = None

    @property
    def voxel_count(self) -> int:
        return len(self.positions)

    @property
    def skinned(self) -> bool:
        return self.weights is not None

    @property
    def nbytes(self) -> int:
        arrays = (self.positions, self.normals, self.colors, self.weights, self.bone_indices)
        return sum(a.nbytes for a in arrays if a is not None)

    def cells(self) -> np.ndarray:
        """(N, 3) int64 absolute lattice cells."""
        return vp.unpack_positions(self.positions)[0] + self.origin_cell

    def finer_flags(self) -> np.ndarray:
        """(N,) uint8: 1 where a finer cascade also holds this mesh."""
        return vp.unpack_positions(self.positions)[1]

    def centres(self) -> np.ndarray:
        """(N, 3) float64 object-space voxel centres in metres."""
        return (self.cells() + 0.5) * self.span

    def attributes(self) -> VoxelAttributes:
        """Unpack to float attributes (normals renormalised; ``plane_offset`` (N,) in metres)."""
        rgba = vp.unpack_unorm8x4(self.colors)
        n = vp.unpack_normals(self.normals)
        n /= np.maximum(norm3(n)[:, None], 1e-12)
        w = vp.unpack_weights(self.weights) if self.weights is not None else None
        i = vp.unpack_indices(self.bone_indices) if self.bone_indices is not None else None
        offset = vp.unpack_plane_offsets(self.normals) * np.float32(self.span)
        return VoxelAttributes(rgba[:, :3], n, rgba[:, 3], w, i, offset)

    @cached_property
    def patches(self) -> tuple[np.ndarray, np.ndarray]:
        """Each voxel's surface patch: its plane clipped to its cube shrunk by PATCH_SHRINK.

        Returns corners (N, 6, 3) float32 object-space metres relative to ``centres()`` and
        count (N,) int8 (< 3: no usable patch, all corners 0 — place the voxel by its centre).
        Computed on first use and kept (the cache is immutable): 73 bytes per voxel.
        """
        attrs = self.attributes()
        corners, count = voxel_patches(attrs.normal, attrs.plane_offset,
                                       (0.5 - PATCH_SHRINK) * self.span)
        corners[count < 3] = 0.0
        return corners.astype(np.float32), count.astype(np.int8)


def pack_cache(key: str, cascade: int, span: float, origin_cell, dims, cells,
               attrs: VoxelAttributes, finer_exists: bool) -> VoxelCache:
    """Pack absolute lattice ``cells`` (N, 3) and their float attributes into a VoxelCache."""
    origin = np.asarray(origin_cell, np.int64)
    rgba = np.concatenate([attrs.albedo, attrs.specular[:, None]], axis=1)
    return VoxelCache(
        key=key, cascade=cascade, span=float(span), origin_cell=origin,
        dims=np.asarray(dims, np.int64),
        positions=vp.pack_positions(np.asarray(cells, np.int64) - origin, int(finer_exists)),
        normals=vp.pack_normals(attrs.normal, None if attrs.plane_offset is None else
                                np.asarray(attrs.plane_offset, np.float64) / float(span)),
        colors=vp.pack_unorm8x4(rgba),
        weights=None if attrs.weights is None else vp.pack_weights(attrs.weights),
        bone_indices=None if attrs.bone_indices is None else vp.pack_indices(attrs.bone_indices),
    )
