"""export_scene.gfg / import_scene.gfg on the bpy module.

One scene with every kind of data: a two-material box with UVs and an image texture, its
linked duplicate under a parented empty (non-identity parent inverse, quaternion rotation), a
subdivided object (apply modifiers), a 3-bone armature with a rolled bone, a keyframed action
(Euler, quaternion and root-location keys, Bezier) skinning a tube, and the session's voxel
caches. Export → import into an empty file → export must give identical bytes; the imported
data must equal the file and the original; the imported rig must play the same poses.
"""
from __future__ import annotations

import importlib
import math

import bpy
import mathutils
import numpy as np
import pytest
from scenes import armature_object, assign_weights, mesh_object, principled

FRAMES = (1, 4, 7, 10, 13, 17, 20)


def _tube(segments=10, radius=0.3):
    """A tube along +Z with rings at z = 0.1, 0.3, …, 2.9: 0.2 m from the bone centres (0.5, 1.5,
    2.5) in whole steps, so its tent weights are multiples of 0.2 = 51/255, which UNORM8 weights
    hold exactly (other weights would move vertices by up to 1/510 of a bone's swing)."""
    z = np.linspace(0.1, 2.9, 15)
    rings = len(z)
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    vertices = [(radius * np.cos(a), radius * np.sin(a), h) for h in z for a in angles]
    faces = [(r * segments + s, r * segments + (s + 1) % segments, (r + 1) * segments + (s + 1) % segments,
              (r + 1) * segments + s) for r in range(rings - 1) for s in range(segments)]
    return vertices, faces, z


def _keyframe_rig(rig):
    pose = rig.pose.bones
    pose["Mid"].rotation_mode = "XYZ"
    for frame, angle in ((1, 0.0), (10, 0.6), (20, -0.3)):
        pose["Mid"].rotation_euler = (angle, 0.2 * angle, 0.0)
        pose["Mid"].keyframe_insert("rotation_euler", frame=frame)
    for frame, quat in ((1, (1, 0, 0, 0)), (20, (math.cos(0.4), 0, math.sin(0.4), 0))):
        pose["Tip"].rotation_quaternion = quat
        pose["Tip"].keyframe_insert("rotation_quaternion", frame=frame)
    for frame, z in ((1, 0.0), (20, 0.5)):
        pose["Root"].location = (0.0, z, 0.0)
        pose["Root"].keyframe_insert("location", frame=frame)


def build_scene(tmp_path):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 20
    red, blue = principled("Red", (0.8, 0.1, 0.1), roughness=0.3), principled("Blue", (0.1, 0.2, 0.9), metallic=0.5)
    wood = principled("Wood", (0.5, 0.4, 0.2))
    image = bpy.data.images.new("wood.png", 1, 1)
    image.source, image.filepath = "FILE", str(tmp_path / "textures" / "wood.png")
    texture = wood.node_tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    bsdf = next(n for n in wood.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    wood.node_tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])

    root = bpy.data.objects.new("Root", None)
    scene.collection.objects.link(root)
    root.location, root.rotation_euler = (0.5, 0.0, 0.2), (0.0, 0.0, 0.3)
    corners = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    box = mesh_object("Box", corners, quads)
    for m in (red, blue, wood):
        box.data.materials.append(m)
    box.data.polygons.foreach_set("material_index", np.array([0, 1, 0, 2, 1, 0], np.int32))
    uv = box.data.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.random.default_rng(0).random(2 * len(box.data.loops)).astype(np.float32))
    box.parent = root
    box.matrix_parent_inverse = mathutils.Matrix(((1, 0, 0, 0.1), (0, 1, 0, 0), (0, 0, 1, -0.2), (0, 0, 0, 1)))
    twin = bpy.data.objects.new("Box Twin", box.data)
    scene.collection.objects.link(twin)
    twin.parent, twin.rotation_mode = root, "QUATERNION"
    twin.rotation_quaternion, twin.location = (0.9, 0.1, 0.3, 0.2), (2.0, 0.0, 0.0)
    bumpy = mesh_object("Bumpy", corners, quads)
    bumpy.location = (-2.0, 0.0, 0.0)
    bumpy.modifiers.new("Subdivision", "SUBSURF").levels = 1

    rig = armature_object("Rig", [("Root", (0, 0, 0), (0, 0, 1), None, True),
                                  ("Mid", (0, 0, 1), (0, 0, 2), "Root", True, True, 0.25),
                                  ("Tip", (0, 0, 2), (0, 0, 3), "Mid", True, True)])
    rig.location = (0.0, 3.0, 0.0)
    vertices, faces, heights = _tube()
    tube = mesh_object("Tube", vertices, faces)
    tube.data.materials.append(red)
    centres = np.array([0.5, 1.5, 2.5])
    ring = np.maximum(0.0, 1.0 - np.abs(np.clip(heights, 0.5, 2.5)[:, None] - centres) / 1.0)
    assign_weights(tube, ["Root", "Mid", "Tip"], np.repeat(ring / ring.sum(1, keepdims=True), 10, axis=0))
    tube.modifiers.new("Armature", "ARMATURE").object = rig
    tube.parent = rig
    _keyframe_rig(rig)
    scene.frame_set(1)

    snapshot = importlib.import_module("voxgi.blender.snapshot.scene").take_snapshot(bpy.context)
    caches = importlib.import_module("voxgi.voxgi_addon.voxelize.scene_caches").build_scene_caches(snapshot, 0.25, 2)
    importlib.import_module("voxgi.blender.session").scene_session(scene.name_full).caches = caches
    return caches


def evaluated_world_positions(name, frames):
    """{frame: (V, 3) world positions} of an object's evaluated mesh, and its rest positions."""
    scene, obj = bpy.context.scene, bpy.data.objects[name]
    rest = np.array([v.co[:] for v in obj.data.vertices], np.float32)
    out = {}
    for frame in frames:
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        matrix = np.array(evaluated.matrix_world)
        out[frame] = co.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
        evaluated.to_mesh_clear()
    scene.frame_set(1)
    return rest, out


def reset_to_empty_file(voxgi):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()


def test_export_import_export_is_identical_and_plays_the_same_poses(voxgi, tmp_path):
    gfg = importlib.import_module("voxgi.voxgi_addon.files.gfg")
    caches = build_scene(tmp_path)
    bone_matrices = {b.name: np.array(b.matrix_local, np.float32) for b in bpy.data.objects["Rig"].data.bones}
    rest, posed = evaluated_world_positions("Tube", FRAMES)
    first, second = tmp_path / "first.gfg", tmp_path / "second.gfg"
    assert bpy.ops.export_scene.gfg(filepath=str(first)) == {"FINISHED"}

    reset_to_empty_file(voxgi)
    assert bpy.ops.import_scene.gfg(filepath=str(first)) == {"FINISHED"}
    assert sorted(o.name for o in bpy.data.objects) == ["Box", "Box Twin", "Bumpy", "Rig", "Root", "Tube"]
    assert bpy.ops.export_scene.gfg(filepath=str(second)) == {"FINISHED"}
    assert second.read_bytes() == first.read_bytes()

    data = gfg.read_gfg(first)
    assert [n.name for n in data.nodes] == ["Bumpy", "Rig", "Tube", "Root", "Box", "Box Twin"]
    assert [m.name for m in data.meshes] == ["Bumpy (modified)", "Tube", "Box"]  # the twin shares "Box"
    assert data.materials[2].textures == {0: "textures/wood.png"}
    # Meshes: the imported Blender data is the file's, exactly.
    for m in data.meshes:
        a = gfg.mesh_arrays(m)
        mesh = bpy.data.meshes[m.name]
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        assert np.array_equal(co.reshape(-1, 3), a.positions)
        normals = np.empty(len(mesh.loops) * 3, np.float32)
        mesh.corner_normals.foreach_get("vector", normals)
        tris = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", tris)
        assert np.array_equal(tris.reshape(-1, 3), a.triangles)
        assert np.array_equal(normals.reshape(-1, 3), a.normals[a.triangles].reshape(-1, 3))
    box = gfg.mesh_arrays(data.meshes[[m.name for m in data.meshes].index("Box")])
    assert box.slot_materials.tolist() == [0, 1, 2] and box.uvs is not None
    # Weights: vertex groups hold the file's weights; the rig's rest matrices are the original's.
    tube = bpy.data.objects["Tube"]
    a = gfg.mesh_arrays(next(m for m in data.meshes if m.name == "Tube"))
    names = data.skeletons[0].bone_names
    for v in range(0, len(a.positions), 7):
        groups = {tube.vertex_groups[g.group].name: g.weight for g in tube.data.vertices[v].groups}
        expected = {names[i]: w for i, w in zip(a.bone_indices[v], a.weights[v]) if w > 0}
        assert groups == pytest.approx(expected, abs=0) and abs(sum(groups.values()) - 1) < 1e-6
    for bone in bpy.data.objects["Rig"].data.bones:
        assert np.array_equal(np.array(bone.matrix_local, np.float32), bone_matrices[bone.name])
    assert np.array_equal(data.skeletons[0].rest_matrices, np.stack([bone_matrices[n] for n in names]))
    # Animation keys: the imported F-curves hold the file's values at the file's frames.
    animation = data.animations[0]
    assert len(animation.times) == 20 and animation.hip_translations is not None
    bag = importlib.import_module("bpy_extras.anim_utils").animdata_get_channelbag_for_assigned_slot(
        bpy.data.objects["Rig"].animation_data)
    for b, name in enumerate(names):
        for i in range(4):
            curve = bag.fcurves.find(f'pose.bones["{name}"].rotation_quaternion', index=i)
            keys = np.empty(2 * len(curve.keyframe_points), np.float32)
            curve.keyframe_points.foreach_get("co", keys)
            assert np.array_equal(keys[0::2], np.arange(1, 21, dtype=np.float32))
            assert np.array_equal(keys[1::2], animation.rotations[:, b, i])
    # Voxel caches: attached to the new session, equal to the original run's.
    session = importlib.import_module("voxgi.blender.session").scene_session(bpy.context.scene.name_full)
    assert list(session.caches.caches) == list(caches.caches)
    for key, per_cascade in caches.caches.items():
        for c, d in zip(per_cascade, session.caches.caches[key]):
            assert (c is None) == (d is None)
            if c is not None:
                for f in ("positions", "normals", "colors", "weights", "bone_indices", "origin_cell", "dims"):
                    assert (getattr(c, f) is None and getattr(d, f) is None) or \
                        np.array_equal(getattr(c, f), getattr(d, f))
    # The imported rig plays the same poses (vertices matched by rest position).
    imported_rest, imported_posed = evaluated_world_positions("Tube", FRAMES)
    lookup = {p.tobytes(): i for i, p in enumerate(rest)}
    match = np.array([lookup[p.tobytes()] for p in imported_rest])
    for frame in FRAMES:
        assert np.abs(imported_posed[frame] - posed[frame][match]).max() < 1e-5, frame
    assert np.abs(posed[20] - posed[1]).max() > 0.5  # the animation does move the tube


def test_options_select_what_is_written_and_menus_are_registered(voxgi, tmp_path):
    gfg = importlib.import_module("voxgi.voxgi_addon.files.gfg")
    build_scene(tmp_path)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.name == "Tube")
    path = tmp_path / "options.gfg"
    assert bpy.ops.export_scene.gfg(filepath=str(path), use_selection=True, export_animation=False,
                                    export_voxel_caches=False, normal_type="NORM_2_10_10_10",
                                    weight_type="FLOAT_4", vertex_layout="SEPARATE") == {"FINISHED"}
    data = gfg.read_gfg(path)
    assert [n.name for n in data.nodes] == ["Rig", "Tube"]  # the deforming armature comes along
    assert data.voxels is None and data.animations == [] and not data.meshes[0].interleaved
    assert [gfg.data_types.name_of(c.data_type) for c in data.meshes[0].components] == \
        ["FLOAT_3", "NORM_2_10_10_10", "FLOAT_4", "UINT8_4"]
    assert bpy.ops.export_scene.gfg(filepath=str(path), use_selection=True, export_skeleton=False) == {"FINISHED"}
    data = gfg.read_gfg(path)
    assert [n.name for n in data.nodes] == ["Tube"] and data.skeletons == [] and data.meshes[0].skeleton == -1
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj.name == "Bumpy")
    for apply, name, triangles in ((True, "Bumpy (modified)", 48), (False, "Bumpy", 12)):
        assert bpy.ops.export_scene.gfg(filepath=str(path), use_selection=True,
                                        use_apply_modifiers=apply) == {"FINISHED"}
        mesh = gfg.read_gfg(path).meshes[0]
        assert (mesh.name, len(mesh.indices) // 3) == (name, triangles)
    assert bpy.data.objects["Bumpy"].modifiers[0].show_viewport  # switched back on
    export_menu = [f.__name__ for f in bpy.types.TOPBAR_MT_file_export._dyn_ui_initialize()]
    import_menu = [f.__name__ for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()]
    assert "_menu_entry" in export_menu and "_menu_entry" in import_menu
    broken = tmp_path / "broken.gfg"
    broken.write_bytes(path.read_bytes()[:-10])
    with pytest.raises(RuntimeError, match="GFG import failed: header: file_size"):
        bpy.ops.import_scene.gfg(filepath=str(broken))
