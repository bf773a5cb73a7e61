"""Cycles' pixel filter over the neighbours (``preview.passes.filter_passes``): each pixel's own
sub-pixel passes sample the filter inside its square (``camera.filter_samples``, a weighted
grid; the viewport's samples ``camera.filter_offsets``, drawn by importance), and the
filter's tails bring in the neighbours' squares — light passes divided as Cycles' film divides
them, Σ light × colour over Σ colour, so a pixel with no colour of its own beside a coloured
surface takes that surface's light (no dark outline where a diffuse wall meets metal)."""
import numpy as np
import pytest

from voxgi.voxgi_addon.preview.passes import (
    PASS_NAMES,
    filter_passes,
    light_edge_pixels,
    neighbour_weights,
)
from voxgi.voxgi_addon.scene.camera import blackman_harris, filter_offsets, filter_samples


def passes_of(light, colour, combined=None):
    """PASS_NAMES images of a diffuse scene: Diffuse Direct = light where colour > 0."""
    height, width = colour.shape[:2]
    out = {name: np.zeros((height, width, 3)) for name in PASS_NAMES}
    out["Diffuse Color"] = colour
    out["Diffuse Direct"] = np.where(colour > 0.0, light, 0.0)
    out["Combined"] = colour * light if combined is None else combined
    return out


def wall_beside_metal(wall_columns=4, width=8, height=3, light=2.0, colour=0.7):
    """A diffuse wall (colour, light) in the left columns, a metal (no diffuse colour) the
    rest."""
    c = np.zeros((height, width, 3))
    c[:, :wall_columns] = colour
    return np.full((height, width, 3), light), c


def test_a_pixel_beside_a_wall_takes_the_walls_light_as_cycles_does():
    light, colour = wall_beside_metal()
    out = filter_passes(passes_of(light, colour), 1.5)["Diffuse Direct"]
    assert np.allclose(out[:, :4], 2.0)          # the wall itself: unchanged
    assert np.allclose(out[:, 4], 2.0)           # its neighbour: the wall is in its footprint
    assert np.all(out[:, 5:] == 0.0)             # beyond the filter's reach: no light


def test_point_sampling_keeps_pixels_to_themselves():
    light, colour = wall_beside_metal()
    for size in (0.0, 0.5):
        passes = passes_of(light, colour)
        assert all(np.array_equal(filter_passes(passes, size)[k], passes[k]) for k in passes)


def test_a_sliver_in_a_neighbour_does_not_spread():
    """A neighbour holding only a sliver of the wall (a tenth of the wall's colour) may have it
    on its far side, outside the pixel's footprint: a pixel with no colour borrows nothing."""
    light, colour = wall_beside_metal()
    colour[:, 4] = 0.07
    out = filter_passes(passes_of(light, colour), 1.5)["Diffuse Direct"]
    assert np.allclose(out[:, 4], 2.0)
    assert np.all(out[:, 5] == 0.0)


def test_a_light_edge_is_blended_by_the_filters_share_of_each_neighbour():
    """One surface, light 1 on the left half and 0 on the right: the pixels beside the edge get
    the neighbours' light by the filter's share of their squares (0.155 : 1 : 0.155 across at
    Filter Size 1.5) — Cycles' filtered image, not the pixel-centre samples."""
    width = 8
    light = np.zeros((5, width, 3))
    light[:, :4] = 1.0
    colour = np.full((5, width, 3), 0.5)
    out = filter_passes(passes_of(light, colour), 1.5)
    side = neighbour_weights(1.5)[1, 0]
    expected = side / (1.0 + 2.0 * side)
    assert out["Diffuse Direct"][2, 4] == pytest.approx(expected, rel=1e-5)
    assert out["Diffuse Direct"][2, 3] == pytest.approx(1.0 - expected, rel=1e-5)
    assert out["Combined"][2, 4] == pytest.approx(0.5 * expected, rel=1e-5)
    assert np.allclose(out["Diffuse Direct"][:, [0, 1, 6, 7], 0], [[1, 1, 0, 0]] * 5, atol=1e-6)


def test_a_background_pixel_beside_an_object_is_partly_covered():
    """As Cycles' film: the background next to an object gets a share of its colour and
    Combined, and its light (the pass ratio), while pixels two away stay black."""
    light, colour = wall_beside_metal()
    out = filter_passes(passes_of(light, colour), 1.5)
    assert 0.0 < out["Diffuse Color"][1, 4, 0] < 0.2 * 0.7
    assert out["Diffuse Direct"][1, 4, 0] == pytest.approx(2.0)
    assert np.all(out["Combined"][:, 5:] == 0.0)


@pytest.mark.parametrize("size", [1.0, 1.5, 3.0])
def test_the_neighbours_share_is_the_filters(size):
    weights = neighbour_weights(size)
    assert weights[1, 1] == 1.0
    assert np.allclose(weights, weights.T) and np.allclose(weights, weights[::-1, ::-1])
    assert 0.0 < weights[1, 0] < 1.0 and np.isclose(weights[0, 0], weights[1, 0] ** 2)
    if size == 1.5:  # 11.9% of Cycles' 1.5 px Blackman-Harris beyond half a pixel on each side
        assert weights[1, 0] == pytest.approx(0.1555, abs=2e-3)


@pytest.mark.parametrize("size", [0.3, 1.5, 3.0])
def test_the_sub_pixel_offsets_sample_the_filter_inside_the_pixel(size):
    """The 4 × 4 offsets stay in the pixel's square (within the filter's reach), stratified by
    the filter: their mean weight over the square equals the filter's mean there."""
    offsets = filter_offsets(size, 4)
    along = np.unique(offsets[:, 0])
    assert len(along) == 4 and np.abs(offsets).max() < min(0.5, size)
    assert np.allclose(along, -along[::-1])
    x = np.linspace(-min(0.5, size), min(0.5, size), 2001)
    f = blackman_harris(x, size)
    cdf = np.cumsum(f) / f.sum()
    assert np.allclose(np.interp(along, x, cdf), (np.arange(4) + 0.5) / 4, atol=2e-3)


@pytest.mark.parametrize("size", [0.3, 0.5, 0.75, 1.5, 3.0])
def test_the_sub_pixel_samples_weigh_the_filter_inside_the_pixel(size):
    """The one-shot image's 4 × 4 samples lie on a grid of equal cells of the pixel's square
    (so one raster four times finer draws them all), each weighted by the filter's mass over
    its cell: their weighted mean of anything smooth is the filter's mean over the square as
    closely as the importance-drawn offsets', and a straight edge anywhere across the pixel is
    covered within a column's share of Cycles' coverage and within 1.3 × the drawn offsets'
    worst. A filter narrower than Cycles' default keeps the drawn offsets."""
    offsets, weights = filter_samples(size, 4)
    reach = min(size, 0.5)
    if size < 1.5:  # narrow: the grid's central columns hold most of it; drawn, equal weights
        assert np.allclose(offsets, filter_offsets(size, 4)) and (weights == 1.0).all()
    else:
        along = (np.arange(4) + 0.5) / 4 - 0.5
        assert np.allclose(np.unique(offsets[:, 0]), along)
        assert np.allclose(np.unique(offsets[:, 1]), along)
    assert weights.mean() == pytest.approx(1.0) and (weights > 0.0).all()
    assert np.allclose(weights.reshape(4, 4), weights.reshape(4, 4).T)  # symmetric
    drawn = filter_offsets(size, 4)  # the same filter drawn by importance, equal weights
    x = np.linspace(-reach, reach, 4001)
    f = blackman_harris(x, size)
    for g in (lambda t: t * t, lambda t: np.cos(2.0 * t), lambda t: t + 0.3):
        truth = (f * g(x)).sum() / f.sum()
        got = np.sum(weights * g(offsets[:, 0])) / weights.sum()
        assert abs(got - truth) <= max(abs(g(drawn[:, 0]).mean() - truth), 0.003) * 1.5 + 1e-9
    # a vertical edge at e: Cycles' coverage of x < e over the square against the samples',
    # at most a column of samples' share off, and about as close as the drawn offsets come
    worst = drawn_worst = 0.0
    for e in np.linspace(-reach, reach, 41):
        truth = f[x < e].sum() / f.sum()
        worst = max(worst, abs(np.sum(weights * (offsets[:, 0] < e)) / weights.sum() - truth))
        drawn_worst = max(drawn_worst, abs(np.mean(drawn[:, 0] < e) - truth))
    assert worst <= max(weights.reshape(4, 4)[1].sum() / 16, 0.25) + 1e-9
    assert worst <= 1.3 * drawn_worst
    centre, ones = filter_samples(0.0, 4)
    assert not centre.any() and (ones == 1.0).all()


def _sub_pixel_film(lit, width=3, height=3, size=1.5):
    """Diffuse Direct of the centre pixel of a ``width`` × ``height`` diffuse surface (colour 1
    everywhere) whose samples are lit where ``lit(column, row, ox, oy)``, every pixel drawn
    by the 16 sub-pixel passes: (with each sample's own filter weight in the neighbours, with
    the neighbours' means)."""
    from voxgi.voxgi_addon.preview.passes import (
        SUMS,
        add_tails,
        dense_tails,
        finish_passes,
        new_sums,
        pass_tail_weights,
        pass_weights,
        subpixel_passes,
    )
    plan = subpixel_passes(size, 16)
    sums, tails = new_sums(width * height), new_sums(width * height)
    pixels = np.arange(width * height)
    for ((ox, oy), _), weights, weight in zip(plan, pass_tail_weights(plan, size),
                                              pass_weights(plan, size)):
        one = new_sums(width * height)
        one["diffuse_color"][:] = 1.0
        one["coverage"][:] = 1.0
        row, column = np.divmod(pixels, width)
        one["diffuse_direct"][lit(column, row, ox, oy)] = 1.0
        for name in SUMS:  # as the previews sum them: each pass by its weight
            sums[name] += weight * one[name]
        add_tails(tails, {name: weight * one[name] / len(plan) for name in SUMS}, pixels,
                  weights, width, height)
    exact = finish_passes(sums, len(plan), width, height, size, dense_tails(tails))["Diffuse Direct"]
    means = finish_passes(sums, len(plan), width, height, size)["Diffuse Direct"]
    return exact[height // 2, width // 2, 0], means[height // 2, width // 2, 0]


def test_a_neighbours_samples_count_by_the_filter_at_their_own_place():
    """Light on the near half of the left neighbour only (a 1-pixel slot beside a lit edge):
    Cycles' pixel takes ∫ of its filter over that half over the whole window (0.112 at Filter
    Size 1.5); the neighbour's mean × its share gives half the neighbour's share (0.059) —
    the samples' own weights give Cycles' value."""
    exact, means = _sub_pixel_film(lambda column, row, ox, oy: (column == 0) & (ox > 0.0))
    x = np.linspace(-1.5, 1.5, 30001)
    f = blackman_harris(x, 1.5)
    truth = f[(x > -1.0) & (x <= -0.5)].sum() / f.sum()
    assert exact == pytest.approx(truth, rel=0.02)
    assert abs(means - truth) > 0.4 * truth


def test_sample_weights_keep_an_evenly_lit_surface_even():
    exact, _ = _sub_pixel_film(lambda column, row, ox, oy: np.ones_like(column, bool))
    assert exact == pytest.approx(1.0, rel=1e-6)


def test_passes_summed_before_one_scatter_give_the_tails_of_a_scatter_per_pass():
    """The sub-pixel passes' tails are linear in their samples: summing the passes' weighted
    samples and scattering once (``stacked_tails`` over ``pack_sums``, what the previews do)
    gives the tails of one scatter per pass (``add_tails``), pixels at the border
    included."""
    from voxgi.voxgi_addon.preview.passes import (
        SUMS,
        add_tails,
        new_sums,
        pack_sums,
        pass_tail_weights,
        stacked_tails,
        subpixel_passes,
        unpack_sums,
    )
    rng = np.random.default_rng(3)
    width, height = 13, 7
    listed = np.sort(rng.choice(width * height, 40, replace=False))
    listed[0] = 0  # a corner: its neighbours beyond the image are dropped
    plan = subpixel_passes(1.5, 16)
    weights = pass_tail_weights(plan, 1.5)
    per_pass, samples = new_sums(width * height), []
    for row in weights:
        values = {name: rng.random((len(listed),) + per_pass[name].shape[1:]) for name in SUMS}
        add_tails(per_pass, values, listed, row, width, height)
        samples.append(pack_sums(values))
    at, packed = stacked_tails(np.stack(samples), weights, listed, width, height)
    assert np.all(np.diff(at) > 0)
    once = unpack_sums(packed)
    reached = np.zeros(width * height, bool)
    reached[at] = True
    for name in SUMS:
        assert np.any(once[name] != 0.0)
        np.testing.assert_allclose(once[name], per_pass[name][at], rtol=1e-12, atol=1e-12)
        # nothing reaches a pixel left out
        assert not np.any(per_pass[name][~reached])


def test_sub_pixel_passes_go_to_a_shadows_edge_not_to_a_dim_highlights_tail():
    """The light edges that get sub-pixel passes (``light_edge_pixels``): a lamp's shadow edge
    across a lit floor and a bright highlight's peak, but not the dim tail of a glossy
    highlight over a metal, which falls by a third each pixel (more than a pass's share of
    its own light) yet stays far below the image's light: there the filter over the pixel
    centres is within a hair of Cycles' filter over the light itself."""
    height, width = 9, 48
    light = np.ones((height, width))  # a lit floor...
    light[:, 10:20] = 0.0  # ...whose lamp is shadowed from column 10

    def tail(x):  # a highlight's tail, falling by a third each pixel from 0.03
        return 0.03 * (2.0 / 3.0) ** (np.asarray(x, np.float64) - 20.0)

    light[:, 20:40] = tail(np.arange(20, 40))
    light[:, 40:43] = (0.6, 1.6, 0.6)  # a highlight's bright peak
    edges = light_edge_pixels(light, np.ones((height, width), bool), 1, 16)
    assert edges[:, 9:11].all()  # both sides of the shadow's edge
    assert edges[:, 40:43].all()
    bend = np.abs(light[:, 21:38] + light[:, 23:40] - 2.0 * light[:, 22:39])
    assert (bend * 16 > light[:, 21:38]).all()  # more than a pass's share of its own light
    assert not edges[:, 22:38].any()
    # what the passes would give there: Cycles' filter over the tail's light itself (the
    # window spans 3 pixels at Filter Size 1.5), against the filter over the centres alone
    # (filter_passes): within 1% of the floor's light
    u = np.linspace(-1.5, 1.5, 3001)
    window = blackman_harris(u, 1.5)
    x = np.arange(22, 38)
    exact = np.array([(tail(c + u) * window).sum() / window.sum() for c in x])
    centres = filter_passes(passes_of(light[..., None].repeat(3, -1),
                                      np.full((height, width, 3), 0.5)), 1.5)["Diffuse Direct"]
    assert np.abs(exact - centres[4, x, 0]).max() < 0.01
