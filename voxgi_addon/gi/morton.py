"""3D Morton (Z-order) codes, vectorised, uint64, up to 21 bits per axis.

Bit 3b of a key is bit b of x, bit 3b+1 bit b of y, bit 3b+2 bit b of z. So ``key & 7`` is a
node's octant ``z<<2 | y<<1 | x`` inside its parent (the thesis' child order) and ``key >> 3``
is the parent's key: the children of a node are contiguous in sorted key order. Keys use at most
63 bits; bit 63 is never set by an encoded coordinate (``svo_sampling`` uses it as "invalid").
"""
from __future__ import annotations

import numpy as np

MAX_BITS = 21
MAX_COORD = (1 << MAX_BITS) - 1

_U = np.uint64
# (shift, mask) steps of the classic "part 1 by 2" bit spreading for 21-bit inputs.
_SPREAD_STEPS = (
    (_U(32), _U(0x1F00000000FFFF)),
    (_U(16), _U(0x1F0000FF0000FF)),
    (_U(8), _U(0x100F00F00F00F00F)),
    (_U(4), _U(0x10C30C30C30C30C3)),
    (_U(2), _U(0x1249249249249249)),
)
# The same steps undone in reverse order: shift right, xor, keep the previous step's mask.
_COMPACT_STEPS = (
    (_U(2), _U(0x10C30C30C30C30C3)),
    (_U(4), _U(0x100F00F00F00F00F)),
    (_U(8), _U(0x1F0000FF0000FF)),
    (_U(16), _U(0x1F00000000FFFF)),
    (_U(32), _U(MAX_COORD)),
)
_LOW21 = _U(MAX_COORD)
_EVERY_THIRD = _U(0x1249249249249249)


def spread_bits(values: np.ndarray) -> np.ndarray:
    """Any-shape integers in [0, 2^21) → uint64 of the same shape with bit b moved to bit 3b.

    No range check (bits above 21 are dropped); use ``morton_encode`` for checked input.
    """
    v = np.asarray(values).astype(np.uint64) & _LOW21
    tmp = np.empty_like(v)
    for shift, mask in _SPREAD_STEPS:
        np.left_shift(v, shift, out=tmp)
        v |= tmp
        v &= mask
    return v


def compact_bits(keys: np.ndarray) -> np.ndarray:
    """Inverse of ``spread_bits`` on bits 0, 3, 6, …: any-shape uint64 → uint64 in [0, 2^21)."""
    v = np.asarray(keys, dtype=np.uint64) & _EVERY_THIRD
    tmp = np.empty_like(v)
    for shift, mask in _COMPACT_STEPS:
        np.right_shift(v, shift, out=tmp)
        v ^= tmp
        v &= mask
    return v


def morton_encode(coords: np.ndarray) -> np.ndarray:
    """(N, 3) integer coordinates in [0, 2^21) → (N,) uint64 Morton keys.

    Raises ValueError for coordinates outside [0, 2^21).
    """
    c = np.asarray(coords)
    if c.ndim != 2 or c.shape[1] != 3:
        raise ValueError(f"expected (N, 3) coordinates, got shape {c.shape}")
    if c.size and (c.min() < 0 or c.max() > MAX_COORD):
        raise ValueError(f"Morton coordinates must lie in [0, 2^{MAX_BITS})")
    key = spread_bits(c[:, 0])
    key |= spread_bits(c[:, 1]) << _U(1)
    key |= spread_bits(c[:, 2]) << _U(2)
    return key


def morton_decode(keys: np.ndarray) -> np.ndarray:
    """(N,) uint64 Morton keys → (N, 3) int64 coordinates (x, y, z)."""
    k = np.asarray(keys, dtype=np.uint64)
    out = np.empty(k.shape + (3,), dtype=np.int64)
    for axis in range(3):
        out[..., axis] = compact_bits(k >> _U(axis))
    return out
