"""The world as a light (voxgi_addon/gi/world_light.py): its tables, its sampling and its direct
light against brute-force integrals over the map."""
import dataclasses
import math

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
from voxgi.voxgi_addon.gi.sampling import hashed_square
from voxgi.voxgi_addon.gi.world_light import (
    build_world_light,
    one_technique,
    sample_world,
    unshadowed,
    world_direct,
    world_pdf,
    world_table,
)
from voxgi.voxgi_addon.scene.equirect import direction_to_pixel, pixel_directions, row_solid_angles

SUN = np.array([0.45, -0.35, 0.82]) / np.linalg.norm([0.45, -0.35, 0.82])


def sky_with_sun(height=64, width=128, sun=1000.0):
    d = pixel_directions(height, width)
    sky = np.where(d[..., 2:] > 0, np.array([0.2, 0.3, 0.6]), np.array([0.05, 0.04, 0.03]))
    disc = (d @ SUN) > math.cos(math.radians(3.0))
    return sky + disc[..., None] * sun


def brute_force(radiance, normal, visible=None):
    """E(n)/π of a map by summing over its pixels (optionally only the visible directions)."""
    h, w = radiance.shape[:2]
    d = pixel_directions(h, w)
    weight = np.maximum(d @ normal, 0.0) * row_solid_angles(h, w)[:, None] / math.pi
    if visible is not None:
        weight = weight * visible(d)
    return np.einsum("hw,hwc->c", weight, radiance)


def strata_for(count, samples=64, seed=0):
    ids = np.arange(count)
    return lambda points: hashed_square(ids[points], 0, samples, seed)


def test_a_uniform_world_gives_its_radiance_whatever_the_normal():
    world = build_world_light(np.full((8, 16, 3), 0.7))  # the small map a uniform colour gives
    normals = np.array([[0, 0, 1.0], [1, 0, 0], [0.3, -0.5, -0.81]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    np.testing.assert_allclose(unshadowed(world, normals), 0.7, rtol=2e-3)
    assert world_table(world).shape[1] >= 64  # the irradiance table fits beside a small map


def test_the_pdf_integrates_to_one_and_samples_follow_it():
    radiance = sky_with_sun()
    world = build_world_light(radiance)
    h, w = radiance.shape[:2]
    omega = np.repeat(row_solid_angles(h, w)[:, None], w, axis=1)
    assert world_pdf(world, pixel_directions(h, w)).ravel() @ omega.ravel() == pytest.approx(1.0, abs=1e-6)
    samples = sample_world(world, np.random.default_rng(1).random((200_000, 2)))
    np.testing.assert_allclose(np.linalg.norm(samples, axis=1), 1.0, atol=1e-9)
    luminance = radiance @ np.array([0.2126, 0.7152, 0.0722])
    disc = pixel_directions(h, w) @ SUN > math.cos(math.radians(3.0))
    rows, cols = direction_to_pixel(samples, h, w)
    in_disc = disc[np.clip(rows.astype(int), 0, h - 1), cols.astype(int) % w]
    expected = (luminance * omega)[disc].sum() / (luminance * omega).sum()
    assert in_disc.mean() == pytest.approx(expected, rel=0.01)


@pytest.mark.parametrize("normal", [(0, 0, 1.0), (0.6, 0.0, 0.8), (-0.5, 0.5, 0.2)])
def test_unshadowed_light_equals_the_brute_force_integral(normal):
    radiance = sky_with_sun()
    world = build_world_light(radiance)
    n = np.asarray(normal) / np.linalg.norm(normal)
    np.testing.assert_allclose(unshadowed(world, n[None])[0], brute_force(radiance, n), rtol=0.02)


def test_a_low_sun_lights_the_ground_from_where_it_is():
    """A real HDRI's sun a few pixels wide 2.6° above the horizon (a 1024 × 512 map, as
    pedestrian_overpass_1k.hdr): the table is integrated over boxes of 4 × 4 pixels, and a box's
    light taken from its centre, 0.6° lower, read that file's ground irradiance 5% low (its
    Diffuse Direct 2.8% under Cycles') and this map's 2%. From the box's luminous centroid it
    is the map's own."""
    height, width = 512, 1024
    d = pixel_directions(height, width)
    sun = np.array([0.627, -0.778, 0.046]) / np.linalg.norm([0.627, -0.778, 0.046])
    radiance = np.where(d[..., 2:] > 0, np.array([0.3, 0.35, 0.5]), np.array([0.05, 0.04, 0.03]))
    radiance = radiance + ((d @ sun) > math.cos(math.radians(0.3)))[..., None] * 60_000.0
    world = build_world_light(radiance)
    for normal in ((0, 0, 1.0), (0.3, 0.2, 0.93), (0.0, -0.6, 0.8)):
        n = np.asarray(normal) / np.linalg.norm(normal)
        np.testing.assert_allclose(unshadowed(world, n[None])[0], brute_force(radiance, n),
                                   rtol=0.005)


def test_shadowed_light_converges_to_the_visible_integral():
    """A wall blocking every direction with y > 0.2: the visible share estimated by the shadow
    rays (map and cosine samples) converges to the brute-force integral over what is left."""
    radiance = sky_with_sun()
    world = build_world_light(radiance)
    n = np.array([[0.0, 0.0, 1.0]])

    def occluded(origins, dirs):
        return dirs[:, 1] > 0.2

    points = np.zeros((400, 3))
    normals = np.repeat(n, 400, axis=0)
    value = world_direct(world, points, normals, occluded, strata_for(400, 16)).mean(axis=0)
    expected = brute_force(radiance, n[0], lambda d: d[..., 1] <= 0.2)
    np.testing.assert_allclose(value, expected, rtol=0.05)
    # the sun (y < 0.2) stays in view: its light is most of the point's
    assert SUN[1] <= 0.2 and value @ [0.2126, 0.7152, 0.0722] > 2 * brute_force(
        np.where(radiance > 100, 0.0, radiance), n[0]) @ [0.2126, 0.7152, 0.0722]


def test_no_occluder_gives_exactly_the_unshadowed_light():
    world = build_world_light(sky_with_sun())
    normals = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    np.testing.assert_array_equal(
        world_direct(world, np.zeros((2, 3)), normals, lambda o, d: np.zeros(len(d), bool),
                     strata_for(2)),
        unshadowed(world, normals))


def test_the_world_among_the_lights_adds_its_direct_light():
    world = build_world_light(np.full((8, 16, 3), 0.5))
    value = diffuse_direct(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), [world], None)
    np.testing.assert_allclose(value, 0.5, rtol=2e-3)


def test_a_black_or_broken_map_is_no_light():
    assert build_world_light(np.zeros((8, 16, 3))) is None
    assert build_world_light(np.full((8, 16, 3), np.nan)) is None
    world = build_world_light(np.where(np.arange(16)[None, :, None] % 2, np.inf, 1.0) * np.ones((8, 16, 3)))
    assert world is not None and np.isfinite(world.irradiance).all()


def test_a_reused_key_does_not_return_another_worlds_light():
    """The world light is cached by WorldData.key (a content key); a caller that reuses a key
    for other content gets the new map's light, not the cached one's."""
    from voxgi.voxgi_addon.gi.world_light import unshadowed, world_light
    from voxgi.voxgi_addon.scene.snapshot import WorldData

    grey = np.full((16, 32, 3), 0.5, np.float32)
    blue = np.broadcast_to(np.array([0.2, 0.4, 0.9], np.float32), (16, 32, 3)).copy()
    up = np.array([[0.0, 0.0, 1.0]])
    first = unshadowed(world_light(WorldData(np.full(3, 0.5, np.float32), 1.0, grey, "same")), up)
    second = unshadowed(world_light(WorldData(np.full(3, 0.5, np.float32), 1.0, blue, "same")), up)
    np.testing.assert_allclose(first[0], [0.5, 0.5, 0.5], rtol=1e-3)
    np.testing.assert_allclose(second[0], [0.2, 0.4, 0.9], rtol=1e-3)


def test_a_uniform_worlds_irradiance_is_its_radiance_and_the_quadrature_agrees():
    """A plain Background colour's unshadowed irradiance / π is its radiance at every normal
    (∫ L max(0, n·ω) dω = πL): the table takes it at once, and the quadrature that every
    other map goes through gives the same for a map a hair away from uniform."""
    from voxgi.voxgi_addon.gi.world_light import build_world_light

    colour = np.array([0.35, 0.5, 0.8])
    flat = build_world_light(np.tile(colour, (16, 32, 1)))
    assert flat.uniform
    np.testing.assert_allclose(flat.irradiance, np.broadcast_to(colour, flat.irradiance.shape),
                               rtol=1e-7)
    nearly = np.tile(colour, (16, 32, 1))
    nearly[0, 0] *= 1.0 + 1e-6
    quadrature = build_world_light(nearly)
    assert not quadrature.uniform
    np.testing.assert_allclose(quadrature.irradiance, flat.irradiance, rtol=2e-3)


def test_a_bounce_hits_one_ray_a_stratum_converges_to_the_visible_integral():
    """At a bounce hit each stratum draws one ray, by the map or by the cosine
    (``one_technique``: one-sample MIS over the techniques' mean density): half the shadow
    rays, and the mean still converges to the visible integral — with the sun in view, and
    with the sun hidden (where the map's rays are the ones that find the wall)."""
    radiance = sky_with_sun()
    world = build_world_light(radiance)
    n = np.array([[0.0, 0.0, 1.0]])
    points = np.zeros((100_000, 3))  # one stratum each: a hidden sun's rays are rare
    normals = np.repeat(n, len(points), axis=0)
    luminance = [0.2126, 0.7152, 0.0722]
    for wall in (lambda d: d[..., 1] > 0.2, lambda d: d[..., 0] > 0.3):  # sun seen, hidden
        rays = []

        def occluded(origins, dirs, wall=wall):
            rays.append(len(dirs))
            return wall(dirs)

        both = world_direct(world, points, normals, occluded, strata_for(len(points), 1))
        both_rays = sum(rays)
        rays.clear()
        single = world_direct(world, points, normals, occluded, strata_for(len(points), 1),
                              single=True)
        expected = brute_force(radiance, n[0], lambda d, wall=wall: ~wall(d))
        print(f"expected {expected @ luminance:.3f}: one ray {single.mean(0) @ luminance:.3f}, "
              f"two {both.mean(0) @ luminance:.3f}; rays {sum(rays)} against {both_rays}")
        assert sum(rays) <= 0.5 * both_rays + 1
        np.testing.assert_allclose(single.mean(axis=0), expected, rtol=0.04)
        np.testing.assert_allclose(both.mean(axis=0), expected, rtol=0.04)
    # one technique a ray: about half the strata drew each
    mapped, drawn = one_technique(hashed_square(np.arange(1000), 0, 1, 0))
    assert 0.4 < mapped.mean() < 0.6 and drawn.min() >= 0.0 and drawn.max() < 1.0


class _Wall:
    """Hides every direction with y < -0.2 (the sun's among them) from every point."""

    def occluded(self, origins, dirs, max_t):
        return np.asarray(dirs)[:, 1] < -0.2


def test_the_sub_pixel_samples_draw_the_worlds_strata_as_one_estimate():
    """A pixel's AA_SIDE² sub-pixel samples at one point, each drawing its block of the lamps'
    4 × 4 strata: the world draws ``world_block`` of it — four strata of an 8 × 8 set a sample
    — and a sample's estimate is not held at 0, so the samples' mean is the one estimate of all
    64 strata. (One stratum a sample of a sky and a sun was grain the world filter does not
    reach, dark dots along silhouettes and shadow edges; held per sample, a sample whose hidden
    rays outweigh the table read 0 and the pixel bright inside a shadow: docs/gi_pipeline.md
    "The world's strata at the sub-pixel samples".)"""
    from voxgi.voxgi_addon.gi.direct_light import world_block
    from voxgi.voxgi_addon.preview.passes import AA_SIDE, subpixel_passes

    # the map's sun drawn with the rest of it: both trace a sun apart
    # (``test_a_pixels_strata_trace_the_maps_sun_as_a_lamp``), and the whole set's stops at its
    # four corners where they agree, which a sample's four strata do not: equal in the mean only
    world = dataclasses.replace(build_world_light(sky_with_sun()), sun=None)
    points = np.zeros((40, 3))
    normals = np.tile([0.0, -0.3, 1.0], (40, 1)) / math.hypot(0.3, 1.0)
    ids = np.arange(40)
    plan = subpixel_passes(1.5, 4)  # the passes' 4 × 4 (``EDGE_STRATA`` × a centre's 2 × 2)
    assert len(plan) == AA_SIDE ** 2 and all(block[3] == 1 for _, block in plan)
    assert world_block(plan[0][1]) == (8, 0, 0, 2) and world_block((4, 0, 0, 4)) == (4, 0, 0, 4)
    # the default plan's passes already draw 2 × 2 of the lamps' 8 × 8: the world the same four
    assert subpixel_passes(1.5, 16)[0][1] == (8, 0, 0, 2) == world_block((8, 0, 0, 2))
    samples = [diffuse_direct(points, normals, [world], _Wall(), sample_ids=ids, seed=3,
                              strata_block=block) for _, block in plan]
    whole = diffuse_direct(points, normals, [world], _Wall(), sample_ids=ids, seed=3,
                           strata_block=(8, 0, 0, 8))
    mean = np.mean(samples, axis=0)
    assert min(s.min() for s in samples) < 0.0  # some samples' hidden rays outweigh the table
    # the whole set's estimate is a pixel's light, held at 0: equal where it is not held
    lit = whole > 0.0
    assert lit.mean() > 0.8
    np.testing.assert_allclose(mean[lit], whole[lit], rtol=1e-4, atol=1e-6)
    assert np.all(mean[~lit] <= 1e-6)
    # with its sun traced apart (the wall hides it): the samples' mean and the whole set agree
    # over the points to their noise, and the samples' sun is not grain of a few map rays
    world = build_world_light(sky_with_sun())
    points, normals = np.zeros((400, 3)), np.tile(normals[:1], (400, 1))
    ids = np.arange(400)
    samples = [diffuse_direct(points, normals, [world], _Wall(), sample_ids=ids, seed=3,
                              strata_block=block) for _, block in plan]
    whole = diffuse_direct(points, normals, [world], _Wall(), sample_ids=ids, seed=3,
                           strata_block=(8, 0, 0, 8))
    mean = np.mean(samples, axis=0)
    spread = 4 * np.std(mean, axis=0) / math.sqrt(len(ids)) + 1e-4
    assert np.all(np.abs(mean.mean(axis=0) - whole.mean(axis=0)) <= spread)
    plain = np.mean([diffuse_direct(points, normals, [dataclasses.replace(world, sun=None)],
                                    _Wall(), sample_ids=ids, seed=3, strata_block=block)
                     for _, block in plan], axis=0)
    assert np.std(mean, axis=0).max() < 0.5 * np.std(plain, axis=0).max()


def test_a_pixels_strata_trace_the_maps_sun_as_a_lamp():
    """A map's sun (its few pixels far brighter than the rest, most of its light) is traced by a
    pixel's 4 × 4 strata as a lamp is: by its own power, the four corner strata first and all
    sixteen only where they disagree; the rest of the map's rays leave it out. Unbiased against
    the brute-force sum where a wall hides part of the sky and half the sun, fewer rays, and
    less grain inside the sun's shadow (docs/gi_pipeline.md "The sun of an HDRI traced as a
    lamp")."""
    world = build_world_light(sky_with_sun())
    assert world.sun is not None and 1 <= len(world.sun.rows) <= 256
    whole = dataclasses.replace(world, sun=None)  # the map's rays drawn over all of it
    count = 4000
    normals = np.tile([0.0, -0.3, 1.0], (count, 1)) / math.hypot(0.3, 1.0)
    points = np.zeros((count, 3))
    for cut, sun_part in ((-0.8, "seen"), (SUN[1], "half hidden"), (0.0, "hidden")):
        traced = []

        def occluded(origins, dirs, cut=cut):
            traced.append(len(dirs))
            return np.asarray(dirs)[:, 1] < cut

        fine = np.repeat(np.repeat(world.radiance, 8, axis=0), 8, axis=1)  # the cut inside pixels
        exact = brute_force(fine, normals[0], lambda d, cut=cut: d[..., 1] >= cut)
        split = world_direct(world, points, normals, occluded, strata_for(count, 16))
        split_rays = sum(traced)
        traced.clear()
        plain = world_direct(whole, points, normals, occluded, strata_for(count, 16))
        plain_rays = sum(traced)
        # unbiased: the mean over the points' independent strata is the brute-force sum, to
        # four of its standard errors and the unshadowed table's 0.2%
        error = 4 * split.std(axis=0) / math.sqrt(count) + 0.002 * exact + 1e-4
        assert np.all(np.abs(split.mean(axis=0) - exact) <= error), (sun_part, error)
        if sun_part == "hidden":  # held at 0, the whole map's estimate read the shadow bright
            assert np.all(np.abs(split.mean(axis=0) - exact) < 0.2 * (plain.mean(axis=0) - exact))
        else:
            np.testing.assert_allclose(plain.mean(axis=0), exact, rtol=0.01, err_msg=sun_part)
        if sun_part != "half hidden":  # the corners agree: four rays to the sun, no more
            assert split_rays <= plain_rays - 8 * count, (sun_part, split_rays, plain_rays)
        else:  # a penumbra: all sixteen, as a lamp's
            assert split_rays <= plain_rays + 4 * count, (split_rays, plain_rays)
        if sun_part == "hidden":  # in the sun's shadow the grain is the sky's alone
            assert split.std(axis=0).max() < 0.5 * plain.std(axis=0).max()


def test_the_rest_of_a_sunny_map_goes_over_fewer_strata_and_stays_unbiased():
    """Where the world's filter is wide (640 × 480), a pixel's map and cosine rays go over a
    quarter fewer strata a side (3 × 3 at 16 Light Samples); with a sun traced apart, the rest
    of the map goes over that side times its share of the power, at least 2 × 2. The share is
    the map's power outside the sun's pixels; a map without a sun keeps 3 × 3, and so does every
    map where the filter is narrow (160 × 120). At 2 × 2 the rest's estimate is still the
    brute-force sum, in the sun's shadow where the rest is all of a point's light (docs/gi_pipeline.md
    "The rest of a sunny map over fewer strata")."""
    from voxgi.voxgi_addon.preview.passes import world_rest_share, world_strata_side

    world = build_world_light(sky_with_sun())
    h, w = world.radiance.shape[:2]
    power = (world.radiance @ np.array([0.2126, 0.7152, 0.0722])) * row_solid_angles(h, w)[:, None]
    outside = power.sum() - power[world.sun.rows, world.sun.columns].sum()
    assert world.rest_share == pytest.approx(outside / power.sum(), rel=1e-6)
    assert 0.0 < world.rest_share < 0.5
    plain = build_world_light(np.full((8, 16, 3), 0.7))
    assert plain.rest_share == 1.0 and world_rest_share([plain]) == 1.0 and world_rest_share([]) == 1.0
    assert world_rest_share([world]) == world.rest_share
    assert world_strata_side(16, 640, 480) == 3
    assert world_strata_side(16, 640, 480, world.rest_share) == 2
    assert world_strata_side(16, 640, 480, 0.9) == 3 and world_strata_side(64, 640, 480, 0.5) == 3
    assert world_strata_side(16, 160, 120, world.rest_share) == 4
    count = 4000
    normals = np.tile([0.0, -0.3, 1.0], (count, 1)) / math.hypot(0.3, 1.0)

    def occluded(origins, dirs):  # a wall hides the sun and the sky beyond it
        return np.asarray(dirs)[:, 1] < 0.0

    fine = np.repeat(np.repeat(world.radiance, 8, axis=0), 8, axis=1)
    exact = brute_force(fine, normals[0], lambda d: d[..., 1] >= 0.0)
    for side in (3, 2):
        light = world_direct(world, np.zeros((count, 3)), normals, occluded, strata_for(count, 16),
                             rest=strata_for(count, side * side, seed=1),
                             fewer=np.ones(count, bool))
        error = 4 * light.std(axis=0) / math.sqrt(count) + 0.002 * exact + 1e-4
        assert np.all(np.abs(light.mean(axis=0) - exact) <= error), (side, error)
