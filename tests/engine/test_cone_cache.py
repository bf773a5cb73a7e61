"""Fast quality's cones read the radiance cache (voxgi_addon/gi/cone_bounces.py, issue 20): at
Bounces > 1 the voxels also reflect the cache's indirect light by their albedo, so the cones
that sample them carry it; at one bounce (no cache) the update's octrees are used unchanged."""
import dataclasses

import numpy as np
from snapshots import MaterialData, mesh, snapshot, translation

from voxgi.voxgi_addon.gi.cone_bounces import (
    FAST_CACHE_RESOLUTIONS,
    bounced_radiance,
    cone_octrees,
    fast_cache_settings,
)
from voxgi.voxgi_addon.gi.conetrace import ConeSettings, trace_diffuse_and_ao, trace_shadow
from voxgi.voxgi_addon.gi.radiance_cache import build_cache, face_points, with_faces
from voxgi.voxgi_addon.gi.update import GISettings, update_gi
from voxgi.voxgi_addon.preview.gather import GatherSettings
from voxgi.voxgi_addon.scene.geometry import world_triangles
from voxgi.voxgi_addon.scene.snapshot import RAY_ALL, RAY_SHADOW, LightData
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

SUN = LightData("Sun", "SUN", np.ones(3, np.float32), 3.0, np.eye(4))  # straight down
ALBEDO = 0.6


def box_scene(roof_visibility=RAY_ALL):
    """A floor and a roof 1 m above it (the roof's underside faces the floor), a sun above."""
    floor = ([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2), (0, 2, 3)])
    roof = ([(-2, -2, 1), (2, -2, 1), (2, 2, 1), (-2, 2, 1)], [(0, 2, 1), (0, 3, 2)])
    grey = MaterialData("grey", np.full(3, ALBEDO, np.float32))
    snap = snapshot([mesh("Floor", *floor), mesh("Roof", *roof)],
                    [("Floor", "Floor", translation()), ("Roof", "Roof", translation())], [grey])
    objects = [dataclasses.replace(o, visibility=roof_visibility) if o.name == "Roof" else o
               for o in snap.objects]
    snap = dataclasses.replace(snap, objects=objects, lights=[SUN])
    return snap, build_scene_caches(snap, 0.0625, 2)


def box_state(roof_visibility=RAY_ALL):
    snap, caches = box_scene(roof_visibility)
    return snap, update_gi(snap, caches, GISettings(resolution=64), anchor=np.zeros(3))


def uniform_cache(snap, value):
    """A cache (one iteration) whose every face holds ``value`` (E/π)."""
    cache = build_cache(world_triangles(snap), 16, rays=4)
    points, _ = face_points(cache)
    return with_faces(cache, np.full((len(points), 3), value))


def test_voxels_reflect_the_cache_by_their_albedo():
    snap, state = box_state()
    cache = uniform_cache(snap, 0.5)
    bounced = bounced_radiance(state.cascades, state.radiance, cache)
    added = np.concatenate([(after - before) / np.asarray(cv.albedo) for cv, before, after
                            in zip(state.cascades, state.radiance, bounced)])
    # (the coarser cascade's few voxels at the floor's rim lie outside the cache's grid: 0)
    read = np.mean(np.abs(added - 0.5) < 1e-4)
    assert read > 0.97, read
    assert np.abs(added).max() <= 0.5 + 1e-4
    assert bounced.emission is state.radiance.emission


def test_one_bounce_keeps_the_updates_octrees():
    _, state = box_state()
    octrees = cone_octrees(state, None)
    assert all(octree is state.octree for octree in octrees.values())


def test_diffuse_cones_see_the_cached_light_and_shadow_cones_the_same_occluders():
    """Under the roof a floor point's diffuse cones see the roof's underside (lit by nothing
    but the floor's light: 0 direct); with the cache's light E/π = c on it they see ≈ albedo ×
    c × the share of the hemisphere the roof covers. Shadow cones are unchanged."""
    snap, caches = box_scene()
    state = update_gi(snap, caches, GISettings(resolution=64), anchor=np.zeros(3))
    cache = uniform_cache(snap, 0.5)
    octrees = cone_octrees(state, cache)
    assert octrees["diffuse"] is not state.octree and octrees["glossy"] is octrees["diffuse"]
    assert octrees["shadow"] is octrees["diffuse"]  # the same voxels: one octree
    assert cone_octrees(state, cache) is octrees  # kept for the same update and cache
    again = update_gi(snap, caches, GISettings(resolution=64), anchor=np.zeros(3),
                      previous=state)
    assert again.reused == "all" and cone_octrees(again, cache) is octrees  # same octrees
    points = np.c_[np.linspace(-0.3, 0.3, 5), np.zeros(5), np.zeros(5)]
    normals = np.tile([0.0, 0.0, 1.0], (5, 1))
    cones = ConeSettings()
    before, ao = trace_diffuse_and_ao(state.octree, points, normals, cones)
    after, ao_after = trace_diffuse_and_ao(octrees["diffuse"], points, normals, cones)
    np.testing.assert_array_equal(ao, ao_after)
    roof_share = 1.0 - ao.mean()  # AO distance is 1 m: about what the roof covers
    assert np.abs(before).max() < 1e-3
    gained = (after - before).mean()
    assert 0.5 * ALBEDO * 0.5 * roof_share < gained < 1.5 * ALBEDO * 0.5, (gained, roof_share)
    up = points + np.array([0.0, 0.0, 2.5])
    np.testing.assert_allclose(trace_shadow(octrees["shadow"], points, normals, up, 0.05, cones),
                               trace_shadow(state.octree, points, normals, up, 0.05, cones),
                               atol=1e-6)


def test_a_shadow_view_keeps_its_own_octree():
    """With the roof hidden from shadow rays, the shadow cones keep the shadow rays' octree
    (occlusion only) while the diffuse and glossy ones get the cache."""
    snap, state = box_state(RAY_ALL & ~RAY_SHADOW)
    octrees = cone_octrees(state, uniform_cache(snap, 0.5))
    assert octrees["shadow"] is state.ray_views["shadow"].octree
    assert octrees["diffuse"] is not state.octree


def test_fast_takes_a_coarse_cache_where_the_resolution_is_auto():
    """Auto: the finest of FAST_CACHE_RESOLUTIONS within Auto's ray budget (never Accurate's
    64³); a set resolution and one bounce are kept."""
    snap, _ = box_state()
    tris = world_triangles(snap)
    auto = fast_cache_settings(GatherSettings(bounces=4), tris)
    assert auto.cache_resolution == FAST_CACHE_RESOLUTIONS[0]  # two 4 m planes: few faces
    assert fast_cache_settings(GatherSettings(bounces=4, cache_resolution=64), tris
                               ).cache_resolution == 64
    assert fast_cache_settings(GatherSettings(bounces=1), tris).cache_resolution == 0
    heavy = fast_cache_settings(GatherSettings(bounces=4, cache_rays=4096), tris)
    assert heavy.cache_resolution == FAST_CACHE_RESOLUTIONS[-1]  # over the budget: the coarsest
