"""The numbers the GPU cone tracer reads, packed as one (rows, 4) float32 table (numpy only).

The shaders (``render/shaders/``) read row r with ``texelFetch(params, ivec2(r, 0), 0)``; the
row numbers below are passed to them as defines, so this module is the one place the layout
is written down:

* ``ROW_ROOT``: root_origin xyz, root_size (metres);
* ``ROW_SHAPE``: depth, cascade resolution, cascade count, leaf node size;
* ``ROW_ATLAS``: the atlas' padded block size P, its depth Z (texels) (``volume_textures``);
* ``ROW_LEVELS + ℓ``: level ℓ's window origin xyz (nodes) and size W;
* ``ROW_SLABS + ℓ``: level ℓ's slab start z0 in the atlas;
* ``ROW_CASCADES + i``: cascade i's leaf level and node offset (``svo.VoxelOctree``);
* ``ROW_SETTINGS`` .. +3: the cone settings (see ``settings_rows``);
* ``ROW_CONES + k``: diffuse cone k's axis in the normal's frame xyz and weight.
"""
from __future__ import annotations

import math

import numpy as np

from ..gi.conetrace import ConeSettings, diffuse_cone_set

ROW_ROOT = 0
ROW_SHAPE = 1
ROW_ATLAS = 2
ROW_LEVELS = 3
MAX_LEVELS = 16
ROW_SLABS = ROW_LEVELS + MAX_LEVELS
ROW_CASCADES = ROW_SLABS + MAX_LEVELS
MAX_CASCADES = 8
ROW_SETTINGS = ROW_CASCADES + MAX_CASCADES
SETTINGS_ROWS = 4
ROW_CONES = ROW_SETTINGS + SETTINGS_ROWS
MAX_CONES = 128
PARAM_ROWS = ROW_CONES + MAX_CONES

ROWS = {name: value for name, value in globals().items() if name.startswith("ROW_")}


def settings_rows(cones: ConeSettings) -> np.ndarray:
    """(SETTINGS_ROWS, 4): sample_factor, falloff, ao_falloff, opacity_scale / max_distance,
    ao_distance, start_offset, tan(cone half-angle) / anisotropic, cone count, gi_intensity,
    ao_intensity / radiance_detail, transmittance_exponent, 0, 0."""
    return np.array([
        [cones.sample_factor, cones.falloff, cones.ao_falloff, cones.opacity_scale],
        [cones.max_distance, cones.ao_distance, cones.start_offset,
         math.tan(math.radians(cones.cone_angle))],
        [float(cones.anisotropic), cones.diffuse_cones, cones.gi_intensity, cones.ao_intensity],
        [cones.radiance_detail, cones.transmittance_exponent, 0.0, 0.0],
    ], np.float32)


def trace_params(octree, atlas, cones: ConeSettings) -> np.ndarray:
    """(PARAM_ROWS, 4) float32 table for one update's octree, its ``volume_textures`` atlas
    and the cone settings. Raises ValueError past the table's fixed limits."""
    if octree.depth + 1 > MAX_LEVELS:
        raise ValueError(f"octree depth {octree.depth} exceeds the GPU tracer's {MAX_LEVELS - 1}")
    if len(octree.cascade_levels) > MAX_CASCADES:
        raise ValueError(f"at most {MAX_CASCADES} cascades can be traced on the GPU")
    if cones.diffuse_cones > MAX_CONES:
        raise ValueError(f"at most {MAX_CONES} diffuse cones can be traced on the GPU")
    out = np.zeros((PARAM_ROWS, 4), np.float32)
    out[ROW_ROOT] = (*octree.root_origin, octree.root_size)
    out[ROW_SHAPE] = (octree.depth, octree.resolution, len(octree.cascade_levels),
                      octree.node_size(octree.depth))
    out[ROW_ATLAS] = (atlas.texels.shape[1], atlas.texels.shape[0], 0, 0)
    for w in atlas.windows:
        out[ROW_LEVELS + w.level] = (*w.origin, w.size)
        out[ROW_SLABS + w.level] = (w.z0, 0, 0, 0)
    for i, (ell, off) in enumerate(zip(octree.cascade_levels, octree.cascade_offsets)):
        out[ROW_CASCADES + i] = (ell, off, 0, 0)
    out[ROW_SETTINGS:ROW_SETTINGS + SETTINGS_ROWS] = settings_rows(cones)
    dirs, weights = diffuse_cone_set(cones.diffuse_cones, math.radians(cones.cone_angle))
    out[ROW_CONES:ROW_CONES + len(dirs), :3] = dirs
    out[ROW_CONES:ROW_CONES + len(dirs), 3] = weights
    return out
