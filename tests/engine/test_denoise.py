"""The edge-aware à-trous filter: removes noise, keeps edges of geometry and real light edges."""
import numpy as np

from voxgi.voxgi_addon.preview.denoise import atrous_filter


def _floor_and_wall(h=48, w=64):
    """A G-buffer: left half a floor (normal +z), right half a wall (normal -x), 1 cm pixels."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    position = np.stack([xs * 0.01, ys * 0.01, np.zeros_like(xs)], axis=-1)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    wall = xs >= w // 2
    normal[wall] = (-1.0, 0.0, 0.0)
    position[wall, 0] = (w // 2) * 0.01
    position[wall, 2] = (xs[wall] - w // 2) * 0.01
    return position, normal, wall


def _noisy(clean, sigma, seed=1, ao=0.8):
    """Light (grey noise of deviation sigma) plus a constant AO channel with variance 0."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, sigma, clean.shape[:2])[..., None]
    values = np.concatenate([clean + noise * np.ones(3), np.full(clean.shape[:2] + (1,), ao)], -1)
    variance = np.stack([np.full(clean.shape[:2], sigma**2), np.zeros(clean.shape[:2])], -1)
    return values, variance


def test_noise_on_a_plane_is_averaged_away():
    position, normal, wall = _floor_and_wall()
    clean = np.full(wall.shape + (3,), 0.5)
    noisy, variance = _noisy(clean, 0.1)
    valid = np.ones(wall.shape, bool)
    out, out_var = atrous_filter(noisy, variance, valid, position, normal)
    before = np.abs(noisy[..., :3] - clean).mean()
    after = np.abs(out[..., :3] - clean).mean()
    assert after < before / 4
    assert out_var[..., 0].mean() < variance[..., 0].mean() / 10
    assert np.allclose(out[..., 3], 0.8)


def test_light_does_not_cross_from_floor_to_wall():
    position, normal, wall = _floor_and_wall()
    clean = np.where(wall[..., None], 1.0, 0.1) * np.ones(3)
    noisy, variance = _noisy(clean, 0.02)
    out, _ = atrous_filter(noisy, variance, np.ones(wall.shape, bool), position, normal)
    # The column next to the crease keeps its own side's level.
    c = wall.shape[1] // 2
    assert abs(out[:, c - 1, 0].mean() - 0.1) < 0.02
    assert abs(out[:, c, 0].mean() - 1.0) < 0.05


def test_a_light_edge_far_above_the_noise_survives_on_one_plane():
    position, normal, wall = _floor_and_wall()
    normal[...] = (0.0, 0.0, 1.0)
    position[..., 2] = 0.0
    xs = np.arange(wall.shape[1])
    position[..., 0] = xs * 0.01
    clean = np.where(xs[None, :, None] < 20, 0.05, 0.8) * np.ones((wall.shape[0], 1, 3))
    noisy, variance = _noisy(clean, 0.02)
    out, _ = atrous_filter(noisy, variance, np.ones(wall.shape, bool), position, normal)
    # A plain blur of this size would smear the 0.75 step over ~16 pixels.
    assert abs(out[:, 17, 0].mean() - 0.05) < 0.03
    assert abs(out[:, 22, 0].mean() - 0.8) < 0.05


def test_ao_edges_are_kept_apart_from_the_light():
    """AO has its own similarity test: a contact-shadow step in AO survives where the light is
    flat, and noise in the light does not leak into AO."""
    position, normal, wall = _floor_and_wall()
    normal[...] = (0.0, 0.0, 1.0)
    position[..., 2] = 0.0
    position[..., 0] = np.arange(wall.shape[1]) * 0.01
    values, variance = _noisy(np.full(wall.shape + (3,), 0.5), 0.05)
    values[:, :20, 3] = 0.3
    variance[..., 1] = 0.01**2
    out, _ = atrous_filter(values, variance, np.ones(wall.shape, bool), position, normal)
    assert abs(out[:, 17, 3].mean() - 0.3) < 0.03 and abs(out[:, 22, 3].mean() - 0.8) < 0.03


def test_a_noisy_bright_slot_stays_behind_its_occlusion_edge():
    """A slot between a ceiling and a panel under it: its light is bright and noisy (few rays
    find the lit gap), its AO low and quiet; the open ceiling beside it dim and quiet, its AO
    high. The light's own test lets the slot's noise through (the step is within 4 σ of the
    slot's noise), the AO's test does not: the open ceiling keeps its level up to the edge."""
    position, normal, wall = _floor_and_wall()
    normal[...] = (0.0, 0.0, 1.0)
    position[..., 2] = 0.0
    position[..., 0] = np.arange(wall.shape[1]) * 0.01
    slot = np.arange(wall.shape[1]) < 8
    rng = np.random.default_rng(5)
    shape = wall.shape
    light = np.where(slot, 3.0 + rng.normal(0.0, 1.0, shape), 0.5 + rng.normal(0.0, 0.05, shape))
    ao = np.where(slot, 0.1, 0.9) + rng.normal(0.0, 0.02, shape)
    values = np.concatenate([np.repeat(light[..., None], 3, -1), ao[..., None]], -1)
    variance = np.stack([np.broadcast_to(np.where(slot, 1.0, 0.05**2), shape),
                         np.full(shape, 0.02**2)], -1)
    out, _ = atrous_filter(values, variance, np.ones(shape, bool), position, normal)
    beside = out[:, 8:12, 0].mean()  # the open ceiling's first four columns
    # (with the light's own test alone they read 0.87, 74% over)
    assert abs(beside / 0.5 - 1.0) < 0.05, beside
    assert abs(out[:, :6, 0].mean() / 3.0 - 1.0) < 0.1  # the slot keeps its own level


def test_background_pixels_are_untouched_and_never_read():
    position, normal, wall = _floor_and_wall()
    values = np.full(wall.shape + (4,), 0.3)
    valid = np.ones(wall.shape, bool)
    valid[:, :10] = False
    values[:, :10] = 1e6  # would dominate any average that read it
    out, _ = atrous_filter(values, np.full(wall.shape + (2,), 0.01), valid, position, normal)
    assert np.all(out[:, :10] == 1e6)
    assert np.allclose(out[:, 10:], 0.3, atol=1e-5)


def test_light_sloping_into_a_corner_keeps_its_level_at_the_corner():
    """Light that falls linearly towards the corner where a floor meets a wall (a darkening
    into a corner): at the floor's last columns the taps lie on one side only, and their mean
    is the light a few cells away — brighter. The filter's local linear fit keeps the level
    closer there (the band under the box's ceiling was this bias)."""
    position, normal, wall = _floor_and_wall()
    xs = np.mgrid[0:wall.shape[0], 0:wall.shape[1]][1].astype(np.float64)
    level = np.where(wall, 0.4, 0.1 + 0.02 * (wall.shape[1] // 2 - 1 - xs))  # 0.1 at the corner
    clean = np.repeat(level[..., None], 3, axis=-1)
    noisy, variance = _noisy(clean, 0.05, seed=4)
    out, _ = atrous_filter(noisy, variance, np.ones(wall.shape, bool), position, normal)
    corner = wall.shape[1] // 2 - 1  # the floor's column beside the wall
    # (the weighted mean read +34%, +21%, +11% on the last three columns)
    for column, limit in ((corner, 0.25), (corner - 1, 0.15), (corner - 2, 0.09)):
        got = out[:, column, :3].mean()
        assert abs(got / clean[:, column, 0].mean() - 1.0) < limit, (column, got)
    # and the noise is still averaged away along the slope
    assert np.abs(out[..., :3] - clean)[~wall].mean() < np.abs(noisy[..., :3] - clean)[~wall].mean() / 3


def test_unseen_points_lend_their_ao_but_not_their_light():
    """A floor whose right half is metal: its points drew AO only, so their light (the same
    level, 0.5) is the noise of a few rays, shown by no pass. Flagged unseen, it does not reach
    the diffuse half's light beside it, while both halves' AO mixes along the one plane
    (``atrous_filter(unseen=…)``)."""
    position, normal, _ = _floor_and_wall()
    normal[...] = (0.0, 0.0, 1.0)  # one floor
    position[..., 2] = 0.0
    position[..., 0] = np.arange(64)[None, :] * 0.01
    metal = np.zeros((48, 64), bool)
    metal[:, 32:] = True
    values, variance = _noisy(np.full((48, 64, 3), 0.5), 0.01)
    rng = np.random.default_rng(3)
    few_rays = rng.exponential(0.5, metal.sum())  # a few rays' light: mean 0.5, skewed
    values[metal, :3] = few_rays[:, None]
    variance[metal, 0] = 0.25 / 8
    values[..., 3] = 0.7 + rng.normal(0.0, 0.05, metal.shape)
    variance[..., 1] = 0.05 ** 2
    valid = np.ones(metal.shape, bool)
    out, _ = atrous_filter(values, variance, valid, position, normal, unseen=metal)
    leaky, _ = atrous_filter(values, variance, valid, position, normal)
    edge, leaky_edge = out[:, 29:32, 0], leaky[:, 29:32, 0]
    assert abs(edge.mean() - 0.5) < 0.01, edge.mean()
    assert np.abs(edge - 0.5).mean() < 0.5 * np.abs(leaky_edge - 0.5).mean()
    np.testing.assert_array_equal(out[..., 3], leaky[..., 3])  # the AO is filtered as before
    assert np.abs(out[..., 3] - 0.7).mean() < 0.3 * np.abs(values[..., 3] - 0.7).mean()


def test_a_spike_is_spread_over_its_surface_and_leaves_no_lattice():
    """One cell whose rays found a lamp's highlight (10 against 0.1 ± 0.01): the filter alone
    leaves its light on a lattice of its steps — the cells an even number of cells away read
    far above the odd ones — while spread first (``spread_spikes``) it keeps the light and
    fades smoothly."""
    from voxgi.voxgi_addon.preview.denoise import spread_spikes

    position, normal, _ = _floor_and_wall(41, 41)
    normal[...] = (0.0, 0.0, 1.0)
    position[..., 2] = 0.0
    position[..., 0] = np.arange(41)[None, :] * 0.01
    values, variance = _noisy(np.full((41, 41, 3), 0.1), 0.01)
    values[20, 20, :3] = 10.0
    variance[20, 20, 0] = 100.0 / 8
    valid = np.ones((41, 41), bool)
    spread, spread_var = spread_spikes(values, variance, valid, position, normal)
    assert abs(spread[..., :3].sum() - values[..., :3].sum()) < 1e-6 * values[..., :3].sum()
    assert spread[20, 20, 0] < 5.0
    np.testing.assert_array_equal(spread[..., 3], values[..., 3])  # the AO is not moved

    def lattice(image):  # the row through the spike: even offsets against odd ones
        row = image[20, 12:29, 0]
        return row[0::2].mean() - row[1::2].mean()

    plain, _ = atrous_filter(values, variance, valid, position, normal, fit=False,
                             sigma_luminance=2.0)
    smooth, _ = atrous_filter(spread, spread_var, valid, position, normal, fit=False,
                              sigma_luminance=2.0)
    assert lattice(plain) > 0.1
    assert abs(lattice(smooth)) < 0.25 * lattice(plain)


def _banded_ceiling(h=24, w=40, band_row=11, seed=7):
    """A plane (2 cm cells) with a band one cell tall lit 10× the rest (the ceiling behind a
    panel's edge, lit by the slot over it), traced as the sparse gather traces it: the lattice
    of odd rows and odd columns, the band and the row beside it whole (their cells fail the
    same-surface test or are noisy), the rest holes. Returns (values, variance, holes, position,
    normal, band)."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    position = np.stack([xs * 0.02, ys * 0.02, np.zeros_like(xs)], axis=-1)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    band = ys == band_row
    rng = np.random.default_rng(seed)
    light = np.where(band, 3.0, 0.3) * (1.0 + rng.normal(0.0, 0.05, (h, w)))
    values = np.concatenate([np.repeat(light[..., None], 3, -1), np.full((h, w, 1), 0.8)], -1)
    variance = np.stack([(0.05 * np.where(band, 3.0, 0.3)) ** 2, np.full((h, w), 1e-4)], -1)
    traced = ((ys % 2 == 1) & (xs % 2 == 1)) | band | (ys == band_row - 1)
    holes = ~traced
    values[holes] = 0.0
    variance[holes] = 0.0
    return values, variance, holes, position, normal, band


def test_holes_beside_a_lit_band_take_their_own_surroundings_light():
    """The first pass fills a hole from the traced cells of its 9 × 9 window, compared with
    its traced neighbours' light: holes two rows from a band lit 10× keep the level around
    them (filled by geometry alone they read 0.59-0.87 against 0.3: a dotted line over the
    band, seen over a ceiling panel's edge), and the band keeps its own."""
    values, variance, holes, position, normal, band = _banded_ceiling()
    ok = np.ones(holes.shape, bool)
    out, _ = atrous_filter(values, variance, ok, position, normal, holes=holes)
    near = np.zeros(holes.shape, bool)
    near[8:10] = True  # two and three rows above the band
    print(out[near & holes, 0].min(), out[near & holes, 0].max())
    assert np.abs(out[near, 0] / 0.3 - 1.0).max() < 0.1
    assert abs(out[band, 0].mean() / 3.0 - 1.0) < 0.05
    assert not np.any(out[ok, 0] <= 0.0)  # every hole filled


def test_holes_in_noiseless_sloping_light_are_filled_along_the_slope():
    """Traced cells whose rays all agree (variance 0) on light that slopes: each hole's taps
    differ from its guide by the slope, not by noise, and the spread of its neighbours lets
    them in — every hole is filled, at the slope's level (compared by the noise alone, a
    tap's weight was 0 and the holes stayed black)."""
    h, w = 24, 40
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    position = np.stack([xs * 0.02, ys * 0.02, np.zeros_like(xs)], axis=-1)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    light = 0.5 + 0.02 * xs
    holes = ~((ys % 2 == 1) & (xs % 2 == 1))
    values = np.concatenate([np.repeat(light[..., None], 3, -1), np.full((h, w, 1), 0.8)], -1)
    values[holes] = 0.0
    variance = np.zeros((h, w, 2))
    out, _ = atrous_filter(values, variance, np.ones((h, w), bool), position, normal,
                           holes=holes)
    inner = holes & (ys > 1) & (ys < h - 2) & (xs > 1) & (xs < w - 2)
    assert np.abs(out[inner, 0] / light[inner] - 1.0).max() < 0.01


def test_light_bending_into_a_crease_keeps_its_level_within_the_points_reach():
    """Light that bends steeply into the crease of a floor and a wall (its last centimetres
    darken, as beside a contact): the plane fit through taps up to eight cells away cannot
    follow the bend, and reads the crease's cells too bright. Each point's reach (the harmonic
    mean of its rays' hit distances, short beside the wall) keeps their taps near them, and the
    open floor, whose reach is long, is filtered as before."""
    position, normal, wall = _floor_and_wall()
    xs = np.mgrid[0:wall.shape[0], 0:wall.shape[1]][1].astype(np.float64)
    gap = (wall.shape[1] // 2 - xs) * 0.01  # metres from the floor's pixel to the wall
    level = np.where(wall, 0.4, 0.1 + 0.3 * (1.0 - np.exp(-gap / 0.03)))
    clean = np.repeat(level[..., None], 3, axis=-1)
    noisy, variance = _noisy(clean, 0.03, seed=5)
    valid = np.ones(wall.shape, bool)
    reach = np.where(wall, 1.0, 2.0 * gap + 0.01)  # as a ray's hits beside a wall: ∝ the gap
    plain, _ = atrous_filter(noisy, variance, valid, position, normal)
    reached, _ = atrous_filter(noisy, variance, valid, position, normal, reach=reach)
    crease = slice(wall.shape[1] // 2 - 4, wall.shape[1] // 2)  # the floor's last 4 columns

    def off(image):
        return np.abs(image[:, crease, :3].mean(axis=(0, 2)) / clean[:, crease, 0].mean(axis=0) - 1)

    assert off(reached).max() < 0.6 * off(plain).max(), (off(reached), off(plain))
    # the open floor, 20+ cells from the wall, is as smooth as without the reach
    open_floor = gap >= 0.2
    assert np.abs(reached[..., :3] - clean)[open_floor].mean() < \
        1.3 * np.abs(plain[..., :3] - clean)[open_floor].mean()
    assert np.abs(reached[..., :3] - clean)[open_floor].mean() < \
        np.abs(noisy[..., :3] - clean)[open_floor].mean() / 3
    # no reach anywhere (a scene whose rays all miss): the filter as without it
    none, _ = atrous_filter(noisy, variance, valid, position, normal, reach=np.zeros(wall.shape))
    assert np.array_equal(none, plain)
