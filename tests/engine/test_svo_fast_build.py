"""The octree build's channel-major directional values equal the plain per-face loops bit for bit.

``svo`` computes the leaves' one-sided faces, the parents' front-to-back composites and the
coarser cascades' ½ : ½ merge on (24, M) channel-major arrays, all faces at once
(docs/gi_pipeline.md). The references below are the straightforward forms on (M, 6, 4) arrays,
one face at a time, as the build first computed them; the fast forms must reproduce them
exactly (same float32 operations in the same order), not just to a tolerance.
"""
from __future__ import annotations

import numpy as np
import pytest
from test_svo import random_scene

from voxgi.voxgi_addon.gi import svo
from voxgi.voxgi_addon.gi.svo import FACES, build_octree


def reference_one_sided(nodes) -> np.ndarray:
    """(M, 6, 4): one face at a time."""
    faces = np.repeat(nodes.premultiplied()[:, None, :], len(FACES), axis=1)
    for f in range(len(FACES)):
        axis, s = divmod(f, 2)
        n_dot_v = nodes.normal[:, axis] * (1.0 - 2.0 * s)
        faces[:, f, :3] *= np.clip(1.0 + n_dot_v, 0.0, 1.0)[:, None]
    return faces


def reference_directional_parents(faces, groups, octants, parents) -> np.ndarray:
    """(P, 6, 4) from the children's (M, 6, 4) faces: one face at a time."""
    out = np.empty((parents, len(FACES), 4), np.float32)
    for f in range(len(FACES)):
        axis, s = divmod(f, 2)
        full = np.zeros((parents, 8, 4), np.float32)
        full[groups, octants] = faces[:, f]
        full = full.reshape(parents, 2, 2, 2, 4)  # [parent, z, y, x, channel]
        along = 3 - axis
        front = np.take(full, 1 - s, axis=along)
        back = np.take(full, s, axis=along)
        column = front + (1.0 - front[..., 3:4]) * back
        out[:, f] = column.reshape(parents, 4, 4).mean(axis=1)
    return out


def reference_merged_faces(own_faces, parent_faces, own_keys, parent_keys) -> np.ndarray:
    """(m, 6, 4) directional values of ``_merge_own`` from (n, 6, 4) inputs."""
    keys = np.union1d(own_keys, parent_keys)
    i_own, i_par = np.searchsorted(keys, own_keys), np.searchsorted(keys, parent_keys)
    both = np.isin(own_keys, parent_keys)[:, None, None]
    directional = np.zeros((len(keys), len(FACES), 4), np.float32)
    directional[i_par] = parent_faces
    children = directional[i_own]
    colour = children[..., :3] / np.maximum(children[..., 3:4], 1e-30)
    mixed = np.concatenate([0.5 * (colour + own_faces[..., :3]), np.ones_like(own_faces[..., 3:])], -1)
    directional[i_own] = np.where(both, mixed, own_faces)
    return directional


def as_faces(channel_major: np.ndarray) -> np.ndarray:
    """(24, M) → (M, 6, 4)."""
    return channel_major.T.reshape(-1, len(FACES), 4)


def leaves_of(seed: int, one_sided: bool, signed_zeros: bool = True):
    """The finest cascade's leaves of a random scene (radiance with −0.0 and 0.0 entries)."""
    cascades, radiance = random_scene(seed, 16, 1, 0.3)
    rad = radiance[0]
    if signed_zeros:
        rng = np.random.default_rng(seed)
        rad[rng.uniform(size=rad.shape) < 0.2] = -0.0
        rad[rng.uniform(size=rad.shape) < 0.2] = 0.0
    cv = cascades[0]
    return svo._leaf_nodes(cv.cells, rad, cv.albedo, cv.normal, cv.count, 0, one_sided)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", range(4))
def test_one_sided_faces_equal_the_per_face_loop(seed):
    leaves = leaves_of(seed, one_sided=True)
    assert same_bits(as_faces(leaves.directional), reference_one_sided(leaves))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("one_sided", [False, True])
def test_directional_parents_equal_the_per_face_loop_at_every_level(seed, one_sided):
    nodes = leaves_of(seed, one_sided)
    while len(nodes.keys) > 1:
        parent_keys = nodes.keys >> np.uint64(3)
        starts = svo._group_starts(parent_keys)
        k = np.diff(np.r_[starts, len(parent_keys)])
        octants = (nodes.keys & np.uint64(7)).astype(np.uint8)
        groups = np.repeat(np.arange(len(starts)), k)
        expected = reference_directional_parents(as_faces(nodes.all_faces()), groups, octants,
                                                 len(starts))
        parents = svo._parents(nodes)
        assert same_bits(as_faces(parents.directional), expected)
        nodes = parents


@pytest.mark.parametrize("seed", range(3))
def test_merge_with_a_coarser_cascade_equals_the_per_face_rule(seed):
    leaves = leaves_of(seed, one_sided=True)
    parents = svo._parents(leaves)
    # a coarser cascade's own voxels at the parents' level: some over parents, some alone
    rng = np.random.default_rng(seed)
    picked = parents.keys[rng.uniform(size=len(parents.keys)) < 0.3]
    extra = np.setdiff1d(rng.integers(0, 8 ** 3, 40).astype(np.uint64), parents.keys)
    keys = np.union1d(picked, extra)
    n = len(keys)
    normal = rng.normal(size=(n, 3)).astype(np.float32)
    own = svo._Nodes(keys, rng.uniform(0, 2, (n, 3)).astype(np.float32),
                     rng.uniform(0, 1, (n, 3)).astype(np.float32), normal,
                     np.ones(n, np.float32), np.ones(n, np.int32), np.zeros(n, np.uint8))
    own.directional = svo._one_sided_faces(own)
    merged = svo._merge_own(own, parents)
    expected = reference_merged_faces(as_faces(own.directional), as_faces(parents.directional),
                                      own.keys, parents.keys)
    assert same_bits(as_faces(merged.directional), expected)


def test_directional_tables_hold_the_nodes_faces_and_a_zero_column():
    cascades, radiance = random_scene(5, 8, 3, 0.2)
    octree = build_octree(cascades, radiance, 2, one_sided_leaves=True)
    for lv in octree.levels:
        table = lv.directional
        assert table.shape == (4 * len(FACES), lv.node_count + 1)
        assert table.flags.c_contiguous and not table[:, -1].any()
