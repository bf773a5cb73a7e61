"""Spikes traced again (``preview.sparse_gather.spikes``, ``retrace_spikes``; docs/gi_pipeline.md
"Spikes traced again"): a sparse-gather cell far brighter than every traced cell near it — one
ray that found a small, very bright patch — is traced again with more rays and both estimates
merge by their rays, so the filter's hole fill does not spread a lone ray's light into a
blotch. The price, measured here: where rare rays carry much of the light, it reads lower."""
from __future__ import annotations

import numpy as np

from voxgi.voxgi_addon.preview.gather import GatherSettings
from voxgi.voxgi_addon.preview.sparse_gather import SPIKE, SPIKE_RAYS, gather_lists, retrace_spikes, spikes


def _lattice(shape):
    rows, cols = np.indices(shape)
    return (rows % 2 == 1) & (cols % 2 == 1)


def _grey(level):
    return np.stack([level, level, level, np.ones_like(level)], axis=-1)


def test_a_lone_bright_cell_is_a_spike_and_a_gradient_or_an_island_is_not():
    traced = _lattice((9, 9))
    level = np.where(traced, 0.2, 0.0)
    level[3, 3] = 0.2 * SPIKE * 1.5  # a spike
    expected = np.zeros((9, 9), bool)
    expected[3, 3] = True
    np.testing.assert_array_equal(spikes(traced, _grey(level)), expected)
    # a smooth ramp: no cell is SPIKE × its brightest neighbour
    ramp = np.where(traced, np.linspace(0.1, 2.0, 9)[None, :].repeat(9, 0), 0.0)
    assert not spikes(traced, _grey(ramp)).any()
    # a cell with no traced cell within two cells of it has nothing to be compared with
    alone = np.zeros((9, 9), bool)
    alone[4, 4] = True
    assert not spikes(alone, _grey(np.where(alone, 5.0, 0.0))).any()


def test_a_spike_is_traced_again_with_more_rays_and_merged_by_its_rays():
    traced = _lattice((7, 7))
    values = _grey(np.where(traced, 0.25, 0.0)).astype(np.float32)
    values[3, 3, :3] = 9.0
    variance = np.zeros((7, 7, 4), np.float32)
    variance[traced, :2] = 0.01
    variance[3, 3, :2] = 4.0
    variance[..., 2] = 7.0  # a flag the merge leaves alone
    calls = []

    def trace(cells, settings):
        calls.append((cells.copy(), settings))
        n = int(cells.sum())
        return np.full((n, 4), 0.5), np.full((n, 4), 0.02)

    settings = GatherSettings(rays=96, seed=3, sparse=True)
    again = retrace_spikes(traced, values, variance, settings, trace)
    assert again.sum() == 1 and again[3, 3]
    (cells, more), = calls
    assert cells.sum() == 1 and cells[3, 3]
    assert more.rays == SPIKE_RAYS * 96 and more.seed == 4  # new samples, more of them
    share = 1.0 / (1 + SPIKE_RAYS)
    np.testing.assert_allclose(values[3, 3, :3], share * 9.0 + (1 - share) * 0.5, rtol=1e-6)
    np.testing.assert_allclose(variance[3, 3, :2], share ** 2 * 4.0 + (1 - share) ** 2 * 0.02,
                               rtol=1e-6)
    assert variance[3, 3, 2] == 7.0
    others = traced & ~again
    assert (values[others, :3] == 0.25).all()  # the others untouched


def test_no_spike_no_trace():
    traced = _lattice((7, 7))
    values = _grey(np.where(traced, 0.25, 0.0))
    variance = np.zeros((7, 7, 2))

    def trace(cells, settings):
        raise AssertionError("nothing to trace again")

    assert not retrace_spikes(traced, values, variance, GatherSettings(rays=8), trace).any()


def test_rare_bright_rays_lose_their_spikes_and_part_of_their_light(monkeypatch):
    """Each ray finds a patch 500 times the background with probability 1/2000 (the lit slot
    over a ceiling panel, seen from the wall below it), so a fifth of the light rides on rare
    rays. With the second look the cells brighter than SPIKE × the background are fewer than
    half as many; the mean light, unbiased without it, reads lower by a tenth of it at most
    (all of the loss falls on the rare rays' fifth)."""
    import voxgi.voxgi_addon.preview.sparse_gather as sparse_gather

    shape = (60, 80)
    valid = np.ones(shape, bool)
    traced = _lattice(shape)
    background, patch, p = 0.2, 100.0, 1.0 / 2000.0
    expected = background + p * patch

    def gathered(seed):
        rng = np.random.default_rng(seed)

        def trace(cells, settings):
            n = int(cells.sum())
            hits = rng.binomial(settings.rays, p, n)
            mean = background + patch * hits / settings.rays
            var_mean = patch ** 2 * p * (1 - p) / settings.rays
            return (np.stack([mean, mean, mean, np.ones(n)], axis=1),
                    np.stack([np.full(n, var_mean), np.zeros(n)], axis=1))

        values = np.zeros(shape + (4,))
        variance = np.zeros(shape + (2,))
        out = gather_lists(traced, valid, valid, values, variance,
                           GatherSettings(rays=96, sparse=True), trace)
        light = values[out][:, 0]
        return light.mean(), np.count_nonzero(light > SPIKE * background)

    second = [gathered(seed) for seed in range(8)]
    monkeypatch.setattr(sparse_gather, "SPIKE", np.inf)  # no cell is a spike
    plain = [gathered(seed) for seed in range(8)]
    noise = np.sqrt(patch ** 2 * p / 96 / traced.sum() / 8)  # of the mean over cells and seeds
    plain_mean, second_mean = np.mean([m for m, _ in plain]), np.mean([m for m, _ in second])
    assert abs(plain_mean - expected) < 4 * noise
    assert 0.9 * expected < second_mean < expected
    assert sum(c for _, c in second) < 0.5 * sum(c for _, c in plain)
