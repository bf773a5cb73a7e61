"""Shader mixes (blender/snapshot/shader_mix.py) as artists build them: two Principled BSDFs
under a mask, a Diffuse and a Glossy BSDF mixed by a Fresnel, a Glossy BSDF alone. Each is read
as one Principled BSDF of mixed parameters (per texel where a mask comes from nodes), and
reflects as in Cycles. (A mix was read as its first Principled BSDF, or as its diffuse colour
with no glossy layer.)"""
from __future__ import annotations

import math

import bpy
import numpy as np
from cycles_reference import render_cycles_passes

WIDTH, HEIGHT = 80, 60


def _bare(name):
    """A new material with only its output: (material, tree, output)."""
    material = bpy.data.materials.new(name)
    tree = material.node_tree
    for node in list(tree.nodes):
        if node.type != "OUTPUT_MATERIAL":
            tree.nodes.remove(node)
    return material, tree, next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL")


def _principled(tree, colour, roughness=0.5, metallic=0.0):
    node = tree.nodes.new("ShaderNodeBsdfPrincipled")
    node.inputs["Base Color"].default_value = (*colour, 1.0)
    node.inputs["Roughness"].default_value = roughness
    node.inputs["Metallic"].default_value = metallic
    return node


def _mix(tree, output, first, second, fac=0.5):
    mix = tree.nodes.new("ShaderNodeMixShader")
    mix.inputs[0].default_value = fac
    tree.links.new(first.outputs[0], mix.inputs[1])
    tree.links.new(second.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])
    return mix


def plastic(name="Plastic"):
    """The classic plastic: Mix(Fresnel IOR 1.5, Diffuse red, Glossy white at 0.15)."""
    material, tree, output = _bare(name)
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.7, 0.1, 0.1, 1.0)
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    glossy.inputs["Roughness"].default_value = 0.15
    fresnel = tree.nodes.new("ShaderNodeFresnel")
    fresnel.inputs["IOR"].default_value = 1.5
    mix = _mix(tree, output, diffuse, glossy)
    tree.links.new(fresnel.outputs[0], mix.inputs[0])
    return material


def checker_inlay(name="Inlay"):
    """A floor: Mix(Checker Fac, Principled stone, Principled gold metal)."""
    material, tree, output = _bare(name)
    stone = _principled(tree, (0.6, 0.55, 0.5), roughness=0.6)
    gold = _principled(tree, (1.0, 0.76, 0.33), roughness=0.25, metallic=1.0)
    mix = _mix(tree, output, stone, gold)
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 6.0
    checker.inputs["Color1"].default_value = (1, 1, 1, 1)
    checker.inputs["Color2"].default_value = (0, 0, 0, 1)
    tree.links.new(checker.outputs["Fac"], mix.inputs[0])
    return material


def test_mixes_of_values_read_as_one_mixed_principled(voxgi):
    from voxgi.blender.snapshot.materials import MaterialTable

    half, tree, output = _bare("Half Gold")
    _mix(tree, output, _principled(tree, (0.8, 0.1, 0.1), 0.6),
         _principled(tree, (1.0, 0.8, 0.4), 0.2, metallic=1.0), fac=0.25)
    chrome, tree, output = _bare("Chrome")
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    glossy.inputs["Color"].default_value = (0.9, 0.9, 0.9, 1.0)
    glossy.inputs["Roughness"].default_value = 0.1
    tree.links.new(glossy.outputs[0], output.inputs["Surface"])
    matte, tree, output = _bare("Matte")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.2, 0.5, 0.3, 1.0)
    tree.links.new(diffuse.outputs[0], output.inputs["Surface"])
    warnings = []
    table = MaterialTable(warnings)
    read = {m.name: table.materials[table.index_of(m)] for m in (half, chrome, plastic(), matte)}
    assert warnings == []  # values alone: no bake asked for (without a mesh it would warn)
    np.testing.assert_allclose(read["Matte"].base_color, [0.2, 0.5, 0.3], atol=1e-6)
    assert read["Matte"].specular == 0.0 and read["Matte"].metallic == 0.0
    np.testing.assert_allclose(read["Half Gold"].base_color, [0.85, 0.275, 0.175], atol=1e-6)
    assert abs(read["Half Gold"].metallic - 0.25) < 1e-6
    assert abs(read["Half Gold"].roughness - 0.5) < 1e-6
    np.testing.assert_allclose(read["Chrome"].base_color, [0.9, 0.9, 0.9], atol=1e-6)
    assert read["Chrome"].metallic == 1.0 and abs(read["Chrome"].roughness - 0.1) < 1e-6
    # the Fresnel mix: the Diffuse's colour, the Glossy's roughness, IOR 1.5's reflectance
    np.testing.assert_allclose(read["Plastic"].base_color, [0.7, 0.1, 0.1], atol=1e-6)
    assert read["Plastic"].metallic == 0.0 and abs(read["Plastic"].roughness - 0.15) < 1e-6
    assert abs(read["Plastic"].specular - 0.5) < 1e-3


def _room(scene, materials):
    """A floor and a back wall (grey) and one sphere per material, an area lamp, a camera."""
    wall = bpy.data.materials.new("Wall")
    for location, rotation in (((0, 0, 0), (0, 0, 0)), ((0, 3, 5), (math.pi / 2, 0, 0))):
        bpy.ops.mesh.primitive_plane_add(size=10, location=location, rotation=rotation)
        bpy.context.object.data.materials.append(wall)
    for i, material in enumerate(materials):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.7, location=(1.6 * i - 0.8 * (len(materials) - 1), 0.5, 0.7))
        bpy.ops.object.shade_smooth()
        bpy.context.object.data.materials.append(material)
    lamp = bpy.data.objects.new("Lamp", bpy.data.lights.new("Lamp", "AREA"))
    lamp.data.energy, lamp.data.size, lamp.location = 300.0, 1.0, (1.0, -1.0, 3.0)
    scene.collection.objects.link(lamp)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location, camera.rotation_euler = (0.0, -4.5, 1.4), (math.radians(80), 0.0, 0.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    world = bpy.data.worlds.new("Sky")
    world.color = (0.3, 0.35, 0.45)
    scene.world = world


def _preview(tmp_path):
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=WIDTH,
                                        resolution_y=HEIGHT) == {"FINISHED"}
    return {k: np.asarray(v, np.float64) for k, v in read_exr_passes(str(tmp_path / "p.exr")).items()}


def test_a_fresnel_mixed_plastic_has_its_highlight_as_in_cycles(voxgi, tmp_path):
    scene = bpy.context.scene
    _room(scene, [plastic()])
    ours = _preview(tmp_path)
    cycles = {k: np.asarray(v, np.float64) for k, v in
              render_cycles_passes(scene, WIDTH, HEIGHT, 64, glossy_bounces=1).items()}
    sphere = np.abs(cycles["Diffuse Color"] - [0.7, 0.1, 0.1]).max(-1) < 0.05
    assert sphere.sum() > 200
    glossy = [(p["Glossy Direct"] * p["Glossy Color"])[sphere].sum() for p in (ours, cycles)]
    assert abs(glossy[0] / glossy[1] - 1.0) < 0.25, glossy  # it had none
    combined = [p["Combined"][sphere].sum() for p in (ours, cycles)]
    assert abs(combined[0] / combined[1] - 1.0) < 0.05, combined


def test_a_masked_mix_is_each_side_per_texel_as_in_cycles(voxgi, tmp_path):
    scene = bpy.context.scene
    _room(scene, [])
    bpy.data.objects["Plane"].data.materials[0] = checker_inlay()
    ours = _preview(tmp_path)
    cycles = {k: np.asarray(v, np.float64) for k, v in
              render_cycles_passes(scene, WIDTH, HEIGHT, 16).items()}
    floor = np.zeros((HEIGHT, WIDTH), bool)
    floor[HEIGHT // 2 + 4:] = True  # below the horizon of the back wall's foot
    for name in ("Diffuse Color", "Glossy Color"):
        error = np.abs(ours[name] - cycles[name])[floor].sum() / cycles[name][floor].sum()
        assert error < 0.1, (name, error)
    gold = (cycles["Diffuse Color"].max(-1) < 0.05) & floor  # the metal squares
    assert 0.3 < gold.sum() / floor.sum() < 0.7


def test_a_gfg_export_writes_a_mix_as_the_principled_the_preview_reads(voxgi, tmp_path):
    from voxgi.blender.gfg.material import export_material
    from voxgi.voxgi_addon.files.gfg.spec import MaterialLogic, PrincipledSlot

    half, tree, output = _bare("Half Gold")
    _mix(tree, output, _principled(tree, (0.8, 0.1, 0.1), 0.6),
         _principled(tree, (1.0, 0.8, 0.4), 0.2, metallic=1.0), fac=0.25)
    warnings = []
    exported = {m.name: export_material(m, str(tmp_path), warnings) for m in (half, plastic())}
    gold, shiny = exported["Half Gold"], exported["Plastic"]
    assert gold.logic == shiny.logic == MaterialLogic.PRINCIPLED
    np.testing.assert_allclose(gold.uniforms[PrincipledSlot.BASE_COLOR], [0.85, 0.275, 0.175, 1.0],
                               atol=1e-6)
    np.testing.assert_allclose(gold.uniforms[PrincipledSlot.METALLIC], [0.25], atol=1e-6)
    np.testing.assert_allclose(gold.uniforms[PrincipledSlot.ROUGHNESS], [0.5], atol=1e-6)
    np.testing.assert_allclose(shiny.uniforms[PrincipledSlot.SPECULAR], [0.5], atol=1e-3)
    np.testing.assert_allclose(shiny.uniforms[PrincipledSlot.ROUGHNESS], [0.15], atol=1e-6)
    assert warnings == []  # the plastic's Fresnel is read, not a value taken from nodes


def test_a_normal_map_both_sides_share_is_the_mixs_own(voxgi):
    """A layered material whose Normal Map node feeds both Principled BSDFs keeps its normal
    map; two different normal maps are named as left out."""
    from voxgi.blender.snapshot.materials import MaterialTable

    def normal_map(tree, name):
        image = bpy.data.images.new(name, 8, 8)
        image.colorspace_settings.name = "Non-Color"
        texture = tree.nodes.new("ShaderNodeTexImage")
        texture.image = image
        node = tree.nodes.new("ShaderNodeNormalMap")
        tree.links.new(texture.outputs["Color"], node.inputs["Color"])
        return node

    materials = {}
    for name, shared in (("Shared", True), ("Apart", False)):
        material, tree, output = _bare(name)
        first, second = _principled(tree, (0.8, 0.1, 0.1)), _principled(tree, (0.1, 0.1, 0.8))
        _mix(tree, output, first, second, fac=0.5)
        bump = normal_map(tree, f"{name} bumps")
        tree.links.new(bump.outputs[0], first.inputs["Normal"])
        tree.links.new((bump if shared else normal_map(tree, f"{name} more")).outputs[0],
                       second.inputs["Normal"])
        materials[name] = material
    warnings = []
    table = MaterialTable(warnings)
    read = {name: table.materials[table.index_of(m)] for name, m in materials.items()}
    assert read["Shared"].normal_texture >= 0 and read["Apart"].normal_texture < 0
    assert [w for w in warnings if "different nodes" in w and "'Apart'" in w], warnings
    assert not [w for w in warnings if "'Shared'" in w], warnings
