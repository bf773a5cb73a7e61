"""The GLSL à-trous filter (render/shaders/denoise.glsl) equals its numpy reference."""
from __future__ import annotations

import numpy as np


def _gbuffer_textures(position, normal, hit):
    """G-buffer textures as the rasterizer lays them out (row 0 = bottom; w = hit flag)."""
    from voxgi.render.gpu_volume import float_texture

    h, w = hit.shape
    pos = np.concatenate([position, hit[..., None].astype(np.float64)], axis=-1)
    nor = np.concatenate([normal, np.zeros((h, w, 1))], axis=-1)
    return {"gbuffer_position": float_texture(np.flipud(pos), (w, h)),
            "gbuffer_normal": float_texture(np.flipud(nor), (w, h))}


def _scene(h=30, w=40, seed=3):
    """Floor (left) and wall (right) with a hole of background, noisy light with a step."""
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
    clean = np.where((xs < 12)[..., None], 0.1, 0.6) * np.array([1.0, 0.8, 0.6])
    values = clean + rng.normal(0.0, 0.05, (h, w, 1))
    variance = np.full((h, w), 0.05**2) * rng.uniform(0.5, 1.5, (h, w))
    return values, variance, hit, position, normal


def test_gpu_denoise_equals_numpy(voxgi):
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_tracer import denoise, read_texture
    from voxgi.render.gpu_volume import float_texture
    from voxgi.voxgi_addon.preview.denoise import atrous_filter

    ready, why = ensure_gpu_context()
    assert ready, why
    values, variance, hit, position, normal = _scene()
    h, w = hit.shape
    low = float_texture(np.flipud(np.concatenate([values, variance[..., None]], axis=-1)), (w, h))
    out = np.flipud(read_texture(denoise(low, _gbuffer_textures(position, normal, hit), 1, w, h)))
    ref, ref_var = atrous_filter(values, variance, hit, position, normal, iterations=4)
    assert np.allclose(out[hit][:, :3], ref[hit], rtol=1e-3, atol=1e-4)
    assert np.allclose(out[hit][:, 3], ref_var[hit], rtol=1e-2, atol=1e-8)
    # and the filter did something: the noise is mostly gone
    assert np.abs(out[hit][:, :3] - values[hit]).mean() > 0.02
