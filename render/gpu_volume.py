"""The octree atlas and the parameter table as GPU textures (docs/gi_pipeline.md "The GPU tracer").

A ``GPUVolume`` holds the 3D RGBA16F atlas of every octree level (``voxgi_addon.preview.volume_textures``)
and the small RGBA32F parameter table (``voxgi_addon.preview.trace_params``). ``update`` uploads the
atlas only when its texels differ from the last upload (bpy's ``GPUTexture`` cannot update a
sub-region, so the atlas is the unit of upload); ``uploaded_bytes`` tells what the last update
sent. When the octree has an emission octree (``VoxelOctree.emission``) its atlas is stacked
after the radiance atlas in z (``volume_textures.stacked_atlas``; the table's ``ROW_ATLAS``
.y is then the stack's depth and .z where the emission starts), and a world
(``conetrace.WorldMips``) is packed after the table's rows (``volume_textures.world_mip_rows``)
for the cones that leave the voxels (docs/gi_pipeline.md "Fast quality: world and emission").
Needs a GPU context.
"""
from __future__ import annotations

import gpu
import numpy as np

from ..voxgi_addon.preview.trace_params import ROW_ATLAS, trace_params
from ..voxgi_addon.preview.volume_textures import stacked_atlas, volume_atlas, world_mip_rows

ATLAS_FORMAT = "RGBA16F"


def float_texture(array: np.ndarray, size, texture_format: str = "RGBA32F"):
    """A GPUTexture of ``size`` (2D or 3D, x first) holding the C-ordered float array (…, 4)."""
    flat = np.ascontiguousarray(array, dtype=np.float32).ravel()
    return gpu.types.GPUTexture(size, format=texture_format,
                                data=gpu.types.Buffer("FLOAT", flat.size, flat))


def _same_world(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a is b or (len(a.maps) == len(b.maps)
                      and all(np.array_equal(x, y) for x, y in zip(a.maps, b.maps)))


class GPUVolume:
    """Atlas texture and parameter table of the latest octree."""

    def __init__(self):
        self.atlas = None
        self.params = None
        self._texels = None          # texels of the atlas on the GPU
        self._octree = self._cones = self._world = self._atlas = None
        self._emission_z = 0         # where the emission atlas starts in z (0: none)
        self.uploaded_bytes = 0      # atlas bytes sent by the last update (0 = unchanged)

    def update(self, octree, cones, atlas=None, world=None) -> None:
        """atlas : ``volume_atlas(octree)`` when the caller already has it (the viewport's
        worker builds it off the main thread); built here when None.
        world : the ``conetrace.WorldMips`` the cones see where they leave the voxels (None:
        black); a new world alone rebuilds only the parameter table."""
        self.uploaded_bytes = 0
        same_octree = octree is self._octree and cones == self._cones
        if same_octree and _same_world(world, self._world):
            return  # the same update's octree: nothing to rebuild
        self._world = world
        if not same_octree:
            self._octree, self._cones = octree, cones
            self._atlas = atlas = volume_atlas(octree) if atlas is None else atlas
            emission = getattr(octree, "emission", None)
            texels, self._emission_z = stacked_atlas(atlas, None if emission is None
                                                     else volume_atlas(emission))
            old = self._texels
            if old is None or old.shape != texels.shape or not np.array_equal(old, texels):
                self.atlas = float_texture(texels, (texels.shape[2], texels.shape[1],
                                                    texels.shape[0]), ATLAS_FORMAT)
                self._texels = texels
                self.uploaded_bytes = int(np.prod(texels.shape[:3])) * 8
        table = trace_params(octree, self._atlas, cones)
        table[ROW_ATLAS, 1:3] = (self._texels.shape[0], self._emission_z)
        if world is not None:
            table = np.concatenate([table, world_mip_rows(world, len(table))])
        self.params = float_texture(table, (len(table), 1))

    @property
    def resident_bytes(self) -> int:
        """Bytes of the atlas on the GPU (half floats), 0 before the first upload."""
        return 0 if self._texels is None else self._texels.size * 2
