"""View-fitted cascades in Blender (docs/gi_pipeline.md "View-fitted cascades"): a 5 m room
seen from 12 m away. With the defaults (Auto) the finest cascades hold the room and cover the
visible geometry; Manual keeps the camera-anchored cascades, whose finest grids stay empty."""
import bpy
import numpy as np
import scenes

ROOM = 5.0
CAMERA = (0.0, -12.0, 2.5)


def build_far_room(scene):
    """A 5 m Cornell-style room (open at -Y, normals inwards, two blocks) lit by a point light,
    seen through its open side by a 35 mm camera 12 m from its centre."""
    h = ROOM / 2
    white = scenes.principled("Far White", (0.8, 0.8, 0.8))
    red = scenes.principled("Far Red", (0.8, 0.05, 0.05))
    corners = [(x, y, z) for z in (0.0, ROOM) for y in (-h, h) for x in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    room = scenes.mesh_object("Far Room", corners, faces, scene=scene)
    room.data.materials.append(white)
    room.data.materials.append(red)
    room.data.polygons.foreach_set("material_index", np.array([0, 0, 0, 1, 0], np.int32))
    room.data.update()
    scenes._block("Far Block", (1.5, 1.5, 3.0), (-1.0, 1.0, 0.0), 0.3, white, scene)
    scenes._light(scene, "Far Light", "POINT", (0.0, 0.0, 4.0), energy=2000.0, shadow_soft_size=0.1)
    camera = scenes.link(bpy.data.objects.new("Far Camera", bpy.data.cameras.new("Far Camera")), scene)
    camera.location = CAMERA
    camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
    camera.data.lens = 35.0
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    return room


def last(session):
    return session.scene_session(bpy.context.scene.name_full)


def test_auto_puts_the_far_room_into_the_finest_cascades(voxgi, session):
    scene = bpy.context.scene
    build_far_room(scene)
    assert scene.voxgi.span_mode == "AUTO"
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    state = last(session)
    gi, fit = state.gi_state, state.view_fit
    print("Auto:", [(g.span, g.size) for g in gi.grids], gi.voxel_counts, np.round(gi.view_shares, 3))
    assert fit is not None and gi.grids[0].span == fit.base_span == state.caches.cascade_stats[0].span
    assert float(np.log2(fit.base_span)).is_integer()
    assert gi.voxel_counts[0] > 1000
    assert gi.view_shares[:2].sum() >= 0.9 and gi.view_shares[0] >= 0.8
    assert gi.grids[0].size <= 4 * ROOM  # fitted to the room, not to the 12 m to the camera
    lines = [m for _, m in state.last_report]
    assert any(m.startswith("Voxel fit: Auto") and "MB budget" in m for m in lines)
    cover = [m for m in lines if m.startswith("Cascade ")]
    assert len(cover) == 3 and all("m cube" in m and "of the view" in m and "voxels" in m
                                   for m in cover)

    # A small camera move keeps the span, the grids and the caches (nothing re-voxelized).
    caches = state.caches
    scene.camera.location.x += 0.05
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert state.caches is caches
    for a, b in zip(gi.grids, state.gi_state.grids):
        assert np.array_equal(a.origin, b.origin) and a.span == b.span


def test_manual_keeps_the_camera_anchored_cascades(voxgi, session):
    from voxgi.voxgi_addon.gi.cascades import place_cascades

    scene = bpy.context.scene
    build_far_room(scene)
    scene.voxgi.span_mode = "MANUAL"
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    state = last(session)
    gi = state.gi_state
    print("Manual:", [(g.span, g.size) for g in gi.grids], gi.voxel_counts, np.round(gi.view_shares, 3))
    assert state.view_fit is None
    ahead = np.array(CAMERA) + np.array([0.0, 1.0, 0.0]) * 0.5 * 64 * scene.voxgi.base_span
    for grid, want in zip(gi.grids, place_cascades(ahead, scene.voxgi.base_span, 64, 3)):
        assert np.allclose(grid.origin, want.origin) and grid.span == want.span
    assert gi.voxel_counts[0] == 0  # the measured problem: nothing in the finest cascade
    assert gi.view_shares[:2].sum() < 0.5
    assert any(m.startswith("Voxel fit: Manual") for _, m in state.last_report)


def test_switching_modes_reuses_each_spans_caches(voxgi, session, tmp_path):
    scene = bpy.context.scene
    build_far_room(scene)
    scene.voxgi.quality = "FAST"  # the cones' preview voxelizes (Accurate needs no voxels)
    path = str(tmp_path / "far.exr")
    assert bpy.ops.voxgi.render_preview(filepath=path, resolution_x=32, resolution_y=24) == {"FINISHED"}
    state = last(session)
    auto_caches = state.caches
    lines = [m for _, m in state.last_report]
    assert any(m.startswith("Voxel fit: Auto") for m in lines)
    assert sum(m.startswith("Cascade ") and "of the view" in m for m in lines) == 3
    scene.voxgi.span_mode = "MANUAL"
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert state.caches is not auto_caches
    scene.voxgi.span_mode = "AUTO"
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert state.caches is auto_caches  # the Auto span's caches were kept


def test_panels_show_the_mode_settings_and_what_each_cascade_covers(voxgi):
    from test_demo_scene import _Layout

    scene = bpy.context.scene
    build_far_room(scene)
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    layout = _Layout()
    bpy.types.VOXGI_PT_gi.draw(type("PanelStub", (), {"layout": layout})(), bpy.context)
    assert "view_ahead" not in layout.props
    assert "Auto: fitted to the view" in layout.labels
    assert sum(text.endswith("of view") for text in layout.labels) == 4  # 3 cascades + outside
    scene.voxgi.span_mode = "MANUAL"
    layout = _Layout()
    bpy.types.VOXGI_PT_main.draw(type("PanelStub", (), {"layout": layout})(), bpy.context)
    assert layout.props == ["span_mode", "base_span", "cascade_count", "grid_resolution"]
