"""Fast quality sees every light (issue 17 point 5): cones that leave the voxels see the world,
voxels carry their emission, and direct light with shadows by cones has the world and the
emissive surfaces (docs/gi_pipeline.md "Fast quality: world and emission")."""
import dataclasses

import numpy as np
import pytest
from snapshots import MaterialData, mesh, snapshot, translation
from volumes import DenseMipVolume

from voxgi.voxgi_addon.gi.cone_shadows import cone_shadowed_direct, emitter_groups
from voxgi.voxgi_addon.gi.conetrace import (
    LUMINANCE,
    ConeSettings,
    trace_diffuse_and_ao,
    trace_glossy,
    trace_world_visibility,
    world_mips,
)
from voxgi.voxgi_addon.gi.emitters import clipped_form_factors, emitter_light
from voxgi.voxgi_addon.gi.light_injection import SHADOW_START_VOXELS, voxel_centres, voxel_emission
from voxgi.voxgi_addon.gi.svo import build_octree
from voxgi.voxgi_addon.gi.update import GISettings, update_gi
from voxgi.voxgi_addon.gi.world_light import unshadowed, world_light
from voxgi.voxgi_addon.preview.volume_textures import world_mip_rows
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import WorldData
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

R, SIZE = 32, 8.0
GLOW = np.array([2.0, 1.0, 0.5])


def uniform_world(value=0.7):
    return world_mips(np.full((8, 16, 3), value, np.float32))


def up_points(count=6):
    rng = np.random.default_rng(3)
    points = np.c_[rng.uniform(-1, 1, (count, 2)), np.full(count, -3.0)]
    return points, np.tile([0.0, 0.0, 1.0], (count, 1))


def test_cones_in_empty_space_see_the_uniform_world_whole():
    """Nothing in the way: the diffuse cone set sees exactly L (irradiance/π of a uniform
    world), a glossy cone sees L."""
    empty = DenseMipVolume(np.zeros((R, R, R), bool), np.zeros((R, R, R, 3)), [-SIZE / 2] * 3, SIZE)
    points, normals = up_points()
    seen = trace_world_visibility(empty, points, normals, ConeSettings(), uniform_world(0.7))
    np.testing.assert_allclose(seen[:, :3], 0.7, rtol=1e-6)
    np.testing.assert_allclose(seen[:, 3], 0.7 * LUMINANCE.sum(), rtol=1e-6)
    glossy = trace_glossy(empty, points, normals, np.tile([0.3, 0.0, -1.0], (6, 1)) / np.hypot(0.3, 1),
                          np.full(6, 0.3), ConeSettings(), uniform_world(0.7))
    np.testing.assert_allclose(glossy, 0.7, rtol=1e-6)


def test_a_roof_hides_the_world_from_the_cones_as_it_occludes_them():
    """Under a wide opaque roof the cones see only the sky low between it and the ground: what
    they see of the world follows what AO (cones reaching as far) leaves open, and a glowing
    roof does not count as sky."""
    z = (np.arange(R) + 0.5) / R * SIZE - SIZE / 2
    roof = np.zeros((R, R, R), bool)
    roof[:, :, np.abs(z + 2.0).argmin()] = True     # a roof 1 m above the points, 8 m wide
    volume = DenseMipVolume(roof, np.full((R, R, R, 3), 5.0), [-SIZE / 2] * 3, SIZE)
    points, normals = up_points()
    settings = ConeSettings(max_distance=20.0, ao_distance=20.0)
    seen = trace_world_visibility(volume, points, normals, settings, uniform_world(1.0))
    _, ao = trace_diffuse_and_ao(volume, points, normals, settings)
    share = seen[:, :3].mean(axis=1)
    assert (share < 0.5).all()                      # most of the hemisphere is roof
    np.testing.assert_allclose(share, ao, atol=0.15)  # and the cones agree with AO on what is open


def test_world_mips_prefilter_by_the_cone_aperture():
    """A map with a bright patch: a mirror-like cone sees the patch's own radiance, a wide cone
    its average over the cone; every map of the chain keeps the map's mean."""
    image = np.full((32, 64, 3), 0.1, np.float32)
    image[8:10, 20:22] = 100.0
    mips = world_mips(image)
    assert [len(m) for m in mips.maps] == [32, 16, 8, 4, 2]
    for m in mips.maps:
        assert m.shape[1] == 2 * m.shape[0]
        np.testing.assert_allclose(m.mean(), image.mean(), rtol=1e-5)
    el, phi = np.pi / 2 - 9.0 * np.pi / 32, -np.pi + 21.0 * 2 * np.pi / 64  # the patch's centre
    towards = np.array([[np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)]])
    sharp = mips.radiance(towards, np.radians(1.0))
    wide = mips.radiance(towards, np.radians(30.0))
    assert sharp[0, 0] > 50.0
    assert 0.1 < wide[0, 0] < 0.2 * sharp[0, 0]
    assert world_mips(np.zeros((8, 16, 3))) is None and world_mips(None) is None


def test_world_mips_pack_for_the_gpu_after_the_parameters():
    mips = world_mips(np.random.default_rng(1).uniform(0, 2, (16, 32, 3)).astype(np.float32))
    rows = world_mip_rows(mips, 200)
    count = len(mips.maps)
    assert rows[-1].tolist() == [count, 0.0, 0.0, -1.0]
    for k, image in enumerate(mips.maps):
        first, height = rows[len(rows) - 1 - count + k, :2]
        assert height == len(image)
        at = int(first) - 200
        np.testing.assert_array_equal(rows[at:at + image.size // 3, :3], image.reshape(-1, 3))


def room(glow=GLOW, world=None):
    """A 4 m floor, and 1 m above it a 1 m emissive panel (both sides glow)."""
    floor = ([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2), (0, 2, 3)])
    panel = ([(-0.5, -0.5, 1), (0.5, -0.5, 1), (0.5, 0.5, 1), (-0.5, 0.5, 1)], [(0, 2, 1), (0, 3, 2)])
    materials = [MaterialData("grey", np.array([0.8, 0.8, 0.8], np.float32)),
                 MaterialData("glow", np.array([0.8, 0.8, 0.8], np.float32),
                              emission=np.asarray(glow, np.float32))]
    snap = snapshot([mesh("Floor", *floor, 0), mesh("Panel", *panel, 1)],
                    [("Floor", "Floor", translation()), ("Panel", "Panel", translation())], materials)
    return dataclasses.replace(snap, world=world or WorldData())


def room_state(snap, light_samples=16):
    caches = build_scene_caches(snap, 0.0625, 2)
    return update_gi(snap, caches, GISettings(resolution=64, light_samples=light_samples),
                     anchor=np.zeros(3))


def test_emissive_voxels_glow_and_light_their_neighbours():
    """The panel's voxels hold its emission; the floor's voxels under it are lit by it as Cycles
    lights them (albedo × the panel's exact E/π, voxel shadows) — what diffuse cones bounce."""
    state = room_state(room())
    assert state.octree.emission is not None
    cv, radiance, emission = state.cascades[0], state.radiance[0], state.radiance.emission[0]
    centres = voxel_centres(cv)
    panel = (np.abs(centres[:, 2] - 1.0) < 0.04) & (np.abs(centres[:, :2]) < 0.45).all(axis=1)
    assert panel.sum() > 100
    np.testing.assert_allclose(emission[panel], np.broadcast_to(GLOW, (panel.sum(), 3)), rtol=1e-5)
    assert (radiance[panel] >= emission[panel] - 1e-6).all()
    beside = (np.abs(centres[:, 2]) < 0.04) & (np.abs(centres[:, :2]) > 1.5).any(axis=1)
    assert beside.any() and np.abs(emission[beside]).max() == 0.0
    under = (np.abs(centres[:, 2]) < 0.04) & (np.linalg.norm(centres[:, :2], axis=1) < 0.15)
    corners = np.array([[-0.5, -0.5, 1], [0.5, -0.5, 1], [0.5, 0.5, 1], [-0.5, 0.5, 1]], float)
    lifted = centres[under] + [0.0, 0.0, SHADOW_START_VOXELS * cv.grid.span]  # where it is lit
    exact = clipped_form_factors(lifted, np.tile([0.0, 0.0, 1.0], (under.sum(), 1)),
                                 corners[[[0, 2, 1], [0, 3, 2]]]).sum(axis=1)
    expected = 0.8 * exact[:, None] * GLOW
    np.testing.assert_allclose(radiance[under].mean(axis=0), expected.mean(axis=0), rtol=0.1)


def test_cones_see_emission_as_light_only_where_it_is_not_direct():
    """A glossy cone from the floor up to the panel sees its emission; the diffuse cones, whose
    light is Diffuse Indirect (one bounce), do not — the panel is direct light there — and give
    what an octree of the voxels' radiance without emission gives."""
    state = room_state(room())
    point, up = np.array([[0.0, 0.3, 0.0]]), np.array([[0.0, 0.0, 1.0]])
    glossy = trace_glossy(state.octree, point, up, np.array([[0.0, 0.0, -1.0]]), np.array([0.2]),
                          ConeSettings())
    assert glossy[0] == pytest.approx(GLOW, rel=0.3)
    diffuse, _ = trace_diffuse_and_ao(state.octree, point, up, ConeSettings())
    bounce = [r - e for r, e in zip(state.radiance, state.radiance.emission)]
    plain = build_octree(state.cascades, bounce, 6, one_sided_leaves=True)
    expected, _ = trace_diffuse_and_ao(plain, point, up, ConeSettings())
    np.testing.assert_allclose(diffuse, expected, rtol=1e-3, atol=1e-6)
    seen_all, _ = trace_diffuse_and_ao(dataclasses.replace(state.octree, emission_build=None), point, up,
                                       ConeSettings())
    assert diffuse.sum() < 0.1 * seen_all.sum()  # what subtracting the emission takes away


def test_voxel_emission_weighs_what_the_triangle_covers():
    """A triangle crossing a whole voxel makes it glow fully; a voxel it covers in part glows
    in part."""
    from voxgi.voxgi_addon.gi.cascades import CascadeGrid, CascadeVoxels

    grid = CascadeGrid(0, 1.0, 4, np.zeros(3))
    cells = np.array([[0, 0, 1], [1, 0, 1]], np.int32)
    voxels = CascadeVoxels(grid, cells, np.full((2, 3), 0.5, np.float32),
                           np.tile([0, 0, 1.0], (2, 1)).astype(np.float32), np.zeros(2, np.float32),
                           np.ones(2, np.int32), np.zeros(2, bool))
    # a square over cell (0, 0, 1) whole and a quarter of cell (1, 0, 1), at z = 1.5
    quad = np.array([[0, 0, 1.5], [1.5, 0, 1.5], [1.5, 0.5, 1.5], [0, 0.5, 1.5], [0, 1, 1.5], [1, 1, 1.5]])
    corners = np.stack([quad[[0, 1, 2]], quad[[0, 2, 3]], quad[[3, 5, 4]], quad[[3, 2, 5]]])
    corners[3] = [[0, 0.5, 1.5], [1, 0.5, 1.5], [1, 1, 1.5]]
    glow = voxel_emission([voxels], corners, np.tile([4.0, 2.0, 1.0], (4, 1)))[0]
    np.testing.assert_allclose(glow[0], [4.0, 2.0, 1.0], rtol=1e-4)
    np.testing.assert_allclose(glow[1], np.array([4.0, 2.0, 1.0]) * 0.25, rtol=1e-4)
    # the clipped triangles are kept per grid and emitter (a posed update keeps both): a grid
    # moved by a cell, or the emitter moved, is clipped again
    moved = CascadeVoxels(CascadeGrid(0, 1.0, 4, np.array([-1.0, 0.0, 0.0])),
                          (cells + [1, 0, 0]).astype(np.int32), voxels.albedo, voxels.normal,
                          voxels.specular, voxels.count, voxels.mesh_has_finer)
    np.testing.assert_allclose(voxel_emission([moved], corners, np.tile([4.0, 2.0, 1.0], (4, 1)))[0],
                               glow, rtol=1e-6)
    shifted = voxel_emission([voxels], corners + [1.0, 0.0, 0.0], np.tile([4.0, 2.0, 1.0], (4, 1)))[0]
    np.testing.assert_allclose(shifted[0], 0.0, atol=1e-6)
    np.testing.assert_allclose(shifted[1], [4.0, 2.0, 1.0], rtol=1e-4)


def test_cone_shadows_light_with_the_world_and_each_emitter():
    """Shadows by cones: a point with open sky gets the world's exact E/π; each connected
    emitter is one shadow cone of its own, and where nothing is in the way the emitters give
    their exact unshadowed light; the panel does not light itself."""
    sky = np.full((8, 16, 3), 0.5, np.float32)
    snap = room(world=WorldData(np.full(3, 0.5, np.float32), 1.0, sky, "grey sky"))
    state = room_state(snap, light_samples=1)
    world = world_light(snap.world)
    far = np.array([[1.8, 1.8, 0.0]])
    up = np.array([[0.0, 0.0, 1.0]])
    lit = cone_shadowed_direct(state.octree, far, up, [world], ConeSettings())
    exact = unshadowed(world, up)
    assert lit[0] == pytest.approx(exact[0], rel=0.12)
    assert (lit[0] <= exact[0] + 1e-6).all()
    # two emitters: the panel and a small separate tile
    tris = world_triangles(snap)
    tile = np.array([[[1.5, -1.6, 0.5], [1.7, -1.6, 0.5], [1.7, -1.4, 0.5]]])
    both = dataclasses.replace(tris, positions=np.concatenate([tris.positions, tile]),
                               normals=np.concatenate([tris.normals, [[0, 0, 1.0]]]),
                               materials=np.concatenate([tris.materials, [1]]),
                               objects=np.concatenate([tris.objects, [2]]))
    emitters = emitter_light(both, np.array([[0, 0, 0], GLOW, [0, 0, 0]], float))
    groups = emitter_groups(emitters)
    assert sorted(len(g.corners) for g in groups) == [1, 2]
    np.testing.assert_allclose(sum(g.area.sum() for g in groups), emitters.area.sum())
    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct

    points = np.array([[0.0, 0.2, 0.0], [1.2, -1.2, 0.0]])
    normals = np.tile(up, (2, 1))
    direct = cone_shadowed_direct(state.octree, points, normals, [emitters], ConeSettings())
    unshadowed_sum = diffuse_direct(points, normals, [emitters], None)
    assert (unshadowed_sum[:, 0] > 0.05).all()
    np.testing.assert_allclose(direct, unshadowed_sum, rtol=0.1)
    on_panel = cone_shadowed_direct(state.octree, np.array([[0.0, 0.0, 1.0]]), -up, [emitters],
                                    ConeSettings())
    assert on_panel[0, 0] < 0.05 * direct[0, 0]  # from the tile only, far away and low


def test_an_emission_edit_alone_relights_the_voxels():
    """Changing only a material's emission (nothing moved) must not reuse the previous
    update's light: the voxels glow with the new emission."""
    snap = room()
    caches = build_scene_caches(snap, 0.0625, 2)
    settings = GISettings(resolution=64)
    first = update_gi(snap, caches, settings, anchor=np.zeros(3))
    dimmer = [snap.materials[0], dataclasses.replace(snap.materials[1],
                                                     emission=np.float32(0.25) * GLOW.astype(np.float32))]
    again = update_gi(dataclasses.replace(snap, materials=dimmer), caches, settings,
                      anchor=np.zeros(3), previous=first)
    assert again.reused != "all"
    glow = again.radiance.emission[0]
    assert glow.max() == pytest.approx(0.25 * GLOW.max(), rel=1e-4)
    same = update_gi(snap, caches, settings, anchor=np.zeros(3), previous=first)
    assert same.reused == "all"  # an unchanged scene still reuses everything


def test_many_separate_emitters_share_a_few_shadow_cones():
    """Twenty glowing tiles: the strongest stay one cone each, the rest share one, and every
    triangle is in exactly one group."""
    from voxgi.voxgi_addon.gi.cone_shadows import MAX_EMITTER_CONES
    from voxgi.voxgi_addon.scene.geometry import SceneTriangles

    tiles = np.array([[[x, 0, 2], [x + 0.2, 0, 2], [x, 0.2, 2]] for x in np.arange(20) * 0.5], float)
    strength = np.arange(1, 21, dtype=float)
    tris = SceneTriangles(tiles, np.tile([0, 0, 1.0], (20, 1)), np.arange(20, dtype=np.int32),
                          np.arange(20, dtype=np.int32))
    emitters = emitter_light(tris, np.r_[strength[:, None] * [1.0, 1.0, 1.0], [[0, 0, 0]]])
    groups = emitter_groups(emitters)
    assert len(groups) == MAX_EMITTER_CONES
    sizes = sorted(len(g.corners) for g in groups)
    assert sizes == [1] * (MAX_EMITTER_CONES - 1) + [20 - MAX_EMITTER_CONES + 1]
    strongest = sorted(float(g.radiance.max()) for g in groups if len(g.corners) == 1)
    assert strongest == list(strength[-(MAX_EMITTER_CONES - 1):])
