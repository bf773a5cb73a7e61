"""Reductions over a short axis (3 coordinates, 3 vertices, 8 corners) a slice at a time.

numpy's ``all``/``any``/``max``/``min`` along an axis of a few elements are 20–30 times slower
here than the same operation written a slice at a time, and ``np.linalg.norm(v, axis=-1)``
of 3-vectors 3–6 times slower than its sum of squares written out; the engine asks these of
every triangle, voxel, ray or pixel. Each function returns numpy's own reduction bit for bit
(NaN and signed zeros included; tests/engine/test_short_axis_reductions.py): the order is
numpy's own, ``((v0 ∘ v1) ∘ v2) ∘ …``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["norm3", "all_along", "any_along", "max_along", "min_along"]


def norm3(v) -> np.ndarray:
    """(..., 3) real vectors → (...,) lengths, ``np.linalg.norm(v, axis=-1)`` bit for bit
    (its ``sqrt((x² + y²) + z²)``, in float64 for integer input) without its slow reduce."""
    v = np.asarray(v)
    if not np.issubdtype(v.dtype, np.inexact):
        v = v.astype(float)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    s = x * x
    s += y * y
    s += z * z
    return np.sqrt(s, out=s)


def _slices(a, axis: int):
    return np.moveaxis(np.asarray(a), axis, 0)


def _fold(op, a, axis: int, fallback):
    parts = _slices(a, axis)
    if len(parts) < 2:
        return fallback(np.asarray(a), axis=axis)
    out = op(parts[0], parts[1])
    for part in parts[2:]:
        op(out, part, out=out)
    return out


def all_along(a, axis: int = -1) -> np.ndarray:
    """``a.all(axis=axis)`` of a bool array, a slice at a time (numpy's reduce is slow here)."""
    return _fold(np.logical_and, np.asarray(a, bool), axis, np.all)


def any_along(a, axis: int = -1) -> np.ndarray:
    """``a.any(axis=axis)`` of a bool array, a slice at a time (numpy's reduce is slow here)."""
    return _fold(np.logical_or, np.asarray(a, bool), axis, np.any)


def max_along(a, axis: int = -1) -> np.ndarray:
    """``a.max(axis=axis)``, a slice at a time (NaN propagates, as numpy's; not ``fmax``)."""
    return _fold(np.maximum, a, axis, np.max)


def min_along(a, axis: int = -1) -> np.ndarray:
    """``a.min(axis=axis)``, a slice at a time (NaN propagates, as numpy's; not ``fmin``)."""
    return _fold(np.minimum, a, axis, np.min)
