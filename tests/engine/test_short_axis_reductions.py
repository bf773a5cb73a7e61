"""scene/short_axis: each reduction equals numpy's own bit for bit (NaN, ±inf, ±0, denormals)."""
from __future__ import annotations

import numpy as np
import pytest

from voxgi.voxgi_addon.scene.short_axis import all_along, any_along, max_along, min_along, norm3


def _awkward(shape, dtype, seed=0):
    """Random values over many magnitudes with NaN, ±inf, ±0, denormals and huge values."""
    rng = np.random.default_rng(seed)
    info = np.finfo(dtype)
    a = rng.standard_normal(shape) * 10.0 ** rng.integers(-40, 40, shape)
    pick = rng.random(shape)
    a[pick < 0.02] = np.nan
    a[(pick >= 0.02) & (pick < 0.04)] = np.inf
    a[(pick >= 0.04) & (pick < 0.06)] = -np.inf
    a[(pick >= 0.06) & (pick < 0.09)] = 0.0
    a[(pick >= 0.09) & (pick < 0.12)] = -0.0
    with np.errstate(over="ignore"):
        a = a.astype(dtype)
    tiny = (pick >= 0.12) & (pick < 0.16)
    a[tiny] = (rng.standard_normal(int(tiny.sum())) * float(info.tiny) / 64).astype(dtype)
    huge = (pick >= 0.16) & (pick < 0.18)
    a[huge] = (rng.uniform(-1, 1, int(huge.sum())) * float(info.max)).astype(dtype)
    return a


def _same_bits(got, want, signed_zero: bool = True):
    """signed_zero False: +0 and −0 count as one (the sign of the least of +0 and −0 is
    IEEE's to leave open, and numpy's own reductions pick either by the CPU's SIMD path)."""
    assert got.dtype == want.dtype and got.shape == want.shape
    if got.dtype == bool:
        assert np.array_equal(got, want)
        return
    nan = np.isnan(want)
    assert np.array_equal(np.isnan(got), nan)
    if not signed_zero:
        got, want = got + 0, want + 0  # (−0 + 0 is +0)
    word = np.uint32 if got.dtype == np.float32 else np.uint64
    assert np.array_equal(got[~nan].view(word), want[~nan].view(word))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_norm3_is_numpys_norm(dtype):
    v = _awkward((50_000, 3), dtype)
    with np.errstate(all="ignore"):
        _same_bits(norm3(v), np.linalg.norm(v, axis=1))
        _same_bits(norm3(v[::2]), np.linalg.norm(v[::2], axis=1))  # strided rows
        _same_bits(norm3(np.asfortranarray(v)), np.linalg.norm(v, axis=1))
        w = v[:48_000].reshape(-1, 4, 3)
        _same_bits(norm3(w), np.linalg.norm(w, axis=-1))
    ints = np.random.default_rng(1).integers(-1000, 1000, (1000, 3))
    _same_bits(norm3(ints), np.linalg.norm(ints, axis=1))


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64])
@pytest.mark.parametrize("shape, axis", [((40_000, 3), 1), ((40_000, 3), -1), ((9_000, 3, 3), 1),
                                         ((6_000, 8), 1), ((7, 5_000), 0), ((5_000, 2), 1)])
def test_max_min_are_numpys(dtype, shape, axis):
    if dtype == np.int64:
        a = np.random.default_rng(2).integers(-5, 5, shape)
    else:
        a = _awkward(shape, dtype, seed=3)
    _same_bits(max_along(a, axis), a.max(axis=axis), signed_zero=False)
    _same_bits(min_along(a, axis), a.min(axis=axis), signed_zero=False)
    if a.ndim == 3:  # a strided view
        _same_bits(max_along(a[:, :, 1:], axis), a[:, :, 1:].max(axis=axis), signed_zero=False)


@pytest.mark.parametrize("shape, axis", [((40_000, 3), 1), ((9_000, 3, 3), -1), ((6_000, 8), 1),
                                         ((6_000, 7), -1), ((3, 5_000), 0), ((5_000, 1), 1)])
def test_all_any_are_numpys(shape, axis):
    rng = np.random.default_rng(4)
    for p in (0.1, 0.5, 0.9):
        b = rng.random(shape) < p
        _same_bits(all_along(b, axis), b.all(axis=axis))
        _same_bits(any_along(b, axis), b.any(axis=axis))
