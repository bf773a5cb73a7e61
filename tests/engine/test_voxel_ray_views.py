"""Cycles' ray visibility in the voxels (voxgi_addon/gi/ray_views.py, issue 18): an object hidden
from shadow rays casts no voxel shadow (injection's occupancy, the shadow cones' octree), one
hidden from diffuse rays is not in the diffuse cones' or AO's voxels, one hidden from glossy
rays is not in the glossy cones' — and a scene whose objects every ray sees builds one octree."""
import dataclasses

import numpy as np
from snapshots import MaterialData, mesh, snapshot, translation

from voxgi.voxgi_addon.gi.conetrace import ConeSettings, trace_diffuse_and_ao, trace_shadow
from voxgi.voxgi_addon.gi.light_injection import voxel_centres
from voxgi.voxgi_addon.gi.ray_views import view_octree
from voxgi.voxgi_addon.gi.update import GISettings, update_gi
from voxgi.voxgi_addon.scene.snapshot import RAY_ALL, RAY_DIFFUSE, RAY_GLOSSY, RAY_SHADOW, LightData
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

SUN = LightData("Sun", "SUN", np.ones(3, np.float32), 3.0, np.eye(4))  # straight down


def roofed(roof_visibility=RAY_ALL):
    """A 4 m floor and 1 m above it a 2 m roof, under a sun straight above."""
    floor = ([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], [(0, 1, 2), (0, 2, 3)])
    roof = ([(-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)], [(0, 2, 1), (0, 3, 2)])
    grey = MaterialData("grey", np.array([0.8, 0.8, 0.8], np.float32))
    snap = snapshot([mesh("Floor", *floor), mesh("Roof", *roof)],
                    [("Floor", "Floor", translation()), ("Roof", "Roof", translation())], [grey])
    objects = [dataclasses.replace(o, visibility=roof_visibility) if o.name == "Roof" else o
               for o in snap.objects]
    return dataclasses.replace(snap, objects=objects, lights=[SUN])


def state_of(snap, previous=None, caches=None):
    caches = caches or build_scene_caches(snap, 0.0625, 2)
    return update_gi(snap, caches, GISettings(resolution=64), anchor=np.zeros(3),
                     previous=previous)


def under_roof(cascade):
    centres = voxel_centres(cascade)
    return (centres[:, 2] < 0.1) & (np.abs(centres[:, :2]) < 0.6).all(axis=1)


def points_under_roof(count=8):
    points = np.c_[np.linspace(-0.5, 0.5, count), np.zeros(count), np.zeros(count)]
    return points, np.tile([0.0, 0.0, 1.0], (count, 1))


def test_every_ray_sees_every_object_one_octree():
    state = state_of(roofed())
    assert state.ray_views == {}
    assert all(view_octree(state, kind) is state.octree for kind in ("diffuse", "glossy", "shadow"))


def test_a_roof_hidden_from_shadow_rays_casts_no_voxel_shadow():
    """The floor's voxels under the roof are lit by the sun (albedo × 3/π) as if it were not
    there, and the shadow cones pass it; it still is in the diffuse and glossy voxels."""
    shadowed, open_sky = state_of(roofed()), state_of(roofed(RAY_ALL & ~RAY_SHADOW))
    lit = 0.8 * 3.0 / np.pi
    for state, expected in ((shadowed, 0.0), (open_sky, lit)):
        below = under_roof(state.cascades[0])
        assert below.sum() > 50
        np.testing.assert_allclose(state.radiance[0][below], expected, atol=0.02 * lit)
    assert open_sky.cascades[0].voxel_count == shadowed.cascades[0].voxel_count  # still seen
    assert set(open_sky.ray_views) == {"shadow"}
    assert open_sky.ray_views["shadow"].cascades[0].voxel_count < open_sky.cascades[0].voxel_count
    points, normals = points_under_roof()
    up = points + np.array([0.0, 0.0, 3.0])  # (inside the coarsest cascade)
    cones = ConeSettings()
    blocked = trace_shadow(view_octree(shadowed, "shadow"), points, normals, up, 0.05, cones)
    free = trace_shadow(view_octree(open_sky, "shadow"), points, normals, up, 0.05, cones)
    assert blocked.max() < 0.1 and free.min() > 0.95


def test_a_roof_hidden_from_diffuse_rays_is_not_in_the_diffuse_cones():
    """No AO and no bounce light from the roof for the diffuse cones; the glossy cones still
    see it, and it still shadows the floor's voxels."""
    seen, hidden = state_of(roofed()), state_of(roofed(RAY_ALL & ~RAY_DIFFUSE))
    points, normals = points_under_roof()
    cones = ConeSettings(ao_distance=3.0)  # (the roof is 1 m above the floor)
    _, ao_seen = trace_diffuse_and_ao(view_octree(seen, "diffuse"), points, normals, cones)
    _, ao_hidden = trace_diffuse_and_ao(view_octree(hidden, "diffuse"), points, normals, cones)
    assert ao_seen.max() < 0.7 and ao_hidden.min() > 0.95
    assert set(hidden.ray_views) == {"glossy", "shadow"}
    assert hidden.ray_views["glossy"].cascades[0].voxel_count == seen.cascades[0].voxel_count
    assert np.abs(hidden.radiance[0][under_roof(hidden.cascades[0])]).max() < 1e-3  # shadowed


def test_glossy_hidden_roof_is_left_out_of_the_glossy_voxels_only():
    state = state_of(roofed(RAY_ALL & ~RAY_GLOSSY))
    assert set(state.ray_views) == {"glossy"}
    glossy = state.ray_views["glossy"]
    assert glossy.cascades[0].voxel_count < state.cascades[0].voxel_count
    assert glossy.octree is view_octree(state, "glossy")


def test_a_visibility_change_alone_updates_the_voxels():
    """Toggling a ray visibility moves nothing, yet the next update must not reuse the light."""
    snap = roofed()
    caches = build_scene_caches(snap, 0.0625, 2)
    first = state_of(snap, caches=caches)
    assert state_of(snap, first, caches).reused == "all"
    toggled = state_of(roofed(RAY_ALL & ~RAY_SHADOW), first, caches)
    assert toggled.reused != "all" and "shadow" in toggled.ray_views
