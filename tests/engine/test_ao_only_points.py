"""Gather points on surfaces that show no diffuse light (a full metal, a black surface) trace
AO only (``preview.sparse_gather.ray_counts``, ``gather_counts``; ``passes.shows_diffuse``):
the Diffuse Indirect pass and Combined take the gathered light × Diffuse Color, so there the
gather's rays would be spent on light no pass shows."""
from __future__ import annotations

import numpy as np

from voxgi.voxgi_addon.preview.gather import GatherSettings
from voxgi.voxgi_addon.preview.passes import shows_diffuse
from voxgi.voxgi_addon.preview.sparse_gather import AO_RAYS, gather_counts, ray_counts
from voxgi.voxgi_addon.scene.snapshot import MaterialData


class _Snapshot:
    def __init__(self, materials):
        self.materials = materials


def test_metals_and_black_surfaces_show_no_diffuse_light():
    grey = MaterialData("grey", np.array([0.8, 0.8, 0.8], np.float32))
    gold = MaterialData("gold", np.array([1.0, 0.8, 0.3], np.float32), metallic=1.0)
    half = MaterialData("half", np.array([1.0, 0.8, 0.3], np.float32), metallic=0.5)
    black = MaterialData("black", np.zeros(3, np.float32))
    shown = shows_diffuse(_Snapshot([grey, gold, half, black]))
    # the last slot is "no material", drawn as Blender's default grey
    assert shown.tolist() == [True, False, True, False, True]


def test_points_without_diffuse_light_draw_the_ao_rays():
    cells = np.array([[True, True, False], [True, True, True]])
    diffuse = np.array([[True, False, False], [False, True, True]])
    counts = ray_counts(cells, diffuse, 96)
    assert counts.tolist() == [[96, AO_RAYS, 0], [AO_RAYS, 96, 96]]
    assert ray_counts(cells, diffuse, 4).max() == 4  # never more than the gather's rays


def test_each_count_is_one_trace_and_the_full_count_draws_the_gathers_own_rays():
    """A cell with every ray is traced with the settings it would have without AO-only cells
    (same rays, same seed: the same samples), the AO-only cells with AO_RAYS."""
    counts = np.array([[96, AO_RAYS, 0], [AO_RAYS, 96, 96]])
    calls = []

    def trace(cells, settings):
        calls.append((cells.copy(), settings))
        n = int(cells.sum())
        return np.full((n, 4), float(settings.rays)), np.full((n, 2), 1.0 / settings.rays)

    values = np.zeros((2, 3, 4))
    variance = np.zeros((2, 3, 2))
    settings = GatherSettings(rays=96, seed=5, sparse=True)
    gather_counts(counts, values, variance, settings, trace)
    assert len(calls) == 2
    full = [s for c, s in calls if s.rays == 96][0]
    assert full == settings
    assert [s.seed for _, s in calls] == [5, 5]
    np.testing.assert_array_equal(values[..., 0], counts)
    assert values[0, 2].sum() == 0.0  # not a listed cell: untouched
