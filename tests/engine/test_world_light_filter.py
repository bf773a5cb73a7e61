"""The world's Diffuse Direct filtered over the image (docs/gi_pipeline.md "The world's light
filtered"): the variance its estimate reports is the variance it has, and the filter takes the
noise out of a sky-lit wall while a shadow's edge, far above that noise, stays where it is."""
from __future__ import annotations

import types

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.world_light import hidden_less, hidden_variance
from voxgi.voxgi_addon.preview.passes import world_filter_passes, world_filtered


def test_the_reported_variance_is_the_estimates_own():
    """Points whose rays are drawn at random (each point with its own hidden share and spread
    of ray weights L cos / pdf, two techniques of 16 strata): over many draws the estimate of
    the hidden part (``hidden_less``) varies as much as the mean of the variance
    ``hidden_variance`` reports for one draw."""
    rng = np.random.default_rng(3)
    points, strata, draws = 6, 16, 4000
    spread = rng.uniform(0.5, 3.0, (points, 1, 1))
    share = rng.uniform(0.1, 0.9, points)
    value = np.full((points, 3), 10.0)
    estimates, reported = [], []
    for _ in range(draws):
        weights = rng.uniform(0.2, 0.2 + spread, (points, 2 * strata, 1)) * \
            np.array([1.0, 0.9, 0.7])
        blocked = rng.random((points, 2 * strata)) < share[:, None]
        light = hidden_less(value, weights, blocked, strata, held=False)
        estimates.append(light @ np.array([0.2126, 0.7152, 0.0722]))
        reported.append(hidden_variance(weights, blocked, strata))
    measured = np.var(np.array(estimates), axis=0)
    predicted = np.mean(np.array(reported), axis=0)
    assert measured.min() > 0.0
    np.testing.assert_allclose(predicted, measured, rtol=0.12)


def _wall(width=48, height=32):
    """A flat wall seen straight on: the G-buffer of every pixel (row 0 on top)."""
    ys, xs = np.mgrid[0:height, 0:width]
    position = np.stack([xs * 0.05, ys * 0.05, np.zeros_like(xs, float)], axis=-1)
    normal = np.broadcast_to([0.0, 0.0, 1.0], (height, width, 3)).copy()
    return types.SimpleNamespace(hit=np.ones((height, width), bool), position=position,
                                 normal=normal)


def test_the_filter_takes_the_noise_and_keeps_a_shadow_edge():
    """Sky light 0.8 on the wall's right half and 0.2 in a shadow on its left, each pixel's
    estimate noisy by its reported variance: filtered, the noise falls at least threefold, and
    two pixels from the edge each side keeps its own light within 3%."""
    seen = _wall()
    height, width = seen.hit.shape
    truth = np.where(np.arange(width) < width // 2, 0.2, 0.8)[None, :].repeat(height, 0)
    sigma = 0.06
    rng = np.random.default_rng(7)
    noisy = truth + rng.normal(0.0, sigma, truth.shape)
    lights = [types.SimpleNamespace(type="SUN"), types.SimpleNamespace(type="WORLD"),
              types.SimpleNamespace(type="EMITTERS")]
    per_light = np.zeros((3, height * width, 3), np.float32)
    per_light[0] = 1.0  # a lamp's light: left as it is
    per_light[1] = (noisy.reshape(-1, 1) - 0.01) * np.ones(3)
    per_light[2] = 0.01  # the emitters': filtered with the world's, into its row
    variance = np.full(height * width, sigma ** 2)
    out = world_filtered(per_light, variance, lights, np.arange(height * width), seen)
    assert np.array_equal(out[0], per_light[0])
    assert not out[2].any()
    filtered = out[1][:, 0].reshape(height, width)
    inner = (slice(4, -4), slice(4, -4))
    away = np.abs(np.arange(width) - width // 2 + 0.5) > 4
    before = np.std((noisy - truth)[inner][:, away[4:-4]])
    after = np.std((filtered - truth)[inner][:, away[4:-4]])
    assert after < before / 3, (before, after)
    edge = width // 2
    for column, light in ((edge - 3, 0.2), (edge + 2, 0.8)):
        assert abs(filtered[4:-4, column].mean() - light) <= 0.03 * light, (column, light)


def test_grain_under_the_gathers_noise_target_is_filtered_too():
    """Sunlit ground that sees nearly all the sky: each pixel's estimate is off by 1% of its
    light, under the 2% at which the gathers' filter keeps a cell as it is. The world's light is
    most of such a pixel, so the filter takes that grain too (threefold less), and pixels
    whose rays all saw the sky (variance 0, their neighbours' too) stay exactly as traced."""
    seen = _wall()
    height, width = seen.hit.shape
    truth = np.full((height, width), 0.8)
    sigma = 0.008
    rng = np.random.default_rng(11)
    noisy = truth + rng.normal(0.0, sigma, truth.shape)
    noisy[4:16, 6:18] = 0.81  # all their rays reached the sky
    lights = [types.SimpleNamespace(type="WORLD")]
    per_light = (noisy.reshape(1, -1, 1) * np.ones(3)).astype(np.float32)
    variance = np.full(height * width, sigma ** 2)
    variance.reshape(height, width)[4:16, 6:18] = 0.0
    out = world_filtered(per_light, variance, lights, np.arange(height * width), seen)
    filtered = out[0][:, 0].reshape(height, width)
    grainy = np.zeros((height, width), bool)
    grainy[4:-4, 22:-4] = True  # away from the sky-seeing pixels
    before = np.std((noisy - truth)[grainy])
    after = np.std((filtered - truth)[grainy])
    assert after < before / 3, (before, after)
    assert np.all(filtered[8:12, 10:14] == np.float32(0.81))  # 4 pixels in


def test_the_filters_window_covers_the_same_part_of_the_scene_at_every_size():
    """Two passes (a 13-pixel window) at 160 × 120; an image twice as wide takes one pass more,
    which doubles the window, so it spans the same part of the scene (and at least two passes
    however small the image)."""
    assert world_filter_passes(160, 120) == 2
    assert world_filter_passes(32, 24) == 2
    for width, height in ((160, 120), (320, 240), (400, 300), (1920, 1080)):
        assert world_filter_passes(2 * width, 2 * height) == world_filter_passes(width, height) + 1
    assert world_filter_passes(640, 480) == 4
    assert world_filter_passes(480, 640) == 4


def test_fewer_world_rays_only_where_the_narrowest_window_sees_no_edge():
    """At 640 × 480 (four passes) a pixel's world rays go over fewer strata only where no
    geometric edge lies within the two-pass window's half width (6 pixels, a square), decided
    for whole 8 × 8 blocks (the GPU's work groups, counted from the bottom row): next to a
    silhouette at column 300 the blocks reaching columns 294-306 keep every stratum, the ones
    beyond are cut, and so is nothing along the image's border. At 160 × 120 (two passes) no
    pixel is."""
    from voxgi.voxgi_addon.preview.passes import (
        WORLD_FEWER_BLOCK,
        WORLD_FEWER_REACH,
        world_fewer_pixels,
    )

    assert (WORLD_FEWER_REACH, WORLD_FEWER_BLOCK) == (6, 8)
    edge = np.zeros((480, 640), bool)
    edge[:, 300] = True  # a silhouette down the image
    edge[[0, -1], :] = edge[:, [0, -1]] = True  # the border, as edge_pixels marks it
    fewer = world_fewer_pixels(edge, 16)
    assert fewer[240, 312] and fewer[240, 287] and not fewer[240, 311] and not fewer[240, 288]
    assert not fewer[:, 288:312].any() and fewer[8:-8, 312:-8].all() and fewer[8:-8, 8:288].all()
    assert not fewer[7, 100] and fewer[8, 100] and not fewer[:8].any() and not fewer[:, -8:].any()
    # blocks counted from the bottom row: an image 100 rows high has its partial block on top
    tall = np.zeros((100, 64), bool)
    tall[50, 30] = True
    cut = world_fewer_pixels(np.pad(tall, ((0, 0), (0, 576)))[:, :640], 16)
    for top in range(100 - 8, -8, -8):
        for left in range(0, 64, 8):
            block = cut[max(top, 0):top + 8, left:left + 8]
            assert block.all() or not block.any(), (top, left)
    assert not cut[50, 30] and not cut[44, 30] and cut[100 - 8 * 8 - 1, 30]
    assert world_fewer_pixels(np.zeros((120, 160), bool), 16) is None
    assert world_fewer_pixels(edge, 1) is None  # one stratum: nothing to cut


def test_the_cut_pixels_draw_the_fewer_strata_and_the_rest_all():
    """``world_direct`` with ``fewer``: the flagged points' light is the one drawn with the
    fewer strata alone, the others' the one with every stratum, ray for ray."""
    from test_world_light import _Wall, build_world_light, sky_with_sun

    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct

    world = build_world_light(sky_with_sun())
    count = 300
    points = np.zeros((count, 3))
    normals = np.tile([0.0, -0.3, 1.0], (count, 1)) / np.hypot(0.3, 1.0)
    ids = np.arange(count)
    fewer = np.arange(count) % 3 == 0
    kwargs = dict(sample_ids=ids, seed=5, world_variance=None)
    every = diffuse_direct(points, normals, [world], _Wall(), **kwargs)
    cut = diffuse_direct(points, normals, [world], _Wall(), world_strata=3, **kwargs)
    both = diffuse_direct(points, normals, [world], _Wall(), world_strata=3, world_fewer=fewer,
                          **kwargs)
    assert np.abs(cut - every).max() > 1e-3  # the two draws differ
    np.testing.assert_allclose(both[fewer], cut[fewer], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(both[~fewer], every[~fewer], rtol=1e-6, atol=1e-7)


def test_the_gather_points_hidden_sky_reports_the_variance_it_has():
    """The gather points' hidden part of a uniform sky (``passes.hidden_variances``, from the
    share of their cosine rays hidden): over many draws the hidden light's luminance and the
    share vary as much as the variances it reports for them (a binomial's, the share pulled
    half a ray towards ½), and a point whose rays all saw the sky reports no light hidden and
    a variance that still admits a neighbour within a ray's worth; points of fewer rays (a
    metal's, which draws its AO alone) report more."""
    from voxgi.voxgi_addon.preview.passes import hidden_variances

    rng = np.random.default_rng(5)
    draws = 20000
    rays = 96
    sky = np.array([0.35, 0.5, 0.8])
    share = np.array([0.05, 0.3, 0.5, 0.8])
    hidden = rng.binomial(rays, share[:, None], (len(share), draws)) / rays
    points = np.concatenate([hidden[..., None] * sky, hidden[..., None]], axis=-1)
    reported = hidden_variances(points.reshape(-1, 4), rays).reshape(len(share), draws, 2)
    luminance = points[..., :3] @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(reported[..., 1].mean(axis=1), hidden.var(axis=1), rtol=0.1)
    np.testing.assert_allclose(reported[..., 0].mean(axis=1), luminance.var(axis=1), rtol=0.15)
    open_sky = hidden_variances(np.zeros((1, 4)), rays)
    assert open_sky[0, 0] == 0.0 and 0.0 < open_sky[0, 1] < 1.0 / rays
    half = np.array([[0.5 * 0.35, 0.25, 0.4, 0.5]] * 2)
    each = hidden_variances(half, np.array([rays, 8]))
    np.testing.assert_allclose(each[0], hidden_variances(half[:1], rays)[0])
    assert (each[1] > 5.0 * each[0]).all()


def test_the_gather_points_hidden_map_reports_the_spread_of_its_radiance():
    """Under a map whose radiance varies with direction, a gather point's hidden light varies
    with where its hidden rays point as well as with how many are hidden: over many draws the
    hidden light's luminance varies as much as ``hidden_variances`` reports with the map's
    spread (``rest_spread``'s c²), and several times what the binomial alone reports where
    nearly every ray is hidden (a room lit through a window, whose filter otherwise kept the
    noise as blotches)."""
    from voxgi.voxgi_addon.preview.passes import hidden_variances, rest_spread

    rng = np.random.default_rng(7)
    rows, cols = 64, 128
    theta = (np.arange(rows) + 0.5) * np.pi / rows
    # a sky twice as bright as the ground, with a brighter band: the map's rays' radiance
    radiance = np.where(theta[:, None] < np.pi / 2, 2.0, 0.6) * np.ones((rows, cols))
    radiance[10:14] *= 4.0
    world = _Map(type="WORLD", uniform=False, key="map", sun=None,
                                  radiance=np.repeat(radiance[..., None], 3, axis=2))
    c2 = rest_spread([world], True)
    weight = (np.sin(theta)[:, None] * np.ones((rows, cols))).ravel()
    lum = radiance.ravel()
    mean = (weight * lum).sum() / weight.sum()
    assert c2 == pytest.approx((weight * lum * lum).sum() / weight.sum() / mean ** 2 - 1.0)
    assert c2 > 0.2
    rays, draws = 96, 20000
    for share in (0.5, 0.95):
        # each ray's radiance drawn by solid angle over the map, hidden at random
        picked = lum[rng.choice(lum.size, (draws, rays), p=weight / weight.sum())]
        hidden = rng.random((draws, rays)) < share
        light = (picked * hidden).mean(axis=1)
        points = np.stack([light, light, light, hidden.mean(axis=1)], axis=1)
        reported = hidden_variances(points, rays, c2)[:, 0]
        binomial = hidden_variances(points, rays)[:, 0]
        np.testing.assert_allclose(reported.mean(), light.var(), rtol=0.15)
        if share > 0.9:
            assert reported.mean() > 4.0 * binomial.mean()
    # another map under the same key (a world edited in place) has its own spread
    brighter = _Map(type="WORLD", uniform=False, key="map", sun=None,
                    radiance=np.repeat((radiance ** 2)[..., None], 3, axis=2))
    assert rest_spread([brighter], True) > 1.5 * c2
    assert rest_spread([world], True) == c2
    assert rest_spread([_Map(type="WORLD", uniform=True)], True) == 0.0
    assert rest_spread([], True) == 0.0


class _Map(types.SimpleNamespace):
    """A stand-in WorldLight: ``rest_spread`` keeps its c² by the world object (weakly)."""

    __hash__ = object.__hash__
