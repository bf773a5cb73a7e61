"""Injection that costs what its voxels need (docs/gi_pipeline.md "Posed updates"): shadow
rays skip empty space with the result of the half-voxel march, and an injection after a move
marches only the rays that meet what moved, with the result of marching them all."""
import math

import numpy as np
import pytest

from voxgi.voxgi_addon.gi.cascades import CascadeVoxels, place_cascades
from voxgi.voxgi_addon.gi.light_injection import inject_direct_light
from voxgi.voxgi_addon.gi.voxel_shadows import CascadeOccupancy
from voxgi.voxgi_addon.scene.snapshot import LightData, SceneSnapshot, WorldData

RES = 32


def voxels(grid, cells, normal=(0.0, 0.0, 1.0)):
    cells = np.unique(np.asarray(cells, np.int32).reshape(-1, 3), axis=0)
    n = len(cells)
    return CascadeVoxels(grid, cells, np.full((n, 3), 0.7, np.float32),
                         np.tile(np.asarray(normal, np.float32), (n, 1)), np.zeros(n, np.float32),
                         np.ones(n, np.int32), np.zeros(n, bool))


def room(block_at=(14, 14, 4), seed=0):
    """Three nested 32³ cascades: a floor in every cascade, a few random voxels, and a 4³ block
    (the 'character') in the finest at ``block_at``."""
    rng = np.random.default_rng(seed)
    grids = place_cascades(np.array([0.2, -0.1, 1.0]), 0.125, RES, 3)
    xy = np.stack(np.meshgrid(np.arange(RES), np.arange(RES), indexing="ij"), -1).reshape(-1, 2)
    out = []
    for g in grids:
        cells = [np.column_stack([xy, np.full(len(xy), 2)]), rng.integers(0, RES, (60, 3))]
        if g.index == 0:
            block = np.stack(np.meshgrid(*[np.arange(4)] * 3, indexing="ij"), -1).reshape(-1, 3)
            cells.append(block + np.asarray(block_at))
        out.append(voxels(g, np.concatenate(cells)))
    return out


def lit_snapshot(lights):
    return SceneSnapshot(meshes={}, materials=[], objects=[], lights=lights,
                         world=WorldData(radiance=np.full((8, 16, 3), 0.2, np.float32),
                                         color=np.full(3, 0.2, np.float32), strength=1.0,
                                         key="grey sky"))


def lamp(kind, location, **extra):
    m = np.eye(4)
    m[:3, 3] = location
    if kind == "SUN":  # shining down and sideways
        c, s = math.cos(0.6), math.sin(0.6)
        m[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    return LightData(name=kind, type=kind, color=np.ones(3, np.float32), power=50.0,
                     world_matrix=m, **extra)


LIGHTS = [lamp("SUN", (0, 0, 10), angle=0.1), lamp("POINT", (0.5, 0.3, 2.5), radius=0.2),
          lamp("AREA", (-0.4, 0.2, 2.8), size=0.8, shape="SQUARE")]


def test_skipping_empty_blocks_tests_the_points_of_the_half_voxel_march():
    cascades = room()
    occupancy = CascadeOccupancy(cascades)
    assert occupancy.nested
    rng = np.random.default_rng(3)
    n = 6000
    grid = cascades[1].grid
    origins = grid.origin + rng.random((n, 3)) * grid.size
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    axis = np.zeros((n, 3))  # rays along the axes, from voxel centres: points on cell faces
    axis[np.arange(n), rng.integers(0, 3, n)] = rng.choice([-1.0, 1.0], n)
    centres = cascades[0].grid.origin + (rng.integers(0, RES, (n, 3)) + 0.5) * 0.125
    lengths = np.where(rng.random(n) < 0.5, np.inf, rng.random(n) * 6.0)
    for o, d in ((origins, dirs), (centres, axis), (centres + 1.5 * 0.125 * axis, axis)):
        skipped = occupancy.occluded(o, d, lengths)
        assert np.array_equal(skipped, occupancy._march(o, d, lengths))
        assert 0.05 < skipped.mean() < 0.95


def test_cascades_that_do_not_nest_are_marched_step_by_step():
    cascades = room()
    moved = [cascades[0], CascadeVoxels(place_cascades(np.array([3.0, 0, 0]), 0.25, RES, 1)[0],
                                        *[getattr(cascades[1], f) for f in
                                          ("cells", "albedo", "normal", "specular", "count",
                                           "mesh_has_finer")])]
    occupancy = CascadeOccupancy(moved)
    assert not occupancy.nested
    o = np.zeros((50, 3)) + [0.0, 0.0, 0.5]
    d = np.tile([0.0, 0.0, -1.0], (50, 1))
    assert occupancy.occluded(o, d, np.inf).all()


@pytest.mark.parametrize("samples", [1, 4])
def test_an_injection_after_a_move_marches_only_what_meets_it_and_equals_a_fresh_one(samples):
    snapshot = lit_snapshot(LIGHTS)
    before = room(block_at=(14, 14, 4))
    first = inject_direct_light(before, snapshot, samples=samples, keep_rays=True)
    assert first.rays is not None and first.reused == 0 and first.marched > 0

    after = room(block_at=(15, 13, 4))  # the block moved by a voxel
    kept = inject_direct_light(after, snapshot, samples=samples, rays=first.rays)
    fresh = inject_direct_light(after, snapshot, samples=samples)
    for mine, theirs in zip(kept, fresh, strict=True):
        assert np.array_equal(mine, theirs)
    voxels = sum(cv.voxel_count for cv in after)
    assert 0 < kept.relit < voxels / 4  # most voxels' rays never come near the block
    assert 0 < 5 * kept.marched < first.marched

    same = inject_direct_light(after, snapshot, samples=samples, rays=kept.rays)
    assert same.marched == same.relit == 0  # nothing moved: every voxel keeps its light
    for mine, theirs in zip(same, fresh, strict=True):
        assert np.array_equal(mine, theirs)
    back = inject_direct_light(before, snapshot, samples=samples, rays=same.rays)
    again = inject_direct_light(before, snapshot, samples=samples)
    for mine, theirs in zip(back, again, strict=True):  # and back: what was kept still holds
        assert np.array_equal(mine, theirs)


def two_blocks(shift):
    """``room``'s cascades with two 3³ blocks far apart in the finest (two limbs), both moved
    by ``shift`` voxels along x."""
    out = room(block_at=(0, 0, 40))  # (its 4³ block outside the grid: left out)
    first = out[0]
    blocks = [np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), -1).reshape(-1, 3)
              + np.asarray(at) + (shift, 0, 0) for at in ((5, 6, 4), (23, 24, 4))]
    keep = (first.cells < RES).all(axis=1)
    out[0] = voxels(first.grid, np.concatenate([first.cells[keep], *blocks]))
    return out


def test_rays_that_pass_between_two_moved_blocks_keep_their_result(monkeypatch):
    """Two limbs that move: the cells that changed are boxed part by part
    (``kept_rays.SPLIT``), not in one box spanning both, so voxels whose rays pass between
    them are not lit again; the light is still a fresh injection's."""
    from voxgi.voxgi_addon.gi import kept_rays

    snapshot = lit_snapshot(LIGHTS)
    before, after = two_blocks(0), two_blocks(1)
    fresh = inject_direct_light(after, snapshot, samples=1)
    relit = {}
    for split in (1, kept_rays.SPLIT):
        monkeypatch.setattr(kept_rays, "SPLIT", split)
        first = inject_direct_light(before, snapshot, samples=1, keep_rays=True)
        kept = inject_direct_light(after, snapshot, samples=1, rays=first.rays)
        for mine, theirs in zip(kept, fresh, strict=True):
            assert np.array_equal(mine, theirs)
        relit[split] = kept.relit
    assert 0 < relit[kept_rays.SPLIT] < 0.6 * relit[1], relit


def test_a_moved_light_marches_its_own_rays_again():
    before = room()
    first = inject_direct_light(before, lit_snapshot(LIGHTS), samples=1, keep_rays=True)
    moved = [LIGHTS[0], lamp("POINT", (0.9, 0.3, 2.5), radius=0.2), LIGHTS[2]]
    kept = inject_direct_light(before, lit_snapshot(moved), samples=1, rays=first.rays)
    fresh = inject_direct_light(before, lit_snapshot(moved), samples=1)
    for mine, theirs in zip(kept, fresh, strict=True):
        assert np.array_equal(mine, theirs)
    assert kept.relit == sum(cv.voxel_count for cv in before)  # other lights: all lit again
    assert 0 < kept.marched < first.marched / 2  # but only the point light's rays marched


def test_voxels_draw_their_rays_from_their_cells_not_their_order():
    """A voxel's shadow rays follow its cell: the same voxels in another order (another
    object merged in front of them) get the same light."""
    cascades = room()
    snapshot = lit_snapshot(LIGHTS)
    light = inject_direct_light(cascades, snapshot, samples=4)
    order = np.random.default_rng(5).permutation(cascades[0].voxel_count)
    shuffled = CascadeVoxels(cascades[0].grid, *[getattr(cascades[0], f)[order] for f in
                                                  ("cells", "albedo", "normal", "specular",
                                                   "count", "mesh_has_finer")])
    again = inject_direct_light([shuffled, *cascades[1:]], snapshot, samples=4)
    assert np.array_equal(again[0], light[0][order])
