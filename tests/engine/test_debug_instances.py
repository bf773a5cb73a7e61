"""The debug views' instance order (voxgi_addon/preview/debug_instances.py ``spread``): the
views draw a slice of instances per draw, so every prefix of the order must cover all of them
— not the one corner a voxel order's prefix is."""
from __future__ import annotations

import numpy as np
import pytest

from voxgi.voxgi_addon.preview.debug_instances import Instances, spread


def test_every_prefix_of_the_spread_order_covers_the_whole_set():
    # a 40³ block of voxels in x-major order, as cells come out of the voxelizer
    cells = np.stack(np.meshgrid(*[np.arange(40)] * 3, indexing="ij"), -1).reshape(-1, 3)
    colours = cells / 40.0
    instances = Instances(cells + 0.5, 1.0, colours)
    ordered = spread(instances)
    assert len(ordered) == len(instances)
    # the same instances, each with its own size and colour
    key = np.lexsort(ordered.centres.T)
    assert np.array_equal(ordered.centres[key], instances.centres[np.lexsort(instances.centres.T)])
    assert np.allclose(ordered.colours, (ordered.centres - 0.5) / 40.0)
    for share in (0.01, 0.1):
        k = int(share * len(instances))
        first, plain = ordered.centres[:k], instances.centres[:k]
        # every eighth of the block gets about its share of the prefix
        octants = np.bincount(((first >= 20).astype(int) * (1, 2, 4)).sum(1), minlength=8)
        assert octants.min() > 0.8 * k / 8, (share, octants)
        assert np.ptp(plain[:, 0]) < 0.15 * 40  # the plain order: one slab only
    # fixed: the same order every time (the layer's slices stay the same cubes)
    assert np.array_equal(spread(instances).centres, ordered.centres)


def test_spread_of_nothing_is_nothing():
    empty = spread(Instances(np.zeros((0, 3)), 1.0, np.zeros((0, 3))))
    assert len(empty) == 0


@pytest.mark.parametrize("n", [1, 7])
def test_spread_keeps_small_sets(n):
    instances = Instances(np.arange(3 * n).reshape(n, 3), np.arange(1, n + 1), np.zeros((n, 3)))
    ordered = spread(instances)
    assert sorted(ordered.size.tolist()) == sorted(instances.size.tolist())
