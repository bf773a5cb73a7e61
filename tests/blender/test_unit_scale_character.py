"""Issue 22 (1), acceptance (a): a rigged character as Blender's glTF/FBX importers leave it
(armature object at scale 0.01, mesh vertices and bones in centimetres, the mesh parented to
the armature) gives the voxels and the previews of the same character with its scale applied.

Also: the rig round-tripped through Blender's glTF exporter and importer against itself with
Object › Apply › Scale; rigid meshes under scaled empties keep their baked scale; ``voxgi.update``
redoes nothing when nothing changed and only the moved character when it is posed.
"""
from __future__ import annotations

import importlib

import bpy
import numpy as np
import pytest
import unit_scale_scenes as scenes

WIDTH, HEIGHT = 64, 48


def _exr(voxgi):
    return importlib.import_module("voxgi.voxgi_addon.files.exr")


def _character_run(voxgi, session, tmp_path, unit):
    """Build the room with the character at ``unit``; voxelize, update and render both
    previews. Returns cache voxels per cascade, cascade voxels per cascade, previews."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()
    scene = bpy.context.scene
    scenes.build_character_room(scene, unit)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    state = session.scene_session(scene.name_full)
    caches = [s.voxel_count for s in state.caches.cascade_stats]
    warnings = [m for level, m in state.last_report if level == "WARNING"]
    assert not any("skipped" in m or "scale" in m for m in warnings), warnings
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    cascades = state.gi_state.voxel_counts
    previews = {}
    for quality in ("ACCURATE", "FAST"):
        scene.voxgi.quality = quality
        path = tmp_path / f"unit{unit}_{quality}.exr"
        assert bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=WIDTH,
                                            resolution_y=HEIGHT) == {"FINISHED"}
        previews[quality] = _exr(voxgi).read_exr_passes(path)["Combined"]
    return caches, cascades, previews


def test_a_centimetre_rig_at_scale_001_voxelizes_and_renders_as_the_applied_one(
        voxgi, session, tmp_path):
    cm = _character_run(voxgi, session, tmp_path, 0.01)
    m = _character_run(voxgi, session, tmp_path, 1.0)
    (cm_caches, cm_cascades, cm_previews), (m_caches, m_cascades, m_previews) = cm, m
    print(f"cache voxels: cm {cm_caches}, applied {m_caches}; cascade voxels: cm {cm_cascades}, "
          f"applied {m_cascades}")
    assert m_caches[0] > 1000 and m_cascades[0] > 1000
    for a, b in zip((*cm_caches, *cm_cascades), (*m_caches, *m_cascades)):
        assert abs(a - b) <= 0.02 * max(b, 50), (cm_caches, m_caches, cm_cascades, m_cascades)
    for quality in ("ACCURATE", "FAST"):
        a, b = cm_previews[quality], m_previews[quality]
        lit = b.sum(axis=-1) > 0
        assert lit.mean() > 0.5  # the room fills the view
        error = float(np.abs(a - b)[lit].sum() / np.abs(b[lit]).sum())
        print(f"{quality}: Combined relative L1 between the cm rig and the applied one {error:.4f}")
        assert error <= 0.02


def _rigid_run(voxgi, session, unit):
    """A sphere in units of ``unit`` metres under two empties scaled by sqrt(unit) each, the
    character's room around it; cache voxels per cascade of the sphere's key."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()
    scene = bpy.context.scene
    scenes.build_character_room(scene, 1.0)
    mesh = bpy.data.meshes.new("Ball")
    import bmesh

    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=32, v_segments=16, radius=0.35 / unit)
    bm.to_mesh(mesh)
    bm.free()
    ball = bpy.data.objects.new("Ball", mesh)
    scene.collection.objects.link(ball)
    parent = None
    for i, factor in enumerate((unit ** 0.5, unit ** 0.5)):
        empty = bpy.data.objects.new(f"Empty {i}", None)
        scene.collection.objects.link(empty)
        empty.scale = (factor,) * 3
        empty.rotation_euler = (0.0, 0.0, 0.3 * (i + 1))
        empty.parent = parent
        parent = empty
    parent.location = (0.0, 0.0, 0.6 / unit ** 0.5)  # in the outer empty's units
    ball.parent = parent
    bpy.context.view_layer.update()
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    caches = session.scene_session(scene.name_full).caches
    key = caches.bindings["Ball"].cache_key
    return np.array(ball.matrix_world), key, [c.voxel_count for c in caches.caches[key]]


def test_rigid_meshes_under_scaled_empties_keep_their_baked_scale(voxgi, session):
    cm_world, cm_key, cm_counts = _rigid_run(voxgi, session, 0.01)
    m_world, m_key, m_counts = _rigid_run(voxgi, session, 1.0)
    np.testing.assert_allclose(cm_world[:3, 3], m_world[:3, 3], atol=1e-5)  # the same place
    assert cm_key.startswith("Ball|scale:") and m_key == "Ball"
    assert m_counts[0] > 100
    print(f"ball cache voxels: cm {cm_counts}, applied {m_counts}")
    assert cm_counts == pytest.approx(m_counts, rel=0.02)


def test_update_redoes_nothing_unchanged_and_only_the_posed_character(voxgi, session):
    scene = bpy.context.scene
    built = scenes.build_character_room(scene, 0.01)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    state = session.scene_session(scene.name_full)
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    first = state.gi_state
    assert first.reused == ""
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    assert state.gi_state.reused == "all" and state.gi_state.octree is first.octree
    assert "nothing changed" in state.last_report[0][1]
    built["rig"].pose.bones["Forearm.L"].rotation_euler.x += 0.5
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    posed = state.gi_state
    assert posed.reused == "objects" and posed.placed_objects == ("Character",)
    assert any(not np.array_equal(a.cells, b.cells) for a, b in zip(first.cascades, posed.cascades))
    built["sun"].data.energy *= 2  # a light: the voxels stay, the light is injected again
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    lit = state.gi_state
    assert lit.reused == "objects" and lit.placed_objects == () and lit.cascades is not posed.cascades
    assert all(np.array_equal(a.cells, b.cells) for a, b in zip(posed.cascades, lit.cascades))
    assert lit.radiance[0].sum() > posed.radiance[0].sum()


def _imported_room(path):
    """The room with its own character replaced by the one Blender's glTF importer makes of
    ``path`` (armature at 0.01, mesh and bones in cm). Returns (mesh object, armature)."""
    scene = bpy.context.scene
    built = scenes.build_character_room(scene, 1.0)
    for role in ("body", "rig"):
        bpy.data.objects.remove(built[role])
    assert bpy.ops.import_scene.gltf(filepath=str(path)) == {"FINISHED"}
    rig = next(o for o in scene.objects if o.type == "ARMATURE")
    body = next(o for o in scene.objects if o.type == "MESH" and o.parent is rig)
    return body, rig


def _voxels_and_fast_preview(session, path):
    scene = bpy.context.scene
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    caches = [s.voxel_count for s in session.scene_session(scene.name_full).caches.cascade_stats]
    scene.voxgi.quality = "FAST"
    assert bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=WIDTH,
                                        resolution_y=HEIGHT) == {"FINISHED"}
    return caches, importlib.import_module("voxgi.voxgi_addon.files.exr").read_exr_passes(path)


def test_a_gltf_round_tripped_rig_matches_itself_with_the_scale_applied(voxgi, session, tmp_path):
    """Through Blender's own glTF exporter and importer (what users actually get), then
    Object › Apply › Scale on the armature and its mesh, as issue 22 measured."""
    scene = bpy.context.scene
    scenes.add_character(scene, 0.01)
    bpy.context.view_layer.update()
    glb = tmp_path / "character.glb"
    assert bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB") == {"FINISHED"}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()
    body, rig = _imported_room(glb)
    assert rig.scale[0] == pytest.approx(0.01) and rig.data.bones[0].head_local.length > 50
    imported = _voxels_and_fast_preview(session, tmp_path / "imported.exr")
    view_layer = bpy.context.view_layer
    for obj in bpy.context.scene.objects:
        obj.select_set(obj in (body, rig))
    view_layer.objects.active = rig
    with bpy.context.temp_override(active_object=rig, object=rig,
                                   selected_editable_objects=[rig, body]):
        assert bpy.ops.object.transform_apply(location=False, rotation=False,
                                              scale=True) == {"FINISHED"}
    view_layer.update()
    assert rig.scale[0] == pytest.approx(1.0)
    assert np.abs(np.array(body.matrix_world)[:3, :3]).max() > 0.5  # metres now
    applied = _voxels_and_fast_preview(session, tmp_path / "applied.exr")
    print(f"glTF round trip: cache voxels imported {imported[0]}, applied {applied[0]}")
    assert applied[0][0] > 1000
    assert imported[0] == pytest.approx(applied[0], rel=0.02)
    a, b = imported[1]["Combined"], applied[1]["Combined"]
    lit = b.sum(axis=-1) > 0
    error = float(np.abs(a - b)[lit].sum() / np.abs(b[lit]).sum())
    print(f"glTF round trip: Fast Combined relative L1 imported vs applied {error:.4f}")
    assert error <= 0.02
