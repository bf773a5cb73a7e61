"""Sparse voxel octree: every query against an independent dense-grid brute force.

The brute force builds full 3D arrays at every level straight from the cascades and averages
them down with reshape-sums following the rules of docs/gi_pipeline.md and ``svo``'s
docstring; it shares no code with ``svo`` (no Morton keys, no reduceat).
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from voxgi.voxgi_addon.gi.cascades import CascadeGrid, CascadeVoxels
from voxgi.voxgi_addon.gi.morton import morton_decode, morton_encode
from voxgi.voxgi_addon.gi.svo import build_octree

# The cascades' own types; make_grids below also builds the tiny grids (2³, 4³) that
# place_cascades refuses, so the octree can be checked exhaustively.
Grid, Voxels = CascadeGrid, CascadeVoxels


def make_grids(camera, base_span: float, res: int, n: int) -> list[Grid]:
    coarse = base_span * 2 ** (n - 1)
    centre = np.round(np.asarray(camera, float) / coarse) * coarse
    return [Grid(i, base_span * 2 ** i, res, centre - (res / 2) * base_span * 2 ** i)
            for i in range(n)]


def voxels(grid: Grid, cells, rng) -> Voxels:
    cells = np.asarray(cells, np.int32).reshape(-1, 3)
    k = len(cells)
    normal = rng.normal(size=(k, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return Voxels(grid, cells, rng.uniform(0, 1, (k, 3)).astype(np.float32),
                  normal.astype(np.float32), rng.uniform(0, 1, k).astype(np.float32),
                  rng.integers(1, 6, k).astype(np.int32), np.zeros(k, bool))


def random_scene(seed: int, res: int, n: int, fill: float, clustered: bool = True):
    """Random cells in every cascade (overlaps with finer cascades included), random radiance."""
    rng = np.random.default_rng(seed)
    grids = make_grids(rng.uniform(-5, 5, 3), 0.25, res, n)
    cascades = []
    for g in grids:
        occupied = rng.uniform(size=(res,) * 3) < fill
        if clustered:  # whole 2×2×2 blocks too, so parents see every child count 0..8
            blocks = rng.uniform(size=(res // 2,) * 3) < fill
            occupied |= blocks.repeat(2, 0).repeat(2, 1).repeat(2, 2)
        cells = np.argwhere(occupied)
        cascades.append(voxels(g, rng.permutation(cells), rng))
    radiance = [rng.uniform(0, 3, (len(c.cells), 3)).astype(np.float32) for c in cascades]
    return cascades, radiance


# ---- independent brute force -------------------------------------------------------------

def octree_depth(cascades):
    """log2(resolution) + cascades − 1: the level of the finest cascade's voxels."""
    return int(round(np.log2(cascades[0].grid.resolution))) + len(cascades) - 1


def leaf_nodes(cascades, radiance):
    """Per cascade: (cascade, its radiance, octree level ℓ_i, nodes per axis, node coords)."""
    n = len(cascades)
    res = cascades[0].grid.resolution
    log_res = int(round(np.log2(res)))
    for cv, rad in zip(cascades, radiance):
        i = cv.grid.index
        ell = log_res + n - 1 - i
        c = cv.cells.astype(np.int64) + (res // 2) * (2 ** (n - 1 - i) - 1)
        yield cv, rad, ell, 2 ** ell, c


def brute_force(cascades, radiance):
    """Dense arrays per level: dict(present, radiance, albedo, normal, occlusion, count)."""
    depth = octree_depth(cascades)
    own = {}
    for cv, rad, ell, s, c in leaf_nodes(cascades, radiance):
        arrays = {"present": np.zeros((s,) * 3, bool), "count": np.zeros((s,) * 3, np.int64)}
        for name, values in (("radiance", rad), ("albedo", cv.albedo), ("normal", cv.normal)):
            arrays[name] = np.zeros((s,) * 3 + (3,))
            arrays[name][c[:, 0], c[:, 1], c[:, 2]] = values
        arrays["present"][c[:, 0], c[:, 1], c[:, 2]] = True
        arrays["count"][c[:, 0], c[:, 1], c[:, 2]] = cv.count
        own[ell] = arrays
    levels = {depth: dict(own[depth], occlusion=own[depth]["present"].astype(float))}
    for ell in range(depth - 1, -1, -1):
        s = 2 ** ell
        child = levels[ell + 1]

        def block_sum(a):
            return a.reshape(s, 2, s, 2, s, 2, *a.shape[3:]).sum(axis=(1, 3, 5))

        k = block_sum(child["present"].astype(np.int64))
        lvl = {"present": k > 0, "occlusion": k / 8.0, "count": block_sum(child["count"])}
        for name in ("radiance", "albedo", "normal"):
            total = block_sum(child[name] * child["present"][..., None])
            lvl[name] = total / np.maximum(k, 1)[..., None]
        if ell in own:
            mine = own[ell]
            both = mine["present"] & (k > 0)
            only = mine["present"] & (k == 0)
            for name in ("radiance", "albedo", "normal"):
                lvl[name][both] = 0.5 * (mine[name][both] + lvl[name][both])
                lvl[name][only] = mine[name][only]
            lvl["occlusion"][mine["present"]] = 1.0
            lvl["present"] |= mine["present"]
            lvl["count"] = lvl["count"] + mine["count"]
        levels[ell] = lvl
    return levels


def brute_trilinear(levels, points, level, root_origin, root_size):
    """Node-centred trilinear of (radiance·occlusion, occlusion) with a linear level blend."""
    depth = max(levels)
    lev = np.clip(level, 0, depth)
    out = np.zeros((len(points), 4))
    for p, (point, l_) in enumerate(zip(points, lev)):
        lo = int(np.floor(l_))
        for ell, w_level in ((lo, 1 - (l_ - lo)), (min(lo + 1, depth), l_ - lo)):
            if w_level == 0:
                continue
            s = 2 ** ell
            u = (point - root_origin) / (root_size / s) - 0.5
            base = np.floor(u).astype(int)
            f = u - base
            for corner in np.ndindex(2, 2, 2):
                node = base + corner
                if np.any(node < 0) or np.any(node >= s):
                    continue
                w = np.prod(np.where(corner, f, 1 - f))
                lvl = levels[ell]
                occ = lvl["occlusion"][tuple(node)]
                out[p, :3] += w_level * w * occ * lvl["radiance"][tuple(node)]
                out[p, 3] += w_level * w * occ
    return out


def all_nodes(s):
    return np.argwhere(np.ones((s,) * 3, bool)).astype(np.int64)


def assert_matches_brute_force(octree, levels, rng):
    for ell, lvl in levels.items():
        s = 2 ** ell
        if s <= 32:
            nodes = all_nodes(s)
        else:  # present nodes, random nodes and a shell just outside the level
            nodes = np.concatenate([np.argwhere(lvl["present"]),
                                    rng.integers(-2, s + 2, size=(3000, 3))])
        radiance, occlusion, present = octree.lookup(ell, nodes)
        inside = np.all((nodes >= 0) & (nodes < s), axis=1)
        c = np.clip(nodes, 0, s - 1)
        idx = (c[:, 0], c[:, 1], c[:, 2])
        want_present = lvl["present"][idx] & inside
        assert np.array_equal(present, want_present), f"level {ell}"
        want_occ = np.where(want_present, lvl["occlusion"][idx], 0)
        np.testing.assert_allclose(occlusion, want_occ, atol=1e-6, err_msg=f"level {ell}")
        want_rad = np.where(want_present[:, None], lvl["radiance"][idx], 0)
        np.testing.assert_allclose(radiance, want_rad, rtol=1e-5, atol=1e-5,
                                   err_msg=f"level {ell}")
        assert np.all(occlusion <= 1) and radiance.dtype == np.float32
        assert octree.stats()[ell].nodes == int(lvl["present"].sum())


def stored_attributes(octree, ell):
    """(coords (M, 3), albedo, normal, count) of the present nodes of a level, any kind."""
    lv = octree.levels[ell]
    if lv.kind == "dense":
        coords = np.argwhere(lv.occlusion > 0)
        idx = tuple(coords.T)
        return coords, lv.albedo[idx], lv.normal[idx], lv.count[idx]
    return morton_decode(lv.keys), lv.albedo, lv.normal, lv.count


# ---- tests -------------------------------------------------------------------------------

@pytest.mark.parametrize("res, n, dense_depth", [(8, 3, 2), (8, 3, 5), (16, 2, 3), (16, 3, 6),
                                                 (4, 1, 0), (8, 2, 4)])
def test_lookups_equal_dense_brute_force(res, n, dense_depth):
    cascades, radiance = random_scene(seed=res * 10 + n, res=res, n=n, fill=0.08)
    octree = build_octree(cascades, radiance, dense_depth)
    levels = brute_force(cascades, radiance)
    assert octree.depth == max(levels) == int(np.log2(res)) + n - 1
    assert [lv.kind for lv in octree.levels] == (
        ["dense"] * (dense_depth + 1) + ["sparse"] * (octree.depth - dense_depth))
    assert_matches_brute_force(octree, levels, np.random.default_rng(0))
    for ell, lvl in levels.items():  # albedo, normal and count too, on every present node
        coords, albedo, normal, count = stored_attributes(octree, ell)
        idx = tuple(coords.T)
        assert len(coords) == lvl["present"].sum() and lvl["present"][idx].all()
        np.testing.assert_allclose(albedo, lvl["albedo"][idx], atol=1e-5)
        np.testing.assert_allclose(normal, lvl["normal"][idx], atol=1e-5)
        assert np.array_equal(count, lvl["count"][idx])


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), res=st.sampled_from([2, 4, 8, 16]),
       n=st.integers(1, 3), fill=st.floats(0, 0.6), dense=st.integers(0, 6),
       clustered=st.booleans(), index_maps=st.booleans())
def test_random_voxel_sets_match_brute_force(seed, res, n, fill, dense, clustered, index_maps):
    cascades, radiance = random_scene(seed, res, n, fill, clustered)
    octree = build_octree(cascades, radiance, dense,
                          max_index_window=16 ** 3 if index_maps else 0)
    assert octree.dense_depth == min(dense, octree.depth)
    levels = brute_force(cascades, radiance)
    rng = np.random.default_rng(seed)
    assert_matches_brute_force(octree, levels, rng)
    points = octree.root_origin + rng.uniform(-0.05, 1.05, (40, 3)) * octree.root_size
    level = rng.uniform(-0.2, octree.depth + 0.2, 40)
    got_rad, got_occ = octree.sample(points, level)
    want = brute_trilinear(levels, points, level, octree.root_origin, octree.root_size)
    np.testing.assert_allclose(got_rad, want[:, :3], rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(got_occ, want[:, 3], rtol=1e-4, atol=1e-5)


def test_parent_averages_present_children_with_occlusion_k_over_8():
    rng = np.random.default_rng(7)
    grid = make_grids([0, 0, 0], 1.0, 4, 1)[0]
    for k in range(1, 9):
        children = np.argwhere(np.ones((2, 2, 2), bool))[rng.permutation(8)[:k]] + [2, 0, 2]
        cv = voxels(grid, children, rng)
        rad = rng.uniform(0, 1, (k, 3)).astype(np.float32)
        octree = build_octree([cv], [rad], dense_depth=1)  # level 1 dense, level 2 sparse
        radiance, occlusion, present = octree.lookup(1, np.array([[1, 0, 1]]))
        assert present[0] and occlusion[0] == pytest.approx(k / 8)
        np.testing.assert_allclose(radiance[0], rad.mean(axis=0), rtol=1e-6)
        np.testing.assert_allclose(octree.levels[1].normal[1, 0, 1], cv.normal.mean(axis=0),
                                   rtol=1e-5)
        assert octree.levels[1].count[1, 0, 1] == cv.count.sum()
        _, root_occ, _ = octree.lookup(0, np.zeros((1, 3)))
        assert root_occ[0] == pytest.approx(1 / 8)  # one present child at level 1


def test_coarse_voxel_over_finer_children_averages_half_and_half():
    rng = np.random.default_rng(8)
    fine_grid, coarse_grid = make_grids([0.3, 0.1, -0.2], 0.5, 4, 2)
    # Coarse cell (1, 1, 1) is covered by the fine cascade: fine cells (0..1)³ lie in it.
    fine = voxels(fine_grid, [[0, 0, 0], [1, 1, 0], [1, 1, 1]], rng)
    coarse = voxels(coarse_grid, [[1, 1, 1], [0, 0, 0]], rng)
    rad_f = rng.uniform(0, 1, (3, 3)).astype(np.float32)
    rad_c = rng.uniform(0, 1, (2, 3)).astype(np.float32)
    octree = build_octree([fine, coarse], [rad_f, rad_c], dense_depth=0)
    radiance, occlusion, present = octree.lookup(2, np.array([[1, 1, 1], [0, 0, 0]]))
    assert present.all() and np.allclose(occlusion, 1.0)  # max(1, k/8): never above 1
    np.testing.assert_allclose(radiance[0], 0.5 * rad_c[0] + 0.5 * rad_f.mean(axis=0), rtol=1e-6)
    np.testing.assert_allclose(radiance[1], rad_c[1], rtol=1e-6)  # no children: the voxel
    lv = octree.levels[2]  # sparse (dense_depth 0)
    row = int(np.searchsorted(lv.keys, morton_encode(np.array([[1, 1, 1]]))[0]))
    assert lv.count[row] == coarse.count[0] + fine.count.sum()
    assert lv.child_mask[row] == 1 << 0 | 1 << 3 | 1 << 7  # fine nodes (2,2,2) (3,3,2) (3,3,3)
    np.testing.assert_allclose(lv.albedo[row],
                               0.5 * coarse.albedo[0] + 0.5 * fine.albedo.mean(axis=0), rtol=1e-6)
    np.testing.assert_allclose(lv.normal[row],
                               0.5 * coarse.normal[0] + 0.5 * fine.normal.mean(axis=0), rtol=1e-5)


def test_sample_equals_independent_trilinear_at_integer_and_fractional_levels():
    cascades, radiance = random_scene(seed=11, res=8, n=3, fill=0.15)
    levels = brute_force(cascades, radiance)
    rng = np.random.default_rng(12)
    m = 400
    for window in (None, 0):  # with the sparse index maps and with searchsorted only
        kwargs = {} if window is None else {"max_index_window": window}
        octree = build_octree(cascades, radiance, dense_depth=2, **kwargs)
        lo, size = octree.root_origin, octree.root_size
        points = lo + rng.uniform(-0.1, 1.1, (m, 3)) * size  # outside the root too
        points[: m // 2] = lo + rng.uniform(0.3, 0.7, (m // 2, 3)) * size  # inner cascades
        level = np.concatenate([rng.integers(0, octree.depth + 1, m // 4).astype(float),
                                rng.uniform(-0.5, octree.depth + 0.5, m - m // 4)])
        got_rad, got_occ = octree.sample(points, level)
        want = brute_trilinear(levels, points, level, lo, size)
        assert got_rad.shape == (m, 3) and got_occ.shape == (m,)
        np.testing.assert_allclose(got_rad, want[:, :3], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(got_occ, want[:, 3], rtol=1e-4, atol=1e-5)
        # a scalar level and node centres: the node's own premultiplied value
        ell = octree.cascade_levels[0]
        nodes = np.argwhere(levels[ell]["present"])[:50]
        centres = lo + (nodes + 0.5) * octree.node_size(ell)
        got_rad, got_occ = octree.sample(centres, float(ell))
        idx = tuple(nodes.T)
        np.testing.assert_allclose(got_occ, levels[ell]["occlusion"][idx], rtol=1e-5)
        np.testing.assert_allclose(got_rad, levels[ell]["radiance"][idx]
                                   * levels[ell]["occlusion"][idx][:, None], rtol=1e-5)


def test_sample_many_points_in_chunks_matches_small_calls():
    cascades, radiance = random_scene(seed=13, res=16, n=2, fill=0.05)
    octree = build_octree(cascades, radiance, dense_depth=3)
    rng = np.random.default_rng(14)
    points = octree.root_origin + rng.uniform(0, 1, (100_000, 3)) * octree.root_size
    level = rng.uniform(0, octree.depth, 100_000)
    rad, occ = octree.sample(points, level)
    part = slice(70_000, 70_300)
    rad_part, occ_part = octree.sample(points[part], level[part])
    np.testing.assert_allclose(rad[part], rad_part, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(occ[part], occ_part, rtol=1e-6, atol=1e-7)
    assert rad.flags.c_contiguous and rad.dtype == np.float32 and occ.max() <= 1 + 1e-6


def test_cascades_nest_at_their_levels_and_finest_level_at():
    rng = np.random.default_rng(15)
    res, n = 8, 3
    grids = make_grids([1.7, -0.4, 2.2], 0.3, res, n)
    cells = [np.array([[4, 4, 4], [2, 5, 3]]),   # cascade 0 (anywhere)
             np.array([[0, 0, 0], [7, 3, 1]]),   # cascade 1, outside cascade 0's cells [2, 6)
             np.array([[0, 7, 0], [1, 6, 7]])]   # cascade 2, outside cascade 1's cells [2, 6)
    cascades = [voxels(g, c, rng) for g, c in zip(grids, cells)]
    radiance = [rng.uniform(0, 1, (2, 3)).astype(np.float32) for _ in cascades]
    octree = build_octree(cascades, radiance, dense_depth=3)
    assert octree.cascade_levels == (5, 4, 3) and octree.depth == 5
    np.testing.assert_allclose(octree.root_origin, grids[2].origin)
    assert octree.root_size == pytest.approx(res * grids[2].span)
    for i, (g, c, rad) in enumerate(zip(grids, cells, radiance)):
        ell = octree.cascade_levels[i]
        nodes = c + (res // 2) * (2 ** (n - 1 - i) - 1)
        got_rad, occ, present = octree.lookup(ell, nodes)
        assert present.all() and np.allclose(occ, 1)
        np.testing.assert_allclose(got_rad, rad)
        # The node centre is the cascade cell's centre in world space.
        np.testing.assert_allclose(octree.root_origin + (nodes + 0.5) * octree.node_size(ell),
                                   g.origin + (c + 0.5) * g.span, atol=1e-9)
        assert octree.node_size(ell) == pytest.approx(g.span)
        assert octree.finest_level_at(g.origin + (c + 0.5) * g.span).tolist() == [ell, ell]
    # Random points against "finest grid whose cell range contains the point".
    points = grids[2].origin + rng.uniform(-0.2, 1.2, (20_000, 3)) * res * grids[2].span
    want = np.full(len(points), -1)
    for g in reversed(grids):
        cell = np.floor((points - g.origin) / g.span)
        want[np.all((cell >= 0) & (cell < res), axis=1)] = octree.cascade_levels[g.index]
    assert np.array_equal(octree.finest_level_at(points), want)
    assert set(np.unique(want)) == {-1, 3, 4, 5}


def test_child_links_reach_every_present_child():
    cascades, radiance = random_scene(seed=16, res=8, n=3, fill=0.1)
    octree = build_octree(cascades, radiance, dense_depth=2)
    for ell in range(octree.dense_depth, octree.depth):
        lv, nxt = octree.levels[ell], octree.levels[ell + 1]
        if lv.kind == "dense":
            coords = np.argwhere(lv.occlusion > 0)
            base, mask = lv.child_base[tuple(coords.T)], lv.child_mask[tuple(coords.T)]
            assert (lv.child_base[lv.occlusion == 0] == -1).all()
        else:
            coords, base, mask = morton_decode(lv.keys), lv.child_base, lv.child_mask
        assert mask.sum() > 0
        for octant in range(8):
            offset = np.array([octant & 1, octant >> 1 & 1, octant >> 2 & 1])
            _, _, present = octree.lookup(ell + 1, 2 * coords + offset)
            bit = (mask >> octant) & 1
            assert np.array_equal(bit.astype(bool), present)
            below = mask & ((1 << octant) - 1)
            rank = np.array([bin(int(b)).count("1") for b in below])
            rows = (base + rank)[present]
            want_keys = morton_encode(2 * coords[present] + offset)
            assert np.array_equal(nxt.keys[rows], want_keys)
    assert octree.levels[-1].child_mask.sum() == 0


def test_stats_count_nodes_and_bytes():
    cascades, radiance = random_scene(seed=17, res=8, n=3, fill=0.1)
    levels = brute_force(cascades, radiance)
    for window in (None, 0):
        kwargs = {} if window is None else {"max_index_window": window}
        octree = build_octree(cascades, radiance, dense_depth=3, **kwargs)
        stats = octree.stats()
        assert [s.level for s in stats] == list(range(octree.depth + 1))
        for s in stats:
            m, side = int(levels[s.level]["present"].sum()), 2 ** s.level
            assert s.nodes == m
            if s.kind == "dense":
                # radiance, normal, albedo 3×f32, occlusion f32, count i32, table 4×f32 (+1 row),
                # directional 24×f32 per present node (+1 column), its i32 index per table column
                expected = side ** 3 * (36 + 4 + 4) + 16 * (side ** 3 + 1)
                expected += 96 * (m + 1) + 4 * (side ** 3 + 1)
                if s.level == octree.dense_depth:
                    expected += side ** 3 * (8 + 1)  # child_base i64 + child_mask u8
            else:
                # key u64, 3 × 3 f32, occlusion f32, count i32, child_base i64, mask u8, table,
                # window origin 3 × i64, directional 24×f32 (+1 column)
                expected = m * (8 + 36 + 4 + 4 + 8 + 1) + 16 * (m + 1) + 24 + 96 * (m + 1)
                if window is None:
                    expected += 4 * (octree.levels[s.level].window_size ** 3 + 1)
            assert s.bytes == expected, s


def test_empty_cascades_give_an_empty_octree():
    grids = make_grids([0, 0, 0], 1.0, 4, 2)
    rng = np.random.default_rng(0)
    cascades = [voxels(g, np.zeros((0, 3)), rng) for g in grids]
    octree = build_octree(cascades, [np.zeros((0, 3), np.float32)] * 2, dense_depth=1)
    assert [s.nodes for s in octree.stats()] == [0] * (octree.depth + 1)
    rad, occ = octree.sample(rng.uniform(-4, 4, (100, 3)), rng.uniform(0, 3, 100))
    assert not rad.any() and not occ.any()


def test_inconsistent_inputs_are_refused():
    rng = np.random.default_rng(0)
    grids = make_grids([0, 0, 0], 1.0, 4, 2)
    cascades = [voxels(g, [[1, 1, 1]], rng) for g in grids]
    rad = [np.ones((1, 3), np.float32)] * 2
    with pytest.raises(ValueError, match="one radiance"):
        build_octree(cascades, rad[:1])
    with pytest.raises(ValueError, match="lengths"):
        build_octree(cascades, [np.ones((2, 3), np.float32), rad[1]])
    shifted = Grid(1, 2.0, 4, grids[1].origin + 0.5)
    with pytest.raises(ValueError, match="nested"):
        build_octree([cascades[0], voxels(shifted, [[0, 0, 0]], rng)], rad)
    with pytest.raises(ValueError, match="power-of-two"):
        build_octree([voxels(Grid(0, 1.0, 6, np.zeros(3)), [[0, 0, 0]], rng)], rad[:1])
    with pytest.raises(ValueError, match="indices"):
        build_octree([cascades[1]], rad[:1])
    with pytest.raises(ValueError, match="outside"):
        build_octree([voxels(grids[0], [[4, 0, 0]], rng), cascades[1]], rad)


def test_duplicate_cells_average_weighted_by_count():
    rng = np.random.default_rng(21)
    grid = make_grids([0, 0, 0], 1.0, 4, 1)[0]
    cv = voxels(grid, [[1, 2, 3], [0, 0, 0], [1, 2, 3]], rng)
    cv.count[:] = [1, 2, 3]
    rad = rng.uniform(0, 1, (3, 3)).astype(np.float32)
    octree = build_octree([cv], [rad], dense_depth=2)
    radiance, occlusion, present = octree.lookup(2, np.array([[1, 2, 3]]))
    assert present[0] and occlusion[0] == 1
    np.testing.assert_allclose(radiance[0], (rad[0] + 3 * rad[2]) / 4, rtol=1e-6)
    assert octree.levels[2].count[1, 2, 3] == 4 and octree.stats()[2].nodes == 2


# ---- directional (anisotropic) tables ------------------------------------------------------

FACE_VIEW = [(0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)]  # (axis, side the viewer is on)


def brute_directional(cascades, radiance):
    """Dense (s, s, s, 6, 4) premultiplied face values per level, straight from the cascades:
    leaves (r, g, b, 1) on every face; parents composite each 2-child column along the face's
    axis front to back (front = the child on the viewer's side) and average the 4 columns;
    a node that is also a coarser voxel: ½·own + ½·children's colour per face, α = 1."""
    depth = octree_depth(cascades)
    own = {}
    for cv, rad, ell, s, c in leaf_nodes(cascades, radiance):
        leaf = np.zeros((s, s, s, 6, 4))
        leaf[c[:, 0], c[:, 1], c[:, 2], :, :3] = np.asarray(rad, float)[:, None, :]
        leaf[c[:, 0], c[:, 1], c[:, 2], :, 3] = 1.0
        present = np.zeros((s,) * 3, bool)
        present[c[:, 0], c[:, 1], c[:, 2]] = True
        own[ell] = (leaf, present)
    levels = {depth: own[depth][0]}
    for ell in range(depth - 1, -1, -1):
        s = 2 ** ell
        child = levels[ell + 1].reshape(s, 2, s, 2, s, 2, 6, 4)
        out = np.zeros((s, s, s, 6, 4))
        for f, (axis, side) in enumerate(FACE_VIEW):
            pair = 1 + 2 * axis  # the 2-child axis of ``axis`` in the reshaped array
            front = np.take(child[..., f, :], 1 if side > 0 else 0, axis=pair)
            back = np.take(child[..., f, :], 0 if side > 0 else 1, axis=pair)
            column = front + (1 - front[..., 3:]) * back  # remaining 2-axes are the 4 columns
            out[..., f, :] = column.mean(axis=_other_pairs(pair))
        if ell in own:
            leaf, present = own[ell]
            kids = out[present]
            has_kids = kids[..., 3] > 0
            colour = kids[..., :3] / np.maximum(kids[..., 3:], 1e-30)
            mixed = np.concatenate([0.5 * (colour + leaf[present][..., :3]),
                                    np.ones_like(kids[..., 3:])], axis=-1)
            out[present] = np.where(has_kids[..., None], mixed, leaf[present])
        levels[ell] = out
    return levels


def _other_pairs(pair):
    """Axes of the reshaped (s, 2, s, 2, s, 2) block left after taking ``pair``: the 4 columns."""
    return tuple(a - (a > pair) for a in (1, 3, 5) if a != pair)


@pytest.mark.parametrize("seed, res, n, fill, dense_depth",
                         [(31, 8, 3, 0.1, 2), (32, 8, 2, 0.3, 4), (33, 4, 3, 0.5, 0),
                          (34, 16, 1, 0.05, 2)])
def test_directional_tables_equal_brute_force_front_to_back(seed, res, n, fill, dense_depth):
    cascades, radiance = random_scene(seed=seed, res=res, n=n, fill=fill)
    want = brute_directional(cascades, radiance)
    octree = build_octree(cascades, radiance, dense_depth)
    for ell, faces in want.items():
        nodes = all_nodes(2 ** ell)
        got = octree.lookup_directional(ell, nodes)
        np.testing.assert_allclose(got, faces[tuple(nodes.T)], rtol=1e-5, atol=1e-6,
                                   err_msg=f"level {ell}")
        # Only present nodes have non-zero faces, and every present node is seen from all 6.
        _, _, present = octree.lookup(ell, nodes)
        assert np.array_equal(present, (got[..., 3] > 0).all(axis=1))
        assert (got[~present] == 0).all()


def test_wall_across_x_is_opaque_along_x_and_half_covered_along_y_and_z():
    rng = np.random.default_rng(35)
    res = 16
    grid = make_grids([0, 0, 0], 1.0, res, 1)[0]
    yz = np.argwhere(np.ones((res, res), bool))
    cells = np.column_stack([np.full(len(yz), 5), yz])  # one-voxel wall x = 5
    cv = voxels(grid, cells, rng)
    octree = build_octree([cv], [np.full((len(cells), 3), 2.0, np.float32)], dense_depth=2)
    assert octree.depth == 4
    along_y = {octree.depth: 1.0}
    for ell in range(octree.depth, -1, -1):
        s = 2 ** ell
        nodes = np.argwhere(np.ones((s,) * 3, bool))
        nodes = nodes[nodes[:, 0] == 5 >> (octree.depth - ell)]  # the nodes the wall crosses
        faces = octree.lookup_directional(ell, nodes)
        np.testing.assert_allclose(faces[:, :2, 3], 1.0, atol=1e-6)      # ±x: opaque
        np.testing.assert_allclose(faces[:, :2, :3], 2.0, rtol=1e-6)     # and its colour
        if ell < octree.depth:  # one half of the 2 × 2 columns holds the wall's children
            along_y[ell] = 0.5 * (1 - (1 - along_y[ell + 1]) ** 2)
        np.testing.assert_allclose(faces[:, 2:, 3], along_y[ell], atol=1e-6)
        np.testing.assert_allclose(faces[:, 2:, :3], 2.0 * along_y[ell], rtol=1e-5)
        _, occlusion, _ = octree.lookup(ell, nodes)  # the isotropic field is untouched
        np.testing.assert_allclose(occlusion, 1.0 if ell == octree.depth else 0.5)
    assert along_y[octree.depth - 1] == 0.5  # half covered just above the voxels


def test_extinction_keeps_a_wall_opaque_to_slanted_cones():
    rng = np.random.default_rng(40)
    res = 16
    grid = make_grids([0, 0, 0], 1.0, res, 1)[0]
    yz = np.argwhere(np.ones((res, res), bool))
    cells = np.column_stack([np.full(len(yz), 5), yz])  # one-voxel wall x = 5
    octree = build_octree([voxels(grid, cells, rng)], [np.full((len(cells), 3), 2.0, np.float32)],
                          dense_depth=2)
    # The centre of the level-(depth−1) node holding the wall: opaque along x, half along y/z.
    centre = grid.origin + np.array([5.0, 9.0, 9.0]) * grid.span
    slanted = np.array([[-np.cos(np.radians(50)), np.sin(np.radians(50)), 0.0]])
    level = np.array([float(octree.depth - 1)])
    rad, occ = octree.sample_directional(centre[None], level, slanted)
    _, blended = octree.sample_directional(centre[None], level, slanted, extinction=False)
    assert occ[0] == pytest.approx(1.0, abs=1e-5)  # opaque along x, so opaque at 50° too
    assert blended[0] < 0.99  # the plain d² blend lets a slanted cone through
    np.testing.assert_allclose(rad[0], 2.0, rtol=1e-4)  # colour per unit opacity is kept


def test_sample_directional_equals_sample_for_a_solid_block():
    rng = np.random.default_rng(36)
    res = 16
    grid = make_grids([0, 0, 0], 1.0, res, 1)[0]
    cells = np.argwhere(np.ones((8, 8, 8), bool)) + 4  # cells [4, 12)³: whole 4³ nodes
    cv = voxels(grid, cells, rng)
    octree = build_octree([cv], [np.tile([[0.3, 1.5, 0.7]], (len(cells), 1)).astype(np.float32)],
                          dense_depth=2)
    m = 2000
    points = octree.root_origin + rng.uniform(-0.1, 1.1, (m, 3)) * octree.root_size
    level = rng.uniform(octree.depth - 2, octree.depth + 0.5, m)  # nodes all full or empty
    dirs = rng.normal(size=(m, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs[:10] = np.eye(3)[rng.integers(0, 3, 10)] * rng.choice([-1, 1], (10, 1))  # axes
    rad_iso, occ_iso = octree.sample(points, level)
    rad_dir, occ_dir = octree.sample_directional(points, level, dirs, extinction=False)
    assert occ_iso.max() > 0.99 and (occ_iso == 0).any()
    np.testing.assert_allclose(rad_dir, rad_iso, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(occ_dir, occ_iso, rtol=1e-5, atol=1e-6)


def test_sample_directional_blends_the_faces_facing_the_cone_by_squared_direction():
    cascades, radiance = random_scene(seed=37, res=8, n=3, fill=0.15)
    faces = brute_directional(cascades, radiance)
    rng = np.random.default_rng(38)
    m = 300
    for window in (None, 0):
        kwargs = {} if window is None else {"max_index_window": window}
        octree = build_octree(cascades, radiance, dense_depth=2, **kwargs)
        lo, size = octree.root_origin, octree.root_size
        points = lo + rng.uniform(-0.1, 1.1, (m, 3)) * size
        points[: m // 2] = lo + rng.uniform(0.3, 0.7, (m // 2, 3)) * size
        level = rng.uniform(-0.5, octree.depth + 0.5, m)
        dirs = rng.normal(size=(m, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        want = np.zeros((m, 4))
        for axis in range(3):
            for f, moving in ((2 * axis, dirs[:, axis] <= 0), (2 * axis + 1, dirs[:, axis] > 0)):
                # A cone travelling −axis sees the face viewed from +axis, and vice versa.
                as_levels = {ell: {"occlusion": v[..., f, 3],
                                   "radiance": v[..., f, :3] / np.maximum(v[..., f, 3:], 1e-30)}
                             for ell, v in faces.items()}
                part = brute_trilinear(as_levels, points[moving], level[moving], lo, size)
                want[moving] += dirs[moving, axis, None] ** 2 * part
        got_rad, got_occ = octree.sample_directional(points, level, dirs, extinction=False)
        assert got_rad.shape == (m, 3) and got_occ.dtype == np.float32
        np.testing.assert_allclose(got_rad, want[:, :3], rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(got_occ, want[:, 3], rtol=1e-4, atol=1e-5)
    with pytest.raises(ValueError, match="direction"):
        octree.sample_directional(points, level, dirs[:-1])


def test_one_sided_leaves_hide_the_back_of_a_lit_wall_only():
    rng = np.random.default_rng(39)
    res = 8
    grid = make_grids([0, 0, 0], 1.0, res, 1)[0]
    yz = np.argwhere(np.ones((res, res), bool))
    cv = voxels(grid, np.column_stack([np.full(len(yz), 2), yz]), rng)
    cv.normal[:] = [-1, 0, 0]  # the wall's lit face looks towards −x
    rad = [np.full((len(yz), 3), 1.5, np.float32)]
    plain = build_octree([cv], rad, dense_depth=1)
    sided = build_octree([cv], rad, dense_depth=1, one_sided_leaves=True)
    for ell in range(sided.depth + 1):
        nodes = np.argwhere(np.ones((2 ** ell,) * 3, bool))
        a, b = plain.lookup_directional(ell, nodes), sided.lookup_directional(ell, nodes)
        np.testing.assert_allclose(b[..., 3], a[..., 3])            # occlusion unchanged
        np.testing.assert_allclose(b[:, 0, :3], 0.0)                # from +x: its black back
        np.testing.assert_allclose(b[:, 1:, :3], a[:, 1:, :3], rtol=1e-6)  # front, edge-on
        assert a[:, 0, :3].max() > 0
    np.testing.assert_allclose(sided.lookup(2, [[2, 0, 0]])[0], plain.lookup(2, [[2, 0, 0]])[0])
