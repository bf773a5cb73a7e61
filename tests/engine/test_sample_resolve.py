"""Sub-pixel samples resolved from the shaded pixel centres around them
(``voxgi_addon/preview/resolve.py``; docs/gi_pipeline.md "Anti-aliasing at the cost of a
sample"): a sample takes its surface's light where the centres around it show that light to be
smooth, and is left to be shaded where they cannot (edges of light, slivers, other surfaces)."""
import numpy as np
import pytest

from voxgi.voxgi_addon.preview.resolve import SPREAD, combined_light, resolve_samples

WIDTH, HEIGHT = 12, 10


def floor_centres(material=None, hit=None):
    """Pixel centres on the plane z = 0, centre (row, col) at (col, -row, 0)."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    return {"hit": np.ones((HEIGHT, WIDTH), bool) if hit is None else hit,
            "material": np.zeros((HEIGHT, WIDTH), np.int32) if material is None else material,
            "position": np.dstack([cols, -rows, np.zeros_like(rows)]).astype(np.float64),
            "normal": np.dstack([np.zeros((HEIGHT, WIDTH)), np.zeros((HEIGHT, WIDTH)),
                                 np.ones((HEIGHT, WIDTH))])}


def samples_at(listed, offset, material=0, hit=True, z=0.0):
    """The samples of the ``listed`` pixels at ``offset`` (x right, y down) on the floor (or
    on a plane at height z)."""
    rows, cols = np.divmod(np.asarray(listed), WIDTH)
    count = len(rows)
    return {"hit": np.full(count, hit), "material": np.full(count, material),
            "position": np.stack([cols + offset[0], -(rows + offset[1]), np.full(count, z)], 1),
            "normal": np.tile([0.0, 0.0, 1.0], (count, 1))}


def light_table(slope):
    """(light (H·W,), values (H·W, 2)): light 1 + slope × column, and the row as a second
    value."""
    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    light = (1.0 + slope * cols).ravel()
    return light, np.stack([light, rows.ravel().astype(np.float64)], 1)


def test_a_smooth_light_is_read_at_the_samples_own_place():
    """Light that runs linearly across the surface: each sample gets exactly the light at its
    own place (the bilinear blend of the four centres around it reproduces a linear light),
    not its pixel centre's."""
    light, values = light_table(0.01)
    listed = np.array([3 * WIDTH + 4, 5 * WIDTH + 7, 6 * WIDTH + 2])
    for offset in ((0.375, -0.125), (-0.375, 0.375), (0.125, 0.125)):
        resolved, blended = resolve_samples(floor_centres(), light, values, listed, WIDTH,
                                            HEIGHT, offset, samples_at(listed, offset))
        assert resolved.all()
        rows, cols = np.divmod(listed, WIDTH)
        np.testing.assert_allclose(blended[:, 0], 1.0 + 0.01 * (cols + offset[0]), rtol=1e-5)
        np.testing.assert_allclose(blended[:, 1], rows + offset[1], atol=1e-5)


def test_light_that_spreads_beyond_the_limit_is_shaded():
    """Where the light across the pixel's 3 × 3 centres spreads by more than SPREAD of the
    largest (a shadow's edge, a contact), the sample is left to be shaded."""
    listed = np.array([4 * WIDTH + 5])
    # columns 4-6 read 1 + 4s … 1 + 6s: a spread of 2s / (1 + 6s), just under / over the limit
    gentle, steep = (k * SPREAD / (2.0 - 6.0 * k * SPREAD) for k in (0.9, 1.1))
    for slope, expected in ((gentle, True), (steep, False)):
        light, values = light_table(slope)
        resolved, blended = resolve_samples(floor_centres(), light, values, listed, WIDTH,
                                            HEIGHT, (0.25, 0.25), samples_at(listed, (0.25, 0.25)))
        assert resolved[0] == expected, slope
        if not expected:
            assert not blended.any()


def test_a_sample_on_another_surface_takes_only_that_surfaces_light():
    """A silhouette: the sample sees a surface (another material) that only some centres see.
    It takes theirs, never the light of the centres on the other side."""
    material = np.zeros((HEIGHT, WIDTH), np.int32)
    material[:, 6:] = 1  # the right half is another surface
    light = np.where(material.ravel() == 1, 5.0, 1.0)
    values = np.stack([light, light], 1)
    listed = np.array([4 * WIDTH + 6])  # the right half's first column
    offset = (-0.375, 0.125)  # its sample lies left of its centre, among the left half's
    resolved, blended = resolve_samples(floor_centres(material), light, values, listed, WIDTH,
                                        HEIGHT, offset, samples_at(listed, offset, material=1))
    assert resolved[0]
    np.testing.assert_allclose(blended[0], 5.0)
    # the same place seen as the left half's surface takes the left half's light
    resolved, blended = resolve_samples(floor_centres(material), light, values, listed, WIDTH,
                                        HEIGHT, offset, samples_at(listed, offset, material=0))
    assert resolved[0]
    np.testing.assert_allclose(blended[0], 1.0)


@pytest.mark.parametrize("case", ["sliver", "off the plane", "textured"])
def test_a_surface_too_few_centres_see_is_shaded(case):
    """A sliver only one centre sees (a thin object), or a point off every centre's plane (a
    step in depth): nothing around tells how its light runs, so it is shaded. So is a
    textured surface's sample: its centres' colour is their whole pixel's texture."""
    material = np.zeros((HEIGHT, WIDTH), np.int32)
    centres = floor_centres(material)
    sample = dict(material=0)
    if case == "sliver":
        material[4, 5] = 2
        sample = dict(material=2)
    elif case == "off the plane":
        sample = dict(z=3.0)
    else:
        centres["textured"] = np.ones((HEIGHT, WIDTH), bool)
    light, values = light_table(0.0)
    listed = np.array([4 * WIDTH + 5])
    resolved, _ = resolve_samples(centres, light, values, listed, WIDTH, HEIGHT,
                                  (0.125, 0.125), samples_at(listed, (0.125, 0.125), **sample))
    assert not resolved[0]


def test_the_sky_resolves_from_the_sky_and_a_holdout_only_from_holdouts():
    hit = np.ones((HEIGHT, WIDTH), bool)
    hit[:3] = False  # the top rows see the world
    centres = floor_centres(hit=hit)
    centres["holdout"] = np.zeros((HEIGHT, WIDTH), bool)
    light = np.where(hit.ravel(), 1.0, 0.3)
    values = np.stack([light, light], 1)
    listed = np.array([1 * WIDTH + 4])
    sky = samples_at(listed, (0.0, 0.25), hit=False)
    resolved, blended = resolve_samples(centres, light, values, listed, WIDTH, HEIGHT,
                                        (0.0, 0.25), sky)
    assert resolved[0] and np.isclose(blended[0, 0], 0.3)
    sky["holdout"] = np.array([True])
    resolved, _ = resolve_samples(centres, light, values, listed, WIDTH, HEIGHT, (0.0, 0.25),
                                  sky)
    assert not resolved[0]


def test_combined_light_sums_the_light_passes():
    sums = {"emission": np.array([[1.0, 0.0, 0.0]]), "diffuse_direct": np.array([[0.0, 2.0, 0.0]]),
            "diffuse_indirect": np.array([[0.5, 0.5, 0.5]]),
            "glossy_direct": np.array([[0.0, 0.0, 0.25]]),
            "glossy_indirect": np.array([[0.25, 0.0, 0.0]]),
            "diffuse_color": np.array([[9.0, 9.0, 9.0]]), "coverage": np.array([1.0])}
    assert combined_light(sums)[0] == pytest.approx(5.0)


def test_a_textured_sample_takes_the_centres_light_and_its_own_colours():
    """On a textured surface the centres' colours are their whole pixels' texture: a sample
    there takes only their light (its passes over their colours, ``light_over_colours``) and
    the caller colours it with its own texel (``coloured``), so a checkered floor under smooth
    light resolves to each sample's own colour × the light at its place."""
    from voxgi.voxgi_addon.preview.passes import coloured, light_over_colours, unpack_sums

    rows, cols = np.mgrid[0:HEIGHT, 0:WIDTH]
    irradiance = (1.0 + 0.02 * cols).ravel()[:, None] * np.ones(3)
    texture = np.where(((rows + cols) % 2 == 0).ravel()[:, None], [0.8, 0.2, 0.1],
                       [0.1, 0.3, 0.9])  # each centre's colour: its pixel's texels
    pixels = HEIGHT * WIDTH
    sums = {"emission": np.zeros((pixels, 3)), "coverage": np.ones(pixels),
            "diffuse_color": texture, "ao": np.ones(pixels),
            "glossy_color": np.full((pixels, 3), 0.04),
            "diffuse_direct": texture * irradiance, "diffuse_indirect": 0.5 * texture,
            "glossy_direct": 0.04 * irradiance, "glossy_indirect": np.full((pixels, 3), 0.02),
            "holdout": np.zeros(pixels)}
    table, own, ok = light_over_colours(sums)
    assert ok.all()
    centres = {**floor_centres(), "textured": np.ones((HEIGHT, WIDTH), bool)}
    listed = np.array([3 * WIDTH + 4, 6 * WIDTH + 7])
    offset = (0.375, -0.125)
    sample = {**samples_at(listed, offset), "textured": np.ones(len(listed), bool)}
    plain, _ = resolve_samples(centres, combined_light(sums), table, listed, WIDTH, HEIGHT,
                               offset, {**sample, "textured": np.zeros(len(listed), bool)})
    assert not plain.any()  # without its own colours a textured sample is shaded, as before
    resolved, blended = resolve_samples(centres, combined_light(sums), table, listed, WIDTH,
                                        HEIGHT, offset, sample, light_values=table,
                                        own_light=own, colours_ok=ok)
    assert resolved.all()
    mine = np.array([[0.5, 0.6, 0.7], [0.2, 0.2, 0.2]])  # the samples' own texels
    values = unpack_sums(coloured(blended, mine, np.full((2, 3), 0.04), np.zeros((2, 3))))
    light = 1.0 + 0.02 * (divmod(listed, WIDTH)[1] + offset[0])
    np.testing.assert_allclose(values["diffuse_direct"], mine * light[:, None], rtol=1e-5)
    np.testing.assert_allclose(values["diffuse_indirect"], 0.5 * mine, rtol=1e-5)
    np.testing.assert_allclose(values["diffuse_color"], mine)
    np.testing.assert_allclose(values["glossy_direct"], 0.04 * light[:, None] * np.ones(3),
                               rtol=1e-5)
    # a centre whose colour has a black channel cannot give its light back: none stands in
    dark = dict(sums, diffuse_color=texture * [1.0, 1.0, 0.0])
    table, own, ok = light_over_colours(dark)
    assert not ok.any()
    resolved, _ = resolve_samples(centres, combined_light(dark), table, listed, WIDTH, HEIGHT,
                                  offset, sample, light_values=table, own_light=own,
                                  colours_ok=ok)
    assert not resolved.any()
