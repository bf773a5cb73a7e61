"""Bit packing of voxel cache words, the layout of Yalçıner 2016 fig. 4.2 (little-endian u32).

position word : x bits 0-9, y 10-19, z 20-29 (cells relative to the mesh AABB, so < 1024 per
                axis), bits 30-31 a flag (1 = a finer cascade also holds this mesh).
normal word   : SNORM8 x, y, z in bits 0-7, 8-15, 16-23; bits 24-31 SNORM8 plane offset: the
                signed distance along the normal from the voxel centre to the voxel's surface
                plane, as a fraction of the normal's reach ½(|nx| + |ny| + |nz|) voxel spans
                (of the stored, quantised normal) — the farthest that plane can be from the
                centre and still touch the voxel cube: ½ for an axis normal, up to √3/2 (half
                the diagonal). So every code is a plane through the voxel and the step is at
                most √3/2 / 127 ≈ 0.0068 voxel. The code -128 (never produced by SNORM8
                rounding) means "no plane": the surface only grazes the voxel (NaN unpacked).
colour word   : UNORM8 R, G, B, A = albedo RGB and specular.
weight word   : UNORM8 × 4 bone weights, quantised so the four bytes sum to exactly 255.
index word    : u8 × 4 bone indices.
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import norm3

MAX_CELLS_PER_AXIS = 1024


def pack_positions(cells: np.ndarray, flag: int | np.ndarray = 0) -> np.ndarray:
    """(N, 3) int cells in [0, 1024) and a 0-3 flag → (N,) uint32 position words."""
    c = np.asarray(cells, dtype=np.int64)
    if c.size and (c.min() < 0 or c.max() >= MAX_CELLS_PER_AXIS):
        raise ValueError("voxel position outside the 10-bit range [0, 1024)")
    words = c[:, 0] | (c[:, 1] << 10) | (c[:, 2] << 20) | (np.asarray(flag, np.int64) & 3) << 30
    return words.astype(np.uint32)


def unpack_positions(words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) uint32 → cells (N, 3) int32 and flags (N,) uint8."""
    w = np.asarray(words, dtype=np.uint32)
    cells = np.stack([w & 1023, (w >> 10) & 1023, (w >> 20) & 1023], axis=1).astype(np.int32)
    return cells, (w >> 30).astype(np.uint8)


def _bytes_to_word(b: np.ndarray) -> np.ndarray:
    """(N, k<=4) integers 0-255 → (N,) uint32 with byte i at bits 8i."""
    b = np.asarray(b, dtype=np.uint32)
    out = np.zeros(len(b), dtype=np.uint32)
    for i in range(b.shape[1]):
        out |= b[:, i] << np.uint32(8 * i)
    return out


def _word_to_bytes(words: np.ndarray, count: int) -> np.ndarray:
    """(N,) uint32 → (N, count) uint8, byte i from bits 8i."""
    w = np.asarray(words, dtype=np.uint32)
    return np.stack([(w >> np.uint32(8 * i)) & np.uint32(255) for i in range(count)], axis=1).astype(np.uint8)


def _snorm8(values: np.ndarray) -> np.ndarray:
    """Float in [-1, 1] → int64 in [-127, 127] (round to nearest, clamped, NaN → 0)."""
    v = np.nan_to_num(np.asarray(values, np.float64), nan=0.0)
    return np.clip(np.rint(v * 127.0), -127, 127).astype(np.int64)


def plane_reach(normals: np.ndarray) -> np.ndarray:
    """(N,) ½·|n|₁/|n|₂ of (N, 3) normals (any length): in voxel spans, the largest distance
    from the voxel centre at which a plane with that normal still touches the voxel cube
    (0 for a zero vector)."""
    n = np.asarray(normals, np.float64)
    length = norm3(n)
    return np.divide(0.5 * np.abs(n).sum(axis=1), length, out=np.zeros(len(n)), where=length > 0)


def pack_normals(normals: np.ndarray, plane_offsets: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) float unit vectors → (N,) uint32, SNORM8 per component (round to nearest).

    plane_offsets : optional (N,) signed plane offsets in voxel spans, stored SNORM8 in the top
    byte as a fraction of the quantised normal's ``plane_reach`` (clamped to it); NaN stores
    the "no plane" code -128. Omitted: the top byte is 0 (the plane through the centre).
    """
    q = _snorm8(normals)
    words = _bytes_to_word(q & 255)
    if plane_offsets is not None:
        d = np.asarray(plane_offsets, np.float64).reshape(-1)
        reach = plane_reach(q)
        frac = np.divide(np.nan_to_num(d), reach, out=np.zeros(len(d)), where=reach > 0)
        top = np.where(np.isnan(d), -128, _snorm8(frac)) & 255
        words |= top.astype(np.uint32) << np.uint32(24)
    return words


def unpack_normals(words: np.ndarray) -> np.ndarray:
    """(N,) uint32 → (N, 3) float32 in [-1, 1] (error ≤ 1/254 per component)."""
    b = _word_to_bytes(words, 3).view(np.int8).astype(np.float32)
    return np.maximum(b / 127.0, -1.0)


def unpack_plane_offsets(words: np.ndarray) -> np.ndarray:
    """(N,) uint32 normal words → (N,) float32 plane offsets in voxel spans (error ≤ 1/254 of
    the normal's reach ≤ 0.0035 voxel), NaN for the "no plane" code."""
    w = np.asarray(words, dtype=np.uint32)
    top = (w >> np.uint32(24)).astype(np.uint8).view(np.int8)
    reach = plane_reach(_word_to_bytes(w, 3).view(np.int8))
    return np.where(top == -128, np.nan, top / 127.0 * reach).astype(np.float32)


def pack_unorm8x4(values: np.ndarray) -> np.ndarray:
    """(N, 4) float in [0, 1] → (N,) uint32 (round to nearest; out-of-range values clamp)."""
    v = np.nan_to_num(np.asarray(values, np.float64), nan=0.0)
    return _bytes_to_word(np.clip(np.rint(v * 255.0), 0, 255))


def unpack_unorm8x4(words: np.ndarray) -> np.ndarray:
    """(N,) uint32 → (N, 4) float32 in [0, 1]."""
    return _word_to_bytes(words, 4).astype(np.float32) / 255.0


def quantize_weights(weights: np.ndarray, levels: int = 255) -> np.ndarray:
    """(N, 4) weights (any scale) → (N, 4) integers summing to exactly ``levels`` (or 0 for a
    zero row): uint8 for the default 255, uint16 up to 65535.

    Largest-remainder rounding, so a normalised set of weights stays normalised once packed.
    """
    w = np.clip(np.nan_to_num(np.asarray(weights, np.float64)), 0.0, None)
    total = w.sum(axis=1, keepdims=True)
    scaled = np.divide(w * float(levels), total, out=np.zeros_like(w), where=total > 0)
    floor = np.floor(scaled)
    missing = (np.where(total[:, 0] > 0, levels, 0) - floor.sum(axis=1)).astype(np.int64)
    order = np.argsort(-(scaled - floor), axis=1, kind="stable")
    ranks = np.argsort(order, axis=1)
    floor += ranks < missing[:, None]
    return floor.astype(np.uint8 if levels <= 255 else np.uint16)


def pack_weights(weights: np.ndarray) -> np.ndarray:
    """(N, 4) float weights → (N,) uint32 UNORM8 × 4 summing to 255."""
    return _bytes_to_word(quantize_weights(weights))


def unpack_weights(words: np.ndarray) -> np.ndarray:
    """(N,) uint32 → (N, 4) float32 weights (sum 1 for skinned voxels)."""
    return _word_to_bytes(words, 4).astype(np.float32) / 255.0


def pack_indices(indices: np.ndarray) -> np.ndarray:
    """(N, 4) int in [0, 255] → (N,) uint32."""
    i = np.asarray(indices, dtype=np.int64)
    if i.size and (i.min() < 0 or i.max() > 255):
        raise ValueError("bone index outside [0, 255]")
    return _bytes_to_word(i)


def unpack_indices(words: np.ndarray) -> np.ndarray:
    """(N,) uint32 → (N, 4) uint8 bone indices."""
    return _word_to_bytes(words, 4)
