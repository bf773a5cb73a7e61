"""The sub-pixel samples' sums on the GPU (render/gpu_tails.py, render/shaders/aa_tails.glsl,
aa_place.glsl) equal their numpy reference, voxgi_addon/preview/passes.py
stacked_tails plus each edge pixel's own weighted sum."""
from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture
def gpu_ready(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    assert ready, why


def _raster(samples, rows: int, side: int):
    """The texture aa_resolve.glsl writes for a raster's passes ``samples`` (K, N, 4): pass k's
    sample of list entry n at texel (n % side, n // side + k · rows)."""
    from voxgi.render.gpu_volume import float_texture

    texels = np.zeros((len(samples), rows * side, 4), np.float32)
    texels[:, :samples.shape[1]] = samples
    return float_texture(texels.reshape(len(samples) * rows, side, 4), (side, len(samples) * rows))


def test_the_samples_summed_on_the_gpu_equal_stacked_tails_and_their_own_sums(gpu_ready):
    from voxgi.render.gpu_preview import _pixel_list
    from voxgi.render.gpu_tails import NAMES, GPUTails, reached_pixels
    from voxgi.voxgi_addon.preview.passes import stacked_tails

    width, height = 37, 23
    rng = np.random.default_rng(3)
    edge = rng.random((height, width)) < 0.3
    edge[0, 0] = edge[-1, -1] = edge[5, 0] = edge[0, 9] = True  # the border and the corners
    listed = np.flatnonzero(edge.ravel())
    passes = 16
    samples = rng.uniform(-1.0, 2.0, (passes, len(NAMES), len(listed), 4)).astype(np.float32)
    weights = rng.uniform(0.0, 1.0, (passes, 3, 3))
    groups = [list(range(0, 5)), list(range(5, 13)), list(range(13, 16))]  # rasters of 5, 8, 3

    pixels, size = _pixel_list(listed, width, height)
    side, rows = size
    at = reached_pixels(listed, width, height)
    sums = GPUTails(pixels, size, (width, height), at, *_pixel_list(at, width, height))
    for group in groups:
        raster = {f"out_{k}": _raster(samples[group, b], rows, side) for b, k in enumerate(NAMES)}
        sums.add(raster, weights[group])
    values = sums.read()

    tail_at, tails = stacked_tails(samples, weights, listed, width, height)
    expected = np.zeros((width * height, len(NAMES) * 4))
    expected[tail_at] += tails
    own = np.einsum("p,pbnc->nbc", weights[:, 1, 1], samples.astype(np.float64))
    expected[listed] += own.reshape(len(listed), -1)
    got = np.zeros_like(expected)
    got[at] = np.concatenate([values[f"sum_{k}"] for k in NAMES], axis=1)
    assert set(at) >= set(tail_at) | set(listed)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)
    # every neighbour of an edge pixel got something from it
    assert np.all(np.any(got[at] != 0.0, axis=1))


def test_a_pass_s_shaded_samples_are_placed_among_its_resolved_ones(gpu_ready):
    from voxgi.render.gpu_preview import _pixel_list
    from voxgi.render.gpu_tails import NAMES, GPUTails, reached_pixels
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture

    width, height = 20, 12
    rng = np.random.default_rng(5)
    listed = np.sort(rng.choice(width * height, 50, replace=False))
    pixels, size = _pixel_list(listed, width, height)
    side, rows = size
    resolved = rng.uniform(0.0, 1.0, (3, len(NAMES), len(listed), 4)).astype(np.float32)
    left = np.sort(rng.choice(len(listed), 17, replace=False))  # pass 1's samples it shades
    shaded = rng.uniform(5.0, 6.0, (len(NAMES), len(left), 4)).astype(np.float32)
    _, sub_size = _pixel_list(listed[left], width, height)
    texels = np.zeros((len(NAMES), sub_size[0] * sub_size[1], 4), np.float32)
    texels[:, :len(left)] = shaded
    textures = {f"sum_{k}": float_texture(texels[b].reshape(sub_size[1], sub_size[0], 4),
                                          sub_size) for b, k in enumerate(NAMES)}
    raster = {f"out_{k}": _raster(resolved[:, b], rows, side) for b, k in enumerate(NAMES)}
    at = reached_pixels(listed, width, height)
    sums = GPUTails(pixels, size, (width, height), at, *_pixel_list(at, width, height))
    sums.place(raster, textures, np.stack([left % side, left // side + rows], axis=1), sub_size)
    expected = resolved.copy()
    expected[1][:, left] = shaded
    for b, k in enumerate(NAMES):
        got = read_texture(raster[f"out_{k}"]).reshape(3, rows * side, 4)[:, :len(listed)]
        np.testing.assert_array_equal(got, expected[:, b])
