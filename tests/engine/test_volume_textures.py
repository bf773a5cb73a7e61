"""The octree atlas the GPU tracer samples (voxgi_addon.volume_textures, trace_params).

``sample_atlas`` is the shader's fetch written in numpy (clamped texel coordinates, trilinear
with clamp-to-edge); on every level and block it must give the octree's own node-centred
samples, absent nodes and points outside the level's window included.
"""
import math

import numpy as np
import pytest
from test_svo import random_scene

from voxgi.voxgi_addon.gi import svo_sampling
from voxgi.voxgi_addon.gi.conetrace import ConeSettings, diffuse_cone_set
from voxgi.voxgi_addon.gi.svo import build_octree
from voxgi.voxgi_addon.preview.trace_params import (
    ROW_CASCADES,
    ROW_CONES,
    ROW_LEVELS,
    ROW_ROOT,
    ROW_SHAPE,
    ROW_SLABS,
    trace_params,
)
from voxgi.voxgi_addon.preview.volume_textures import ISOTROPIC_BLOCK, sample_atlas, volume_atlas


@pytest.fixture(scope="module")
def octree():
    cascades, radiance = random_scene(seed=7, res=16, n=3, fill=0.08)
    return build_octree(cascades, radiance, dense_depth=3, one_sided_leaves=True)


def _points_near_nodes(octree, level, rng, n=3000):
    size = octree.node_size(level)
    lv = octree.levels[level]
    columns = np.flatnonzero(lv.table[3, :-1] > 0)
    pick = columns[rng.integers(0, len(columns), n)]
    if lv.kind == "dense":
        s = 1 << level
        nodes = np.stack(np.unravel_index(pick, (s, s, s)), axis=1)
    else:
        from voxgi.voxgi_addon.gi.morton import morton_decode
        nodes = morton_decode(lv.keys[pick])
    # Up to two nodes away: corners outside the window and absent neighbours are sampled too.
    return octree.root_origin + (nodes + rng.uniform(-2.0, 3.0, (n, 3))) * size


def test_atlas_blocks_sample_like_the_octree(octree):
    atlas = volume_atlas(octree)
    rng = np.random.default_rng(3)
    for level in range(octree.depth + 1):
        points = _points_near_nodes(octree, level, rng)
        node_size = octree.node_size(level)
        lv = octree.levels[level]
        expected = svo_sampling.trilinear(lv, points, octree.root_origin, node_size).T
        got = sample_atlas(atlas, level, points, octree.root_origin, octree.root_size,
                           ISOTROPIC_BLOCK)
        np.testing.assert_allclose(got, expected, atol=1e-5)
        for face in range(6):
            axis, side = divmod(face, 2)
            dirs = np.zeros((len(points), 3))
            dirs[:, axis] = 1.0 if side else -1.0  # a cone along -axis reads face 2·axis
            expected = svo_sampling.trilinear_directional(lv, points, dirs, octree.root_origin,
                                                          node_size, extinction=False).T
            got = sample_atlas(atlas, level, points, octree.root_origin, octree.root_size, face)
            np.testing.assert_allclose(got, expected, atol=1e-5)


def test_atlas_size_and_windows(octree):
    atlas = volume_atlas(octree)
    sizes = [w.size for w in atlas.windows]
    assert sizes[:4] == [1, 2, 4, 8]
    pad = max(sizes) + 2
    assert atlas.texture_size == (7 * pad, pad, sum(s + 2 for s in sizes))
    assert [w.z0 for w in atlas.windows] == list(np.cumsum([0] + [s + 2 for s in sizes[:-1]]))
    assert atlas.gpu_bytes == 8 * 7 * pad * pad * sum(s + 2 for s in sizes)


def test_trace_params_rows(octree):
    cones = ConeSettings(cone_angle=25.0, diffuse_cones=9)
    atlas = volume_atlas(octree)
    table = trace_params(octree, atlas, cones)
    np.testing.assert_allclose(table[ROW_ROOT], [*octree.root_origin, octree.root_size], rtol=1e-6)
    assert table[ROW_SHAPE][:3].tolist() == [octree.depth, octree.resolution, 3]
    for w in atlas.windows:
        assert table[ROW_LEVELS + w.level].tolist() == [*w.origin, w.size]
        assert table[ROW_SLABS + w.level][0] == w.z0
    assert table[ROW_CASCADES:ROW_CASCADES + 3, 0].tolist() == list(octree.cascade_levels)
    dirs, weights = diffuse_cone_set(9, math.radians(25.0))
    np.testing.assert_allclose(table[ROW_CONES:ROW_CONES + 9, :3], dirs, atol=1e-7)
    np.testing.assert_allclose(table[ROW_CONES:ROW_CONES + 9, 3], weights, atol=1e-7)
    with pytest.raises(ValueError, match="diffuse cones"):
        trace_params(octree, atlas, ConeSettings(diffuse_cones=500))
