"""The octree atlas and the parameter table as GPU textures (docs/gi_pipeline.md "The GPU tracer").

A ``GPUVolume`` holds the 3D RGBA16F atlas of every octree level (``voxgi_addon.preview.volume_textures``)
and the small RGBA32F parameter table (``voxgi_addon.preview.trace_params``). ``update`` uploads the
atlas only when its texels differ from the last upload (bpy's ``GPUTexture`` cannot update a
sub-region, so the atlas is the unit of upload); ``uploaded_bytes`` tells what the last update
sent. Needs a GPU context.
"""
from __future__ import annotations

import gpu
import numpy as np

from ..voxgi_addon.preview.trace_params import trace_params
from ..voxgi_addon.preview.volume_textures import volume_atlas

ATLAS_FORMAT = "RGBA16F"


def float_texture(array: np.ndarray, size, texture_format: str = "RGBA32F"):
    """A GPUTexture of ``size`` (2D or 3D, x first) holding the C-ordered float array (…, 4)."""
    flat = np.ascontiguousarray(array, dtype=np.float32).ravel()
    return gpu.types.GPUTexture(size, format=texture_format,
                                data=gpu.types.Buffer("FLOAT", flat.size, flat))


class GPUVolume:
    """Atlas texture and parameter table of the latest octree."""

    def __init__(self):
        self.atlas = None
        self.params = None
        self._texels = None          # texels of the atlas on the GPU
        self._octree = self._cones = None
        self.uploaded_bytes = 0      # atlas bytes sent by the last update (0 = unchanged)

    def update(self, octree, cones, atlas=None) -> None:
        """atlas : ``volume_atlas(octree)`` when the caller already has it (the viewport's
        worker builds it off the main thread); built here when None."""
        self.uploaded_bytes = 0
        if octree is self._octree and cones == self._cones:
            return  # the same update's octree: nothing to rebuild
        self._octree, self._cones = octree, cones
        atlas = volume_atlas(octree) if atlas is None else atlas
        old = self._texels
        if old is None or old.shape != atlas.texels.shape or not np.array_equal(old, atlas.texels):
            self.atlas = float_texture(atlas.texels, atlas.texture_size, ATLAS_FORMAT)
            self._texels = atlas.texels
            self.uploaded_bytes = atlas.gpu_bytes
        table = trace_params(octree, atlas, cones)
        self.params = float_texture(table, (len(table), 1))

    @property
    def resident_bytes(self) -> int:
        """Bytes of the atlas on the GPU (half floats), 0 before the first upload."""
        return 0 if self._texels is None else self._texels.size * 2
