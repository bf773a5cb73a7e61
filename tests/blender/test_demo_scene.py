"""The demo scene and add-on registration."""
from __future__ import annotations

import importlib

import bpy
import numpy as np
import pytest


def _evaluated_positions(obj):
    depsgraph = bpy.context.evaluated_depsgraph_get()
    mesh = obj.evaluated_get(depsgraph).data
    out = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", out)
    return out.reshape(-1, 3)


def test_demo_scene_contents(voxgi):
    assert bpy.ops.voxgi.add_demo_scene() == {"FINISHED"}
    scene = bpy.context.scene
    objects = bpy.data.collections["VoxGI Demo"].objects
    assert {o.name for o in objects} == {
        "Cornell Box", "Ceiling Light", "Skinned Tube", "Tube Rig", "Rotating Sphere", "Camera"}
    box = objects["Cornell Box"]
    corners = np.array([v.co[:] for v in box.data.vertices])
    np.testing.assert_allclose(corners.max(axis=0) - corners.min(axis=0), (2.0, 2.0, 2.0))
    assert len(box.data.polygons) == 5  # open front
    assert objects["Ceiling Light"].data.energy == pytest.approx(100.0)

    tube = objects["Skinned Tube"]
    assert [b.name for b in objects["Tube Rig"].data.bones] == ["Tube.0", "Tube.1", "Tube.2"]
    assert len(tube.vertex_groups) == 3
    rest = np.array([v.co[:] for v in tube.data.vertices])
    assert not np.allclose(_evaluated_positions(tube), rest, atol=1e-3)  # the pose bends it

    sphere = objects["Rotating Sphere"]
    scene.frame_set(30)
    angle = sphere.matrix_world.to_euler().z
    scene.frame_set(1)
    assert abs(angle) > 0.1

    assert scene.camera is objects["Camera"]
    # The box centre projects inside the camera frame.
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    ndc = world_to_camera_view(scene, scene.camera, Vector((0.0, 0.0, 1.0)))
    assert 0.3 < ndc.x < 0.7 and 0.3 < ndc.y < 0.7 and ndc.z > 0


def test_demo_floor_is_textured(voxgi):
    """The demo's floor samples a packed tile image per texel (issue 18): the snapshot reads
    it as a texture through the floor's UVs and its Mapping's 2 × 2 repeat."""
    from voxgi.blender.demo_scene import TILE_REPEAT, tile_pixels
    from voxgi.blender.snapshot.scene import take_snapshot

    assert bpy.ops.voxgi.add_demo_scene() == {"FINISHED"}
    assert bpy.data.images["VoxGI Tiles"].packed_file is not None
    snapshot = take_snapshot(bpy.context.scene)
    assert snapshot.warnings == ()
    tiles = next(m for m in snapshot.materials if m.name == "VoxGI Tiles")
    texture = snapshot.textures[tiles.base_color_texture]
    np.testing.assert_allclose(texture.uv_transform, [[TILE_REPEAT, 0, 0], [0, TILE_REPEAT, 0]])
    assert texture.pixels.shape == tile_pixels().shape[:2] + (3,)
    box = snapshot.meshes["Cornell Box"]
    floor = box.triangle_materials == snapshot.materials.index(tiles)
    assert floor.sum() == 2 and np.ptp(box.uvs[floor].reshape(-1, 2), axis=0).tolist() == [1, 1]


def test_unregister_removes_settings_and_operators(voxgi):
    voxgi.unregister()
    try:
        assert not hasattr(bpy.types.Scene, "voxgi")
        assert not hasattr(bpy.types, "VOXGI_OT_voxelize")
        assert not hasattr(bpy.types, "VOXGI_PT_main")
        session = importlib.import_module("voxgi.blender.session")
        assert session._clear_on_load not in bpy.app.handlers.load_post
    finally:
        voxgi.register()
    assert hasattr(bpy.types.Scene, "voxgi")
    assert hasattr(bpy.types, "VOXGI_OT_voxelize")


def test_panel_is_in_the_sidebar(voxgi):
    # Drawing needs a window; background mode can only check where it is registered.
    panel = bpy.types.VOXGI_PT_main
    assert (panel.bl_space_type, panel.bl_region_type, panel.bl_category) == ("VIEW_3D", "UI", "VoxGI")


class _Layout:
    """Records what a panel draws; every container call returns itself."""

    def __init__(self):
        self.labels, self.operators, self.props = [], [], []

    def box(self, **_kwargs):
        return self

    row = column = box

    def label(self, text="", icon="NONE"):
        self.labels.append(text)

    def operator(self, idname, **_kwargs):
        self.operators.append(idname)

    def prop(self, _data, name, **_kwargs):
        self.props.append(name)


def test_panel_draws_settings_and_results(voxgi):
    bpy.ops.voxgi.add_demo_scene()
    bpy.ops.voxgi.voxelize()
    layout = _Layout()
    panel = type("PanelStub", (), {"layout": layout})()
    bpy.types.VOXGI_PT_main.draw(panel, bpy.context)
    assert layout.props == ["span_mode", "memory_budget", "cascade_count"]  # Auto, the default
    assert layout.operators == ["voxgi.voxelize", "voxgi.add_demo_scene"]
    cascades = bpy.context.scene.voxgi.cascade_count
    assert sum(text.startswith("Cascade ") for text in layout.labels) == cascades
    assert "Stage timings" in layout.labels and "snapshot" in layout.labels


def test_gi_panel_draws_cone_settings_buttons_and_the_last_update(voxgi):
    bpy.ops.voxgi.add_demo_scene()
    bpy.ops.voxgi.voxelize()
    bpy.ops.voxgi.update()
    bpy.context.scene.voxgi.quality = "FAST"  # the cone settings are Fast quality's
    layout = _Layout()
    panel = type("PanelStub", (), {"layout": layout})()
    bpy.types.VOXGI_PT_gi.draw(panel, bpy.context)
    assert "cone_angle" in layout.props and "ao_distance" in layout.props
    assert layout.operators == ["voxgi.update", "voxgi.render_preview"]
    assert "Last update" in layout.labels
    assert sum(text.startswith("Cascade ") for text in layout.labels) == 3
    assert any(text.startswith("Octree: ") for text in layout.labels) and "svo" in layout.labels
    assert bpy.types.VOXGI_PT_gi.bl_parent_id == "VOXGI_PT_main"


def test_gi_panel_says_which_tracer_drew_the_last_preview(voxgi, tmp_path):
    bpy.ops.voxgi.add_demo_scene()
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=16,
                                        resolution_y=12) == {"FINISHED"}
    layout = _Layout()
    panel = type("PanelStub", (), {"layout": layout})()
    bpy.types.VOXGI_PT_gi.draw(panel, bpy.context)
    assert {"quality", "gi_rays", "gi_resolution", "tracer"} <= set(layout.props)
    assert "shadows" not in layout.props  # soft-shadow cones are a Fast-quality choice
    assert "cone_angle" not in layout.props and "ao_distance" in layout.props
    assert "Last preview traced with: GPU" in layout.labels
    # Accurate traces the triangles: their BVH is on the GPU, no voxel atlas
    assert any(text.startswith("BVH ") and text.endswith("MB on the GPU") for text in layout.labels)
    assert not any(text.startswith("atlas ") for text in layout.labels)
    bpy.context.scene.voxgi.quality = "FAST"
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "f.exr"), resolution_x=16,
                                        resolution_y=12) == {"FINISHED"}
    fast = _Layout()
    bpy.types.VOXGI_PT_gi.draw(type("PanelStub", (), {"layout": fast})(), bpy.context)
    assert {"shadows", "diffuse_cones"} <= set(fast.props) and "gi_rays" not in fast.props
    assert any(text.startswith("atlas ") and text.endswith("MB on the GPU") for text in fast.labels)
    assert any(text.startswith("Octree: ") for text in fast.labels)  # the voxel update's table
