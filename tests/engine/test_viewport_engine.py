"""The viewport's engine parts: a camera from view matrices, the update planner, incremental
cache rebuilds (fingerprints, undo) and the GI update that reuses cascades."""
import dataclasses

import numpy as np
import pytest
from meshes import box, uv_sphere
from snapshots import MaterialData, mesh, snapshot, translation

from voxgi.voxgi_addon.gi.incremental import update_gi_stages
from voxgi.voxgi_addon.gi.update import GISettings, update_gi
from voxgi.voxgi_addon.scene.camera import camera_rays, view_projection
from voxgi.voxgi_addon.scene.changes import (
    STAGES,
    ObjectEntry,
    SceneIndex,
    StageCounter,
    UpdateRecord,
    full_plan,
    plan_updates,
    view_plan,
)
from voxgi.voxgi_addon.scene.snapshot import CameraData, LightData
from voxgi.voxgi_addon.scene.view_camera import border_rect, camera_from_view, clip_range, crop_window
from voxgi.voxgi_addon.voxelize.incremental import CacheStore, refresh_caches
from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

# ------------------------------------------------------------------ camera from view matrices


def perspective(fov_x, aspect, near, far, shift=(0.0, 0.0)):
    p = np.zeros((4, 4))
    p[0, 0] = 1 / np.tan(fov_x / 2)
    p[1, 1] = p[0, 0] * aspect
    p[0, 2], p[1, 2] = shift
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2 * far * near / (far - near)
    p[3, 2] = -1
    return p


def orthographic(half_w, half_h, near, far):
    p = np.eye(4)
    p[0, 0], p[1, 1] = 1 / half_w, 1 / half_h
    p[2, 2] = -2 / (far - near)
    p[2, 3] = -(far + near) / (far - near)
    return p


def look_at(eye, target):
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = eye - target
    z /= np.linalg.norm(z)
    x = np.cross([0, 0, 1.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    world = np.eye(4)
    world[:3, :3] = np.stack([x, y, z], 1)
    world[:3, 3] = eye
    return world


@pytest.mark.parametrize("window", [perspective(1.0, 4 / 3, 0.1, 50.0, (0.1, -0.05)),
                                    orthographic(3.0, 2.25, -10.0, 40.0)])
def test_camera_from_view_reproduces_the_view_projection(window):
    world = look_at((4, -3, 2), (0, 0, 0.5))
    camera = camera_from_view(np.linalg.inv(world), window, 64, 48)
    assert camera.type == ("ORTHO" if window[3, 3] == 1 else "PERSP")
    assert np.allclose(camera.world_matrix, world)
    # The rasterizer's matrix is the view's projection after the view matrix: what Blender drew.
    assert np.allclose(view_projection(camera, 64, 48), window @ np.linalg.inv(world), atol=1e-9)
    near, far = clip_range(window)
    assert (camera.clip_start, camera.clip_end) == pytest.approx((near, far))
    # The centre pixel's ray goes where the view's centre (shifted) looks.
    origins, dirs = camera_rays(camera, 64, 48)
    assert np.all(np.isfinite(origins)) and np.allclose(np.linalg.norm(dirs, axis=1), 1)


def test_camera_from_view_matches_a_scene_camera_s_own_description():
    """The scene camera described by its matrices gives the same rays as its snapshot."""
    world = look_at((0, -6, 1), (0, 0, 1))
    window = perspective(0.8, 4 / 3, 0.1, 100.0)
    scene_camera = CameraData("Camera", world, window, (80, 60), "PERSP", clip_start=0.1, clip_end=100.0)
    view_camera = camera_from_view(np.linalg.inv(world), window, 80, 60)
    for a, b in zip(camera_rays(scene_camera), camera_rays(view_camera)):
        assert np.allclose(a, b)


# ------------------------------------------------------------------ the update planner

INDEX = SceneIndex(
    objects={
        "Cube": ObjectEntry("CubeMesh", "CubeMesh", ("Red",)),
        "Cube.001": ObjectEntry("CubeMesh", "CubeMesh", ("Red",)),  # a linked duplicate
        "Floor": ObjectEntry("FloorMesh", "FloorMesh", ("Grey",)),
        "Tube": ObjectEntry("Tube (modified)", "TubeMesh", ("Grey",), "skinned", "Rig", "RigData"),
    },
    lights=frozenset({"Lamp"}), light_data=frozenset({"LampData"}))
MOVE = {"snapshot", "transform", "inject", "octree", "trace"}


def rec(id_type, name, t=False, g=False, s=False, object_type=""):
    return UpdateRecord(id_type, name, t, g, s, object_type)


@pytest.mark.parametrize("records, stages, voxelize, albedo", [
    ([rec("OBJECT", "Cube", t=True, object_type="MESH")], MOVE, set(), set()),
    # posing: Blender flags the armature and re-evaluates the skinned mesh (geometry)
    ([rec("OBJECT", "Rig", g=True, object_type="ARMATURE"), rec("ARMATURE", "RigData", t=True, g=True),
      rec("OBJECT", "Tube", g=True, object_type="MESH")], MOVE, set(), set()),
    ([rec("OBJECT", "Lamp", t=True, object_type="LIGHT")], {"snapshot", "inject", "octree", "trace"},
     set(), set()),
    ([rec("OBJECT", "Lamp", g=True, s=True, object_type="LIGHT"), rec("LIGHT", "LampData", True, True, True)],
     {"snapshot", "inject", "octree", "trace"}, set(), set()),
    ([rec("OBJECT", "Cube", g=True, s=True, object_type="MESH"), rec("MESH", "CubeMesh", True, True, True)],
     MOVE | {"voxelize"}, {"CubeMesh"}, set()),
    ([rec("OBJECT", "Cube", s=True, object_type="MESH"), rec("MESH", "CubeMesh", s=True),
      rec("MATERIAL", "Red", s=True), rec("NODETREE", "Shader Nodetree")],
     MOVE | {"albedo"}, set(), {"CubeMesh"}),
    ([rec("OBJECT", "Camera", t=True, object_type="CAMERA")], set(), set(), set()),
    ([rec("SCENE", "Scene", True, True), rec("COLLECTION", "Scene Collection", g=True),
      rec("OBJECT", "Floor", s=True, object_type="MESH")], set(), set(), set()),
    ([rec("SCENE", "Scene"), rec("VISIBILITY", "visible objects", g=True)], MOVE, set(), set()),
    ([rec("OBJECT", "New", t=True, g=True, object_type="MESH")], MOVE, set(), set()),
])
def test_plan_is_the_cheapest_correct_work(records, stages, voxelize, albedo):
    plan = plan_updates(records, INDEX)
    assert plan.stages == stages
    assert plan.voxelize == voxelize and plan.albedo == albedo
    assert "voxelize" not in plan.stages or plan.full_snapshot
    assert plan.triggers or not plan.stages


def test_plan_without_results_does_everything_and_views_only_trace():
    assert plan_updates([], None) == full_plan()
    assert full_plan().rescan and "voxelize" in full_plan().stages
    assert view_plan(False).stages == {"trace"}
    assert view_plan(True).stages == {"transform", "inject", "octree", "trace"}
    counter = StageCounter()
    for plan in (view_plan(False), plan_updates([rec("MESH", "FloorMesh", g=True)], INDEX)):
        counter.count(plan)
    assert counter.stages["trace"] == 2 and counter.stages["voxelize"] == 1
    assert counter.voxelized == ["FloorMesh"] and set(counter.stages) == set(STAGES)


def test_merged_plans_keep_both_changes():
    a = plan_updates([rec("MESH", "FloorMesh", g=True)], INDEX)
    b = plan_updates([rec("MATERIAL", "Red", s=True)], INDEX)
    m = a.merged(b)
    assert m.voxelize == {"FloorMesh"} and m.albedo == {"CubeMesh"} and m.full_snapshot


# ------------------------------------------------------------------ incremental caches

RED = MaterialData("Red", np.array([0.9, 0.1, 0.1], np.float32))
GREY = MaterialData("Grey", np.array([0.5, 0.5, 0.5], np.float32))


def scene(sphere_shift=0.0, colour=(0.9, 0.1, 0.1), cube_at=(0.0, 0.0, 0.0), light_at=(0, 0, 3)):
    pos, tris = uv_sphere(rings=8, segments=12, radius=0.4)
    pos = np.asarray(pos) + [sphere_shift, 0, 0]
    cube_pos, cube_tris = box((0.5, 0.5, 0.5))
    materials = [dataclasses.replace(RED, base_color=np.array(colour, np.float32)), GREY]
    snap = snapshot([mesh("Sphere", pos, tris, 0), mesh("Cube", cube_pos, cube_tris, 1)],
                    [("Sphere", "Sphere", translation(1.0)), ("Cube", "Cube", translation(*cube_at))],
                    materials)
    light = LightData("Lamp", "POINT", np.ones(3, np.float32), 200.0, translation(*light_at))
    camera = CameraData("Camera", look_at((0, -4, 1), (0, 0, 0)), perspective(0.9, 4 / 3, 0.1, 50),
                        (40, 30))
    return dataclasses.replace(snap, lights=[light], camera=camera)


def test_refresh_voxelizes_only_what_changed_and_undo_reuses():
    store = CacheStore()
    first = refresh_caches(store, scene(), 0.1, 2)
    assert first.voxelized == ["Cube", "Sphere"] and first.reused == []
    reference = build_scene_caches(scene(), 0.1, 2)
    assert first.caches.total_voxels == reference.total_voxels
    assert [s.voxel_count for s in first.caches.cascade_stats] == \
        [s.voxel_count for s in reference.cascade_stats]

    moved = refresh_caches(store, scene(cube_at=(0.3, 0.2, 0.0), light_at=(1, 1, 3)), 0.1, 2)
    assert moved.voxelized == [] and moved.caches.caches["Cube"] is first.caches.caches["Cube"]

    edited = refresh_caches(store, scene(sphere_shift=0.05), 0.1, 2)
    assert edited.voxelized == ["Sphere"] and edited.reused == ["Cube"]
    assert edited.caches.caches["Cube"] is first.caches.caches["Cube"]
    assert edited.caches.caches["Sphere"] is not first.caches.caches["Sphere"]

    recoloured = refresh_caches(store, scene(sphere_shift=0.05, colour=(0.1, 0.9, 0.1)), 0.1, 2)
    assert recoloured.voxelized == ["Sphere"]
    colours = recoloured.caches.caches["Sphere"][0].attributes().albedo
    assert colours[:, 1].mean() > colours[:, 0].mean()  # green now

    undone = refresh_caches(store, scene(sphere_shift=0.05), 0.1, 2)  # undo the colour
    assert undone.voxelized == [] and undone.caches.caches["Sphere"] is edited.caches.caches["Sphere"]
    respan = refresh_caches(store, scene(), 0.2, 2)  # a setting every key depends on
    assert respan.voxelized == ["Cube", "Sphere"]


def test_refresh_drops_deleted_keys_and_voxelizes_new_ones():
    store = CacheStore()
    refresh_caches(store, scene(), 0.1, 1)
    snap = scene()
    fewer = dataclasses.replace(snap, objects=[o for o in snap.objects if o.name == "Cube"])
    result = refresh_caches(store, fewer, 0.1, 1)
    assert set(result.caches.caches) == {"Cube"} and result.voxelized == []
    again = refresh_caches(store, snap, 0.1, 1)  # undo the delete: its caches come back
    assert again.voxelized == [] and set(again.caches.caches) == {"Cube", "Sphere"}


# ------------------------------------------------------------------ GI stages


def test_light_move_reuses_the_cascades_and_equals_a_full_update():
    settings = GISettings(resolution=16, dense_depth=3)
    store = CacheStore()
    snap = scene()
    caches = refresh_caches(store, snap, 0.1, 2).caches
    first = update_gi_stages(snap, caches, settings, None, full_plan().stages)
    assert first.stages == ("transform", "inject", "octree")

    lit = scene(light_at=(1.0, -1.0, 2.0))
    caches2 = refresh_caches(store, lit, 0.1, 2).caches
    light_only = plan_updates([rec("OBJECT", "Lamp", t=True, object_type="LIGHT")],
                              SceneIndex(lights=frozenset({"Lamp"})))
    again = update_gi_stages(lit, caches2, settings, first, light_only.stages)
    assert again.stages == ("inject", "octree")
    assert again.state.cascades is first.state.cascades
    full = update_gi(lit, caches2, settings)
    for mine, theirs in zip(again.state.radiance, full.radiance):
        assert np.allclose(mine, theirs, atol=1e-6)
    assert np.allclose(again.state.octree.levels[-1].radiance, full.octree.levels[-1].radiance,
                       atol=1e-6)

    moved = scene(cube_at=(0.2, 0, 0), light_at=(1.0, -1.0, 2.0))
    caches3 = refresh_caches(store, moved, 0.1, 2).caches
    third = update_gi_stages(moved, caches3, settings, again, {"transform", "inject", "octree"})
    assert third.stages == ("transform", "inject", "octree")
    assert third.state.cascades is not again.state.cascades


# ------------------------------------------------------------------ a view's Render Region


@pytest.mark.parametrize("ortho", [False, True])
def test_a_cropped_window_sees_exactly_its_pixels_of_the_view(ortho):
    """The Rendered view's Render Region: the crop's rays are the view's rays through the
    same pixels, and its clipping range is the view's."""
    if ortho:
        window = np.diag([0.5, 0.5 * 4 / 3, -0.02, 1.0])
        window[0, 3], window[2, 3] = 0.1, -1.0
    else:
        window = perspective(np.radians(60), 4 / 3, 0.1, 100, shift=(0.2, -0.1))
    view = np.linalg.inv(translation(0.3, -0.2, 2.0))
    camera = camera_from_view(view, window, 40, 30)
    origins, directions = (a.reshape(30, 40, 3) for a in camera_rays(camera))
    x0, y0, w, h = 7, 4, 18, 11  # from the bottom left
    crop = camera_from_view(view, crop_window(window, (x0, y0, w, h), 40, 30), w, h)
    o, d = (a.reshape(h, w, 3) for a in camera_rays(crop))
    rows = slice(30 - y0 - h, 30 - y0)  # (rays' rows top first)
    assert np.allclose(d, directions[rows, x0:x0 + w], atol=1e-9)
    assert np.allclose(o, origins[rows, x0:x0 + w], atol=1e-9)
    assert crop.type == camera.type and (crop.clip_start, crop.clip_end) == pytest.approx(
        (camera.clip_start, camera.clip_end))
    with pytest.raises(ValueError, match="empty"):
        crop_window(window, (3, 3, 0, 5), 40, 30)


def test_a_render_region_is_cut_as_blender_cuts_a_renders_region():
    assert border_rect((0.2, 0.3, 0.7, 0.85), 64, 48) == (12, 14, 32, 26)
    assert border_rect((0.0, 0.0, 1.0, 1.0), 64, 48) == (0, 0, 64, 48)
    # clipped to the image; a sliver keeps one pixel; outside the image, nothing
    assert border_rect((-0.5, 0.9, 0.5, 1.7), 10, 10) == (0, 9, 5, 1)
    assert border_rect((0.31, 0.31, 0.311, 0.311), 10, 10) == (3, 3, 1, 1)
    assert border_rect((1.2, 0.0, 1.5, 1.0), 10, 10)[2] == 0
    assert border_rect((0.5, 0.5, 0.5, 0.9), 10, 10)[2] == 0

