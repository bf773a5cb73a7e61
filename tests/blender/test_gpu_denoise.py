"""The GLSL à-trous filter (render/shaders/denoise.glsl) equals its numpy reference."""
from __future__ import annotations

import numpy as np
import pytest


def _gbuffer_textures(position, normal, hit):
    """G-buffer textures as the rasterizer lays them out (row 0 = bottom; w = hit flag)."""
    from voxgi.render.gpu_volume import float_texture

    h, w = hit.shape
    pos = np.concatenate([position, hit[..., None].astype(np.float64)], axis=-1)
    nor = np.concatenate([normal, np.zeros((h, w, 1))], axis=-1)
    return {"gbuffer_position": float_texture(np.flipud(pos), (w, h)),
            "gbuffer_normal": float_texture(np.flipud(nor), (w, h))}


def _scene(h=30, w=40, seed=3):
    """Floor (left) and wall (right) with a hole of background; noisy light with a step and a
    noisy AO with a contact-shadow band."""
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    position = np.stack([xs * 0.02, ys * 0.02, np.zeros_like(xs)], axis=-1)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    wall = xs >= 25
    normal[wall] = (-1.0, 0.0, 0.0)
    position[wall, 0], position[wall, 2] = 0.5, (xs[wall] - 25) * 0.02
    hit = np.ones((h, w), bool)
    hit[:5, :5] = False
    light = np.where((xs < 12)[..., None], 0.1, 0.6) * np.array([1.0, 0.8, 0.6])
    light = light + rng.normal(0.0, 0.05, (h, w, 1))
    ao = np.where((xs > 20) & (xs < 25), 0.5, 0.9) + rng.normal(0.0, 0.03, (h, w))
    values = np.concatenate([light, ao[..., None]], axis=-1)
    variance = np.stack([np.full((h, w), 0.05**2), np.full((h, w), 0.03**2)], axis=-1)
    return values, variance * rng.uniform(0.5, 1.5, (h, w, 1)), hit, position, normal


def _sparse_scene(traced_too):
    """``_scene`` with the sparse gather's holes (on a GPU context): every seen cell but the
    lattice of odd rows and columns and the cells ``traced_too(rows, cols)`` picks, their values
    and variances zeroed. Returns (values, variance, hit, position, normal, holes, rows, cols)."""
    from voxgi.render.gpu_context import ensure_gpu_context

    ready, why = ensure_gpu_context()
    assert ready, why
    values, variance, hit, position, normal = _scene()
    rows, cols = np.indices(hit.shape)
    holes = hit & ~(((rows % 2 == 1) & (cols % 2 == 1)) | traced_too(rows, cols))
    values[holes] = 0.0
    variance[holes] = 0.0
    return values, variance, hit, position, normal, holes, rows, cols


def _on_gpu(values, var4, hit, position, normal, **options):
    """``gpu_gather.denoise`` (4 passes) of the (H, W, 4) ``values`` and ``var4`` grids (row 0
    on top), read back in the same layout."""
    from voxgi.render.gpu_gather import denoise
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture

    h, w = hit.shape
    out, _ = denoise(float_texture(np.flipud(values), (w, h)),
                     float_texture(np.flipud(var4), (w, h)),
                     _gbuffer_textures(position, normal, hit), 1, w, h, iterations=4, **options)
    return np.flipud(read_texture(out))


@pytest.mark.parametrize("fit,size", [(True, (30, 40)), (False, (30, 40)), (True, (12, 16))])
def test_gpu_denoise_equals_numpy(voxgi, fit, size):
    """(12 × 16: at the last pass a cell's only tap is itself, where a float32 fit once read
    0.)"""
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_gather import denoise
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.denoise import atrous_filter

    ready, why = ensure_gpu_context()
    assert ready, why
    values, variance, hit, position, normal = _scene(*size)
    h, w = hit.shape
    var4 = np.concatenate([variance, np.zeros((h, w, 2))], axis=-1)
    out, out_var = denoise(float_texture(np.flipud(values), (w, h)),
                           float_texture(np.flipud(var4), (w, h)),
                           _gbuffer_textures(position, normal, hit), 1, w, h, iterations=4,
                           fit=fit)
    out, out_var = np.flipud(read_texture(out)), np.flipud(read_texture(out_var))
    ref, ref_var = atrous_filter(values, variance, hit, position, normal, iterations=4, fit=fit)
    assert np.allclose(out[hit], ref[hit], rtol=1e-3, atol=1e-4)
    assert np.allclose(out_var[hit][:, :2], ref_var[hit], rtol=1e-2, atol=1e-9)
    # and the filter did something: the noise is mostly gone
    assert np.abs(out[hit] - values[hit]).mean() > 0.01


def test_gpu_denoise_keeps_unseen_points_out_of_the_light_as_numpy(voxgi):
    """Cells flagged unseen (variance .w = 1: a metal's points, whose gather drew its AO alone)
    lend their AO but not their light, on the GPU as in numpy, and the flag changes the light
    of their neighbours."""
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.voxgi_addon.preview.denoise import atrous_filter

    ready, why = ensure_gpu_context()
    assert ready, why
    values, variance, hit, position, normal = _scene()
    h, w = hit.shape
    unseen = np.zeros((h, w), bool)
    unseen[:, 8:16] = True
    values[unseen, :3] *= np.random.default_rng(5).exponential(1.0, (unseen.sum(), 1)) * 3.0
    var4 = np.concatenate([variance, np.zeros((h, w, 1)), unseen[..., None] * 1.0], axis=-1)
    out = _on_gpu(values, var4, hit, position, normal, unseen=True)
    ref, _ = atrous_filter(values, variance, hit, position, normal, iterations=4, unseen=unseen)
    plain, _ = atrous_filter(values, variance, hit, position, normal, iterations=4)
    assert np.allclose(out[hit], ref[hit], rtol=1e-3, atol=1e-4)
    shown = hit & ~unseen
    assert np.abs(ref[shown][:, :3] - plain[shown][:, :3]).max() > 0.01


def test_gpu_fills_the_sparse_gathers_holes_as_numpy(voxgi):
    """Holes (variance .z = 1: the cells the sparse gather left out, here all but the lattice of
    odd rows and columns, a band one cell wide lit 10× and the rows beside it) are filled on
    the GPU as in numpy,
    each compared with its traced neighbours' light: the holes beside the band keep their own
    level."""
    from voxgi.voxgi_addon.preview.denoise import atrous_filter

    # the rows beside the band traced too, as the second list picks them (sparse_gather
    # noisy_holes: their neighbours lie across the light's edge)
    values, variance, hit, position, normal, holes, rows, _ = _sparse_scene(
        lambda rows, cols: np.abs(rows - 15) <= 1)
    h, w = hit.shape
    band = rows == 15
    unlit, _ = atrous_filter(values, variance, hit, position, normal, iterations=4, holes=holes)
    values[band, :3] *= 10.0  # (its noise as before: the step is far above it)
    var4 = np.concatenate([variance, holes[..., None] * 1.0, np.zeros((h, w, 1))], axis=-1)
    out = _on_gpu(values, var4, hit, position, normal, holes=True)
    ref, _ = atrous_filter(values, variance, hit, position, normal, iterations=4, holes=holes)
    assert np.allclose(out[hit], ref[hit], rtol=1e-3, atol=1e-4)
    # two and three rows from the band its light adds little (filled by geometry alone: up
    # to 1.0 over the light there without it, 0.35-0.41 on average)
    above = hit & ((rows == 12) | (rows == 13))
    assert np.abs(out[above, 0] - unlit[above, 0]).max() < 0.05


def test_gpu_spreads_the_spikes_as_numpy(voxgi):
    """The glossy gathers' spikes spread over their surface before the passes
    (``spread_spikes``; denoise.glsl options.w = 3 and 4): the GPU's light and variance equal
    numpy's, the light is kept, and the spikes are lower."""
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_gather import denoise
    from voxgi.render.gpu_gather import spread_spikes as gpu_spread
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.denoise import atrous_filter, spread_spikes

    ready, why = ensure_gpu_context()
    assert ready, why
    values, variance, hit, position, normal = _scene()
    h, w = hit.shape
    rng = np.random.default_rng(9)
    spikes = (rng.random((h, w)) < 0.03) & hit
    values[spikes, :3] += 5.0
    variance[spikes, 0] = 25.0 / 8
    var4 = np.concatenate([variance, np.zeros((h, w, 2))], axis=-1)
    gbuffer = _gbuffer_textures(position, normal, hit)
    spread = gpu_spread(float_texture(np.flipud(values), (w, h)),
                        float_texture(np.flipud(var4), (w, h)), gbuffer, 1, w, h)
    out, out_var = (np.flipud(read_texture(t)) for t in spread)
    ref, ref_var = spread_spikes(values, variance, hit, position, normal)
    assert np.allclose(out[hit], ref[hit], rtol=1e-3, atol=1e-4)
    assert np.allclose(out_var[hit][:, 0], ref_var[hit][:, 0], rtol=1e-3, atol=1e-7)
    assert abs(ref[hit][:, :3].sum() / values[hit][:, :3].sum() - 1.0) < 1e-6  # light kept
    assert ref[spikes][:, :3].max() < 0.7 * values[spikes][:, :3].max()
    filtered, _ = denoise(*spread, gbuffer, 1, w, h, iterations=4, fit=False)
    numpy_filtered, _ = atrous_filter(ref, ref_var, hit, position, normal, iterations=4,
                                      fit=False)
    assert np.allclose(np.flipud(read_texture(filtered))[hit], numpy_filtered[hit], rtol=1e-3,
                       atol=1e-4)


def test_gpu_bounds_the_taps_by_the_points_reach_as_numpy(voxgi):
    """Each traced cell's reach (variance .z = −the harmonic mean of its rays' hit distances,
    bvh_gather.glsl; 0: none) bounds its taps on the GPU as in numpy, with the sparse
    gather's holes (which have none) filled alike, and changes the light near the short
    reaches."""
    from voxgi.voxgi_addon.preview.denoise import atrous_filter

    values, variance, hit, position, normal, holes, rows, cols = _sparse_scene(
        lambda rows, cols: cols >= 18)
    h, w = hit.shape
    # short reaches by the wall (column 25), long ones on the open floor, none in a few cells
    reach = np.where(cols < 25, 0.02 + 0.04 * (24 - cols), 1.0)  # metres (2 cm cells)
    reach[rows == 7] = 0.0
    reach[holes] = 0.0
    var4 = np.concatenate([variance, np.where(holes, 1.0, -reach)[..., None],
                           np.zeros((h, w, 1))], axis=-1)
    out = _on_gpu(values, var4, hit, position, normal, holes=True)
    ref, _ = atrous_filter(values, variance, hit, position, normal, iterations=4, holes=holes,
                           reach=reach)
    plain, _ = atrous_filter(values, variance, hit, position, normal, iterations=4, holes=holes)
    assert np.allclose(out[hit], ref[hit], rtol=1e-3, atol=1e-4)
    near = hit & (cols >= 20) & (cols < 25)
    assert np.abs(ref[near][:, :3] - plain[near][:, :3]).max() > 0.01
