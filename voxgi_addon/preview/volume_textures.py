"""The octree's sampling tables laid out as one 3D texture atlas (numpy only).

The GPU tracer (``render/``) samples every octree level with hardware trilinear filtering.
Each level becomes a dense clipmap-style block over the cube of nodes it can hold (all 2^ℓ
nodes of a dense level, the cascade window of a sparse one) with a one-texel border of zeros:
clamped coordinates then read "absent" (0) outside the window, exactly like the numpy
sampler's absent corners. All levels share one texture, because a shader that picks one of
several samplers per sample pays for all of them on Mesa's llvmpipe (measured 8× slower with
9 per-level textures than with one). Layout, P = W_max + 2 (W = window size in nodes)::

    texels[z0_ℓ + z + 1, y + 1, f·P + x + 1, c]
    (x, y, z) = node − window_origin_ℓ, f = 0..5 the directional faces (``svo_sampling.FACES``)
    and 6 the isotropic table, c = premultiplied r·α, g·α, b·α, α,

with level ℓ's slab starting at z0_ℓ = Σ_{k<ℓ} (W_k + 2). The texture is (7·P, P, Σ(W+2))
texels (x, y, z); everything outside the blocks is 0.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gi.morton import morton_decode

BLOCKS = 7          # 6 directional faces + the isotropic table
ISOTROPIC_BLOCK = 6
BYTES_PER_TEXEL = 8  # RGBA16F on the GPU


@dataclass(frozen=True)
class LevelWindow:
    """Where level ``level`` lives: window ``origin`` (3,) int64 node of its texel (1, 1, 1)
    within its blocks, ``size`` W nodes per axis, slab start ``z0`` in the atlas."""

    level: int
    origin: tuple[int, int, int]
    size: int
    z0: int


@dataclass(eq=False)
class VolumeAtlas:
    """texels : (Z, P, 7·P, 4) float32 (depth, height, width, channels); windows per level."""

    texels: np.ndarray
    windows: list[LevelWindow]

    @property
    def texture_size(self) -> tuple[int, int, int]:
        z, y, x, _ = self.texels.shape
        return (x, y, z)

    @property
    def gpu_bytes(self) -> int:
        return int(np.prod(self.texture_size)) * BYTES_PER_TEXEL


def _level_nodes(level) -> tuple[np.ndarray, np.ndarray, int, np.ndarray]:
    """(present columns, window-relative coords (M, 3), window size, window origin)."""
    if level.kind == "dense":
        size = 1 << level.level
        columns = np.flatnonzero(level.table[3, :-1] > 0)
        coords = np.stack(np.unravel_index(columns, (size,) * 3), axis=1)
        return columns, coords, size, np.zeros(3, np.int64)
    origin = np.asarray(level.window_origin, np.int64)
    return np.arange(len(level.keys)), morton_decode(level.keys) - origin, \
        int(level.window_size), origin


def volume_atlas(octree) -> VolumeAtlas:
    """The atlas of every level of ``octree`` (a ``svo.VoxelOctree``)."""
    nodes = [_level_nodes(lv) for lv in octree.levels]
    pad = max(size for _, _, size, _ in nodes) + 2
    windows, z0 = [], 0
    for lv, (_, _, size, origin) in zip(octree.levels, nodes):
        windows.append(LevelWindow(lv.level, tuple(int(o) for o in origin), size, z0))
        z0 += size + 2
    texels = np.zeros((z0, pad, BLOCKS * pad, 4), np.float32)
    for lv, (columns, coords, _, _), win in zip(octree.levels, nodes, windows):
        x, y, z = (coords[:, a] + 1 for a in range(3))
        z = z + win.z0
        faces = lv.directional.reshape(6, 4, -1)
        directional = lv.directional_columns(columns)
        for f in range(6):
            texels[z, y, f * pad + x] = faces[f][:, directional].T
        texels[z, y, ISOTROPIC_BLOCK * pad + x] = lv.table[:, columns].T
    return VolumeAtlas(texels, windows)


def sample_atlas(atlas: VolumeAtlas, level: int, points: np.ndarray, root_origin, root_size,
                 block: int) -> np.ndarray:
    """Reference of the shader's fetch: trilinear (clamp-to-edge) sample of one block of one
    level at world ``points`` (N, 3) → (N, 4). Used by tests to check the layout."""
    win = atlas.windows[level]
    pad = atlas.texels.shape[1]
    t = (np.asarray(points, np.float64) - root_origin) / (root_size / 2 ** level) \
        - np.asarray(win.origin) + 1.0
    t = np.clip(t, 0.0, win.size + 2.0) - 0.5
    lower = np.floor(t).astype(np.int64)
    frac = t - lower
    out = np.zeros((len(t), 4))
    for corner in range(8):
        offset = np.array([corner & 1, (corner >> 1) & 1, (corner >> 2) & 1])
        idx = lower + offset
        weight = np.prod(np.where(offset == 1, frac, 1.0 - frac), axis=1)
        x = block * pad + np.clip(idx[:, 0], 0, pad - 1)
        y = np.clip(idx[:, 1], 0, pad - 1)
        z = win.z0 + np.clip(idx[:, 2], 0, win.size + 1)
        out += weight[:, None] * atlas.texels[z, y, x]
    return out


def world_mip_rows(mips, first: int) -> np.ndarray:
    """(T, 4) float32 texels of a ``conetrace.WorldMips`` for the GPU's parameter table, to be
    placed from texel ``first`` on (after ``trace_params``' rows): every map row-major (rgb, 0),
    finest first, then one texel per map (its first texel, its rows H, 0, 0), then the header
    (map count, 0, 0, −1), the table's last texel (``cone_common.glsl`` world_radiance)."""
    texels, index = [], []
    at = first
    for image in mips.maps:
        rows, cols = image.shape[:2]
        flat = np.zeros((rows * cols, 4), np.float32)
        flat[:, :3] = image.reshape(-1, 3)
        texels.append(flat)
        index.append((at, rows, 0.0, 0.0))
        at += rows * cols
    header = np.array([[len(mips.maps), 0.0, 0.0, -1.0]], np.float32)
    return np.concatenate(texels + [np.asarray(index, np.float32), header])


def stacked_atlas(atlas: VolumeAtlas, emission: VolumeAtlas | None) -> tuple[np.ndarray, int]:
    """(texels, z offset): the atlas with the emission octree's atlas (same nodes, so the same
    layout) stacked after it in z, and where that starts (0: no emission, texels unchanged).
    The shaders read the emission's samples at z + offset (``cone_common.glsl``
    sample_volume)."""
    if emission is None:
        return atlas.texels, 0
    if emission.texels.shape != atlas.texels.shape:
        raise ValueError("the emission octree's atlas must have the radiance atlas' layout")
    return np.concatenate([atlas.texels, emission.texels], axis=0), atlas.texels.shape[0]
