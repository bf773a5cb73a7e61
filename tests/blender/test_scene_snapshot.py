"""take_snapshot: counts, shapes, dtypes, sharing, materials, skinning, restoration."""
from __future__ import annotations

import bpy
import numpy as np
import pytest
import scenes


def _snapshot(snapshot_module):
    return snapshot_module.take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())


def _demo(voxgi):
    from voxgi.blender.demo_scene import build_demo_scene

    return build_demo_scene(bpy.context.scene)


def test_demo_snapshot_counts_shapes_and_dtypes(voxgi, snapshot_module):
    built = _demo(voxgi)
    snap = _snapshot(snapshot_module)

    kinds = {o.name: o.kind for o in snap.objects}
    assert kinds == {"Cornell Box": "static", "Skinned Tube": "skinned", "Rotating Sphere": "rigid"}
    assert len(snap.meshes) == 3 and len(snap.materials) == 6
    for mesh in snap.meshes.values():
        v, t = len(mesh.positions), len(mesh.triangles)
        assert mesh.positions.shape == (v, 3) and mesh.positions.dtype == np.float32
        assert mesh.triangles.shape == (t, 3) and mesh.triangles.dtype == np.int32
        assert mesh.triangle_materials.shape == (t,) and mesh.triangle_materials.dtype == np.int32
        assert 0 <= mesh.triangles.min() and mesh.triangles.max() < v
        assert (mesh.triangle_materials >= 0).all()
        if mesh.uvs is not None:
            assert mesh.uvs.shape == (t, 3, 2) and mesh.uvs.dtype == np.float32
    box = snap.meshes["Cornell Box"]
    assert box.triangles.shape == (10, 3) and box.uvs is not None
    names = [snap.materials[i].name for i in box.triangle_materials]
    assert names.count("VoxGI White") == 4 and names.count("VoxGI Red") == 2 and names.count("VoxGI Green") == 2
    assert names.count("VoxGI Tiles") == 2  # the floor

    tube_obj = next(o for o in snap.objects if o.kind == "skinned")
    assert tube_obj.armature == "Tube Rig" and tube_obj.mesh != "Skinned Tube"  # own key: it has modifiers
    skin = snap.meshes[tube_obj.mesh].skin
    v = len(snap.meshes[tube_obj.mesh].positions)
    assert skin.weights.shape == (v, 4) and skin.weights.dtype == np.float32
    assert skin.bone_indices.shape == (v, 4) and skin.bone_indices.dtype == np.uint8
    np.testing.assert_allclose(skin.weights.sum(axis=1), 1.0, atol=1e-6)
    rig = snap.armatures["Tube Rig"]
    assert rig.bone_names == ("Tube.0", "Tube.1", "Tube.2")
    assert rig.parents.tolist() == [-1, 0, 1] and rig.parents.dtype == np.int32
    assert rig.rest_matrices.shape == (3, 4, 4) and rig.rest_matrices.dtype == np.float64
    assert rig.pose_matrices.shape == (3, 4, 4)
    assert not np.allclose(rig.rest_matrices[2], rig.pose_matrices[2])  # the demo pose is bent
    np.testing.assert_allclose(rig.world_matrix, np.array(built["rig"].matrix_world), atol=1e-6)

    assert [light.type for light in snap.lights] == ["AREA"]
    assert snap.lights[0].power == pytest.approx(100.0) and snap.lights[0].size == pytest.approx(0.5)
    camera = snap.camera
    assert camera.name == "Camera" and camera.world_matrix.shape == (4, 4)
    assert camera.projection_matrix.shape == (4, 4) and camera.projection_matrix.dtype == np.float64
    render = bpy.context.scene.render
    assert camera.resolution == (render.resolution_x * render.resolution_percentage // 100,
                                 render.resolution_y * render.resolution_percentage // 100)
    assert snap.world.strength == pytest.approx(1.0)
    assert snap.warnings == ()


def test_snapshot_reads_the_rest_shape_of_a_posed_skinned_mesh(voxgi, snapshot_module):
    _demo(voxgi)
    tube = bpy.data.objects["Skinned Tube"]
    rest = np.empty(len(tube.data.vertices) * 3, np.float32)
    tube.data.vertices.foreach_get("co", rest)
    snap = _snapshot(snapshot_module)
    np.testing.assert_allclose(snap.meshes["Skinned Tube (modified)"].positions, rest.reshape(-1, 3), atol=1e-6)


def test_linked_duplicates_share_one_mesh(voxgi, snapshot_module):
    original = scenes.quad_object("Quad")
    for i in range(2):
        scenes.link(bpy.data.objects.new(f"Copy {i}", original.data)).location.x = i + 2
    modified = scenes.link(bpy.data.objects.new("With Modifier", original.data))
    modified.modifiers.new("Subdivision", "SUBSURF")

    snap = _snapshot(snapshot_module)

    by_name = {o.name: o.mesh for o in snap.objects}
    assert by_name["Quad"] == by_name["Copy 0"] == by_name["Copy 1"] == original.data.name
    assert by_name["With Modifier"] not in (by_name["Quad"],)
    assert len(snap.meshes) == 2
    assert len(snap.meshes[by_name["With Modifier"]].triangles) > 2  # subdivided
    np.testing.assert_allclose(
        next(o for o in snap.objects if o.name == "Copy 1").world_matrix[0, 3], 3.0
    )


def test_material_values_read_back(voxgi, snapshot_module):
    plain = scenes.principled("Plain", (0.2, 0.4, 0.6), roughness=0.3, metallic=0.7, specular=0.25,
                              emission=(1.0, 0.5, 0.0), emission_strength=2.0)
    textured = scenes.principled("Textured", (1.0, 0.0, 1.0))
    image = bpy.data.images.new("Checker", 2, 1)
    assert image.colorspace_settings.name == "sRGB"
    encoded = np.array([[0.5, 0.2, 1.0, 1.0], [0.0, 0.8, 0.04, 1.0]], dtype=np.float32)
    image.pixels.foreach_set(encoded.ravel())
    tree = textured.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(texture.outputs["Color"], bsdf.inputs["Base Color"])
    no_bsdf = bpy.data.materials.new("No BSDF")
    no_bsdf.node_tree.nodes.remove(next(n for n in no_bsdf.node_tree.nodes if n.type == "BSDF_PRINCIPLED"))
    no_bsdf.diffuse_color = (0.1, 0.9, 0.3, 1.0)

    for i, material in enumerate((plain, textured, no_bsdf)):
        obj = scenes.quad_object(f"Quad {i}")
        obj.data.materials.append(material)

    snap = _snapshot(snapshot_module)
    materials = {m.name: m for m in snap.materials}
    assert set(materials) == {"Plain", "Textured", "No BSDF"}
    m = materials["Plain"]
    np.testing.assert_allclose(m.base_color, (0.2, 0.4, 0.6), atol=1e-6)
    assert m.base_color.dtype == np.float32
    assert (m.roughness, m.metallic, m.specular) == pytest.approx((0.3, 0.7, 0.25))
    np.testing.assert_allclose(m.emission, (2.0, 1.0, 0.0), atol=1e-6)
    # Byte images quantise to 1/255; linearise per pixel, then average.
    quantised = np.round(encoded[:, :3] * 255) / 255
    linear = np.where(quantised <= 0.04045, quantised / 12.92, ((quantised + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(materials["Textured"].base_color, linear.mean(axis=0), atol=1e-4)
    np.testing.assert_allclose(materials["No BSDF"].base_color, (0.1, 0.9, 0.3), atol=1e-6)
    for i, name in enumerate(("Plain", "Textured", "No BSDF")):
        mesh = snap.meshes[f"Quad {i}"]
        assert {snap.materials[k].name for k in mesh.triangle_materials} == {name}


def test_object_linked_material_slots_do_not_share(voxgi, snapshot_module):
    first = scenes.quad_object("First")
    first.data.materials.append(scenes.principled("Red", (1, 0, 0)))
    second = scenes.link(bpy.data.objects.new("Second", first.data))
    second.material_slots[0].link = "OBJECT"
    second.material_slots[0].material = scenes.principled("Blue", (0, 0, 1))
    snap = _snapshot(snapshot_module)
    by_name = {o.name: snap.meshes[o.mesh] for o in snap.objects}
    assert {snap.materials[i].name for i in by_name["First"].triangle_materials} == {"Red"}
    assert {snap.materials[i].name for i in by_name["Second"].triangle_materials} == {"Blue"}


def test_skin_weights_are_top4_normalised_deform_bones(voxgi, snapshot_module):
    strip, rig, names, weights = scenes.skinned_strip()
    rig.pose.bones["B2"].rotation_mode = "XYZ"
    rig.pose.bones["B2"].rotation_euler.z = 0.5

    snap = _snapshot(snapshot_module)

    armature = snap.armatures["Rig"]
    assert armature.bone_names == tuple(f"B{i}" for i in range(6))  # 'ctrl' does not deform
    assert armature.parents.tolist() == [-1, 0, 1, 2, 3, 4]
    skin = snap.meshes["Strip (modified)"].skin
    assert skin.armature == "Rig"
    expected = scenes.expected_top4(weights, 6)
    for vertex, want in enumerate(expected):
        got = {
            int(armature.bone_names[b][1:]): float(w)
            for b, w in zip(skin.bone_indices[vertex], skin.weights[vertex]) if w > 0
        }
        assert got.keys() == want.keys(), vertex
        for bone, w in want.items():
            assert got[bone] == pytest.approx(w, abs=1e-6)
    np.testing.assert_allclose(skin.weights[:3].sum(axis=1), 1.0, atol=1e-6)
    assert skin.weights[3].tolist() == [0, 0, 0, 0]  # only non-deform groups
    # Bone matrices: rest from Bone.matrix_local, pose from PoseBone.matrix (row-major).
    np.testing.assert_allclose(armature.rest_matrices[2], np.array(rig.data.bones["B2"].matrix_local), atol=1e-6)
    np.testing.assert_allclose(armature.pose_matrices[2], np.array(rig.pose.bones["B2"].matrix), atol=1e-6)


def _modifier_state(obj):
    return [(m.name, m.type, m.show_viewport, m.show_render) for m in obj.modifiers], obj.modifiers.active.name


def test_user_modifiers_and_data_are_restored(voxgi, snapshot_module):
    strip, rig, _, _ = scenes.skinned_strip()
    strip.modifiers.new("Solidify", "SOLIDIFY").thickness = 0.05
    hidden = strip.modifiers.new("Hidden Subsurf", "SUBSURF")
    hidden.show_viewport = False
    strip.modifiers.active = strip.modifiers["Armature"]
    rig.pose.bones["B0"].rotation_mode = "XYZ"
    rig.pose.bones["B0"].rotation_euler.z = 0.7
    before = _modifier_state(strip)
    groups = len(bpy.data.node_groups)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    posed_before = np.array([v.co[:] for v in strip.evaluated_get(depsgraph).data.vertices])

    snap = _snapshot(snapshot_module)

    assert _modifier_state(strip) == before
    assert len(bpy.data.node_groups) == groups
    assert not any(a.name.startswith("__voxgi") for a in strip.data.attributes)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    posed_after = np.array([v.co[:] for v in strip.evaluated_get(depsgraph).data.vertices])
    np.testing.assert_allclose(posed_after, posed_before, atol=1e-6)  # deformed again
    rest = snap.meshes["Strip (modified)"].positions
    assert rest.shape == posed_before.shape and not np.allclose(rest, posed_before, atol=1e-3)


def test_object_kinds(voxgi, snapshot_module):
    static = scenes.quad_object("Static")
    constrained = scenes.quad_object("Constrained")
    constrained.constraints.new("COPY_LOCATION").target = static
    parent = scenes.link(bpy.data.objects.new("Animated Empty", None))
    parent.keyframe_insert("location", frame=1)
    child = scenes.quad_object("Child")
    child.parent = parent
    driven = scenes.quad_object("Driven")
    driven.driver_add("location", 0)

    kinds = {o.name: o.kind for o in _snapshot(snapshot_module).objects}

    assert kinds == {"Static": "static", "Constrained": "rigid", "Child": "rigid", "Driven": "rigid"}


def test_hidden_and_non_mesh_objects_are_left_out(voxgi, snapshot_module):
    scenes.quad_object("Shown")
    scenes.quad_object("Hidden").hide_set(True)
    scenes.link(bpy.data.objects.new("Empty", None))
    assert [o.name for o in _snapshot(snapshot_module).objects] == ["Shown"]


def test_lights_and_world(voxgi, snapshot_module):
    for kind, energy in (("POINT", 50.0), ("SUN", 3.0), ("SPOT", 200.0), ("AREA", 80.0)):
        light = bpy.data.lights.new(kind, kind)
        light.energy = energy
        light.color = (1.0, 0.5, 0.25)
        if kind == "POINT":
            light.shadow_soft_size = 0.1
        if kind == "SPOT":
            light.spot_size, light.spot_blend = 0.8, 0.3
        if kind == "AREA":
            light.shape, light.size, light.size_y = "RECTANGLE", 0.5, 0.25
        scenes.link(bpy.data.objects.new(kind, light)).location.z = 2.0
    world = bpy.data.worlds.new("W")
    bg = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    bg.inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    bg.inputs["Strength"].default_value = 0.5
    bpy.context.scene.world = world

    snap = _snapshot(snapshot_module)

    lights = {light.type: light for light in snap.lights}
    assert {t: lights[t].power for t in lights} == {"POINT": 50.0, "SUN": 3.0, "SPOT": 200.0, "AREA": 80.0}
    np.testing.assert_allclose(lights["POINT"].color, (1.0, 0.5, 0.25))
    assert lights["POINT"].world_matrix[2, 3] == pytest.approx(2.0)
    assert (lights["SPOT"].spot_size, lights["SPOT"].spot_blend) == pytest.approx((0.8, 0.3))
    assert (lights["AREA"].shape, lights["AREA"].size, lights["AREA"].size_y) == ("RECTANGLE", 0.5, 0.25)
    assert lights["SUN"].angle > 0 and lights["POINT"].radius == pytest.approx(0.1)
    np.testing.assert_allclose(snap.world.color, (0.1, 0.2, 0.3), atol=1e-6)
    assert snap.world.strength == pytest.approx(0.5)
    assert snap.camera is None


def test_lights_disabled_in_renders_are_left_out(voxgi, snapshot_module):
    """A lamp Blender does not render — Disable in Renders on the object or on a collection
    it is in — lights nothing in the preview either, as a mesh so disabled shows nothing (with
    the diorama's two lamps disabled in renders the preview's Diffuse Direct read 2.5 ×
    Cycles')."""
    for name in ("Shown", "Disabled", "In a disabled collection"):
        light = scenes.link(bpy.data.objects.new(name, bpy.data.lights.new(name, "POINT")))
    bpy.data.objects["Disabled"].hide_render = True
    hidden = bpy.data.collections.new("Off in renders")
    bpy.context.scene.collection.children.link(hidden)
    moved = bpy.data.objects["In a disabled collection"]
    for collection in list(moved.users_collection):
        collection.objects.unlink(moved)
    hidden.objects.link(moved)
    hidden.hide_render = True
    assert light is moved
    names = [light.name for light in _snapshot(snapshot_module).lights]
    assert names == ["Shown"], names


def test_too_many_deform_bones_is_a_clear_error(voxgi, snapshot_module):
    from voxgi.voxgi_addon.errors import VoxGIError

    bones = [(f"B{i}", (0, 0, i), (0, 0, i + 0.5), None, True) for i in range(257)]
    rig = scenes.armature_object("Big Rig", bones)
    quad = scenes.quad_object("Quad")
    quad.vertex_groups.new(name="B0").add([0, 1, 2, 3], 1.0, "REPLACE")
    quad.modifiers.new("Armature", "ARMATURE").object = rig
    with pytest.raises(VoxGIError, match="257 deform bones"):
        _snapshot(snapshot_module)
