"""The progressive viewport's numpy parts (voxgi_addon/preview/progressive.py): tile cameras
see exactly the image's pixels, tiles cover the image once, samples share the one-shot
image's rays and pixel filter, the accumulation averages them and the slice sizer fits a
budget."""
from __future__ import annotations

import numpy as np
import pytest

from voxgi.voxgi_addon.preview.gather import GatherSettings
from voxgi.voxgi_addon.preview.passes import PASS_NAMES
from voxgi.voxgi_addon.preview.progressive import (
    GATHER_SAMPLES,
    Accumulation,
    SliceSizer,
    sample_offset,
    sample_settings,
    tile_camera,
    tile_grid,
    tile_shape,
)
from voxgi.voxgi_addon.scene.camera import camera_rays, filter_offsets
from voxgi.voxgi_addon.scene.view_camera import camera_from_view


def view_camera(kind, width=40, height=30, shift=0.0):
    view = np.eye(4)
    view[:3, 3] = (0.2, -0.1, -3.0)
    window = np.zeros((4, 4))
    if kind == "PERSP":
        window[0] = (1.8, 0.0, shift, 0.0)
        window[1] = (0.0, 1.8 * width / height, 0.0, 0.0)
        window[2] = (0.0, 0.0, -1.002, -0.2002)
        window[3] = (0.0, 0.0, -1.0, 0.0)
    else:
        window[0] = (0.5, 0.0, 0.0, shift)
        window[1] = (0.0, 0.5 * width / height, 0.0, 0.0)
        window[2] = (0.0, 0.0, -0.02, -1.0)
        window[3] = (0.0, 0.0, 0.0, 1.0)
    return camera_from_view(view, window, width, height)


@pytest.mark.parametrize("kind,shift", [("PERSP", 0.0), ("PERSP", 0.3), ("ORTHO", -0.2)])
def test_a_tile_camera_sees_exactly_the_images_pixels(kind, shift):
    camera = view_camera(kind, shift=shift)
    offset = (0.3, -0.2)
    origins, directions = camera_rays(camera, offset=offset)
    origins, directions = origins.reshape(30, 40, 3), directions.reshape(30, 40, 3)
    x0, y0, w, h = 8, 5, 16, 12
    tile = tile_camera(camera, x0, y0, w, h, offset=offset)
    assert tile.resolution == (w, h)
    o, d = camera_rays(tile)
    assert np.allclose(o.reshape(h, w, 3), origins[y0:y0 + h, x0:x0 + w], atol=1e-9)
    assert np.allclose(d.reshape(h, w, 3), directions[y0:y0 + h, x0:x0 + w], atol=1e-9)
    # a tile reaching past the image continues its pixels
    o, d = camera_rays(tile_camera(camera, -4, 20, 16, 12, offset=offset))
    assert np.allclose(d.reshape(12, 16, 3)[:10, 4:], directions[20:, :12], atol=1e-9)
    with pytest.raises(ValueError, match="does not meet"):
        tile_camera(camera, 40, 0, 16, 12)


@pytest.mark.parametrize("shift", [(0, 0), (5, 3), (16, 24), (31, 1)])
def test_the_tiles_cover_every_pixel_once_and_have_one_size(shift):
    from voxgi.voxgi_addon.preview.progressive import inside

    tiles = tile_grid(70, 45, 16, 24, shift)
    cover = np.zeros((45, 70), int)
    for rect in tiles:
        assert rect[2:] == (16, 24)
        window, part = inside(rect, 70, 45)
        cover[window] += 1
        assert np.ones((24, 16))[part].shape == cover[window].shape
    assert (cover == 1).all()


@pytest.mark.parametrize("shift", [(0, 0), (5, 3), (48, 40), (31, 1)])
def test_trimmed_tiles_cover_every_pixel_once_and_trace_little_past_the_image(shift):
    """A 160 × 120 view in 56 × 48 tiles (the viewport's kind: multiples of 8 that are no
    power of two): the border tiles trace their pixels inside the image and at most 15 more
    per side (the least side, 24, at most), not a whole tile past it."""
    from voxgi.voxgi_addon.preview.progressive import fit_side, inside

    tiles = tile_grid(160, 120, 56, 48, shift, trim=lambda n: fit_side(n, 8, 1))
    cover = np.zeros((120, 160), int)
    for rect in tiles:
        window, part = inside(rect, 160, 120)
        cover[window] += 1
        w, h = rect[2:]
        assert w % 8 == 0 and h % 8 == 0 and w & (w - 1) and h & (h - 1), rect
        # (the least such side is 24)
        assert 0 < cover[window].shape[1] <= w < max(24, cover[window].shape[1]) + 16, rect
        assert 0 < cover[window].shape[0] <= h < max(24, cover[window].shape[0]) + 16, rect
    assert (cover == 1).all()
    untrimmed = tile_grid(160, 120, 56, 48, shift)
    assert sum(w * h for *_, w, h in tiles) < sum(w * h for *_, w, h in untrimmed)


def test_tile_shapes_hold_whole_work_groups_of_one_texture_kind():
    def power_of_two(n):
        return n & (n - 1) == 0

    for pixels in (100, 2000, 4096, 9000, 30000):
        w, h = tile_shape(pixels, 320, 180, 16, 2)
        assert w % 16 == 0 and h % 16 == 0
        assert not any(power_of_two(n) for n in (w, h, w // 2, h // 2)), (w, h)
        assert 0.6 * max(pixels, 48 * 48) <= w * h <= 1.3 * max(pixels, 48 * 48)  # about
    assert tile_shape(10 ** 6, 320, 180, 16, 2) == (320, 180)  # the whole image fits
    assert tile_shape(1, 320, 180, 16, 2) == (48, 48)  # the smallest: 3 groups (16, 32: 2ⁿ)
    assert tile_shape(40000, 320, 180, 16, 2) == (192, 192)  # one row of tiles: 180 px high


def test_the_samples_share_the_one_shot_images_rays():
    gather = GatherSettings(rays=64, glossy_rays=8, seed=3)
    parts = [sample_settings(gather, 16, 16, k) for k in range(16)]
    assert sum(p[0].rays for p in parts) == 64
    assert sum(p[0].glossy_rays for p in parts) >= 8
    # the gathering samples carry the one-shot image's light samples between them, and
    # every sample traces as many (the samples are averaged alike)
    assert [p[1] for p in parts] == [16 // GATHER_SAMPLES] * 16
    assert len({p[0].seed for p in parts}) == 16 and parts[0][0].seed == 3
    assert sample_settings(gather, 16, 1, 0) == (gather, 16)
    # the gathers end early: the first GATHER_SAMPLES carry all their rays, the rest none
    assert [p[0].rays for p in parts] == [16] * GATHER_SAMPLES + [0] * (16 - GATHER_SAMPLES)
    assert all(p[0].glossy_rays == 0 for p in parts[GATHER_SAMPLES:])
    assert [sample_settings(gather, 16, 16, k, gathering=16)[0].rays for k in (0, 15)] == [4, 4]
    assert [sample_settings(gather, 16, 2, k)[0].rays for k in (0, 1)] == [32, 32]
    with pytest.raises(ValueError, match="at least 1"):
        sample_settings(gather, 16, 0, 0)
    with pytest.raises(ValueError, match="outside"):
        sample_settings(gather, 16, 4, 4)


def test_the_samples_offsets_are_the_pixel_filters_strata_each_once():
    offsets = np.array([sample_offset(1.5, 16, k) for k in range(16)])
    strata = filter_offsets(1.5, 4)
    assert sorted(map(tuple, offsets)) == sorted(map(tuple, strata))
    # the first sample is a stratum nearest the pixel centre; the next ones spread out
    assert np.hypot(*offsets[0]) == pytest.approx(np.hypot(*strata.T).min())
    assert np.hypot(*(offsets[1] - offsets[0])) > 0.3
    assert sample_offset(0.0, 16, 5) == (0.0, 0.0)


def passes_of(value, colour, shape=(2, 3)):
    out = {name: np.zeros((*shape, 3)) for name in PASS_NAMES}
    out["Combined"] = np.full((*shape, 3), value)
    out["Diffuse Indirect"] = np.full((*shape, 3), value)
    out["Diffuse Color"] = np.full((*shape, 3), colour)
    return out


def test_the_accumulation_averages_samples_as_cyclesfilm_does():
    acc = Accumulation("Combined", 4, 2)
    acc.add((0, 0, 3, 2), passes_of(1.0, 0.5))
    acc.add((0, 0, 3, 2), passes_of(3.0, 0.5))
    assert acc.samples == 0  # column 3 has none yet
    estimate = acc.estimate(coarse=np.full((1, 2, 3), 7.0))
    assert np.allclose(estimate[:, :3], 2.0) and np.allclose(estimate[:, 3], 7.0)
    acc.add((3, 0, 1, 2), passes_of(5.0, 0.5, (2, 1)))
    assert acc.samples == 1 and np.allclose(acc.estimate()[:, 3], 5.0)

    # a light pass is Σ light × colour over Σ colour (a sample that saw no colour adds none)
    light = Accumulation("Diffuse Indirect", 3, 2)
    light.add((0, 0, 3, 2), passes_of(1.0, 1.0))
    light.add((0, 0, 3, 2), passes_of(4.0, 0.0))
    assert np.allclose(light.mean(), 1.0)
    with pytest.raises(ValueError, match="unknown pass"):
        Accumulation("Beauty", 2, 2)
    with pytest.raises(ValueError, match="tile"):
        acc.add((0, 0, 2, 2), passes_of(1.0, 1.0))


def test_the_finished_image_gets_the_filters_tails_as_the_one_shot_image():
    from voxgi.voxgi_addon.preview.passes import filter_passes

    rng = np.random.default_rng(1)
    acc = Accumulation("Combined", 6, 5)
    images = [rng.uniform(0, 1, (5, 6, 3)) for _ in range(3)]
    for image in images:
        sample = {name: image for name in PASS_NAMES}
        acc.add((0, 0, 6, 5), sample)
    mean = np.mean(images, axis=0)
    expected = filter_passes({name: mean for name in PASS_NAMES}, 1.5)["Combined"]
    assert np.allclose(acc.finished(1.5), expected, atol=1e-6)
    assert not np.allclose(acc.finished(1.5), mean, atol=1e-3)


def test_the_slice_sizer_fits_the_budget_from_measured_slices():
    sizer = SliceSizer(0.030, first_pixels=4096, least=256)
    assert sizer.pixels(10 ** 6) == 4096  # nothing measured yet
    sizer.measured(4096, 0.010 + 2e-6 * 4096)
    assert sizer.model() is None and sizer.pixels(10 ** 6) == 8192  # one size: try another
    for pixels in (1000, 8000, 2000):
        sizer.measured(pixels, 0.010 + 2e-6 * pixels)  # 10 ms per slice + 2 µs per pixel
    fixed, per_pixel = sizer.model()
    assert fixed == pytest.approx(0.010) and per_pixel == pytest.approx(2e-6)
    assert sizer.pixels(10 ** 6) == pytest.approx(10_000, abs=2)
    # slices of several sizes keep the fit fresh: no call asks another size (a bigger one ran
    # the draw past its budget)
    assert [sizer.pixels(10 ** 6) for _ in range(8)] == [pytest.approx(10_000, abs=2)] * 8
    # the recent slices all of one size: every 4th call asks half the fit, within the budget
    alike = SliceSizer(0.030, least=256)
    alike.fitted = (0.010, 2e-6)
    for _ in range(20):
        alike.measured(10_000, 0.030)
    assert [alike.pixels(10 ** 6) for _ in range(4)] == [pytest.approx(n, abs=2) for n in
                                                          (10_000, 10_000, 10_000, 5000)]
    # the smallest tile holds every slice: exploring asks for more than the last slice
    stuck = SliceSizer(0.030, least=256)
    stuck.fitted = (0.0, 1e-3)
    for _ in range(20):
        stuck.measured(2304, 0.1)
    assert [stuck.pixels(10 ** 6) for _ in range(4)] == [256, 256, 256, 4608]
    assert tile_shape(4608, 320, 180, 16, 2) != tile_shape(2304, 320, 180, 16, 2)
    assert sizer.pixels(5000) == 5000  # never more than the image
    sizer.measured(2000, 17.0)  # a slice that waited 17 s for a kernel compile
    fixed, per_pixel = sizer.model()
    assert fixed == pytest.approx(0.010, abs=0.002) and per_pixel == pytest.approx(2e-6, rel=0.1)
    # the fixed cost alone is over the budget: slices at least as long again (half tracing)
    slow = SliceSizer(0.030, least=256)
    for pixels in (1000, 3000):
        slow.measured(pixels, 0.040 + 1e-5 * pixels)
    assert slow.pixels(10 ** 6) == pytest.approx(4000, abs=2)
    slower = SliceSizer(0.030, least=256)
    for pixels in (300, 600):
        slower.measured(pixels, 1e-6 + 1e-3 * pixels)
    assert slower.pixels(10 ** 6) == 256
    with pytest.raises(ValueError, match="budget"):
        SliceSizer(0.0)


def test_a_slice_the_view_waits_for_is_never_a_size_to_explore():
    """The coarse first image asks with explore=False: the fitted size every time (an
    exploring call asked twice it, and a coarse image of half the view took 40% longer)."""
    sizer = SliceSizer(0.030, first_pixels=4096, least=256)
    assert sizer.pixels(10 ** 6, explore=False) == 4096
    sizer.measured(4096, 0.010 + 2e-6 * 4096)
    assert sizer.pixels(10 ** 6, explore=False) == 4096  # no fit yet: not twice the last
    for pixels in (1000, 8000, 2000):
        sizer.measured(pixels, 0.010 + 2e-6 * pixels)
    asked = [sizer.pixels(10 ** 6, explore=False) for _ in range(8)]
    assert asked == [pytest.approx(10_000, abs=2)] * 8
    # once the recent slices are of one size, the exploring calls still explore every 4th
    # time, whatever was asked between them
    for _ in range(48):
        sizer.measured(10_000, 0.030)
    assert [sizer.pixels(10 ** 6, explore=False) for _ in range(8)] == \
        [pytest.approx(10_000, abs=2)] * 8
    assert [sizer.pixels(10 ** 6) for _ in range(4)][-1] == pytest.approx(5000, abs=2)


def test_the_slice_sizer_fits_the_budget_with_the_slices_tail_not_their_median():
    """Slices that scatter around the model (another process, the worker's Python) are
    sized so that nine in ten stay within the budget, not half of them."""
    steady, scattered = SliceSizer(0.015, least=256), SliceSizer(0.015, least=256)
    rng = np.random.default_rng(3)
    for k in range(48):
        pixels = (4000, 6000, 8000)[k % 3]
        steady.measured(pixels, 1e-6 * pixels)
        # a fifth of the slices run 1.5-2 times as long as the others of their size
        scattered.measured(pixels, 1e-6 * pixels * (rng.uniform(1.5, 2.0) if k % 5 == 0
                                                      else rng.uniform(0.95, 1.05)))
    assert steady.tail() == pytest.approx(1.0)
    assert steady.pixels(10 ** 6) == pytest.approx(15_000, abs=2)
    assert 1.4 < scattered.tail() < 2.0
    pixels = scattered.pixels(10 ** 6)
    assert pixels < 11_000
    # about nine in ten of the slices measured (43 of the 48), scaled to that size, within
    # the budget
    fixed, per_pixel = scattered.model()
    ratios = np.array([t / (fixed + per_pixel * p) for p, t in scattered.samples])
    assert np.sum(ratios * (fixed + per_pixel * pixels) <= 0.015) >= 43
    # a slice that waited once (a kernel's build: 17 s) is no scatter: it shrinks no slice
    steady.measured(6000, 17.0)
    assert steady.tail() == pytest.approx(1.0)
    # nor do the first few slices, whose quantile is their longest
    few = SliceSizer(0.015, least=256)
    for pixels, seconds in ((4000, 0.008), (8000, 0.008), (6000, 0.024)):
        few.measured(pixels, seconds)
    assert few.tail() == 1.0
    for pixels, seconds in few.samples * 2:  # the same again: now the quantile is taken
        few.measured(pixels, seconds)
    assert few.tail() > 1.5


def test_a_burst_of_slow_slices_shrinks_the_next_at_once():
    """Another process's burst slows every slice twofold: after two such slices in a row the
    next is sized for the slower machine (not once the tail of 48 has moved), one slow slice
    alone shrinks nothing, and a slice at the usual pace ends it."""
    sizer = SliceSizer(0.015, least=256)
    for k in range(48):
        pixels = (4000, 6000, 8000)[k % 3]
        sizer.measured(pixels, 1e-6 * pixels)
    usual = sizer.pixels(10 ** 6, explore=False)
    sizer.measured(6000, 2e-6 * 6000)
    assert sizer.pixels(10 ** 6, explore=False) == usual  # one slow slice: a one-off
    sizer.measured(8000, 2e-6 * 8000)
    burst = sizer.pixels(10 ** 6, explore=False)
    assert burst == pytest.approx(usual / 2, rel=0.05)
    sizer.measured(4000, 1e-6 * 4000)  # the burst is over
    assert sizer.pixels(10 ** 6, explore=False) == usual


def test_the_gathers_are_accumulated_per_cell_of_the_images_grid():
    from voxgi.voxgi_addon.preview.progressive import LUMINANCE, GatherSums

    sums = GatherSums(20, 10, 2)  # 10 × 5 cells
    rng = np.random.default_rng(4)
    first_v, first_var = rng.uniform(0, 1, (3, 4, 4)), rng.uniform(0, 0.1, (3, 4, 4))
    second_v, second_var = rng.uniform(0, 1, (3, 4, 4)), rng.uniform(0, 0.1, (3, 4, 4))
    # .z: −each point's reach (the harmonic mean of its rays' hit distances); 0: none
    first_var[..., 2], second_var[..., 2] = -rng.uniform(0.1, 2, (3, 4)), -rng.uniform(0.1, 2, (3, 4))
    second_var[0, 0, 2] = 0.0  # its 4 rays all missed
    sums.add("diffuse", (4, 2, 8, 6), first_v, first_var, rays=4)
    mean, var = sums.add("diffuse", (4, 2, 8, 6), second_v, second_var, rays=4)
    assert np.allclose(mean, (first_v + second_v) / 2, atol=1e-6)
    pooled = (first_var + second_var) / 4  # of the mean of two
    assert np.allclose(var[..., [0, 1, 3]], pooled[..., [0, 1, 3]], atol=1e-6)
    # the view's filter bounds no tap by the points' reach (F12's does): none handed on
    assert np.array_equal(var[..., 2], np.zeros((3, 4)))
    # a smaller tile inside it: its cells (x 4–5, y 1) get a third sample
    third = rng.uniform(0, 1, (1, 2, 4))
    mean, _ = sums.add("diffuse", (8, 2, 4, 2), third, second_var[:1, :2], rays=4)
    assert np.allclose(mean, (first_v[:1, 2:] + second_v[:1, 2:] + third) / 3, atol=1e-6)
    # one ray per sample: the kernel's variance is 0, the samples' spread is used
    a, b = np.zeros((1, 1, 4)), np.zeros((1, 1, 4))
    a[..., :3], b[..., :3] = 1.0, 3.0
    sums.add("glossy", (0, 0, 2, 2), a, np.zeros((1, 1, 4)), rays=1)
    _, var = sums.add("glossy", (0, 0, 2, 2), b, np.zeros((1, 1, 4)), rays=1)
    lum = np.array([1.0, 3.0]) * LUMINANCE.sum()
    assert var[0, 0, 0] == pytest.approx(np.var(lum, ddof=1) / 2)
    with pytest.raises(ValueError, match="stride-2 block"):
        sums.add("diffuse", (3, 0, 4, 4), first_v[:2, :2], first_var[:2, :2], rays=4)
    with pytest.raises(ValueError, match="cells"):
        sums.add("diffuse", (0, 0, 4, 4), first_v, first_var, rays=4)


def test_gathered_light_is_weighted_by_the_samples_behind_the_gathers():
    acc = Accumulation("Combined", 3, 2)
    first, second = passes_of(2.0, 1.0), passes_of(4.0, 1.0)  # gathered light 2 and 4
    first["Combined"] += 1.0  # 1 of direct light besides
    second["Combined"] += 1.0
    acc.add((0, 0, 3, 2), first, gather_weight=1.0)
    acc.add((0, 0, 3, 2), second, gather_weight=3.0)
    # direct light: the plain mean (1); gathered: (1 × 2 + 3 × 4) / 4
    assert np.allclose(acc.mean(), 1.0 + 14.0 / 4.0)
    ao = Accumulation("Ambient Occlusion", 3, 2)
    for value, weight in ((0.2, 1.0), (0.6, 3.0)):
        sample = passes_of(0.0, 1.0)
        sample["Ambient Occlusion"] = np.full((2, 3, 3), value)
        ao.add((0, 0, 3, 2), sample, gather_weight=weight)
    assert np.allclose(ao.mean(), (0.2 + 1.8) / 4.0)


def test_refreshing_the_estimate_where_a_tile_landed_equals_a_new_estimate():
    """A tile changes its pixels and, by its samples' tails, the pixels around it: the
    image refreshed over the tile's reach equals a new estimate."""
    from voxgi.voxgi_addon.preview.progressive import sample_tail_weights

    rng = np.random.default_rng(7)
    acc = Accumulation("Combined", 10, 8, film=True)

    def sample(h, w):
        out = {name: rng.uniform(0, 1, (h, w, 3)) for name in PASS_NAMES}
        out["Alpha"] = rng.uniform(0, 1, (h, w))
        return out

    acc.add((0, 0, 10, 8), sample(8, 10), tails=sample_tail_weights(1.5, 4, 0))
    image = acc.estimate_rgba()
    for k, rect in enumerate(((-2, 3, 6, 6), (6, -1, 6, 6), (3, 2, 4, 3))):  # two past the image
        acc.add(rect, sample(rect[3], rect[2]), gather_weight=2.0,
                tails=sample_tail_weights(1.5, 4, k + 1))
        acc.estimate_into(image, rect)
    assert np.allclose(image, acc.estimate_rgba(), atol=1e-6)


def test_the_first_sample_is_shown_filtered_as_the_finished_image():
    """What the view shows after any sample is Cycles' pixel filter over the samples so far
    (each pixel's own and its neighbours' by the filter at their offsets), not each pixel's
    own samples alone: after one sample of a sharp edge, the pixels beside it already carry
    the filter's share of the other side, as the finished image does."""
    from voxgi.voxgi_addon.preview.progressive import sample_offset, sample_tail_weights

    samples, size = 16, 1.5
    for k in range(samples):
        acc = Accumulation("Diffuse Direct", 6, 3)
        passes = {name: np.zeros((3, 6, 3)) for name in PASS_NAMES}
        passes["Diffuse Color"][:] = 1.0
        passes["Diffuse Direct"][:, 3:] = 1.0  # lit right of the edge between columns 2 and 3
        acc.add((0, 0, 6, 3), passes, tails=sample_tail_weights(size, samples, k))
        shown = acc.estimate()
        assert np.allclose(shown, acc.finished(size))
        # the filter (2 × 1.5 px wide) reaches one pixel across the border from any offset
        assert 0.0 < shown[1, 2, 0] < 0.5 < shown[1, 3, 0] < 1.0, (k, sample_offset(size, samples, k))
        assert shown[1, 0, 0] == 0.0 and shown[1, 5, 0] == 1.0  # two pixels away: untouched


def test_samples_count_in_the_neighbours_by_the_filter_at_their_own_offsets():
    """The viewport's samples, each a whole image at one sub-pixel offset, add into the
    neighbours by the filter there (``sample_tail_weights``), as F12's sub-pixel passes do:
    light on the near half of the left neighbour only gives the centre pixel the filter's
    integral over that half (0.112 at Filter Size 1.5), and an even light stays even."""
    from voxgi.voxgi_addon.preview.progressive import sample_offset, sample_tail_weights
    from voxgi.voxgi_addon.scene.camera import blackman_harris

    samples, size = 16, 1.5
    acc, even = Accumulation("Diffuse Direct", 3, 3), Accumulation("Diffuse Direct", 3, 3)
    for k in range(samples):
        ox, _ = sample_offset(size, samples, k)
        passes = {name: np.zeros((3, 3, 3)) for name in PASS_NAMES}
        passes["Diffuse Color"][:] = 1.0
        passes["Diffuse Direct"][:, 0] = 1.0 if ox > 0.0 else 0.0
        weights = sample_tail_weights(size, samples, k)
        acc.add((0, 0, 3, 3), passes, tails=weights)
        passes["Diffuse Direct"][:] = 2.0
        even.add((0, 0, 3, 3), passes, tails=weights)
    x = np.linspace(-1.5, 1.5, 30001)
    f = blackman_harris(x, 1.5)
    truth = f[(x > -1.0) & (x <= -0.5)].sum() / f.sum()
    assert acc.finished(size)[1, 1, 0] == pytest.approx(truth, rel=0.02)
    assert np.allclose(even.finished(size), 2.0, rtol=1e-5)


def test_a_staged_sizer_keeps_the_least_tile_where_the_fixed_cost_is_over_the_budget():
    """Whole slices grow past the budget where their fixed cost alone is over it (overhead
    amortized); staged slices are sized by their longest stage, which a bigger tile only
    makes longer: they keep the smallest tile."""
    from voxgi.voxgi_addon.preview.progressive import SliceSizer

    whole, staged = SliceSizer(0.015, least=2304), SliceSizer(0.015, least=2304,
                                                                 amortize=False)
    for sizer in (whole, staged):  # 20 ms fixed + 2 µs per pixel, two sizes
        for pixels in (2304, 4608, 2304, 4608):
            sizer.measured(pixels, 0.020 + 2e-6 * pixels)
        sizer.explore = 0
    assert whole.pixels(10**6) == 10000  # fixed / per pixel: half of it tracing
    assert staged.pixels(10**6) == 2304


def test_a_lattice_sample_adds_its_cells_and_leaves_holes_the_next_sample_fills():
    """The view's first sample gathers at the lattice of the grid (odd row and column from a
    tile's top-left, clamped to its last row and column: F12's sparse plan's first list): only
    those cells are added; the others are holes (variance's third channel 1, mean 0) until a
    sample reaches them."""
    from voxgi.voxgi_addon.preview.progressive import GatherSums, lattice_cells
    from voxgi.voxgi_addon.preview.upsample import sample_pixels

    assert lattice_cells(5, 4).astype(int).tolist() == [
        [0, 0, 0, 0], [0, 1, 0, 1], [0, 0, 0, 0], [0, 1, 0, 1], [0, 1, 0, 1]]
    for h, w in ((1, 1), (6, 7), (9, 2)):  # the pixels a stride-2 grid traces, read as cells
        rows, cols = sample_pixels(h, w, 2)
        expected = np.zeros((h, w), bool)
        expected[rows[:, None], cols[None, :]] = True
        assert np.array_equal(lattice_cells(h, w), expected)

    sums = GatherSums(6, 5, 1)  # tile (0, 0, 6, 5): a lattice of 3 × 3
    rng = np.random.default_rng(2)
    lattice_v, lattice_var = rng.uniform(0.5, 1, (3, 3, 4)), rng.uniform(0, 0.1, (3, 3, 4))
    lattice_var[..., 2:] = 0.0
    mean, var = sums.add("diffuse", (0, 0, 6, 5), lattice_v, lattice_var, rays=8, lattice=True)
    on = lattice_cells(5, 6)
    assert np.allclose(mean[on], lattice_v.reshape(-1, 4)) and np.all(mean[~on] == 0.0)
    assert np.all(var[~on][:, 2] == 1.0) and np.all(var[on][:, 2] == 0.0)
    assert np.array_equal(sums.kinds["diffuse"]["n"], on.astype(float))
    dense_v, dense_var = rng.uniform(0, 1, (5, 6, 4)), np.zeros((5, 6, 4))
    mean, var = sums.add("diffuse", (0, 0, 6, 5), dense_v, dense_var, rays=8)
    assert np.all(var[..., 2] == 0.0)  # no holes left
    assert np.allclose(mean[~on], dense_v[~on])
    assert np.allclose(mean[on], (dense_v[on] + lattice_v.reshape(-1, 4)) / 2)
    with pytest.raises(ValueError, match="3×3 cells"):
        sums.add("diffuse", (0, 0, 6, 5), dense_v, dense_var, rays=8, lattice=True)
