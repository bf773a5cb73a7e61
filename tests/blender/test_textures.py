"""Materials per texel (issue 18 point 2): image textures through UV maps and Mapping nodes,
procedural Base Colors baked by Cycles, sampled per texel on the GPU as in the numpy reference,
against Cycles (tests/data/texture_refs, made by tools/make_texture_references.py with Cycles'
default pixel filter), with the user's file left as it was.
"""
from __future__ import annotations

import json
import math
import pathlib

import bpy
import numpy as np
import pytest
import scenes
import texture_scenes
from cycles_reference import render_cycles_passes

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "texture_refs"
PASSES = ("Combined", "Diffuse Color", "Diffuse Direct", "Diffuse Indirect", "Glossy Indirect")


def relative_l1(ours, reference, mask):
    return float(np.abs(ours[mask] - reference[mask]).sum() / max(np.abs(reference[mask]).sum(), 1e-12))


def build(name="textured_room"):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    texture_scenes.build(name, scene)
    return scene


def preview(scene, tracer="AUTO", width=texture_scenes.WIDTH, height=texture_scenes.HEIGHT):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    scene.voxgi.tracer = tracer
    passes, lines = render_scene_passes(bpy.context, scene, None, width, height)
    assert scene_session(scene.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
    return {k: np.asarray(v, np.float64) for k, v in passes.items()}, lines


def file_state():
    """What a snapshot must leave as it found it: every datablock collection's names, the
    materials' node trees, the meshes' UV maps and material slots, selection and engine."""
    from voxgi.blender.snapshot.world_map import _tree_key

    state = {name: sorted(item.name_full for item in getattr(bpy.data, name))
             for name in ("objects", "meshes", "materials", "images", "scenes", "node_groups",
                          "cameras", "worlds", "textures")}
    state["trees"] = {m.name: repr(_tree_key(m.node_tree)) for m in bpy.data.materials
                      if m.node_tree is not None}
    state["uvs"] = {m.name: [(layer.name, layer.active, layer.active_render)
                             for layer in m.uv_layers] for m in bpy.data.meshes}
    state["slots"] = {o.name: [s.material.name if s.material else None for s in o.material_slots]
                      for o in bpy.data.objects}
    state["selected"] = sorted(o.name for o in bpy.context.view_layer.objects if o.select_get())
    active = bpy.context.view_layer.objects.active
    state["active"] = None if active is None else active.name
    state["engine"] = bpy.context.scene.render.engine
    state["scene"] = bpy.context.scene.name
    return state


def preview_beside_cycles(scene, tmp_path, width, height, name):
    """``name`` pass of voxgi.render_preview (F12) and of Cycles at 16 spp, same size."""
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "p.exr"), resolution_x=width,
                                        resolution_y=height) == {"FINISHED"}
    ours = read_exr_passes(str(tmp_path / "p.exr"))[name][..., :3]
    return ours, render_cycles_passes(scene, width, height, 16)[name][..., :3]


def test_snapshot_reads_the_image_and_bakes_the_procedural_wall(voxgi):
    from voxgi.blender.snapshot import materials as snapshot_materials
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    before = file_state()
    bakes = snapshot_materials.bake_count()
    snapshot = take_snapshot(bpy.context.scene)
    assert snapshot.warnings == ()
    assert file_state() == before  # the bake's scene, object, mesh, material, image are gone
    by_name = {m.name: m for m in snapshot.materials}
    floor = snapshot.textures[by_name["Checker Floor"].base_color_texture]
    # the image: 8-bit sRGB pixels linearised, the Mapping's scale as the UV transform
    pixels = texture_scenes.checker_pixels()[..., :3]
    encoded = np.round(pixels * 255) / 255
    linear = np.where(encoded <= 0.04045, encoded / 12.92, ((encoded + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(floor.pixels, linear, atol=2e-3)
    np.testing.assert_allclose(floor.uv_transform, [[3, 0, 0], [0, 2, 0]], atol=1e-6)
    assert (floor.interpolation, floor.extension) == ("Linear", "REPEAT")
    assert floor.srgb_bytes  # a byte sRGB image: blended in sRGB, as Cycles blends it
    # the Checker Texture node: baked by Cycles over the wall's UV map, its two colours
    wall = snapshot.textures[by_name["Checker Wall"].base_color_texture]
    assert snapshot_materials.bake_count() == bakes + 1
    values = wall.pixels.reshape(-1, 3)
    dark = np.array([0.15, 0.3, 0.6])
    light = np.array([0.8, 0.8, 0.75])
    near_dark = np.abs(values - dark).max(axis=1) < 0.02
    near_light = np.abs(values - light).max(axis=1) < 0.02
    assert near_dark.mean() > 0.4 and near_light.mean() > 0.4
    assert not wall.srgb_bytes  # Cycles' bake: float pixels, blended linearly
    assert snapshot.meshes["Back Wall"].uvs is not None
    # a second snapshot of the same content bakes nothing
    again = take_snapshot(bpy.context.scene)
    assert snapshot_materials.bake_count() == bakes + 1
    assert len(again.textures) == 2


def test_a_diffuse_bsdf_surface_is_baked_as_its_diffuse_colour(voxgi):
    """A material without a Principled BSDF (a Diffuse BSDF fed by a Checker Texture) gets
    Cycles' Diffuse Color pass baked: its checker colours, no glossy layer."""
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    material = bpy.data.materials["Checker Wall"]
    tree = material.node_tree
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    checker = next(n for n in tree.nodes if n.type == "TEX_CHECKER")
    tree.links.new(checker.outputs["Color"], diffuse.inputs["Color"])
    tree.links.new(diffuse.outputs["BSDF"], tree.get_output_node("ALL").inputs["Surface"])
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    before = file_state()
    snapshot = take_snapshot(bpy.context.scene)
    assert file_state() == before
    wall = next(m for m in snapshot.materials if m.name == "Checker Wall")
    assert wall.specular == 0.0 and wall.base_color_texture >= 0
    values = snapshot.textures[wall.base_color_texture].pixels.reshape(-1, 3)
    assert (np.abs(values - [0.15, 0.3, 0.6]).max(axis=1) < 0.02).mean() > 0.4
    assert (np.abs(values - [0.8, 0.8, 0.75]).max(axis=1) < 0.02).mean() > 0.4


def test_a_missing_image_warns_and_still_renders(voxgi):
    build()
    image = bpy.data.images.new("Missing", 4, 4)
    image.source = "FILE"
    image.filepath = "//no/such/file.png"
    node = next(n for n in bpy.data.materials["Checker Floor"].node_tree.nodes
                if n.type == "TEX_IMAGE")
    node.image = image
    passes, lines = preview(bpy.context.scene, "AUTO", 64, 48)
    text = " ".join(str(line) for line in lines)
    assert "Missing" in text and "missing or unreadable file" in text, lines
    # the floor (rows 32–37, columns 16–47 at 64 × 48) takes the Base Color value, 0.5 grey,
    # where the image's terracotta and cream cells would be far from grey
    colour = passes["Diffuse Color"][32:38, 16:48]
    assert colour.min() > 0.3
    assert np.abs(colour[..., 0] - colour[..., 2]).max() < 0.01
    assert np.abs(colour[..., 0] - colour[..., 1]).max() < 0.01


@pytest.mark.parametrize("quality", ["ACCURATE", "FAST"])
def test_numpy_and_gpu_sample_the_same_texels(voxgi, quality):
    """Primary pixels (mip level from the footprint) and bounce hits (level 0) sample the same
    texels on the GPU (atlas, manual wrap and filtering) as in numpy; in Fast quality the
    primary pixels do (and the voxels take their albedo per texel on both)."""
    def textured():
        scene = build()
        scene.voxgi.quality = quality
        return scene

    gpu, _ = preview(textured(), "AUTO", 64, 48)
    reference, _ = preview(textured(), "NUMPY", 64, 48)
    everywhere = np.ones((48, 64), bool)
    # the textures show: the back wall's checker (rows 12–19, columns 16–33 at 64 × 48)
    assert np.ptp(reference["Diffuse Color"][12:20, 16:34, 0]) > 0.3
    for name in PASSES:
        assert relative_l1(gpu[name], reference[name], everywhere) <= 0.02, name


def test_textures_upload_once(voxgi):
    """The atlas and the corner UVs are a part of the GPU scene: a second render of the same
    snapshot content uploads nothing, a recoloured image uploads the textures alone."""
    from voxgi.render.gpu_scene import peek_scene

    scene = build()
    preview(scene, "AUTO", 32, 24)
    assert peek_scene().textured and peek_scene().uploaded.get("textures", 0) > 0
    preview(scene, "AUTO", 32, 24)
    assert peek_scene().uploaded_bytes == 0, peek_scene().uploaded
    image = bpy.data.images["Checker Image"]
    pixels = texture_scenes.checker_pixels()
    pixels[..., :3] *= 0.5
    image.pixels.foreach_set(pixels.ravel())
    image.update()
    preview(scene, "AUTO", 32, 24)
    assert set(peek_scene().uploaded) == {"textures", "materials"}, peek_scene().uploaded


def test_textured_room_against_cycles(voxgi):
    """Relative L1 against Cycles 2048 spp (one bounce of either kind, default pixel filter)
    at tests/data/texture_refs/limits.json (issue 18: Combined ≤ 0.05, Diffuse Color ≤ 0.03);
    Cycles 16 spp + OIDN printed beside."""
    ours, _ = preview(build())
    with np.load(REFS / "textured_room.npz") as data:
        reference = {key: data[key].astype(np.float64) for key in data.files}
    limits = json.loads((REFS / "limits.json").read_text())["textured_room"]
    quick = json.loads((REFS / "cycles_spp.json").read_text())["textured_room"]["checks"]["16+OIDN"]
    mask = reference["Alpha"] > 0.5
    errors = {p: relative_l1(ours[p], reference[p], mask) for p in limits}
    print({k: round(v, 4) for k, v in errors.items()}, "Cycles 16 spp + OIDN", quick["relative_l1"])
    for name, error in errors.items():
        assert error <= limits[name], (name, error, limits[name])


def test_voxel_albedo_reads_the_floor_texture(voxgi):
    """The voxelizer's albedo of the snapshot's textured floor follows its checker per texel
    (voxels a few centimetres wide: dark and light cells), and keeps the image's mean."""
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.voxelize.attributes import average_attributes
    from voxgi.voxgi_addon.voxelize.scene_caches import texel_albedo, triangle_materials
    from voxgi.voxgi_addon.voxelize.surface import voxelize_triangles

    snapshot = take_snapshot(build())
    floor = snapshot.meshes["Floor"]
    positions = np.asarray(floor.positions, np.float64)
    sampler = texel_albedo(snapshot, floor, positions)
    assert sampler is not None
    albedo, spec = triangle_materials(snapshot, floor)
    surface = voxelize_triangles(positions, floor.triangles, 0.1)
    voxels = average_attributes(surface, positions, floor.triangles, albedo, spec,
                                texel_albedo=sampler).albedo
    flat = average_attributes(surface, positions, floor.triangles, albedo, spec).albedo
    assert np.ptp(flat[:, 0]) < 1e-6 and np.ptp(voxels[:, 0]) > 0.3
    texture = snapshot.textures[snapshot.materials[floor.triangle_materials[0]].base_color_texture]
    np.testing.assert_allclose(voxels.mean(axis=0), texture.pixels.reshape(-1, 3).mean(axis=0),
                               atol=0.03)


def test_f12_bakes_inside_the_render_and_leaves_the_file_unchanged(voxgi, tmp_path):
    """F12 of a fresh file (its procedural wall not baked yet): Cycles bakes it from inside
    the VoxGI render (background mode: F12 runs on the main thread), the frame has the
    textures' colours as ``voxgi.render_preview`` has them, and the file is as it was."""
    from voxgi.blender.snapshot import materials as snapshot_materials
    from voxgi.render.engine import enable_passes
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    scene = build()
    snapshot_materials.clear_bake_cache()
    before = file_state()
    bakes = snapshot_materials.bake_count()
    scene.render.engine = "VOXGI"
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    for view_layer in scene.view_layers:
        enable_passes(view_layer)
    scene.render.filepath = str(tmp_path / "f12.exr")
    before["engine"] = "VOXGI"
    before["images"] = sorted(before["images"] + ["Render Result"])  # F12's own
    bpy.ops.render.render(write_still=True)
    assert snapshot_materials.bake_count() == bakes + 1
    assert file_state() == before
    f12 = read_exr_passes(str(tmp_path / "f12.exr"))
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "preview.exr"),
                                        resolution_x=texture_scenes.WIDTH,
                                        resolution_y=texture_scenes.HEIGHT) == {"FINISHED"}
    operator = read_exr_passes(str(tmp_path / "preview.exr"))
    colour, reference = (np.asarray(p["Diffuse Color"], np.float64) for p in (f12, operator))
    assert np.ptp(reference[24:40, 32:96, 0]) > 0.3  # the wall's checker
    assert relative_l1(colour, reference, np.ones(colour.shape[:2], bool)) < 1e-3


def test_roughness_from_an_image_channel_is_read_per_texel(voxgi):
    """Roughness through a Separate Color node from an image (as the glTF importer builds a
    metallic-roughness map): a parameter texture holding the channel (its mean as the
    material's roughness) and the material's variants after it, without a warning; an
    Emission Color from an image is read per texel too (``emission_texture``)."""
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.scene.textures import PARAM_VARIANTS

    build()
    tree = bpy.data.materials["Checker Floor"].node_tree
    image_node = next(n for n in tree.nodes if n.type == "TEX_IMAGE")
    separate = tree.nodes.new("ShaderNodeSeparateColor")
    tree.links.new(image_node.outputs["Color"], separate.inputs["Color"])
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    tree.links.new(separate.outputs["Green"], bsdf.inputs["Roughness"])
    snapshot = take_snapshot(bpy.context.scene)
    index, floor = next((i, m) for i, m in enumerate(snapshot.materials)
                        if m.name == "Checker Floor")
    green = snapshot.textures[floor.base_color_texture].pixels[..., 1]
    params = snapshot.textures[floor.param_texture].pixels
    np.testing.assert_allclose(params[..., 0], green, atol=1e-6)
    np.testing.assert_allclose(params[..., 1], bsdf.inputs["Metallic"].default_value)
    assert floor.roughness == pytest.approx(green.mean(), abs=1e-4)
    assert floor.param_variants == index + 1
    assert len(snapshot.materials) >= index + 1 + PARAM_VARIANTS
    assert not any("Roughness" in w for w in snapshot.warnings), snapshot.warnings
    tree.links.new(image_node.outputs["Color"], bsdf.inputs["Emission Color"])
    bsdf.inputs["Emission Strength"].default_value = 2.0
    snapshot = take_snapshot(bpy.context.scene)
    assert not any("Emission" in w for w in snapshot.warnings), snapshot.warnings
    floor = next(m for m in snapshot.materials if m.name == "Checker Floor")
    # the same image node: the same texture, per texel × the strength (its mean × it per material)
    assert floor.emission_texture == floor.base_color_texture >= 0
    assert floor.emission_strength == 2.0
    np.testing.assert_allclose(floor.emission, 2.0 * floor.base_color, rtol=1e-5)


def test_a_procedural_material_on_a_mesh_without_uvs_is_baked_over_its_own_layout(voxgi, tmp_path):
    """A mesh without a UV map (never unwrapped) whose material is procedural: its polygons
    are laid out in the UV square for the bake (``auto_uvs``) and its triangles read them, so
    the checker on Generated coordinates is drawn as Cycles draws it. (It kept the socket's
    plain value, with a warning: Diffuse Color 0.29 off Cycles' over the wall.)"""
    from voxgi.blender.snapshot.scene import take_snapshot

    scene = build()
    wall = bpy.data.materials["Checker Wall"]
    left = bpy.data.objects["Left Wall"]
    assert len(left.data.uv_layers) == 0
    left.data.materials[0] = wall
    snapshot = take_snapshot(scene)
    assert not any("UV" in w for w in snapshot.warnings), snapshot.warnings
    variants = [m for m in snapshot.materials if m.name == "Checker Wall"]
    assert [m.base_color_texture >= 0 for m in variants] == [True, True]
    assert snapshot.meshes["Left Wall"].uvs is not None
    assert len(left.data.uv_layers) == 0  # the user's mesh is unchanged
    width, height = texture_scenes.WIDTH, texture_scenes.HEIGHT
    ours, cycles = preview_beside_cycles(scene, tmp_path, width, height, "Diffuse Color")
    wall_pixels = np.zeros((height, width), bool)
    wall_pixels[:, : width // 5] = True  # the left wall fills the image's left fifth
    assert relative_l1(ours, cycles, wall_pixels) < 0.06


def test_a_procedural_material_over_tiling_uvs_is_baked_over_its_own_layout(voxgi, tmp_path):
    """A floor whose UVs tile (0–4, as artists scale them to repeat a texture) and whose Base
    Color is a checker on those UVs through a Hue/Saturation node: a bake over the UV map writes
    the UV square alone (a sixteenth of the floor), so it is baked over a layout of the
    polygons, the nodes still reading the tiling UVs (it drew one stretched square: Diffuse
    Color 0.56 off Cycles')."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    mesh = bpy.context.object.data
    uvs = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers[0].data.foreach_get("uv", uvs)
    mesh.uv_layers[0].data.foreach_set("uv", uvs * 4.0)
    material = bpy.data.materials.new("Tiled")
    tree = material.node_tree
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 2.0
    tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["UV"], checker.inputs["Vector"])
    hue = tree.nodes.new("ShaderNodeHueSaturation")
    tree.links.new(checker.outputs["Color"], hue.inputs["Color"])
    tree.links.new(hue.outputs["Color"],
                   next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"])
    mesh.materials.append(material)
    bpy.ops.object.light_add(type="SUN", rotation=(0.3, 0.2, 0.0))
    scenes.camera_looking_at((0.0, 0.0, 6.0), target=(0.0, 0.0, 0.0), scene=scene)
    size = 64
    ours, cycles = preview_beside_cycles(scene, tmp_path, size, size, "Diffuse Color")
    floor = cycles.max(-1) > 0.05
    assert floor.mean() > 0.8
    assert relative_l1(ours, cycles, floor) < 0.1


def test_an_emission_shader_built_of_nodes_glows_per_texel_as_in_cycles(voxgi, tmp_path):
    """A screen: an Emission shader whose Color is a checker and whose Strength is a Math node
    of the checker's Fac (the bright squares brighter still). Cycles bakes the surface's own
    emission; the screen's squares glow as Cycles draws them (it glowed at the values alone:
    one flat colour)."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=2.0, rotation=(math.pi / 2, 0.0, 0.0))
    material = bpy.data.materials.new("Screen")
    tree = material.node_tree
    tree.nodes.remove(next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"))
    glow = tree.nodes.new("ShaderNodeEmission")
    checker = tree.nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = 4.0
    checker.inputs["Color1"].default_value = (1.0, 0.6, 0.2, 1.0)
    checker.inputs["Color2"].default_value = (0.1, 0.3, 1.0, 1.0)
    strength = tree.nodes.new("ShaderNodeMath")
    strength.operation = "MULTIPLY_ADD"
    strength.inputs[1].default_value, strength.inputs[2].default_value = 3.0, 1.0
    tree.links.new(checker.outputs["Color"], glow.inputs["Color"])
    tree.links.new(checker.outputs["Fac"], strength.inputs[0])
    tree.links.new(strength.outputs[0], glow.inputs["Strength"])
    tree.links.new(glow.outputs[0], tree.get_output_node("ALL").inputs["Surface"])
    bpy.context.object.data.materials.append(material)
    scenes.camera_looking_at((0.0, -3.0, 0.0), scene=scene)
    size = 48
    ours, cycles = preview_beside_cycles(scene, tmp_path, size, size, "Combined")
    screen = np.zeros((size, size), bool)
    screen[10:38, 10:38] = True  # inside the screen's 2 m square (2.16 m across the view)
    assert relative_l1(ours, cycles, screen) < 0.05
    bright = cycles[screen].sum(-1)
    assert bright.max() > 3.0 * bright.min()  # the checker is there to be drawn


def test_vertex_colours_on_a_mesh_without_uvs_are_drawn_as_in_cycles(voxgi, tmp_path):
    """A vertex-painted ball, never unwrapped (a Color Attribute into the Base Color): red on
    one side, blue on the other, as Cycles draws it (it was the socket's grey)."""
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0)
    mesh = bpy.context.object.data
    while mesh.uv_layers:
        mesh.uv_layers.remove(mesh.uv_layers[0])
    paint = mesh.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    corners = np.array([mesh.vertices[loop.vertex_index].co.x for loop in mesh.loops])
    colours = np.zeros((len(mesh.loops), 4), np.float32)
    colours[:, 0], colours[:, 2], colours[:, 1], colours[:, 3] = corners > 0, corners <= 0, 0.3, 1
    paint.data.foreach_set("color", colours.ravel())
    material = bpy.data.materials.new("Painted")
    tree = material.node_tree
    attribute = tree.nodes.new("ShaderNodeVertexColor")
    attribute.layer_name = "Paint"
    tree.links.new(attribute.outputs["Color"],
                   next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"])
    mesh.materials.append(material)
    scenes.camera_looking_at((0.0, -5.0, 0.0), scene=scene)
    bpy.ops.object.light_add(type="SUN", rotation=(0.6, 0.2, 0.0))
    width, height = 64, 48
    ours, cycles = preview_beside_cycles(scene, tmp_path, width, height, "Diffuse Color")
    ball = cycles.max(-1) > 0.2
    assert ball.sum() > 400
    assert relative_l1(ours, cycles, ball) < 0.05
    for column in (20, 44):  # the blue side, the red side
        np.testing.assert_allclose(ours[24, column], cycles[24, column], atol=0.05)


def test_the_layout_of_a_mesh_without_uvs_keeps_polygons_apart_and_flat(voxgi):
    """Every polygon in its own square of the UV square, none overlapping, each drawn flat
    (its UV distances ∝ its own), the larger polygons the larger squares."""
    from voxgi.blender.snapshot.auto_uvs import layout, polygon_uvs

    bpy.ops.mesh.primitive_cylinder_add(vertices=12, radius=1.0, depth=3.0)  # 2 n-gons, 12 quads
    mesh = bpy.context.object.data
    uvs = polygon_uvs(mesh).astype(np.float64)
    assert uvs.min() >= 0.0 and uvs.max() <= 1.0
    boxes = []
    for polygon in mesh.polygons:
        loops = list(polygon.loop_indices)
        points = np.array([mesh.vertices[mesh.loops[i].vertex_index].co[:] for i in loops])
        flat = uvs[loops]
        # flat: distances between corners in UV ∝ in space, one ratio per polygon
        ratio = np.linalg.norm(flat[1:] - flat[0], axis=-1) / np.linalg.norm(points[1:] - points[0], axis=-1)
        np.testing.assert_allclose(ratio, ratio[0], rtol=1e-4)
        boxes.append((flat.min(0), flat.max(0), polygon.area))
    for i, (low, high, _) in enumerate(boxes):
        for other_low, other_high, _ in boxes[i + 1:]:
            assert not ((low < other_high).all() and (other_low < high).all())
    # each square's side ∝ √(its polygon's area): the texels spread evenly over the surface
    sides = np.array([max(high - low) / np.sqrt(area) for low, high, area in boxes])
    np.testing.assert_allclose(sides, sides[0], rtol=1e-3)
    # a broken vertex (NaN) leaves every other polygon laid out
    points = np.array([v.co[:] for v in mesh.vertices])[[loop.vertex_index for loop in mesh.loops]]
    points[0] = np.nan
    starts = np.array([p.loop_start for p in mesh.polygons])
    totals = np.array([p.loop_total for p in mesh.polygons])
    normals = np.array([p.normal[:] for p in mesh.polygons])
    broken = layout(points, starts, totals, normals)
    assert np.isfinite(broken).all() and broken.min() >= 0.0 and broken.max() <= 1.0


def test_a_procedural_material_in_a_slot_no_face_uses_is_not_baked(voxgi):
    """A material slot that no face of the mesh uses (a material added to an object and not
    assigned, as users leave them) shows nothing: it is not baked and draws no warning. (Its
    bake once ran over an empty mesh and warned that it failed.)"""
    from voxgi.blender.snapshot import materials
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    floor = bpy.data.objects["Floor"]
    floor.data.materials.append(bpy.data.materials["Checker Wall"])  # slot 1, on no face
    assert not any(p.material_index == 1 for p in floor.data.polygons)
    materials.clear_bake_cache()
    snapshot = take_snapshot(bpy.context.scene)
    assert not any("Checker Wall" in w for w in snapshot.warnings), snapshot.warnings
    wall = [m for m in snapshot.materials if m.name == "Checker Wall"]
    # the wall that has it is still baked
    assert any(m.base_color_texture >= 0 for m in wall)


def test_a_bake_reads_object_info_color_and_pass_index_of_its_object(voxgi):
    """Object Info › Color and Object Index feed the Base Color (objects tinted by their
    Viewport Display colour, as motion-graphics artists set them): the bake's object takes
    them from the object, which Cycles renders with. It baked with its own (white, 0): the
    tint was lost."""
    from voxgi.blender.snapshot import materials
    from voxgi.blender.snapshot.scene import take_snapshot

    build()
    wall = next(o for o in bpy.data.objects if o.type == "MESH" and
                "Checker Wall" in [m.name for m in o.data.materials if m is not None])
    tree = bpy.data.materials["Checker Wall"].node_tree
    principled = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    source = principled.inputs["Base Color"].links[0].from_socket
    info = tree.nodes.new("ShaderNodeObjectInfo")
    tint = tree.nodes.new("ShaderNodeMix")
    tint.data_type, tint.blend_type = "RGBA", "MULTIPLY"
    tint.inputs["Factor"].default_value = 1.0
    tree.links.new(source, tint.inputs["A"])
    tree.links.new(info.outputs["Color"], tint.inputs["B"])
    brightness = tree.nodes.new("ShaderNodeMath")  # × (1 + Object Index) / 4
    brightness.operation = "MULTIPLY_ADD"
    brightness.inputs[1].default_value, brightness.inputs[2].default_value = 0.25, 0.25
    tree.links.new(info.outputs["Object Index"], brightness.inputs[0])
    scaled = tree.nodes.new("ShaderNodeMix")
    scaled.data_type, scaled.blend_type = "RGBA", "MULTIPLY"
    scaled.inputs["Factor"].default_value = 1.0
    tree.links.new(tint.outputs["Result"], scaled.inputs["A"])
    tree.links.new(brightness.outputs["Value"], scaled.inputs["B"])
    tree.links.new(scaled.outputs["Result"], principled.inputs["Base Color"])

    def wall_mean():
        materials.clear_bake_cache()
        snapshot = take_snapshot(bpy.context.scene)
        baked = next(m for m in snapshot.materials if m.name == "Checker Wall")
        pixels = snapshot.textures[baked.base_color_texture].pixels.reshape(-1, 3)
        return pixels[pixels.max(axis=1) > 0].mean(axis=0)

    wall.color, wall.pass_index = (1.0, 1.0, 1.0, 1.0), 3  # × 1: the checker itself
    plain = wall_mean()
    wall.color, wall.pass_index = (0.2, 0.6, 0.9, 1.0), 1  # × the colour × 0.5
    np.testing.assert_allclose(wall_mean(), plain * np.array([0.2, 0.6, 0.9]) * 0.5, rtol=0.02)


def test_masked_sub_pixel_rasters_give_the_same_image(voxgi, monkeypatch):
    """The sub-pixel passes of a textured scene rasterize only the edge pixels they list
    (``gbuffer.PixelMask``: depth 0 elsewhere, so the textured fragments there are never
    shaded): the preview is the one the unmasked rasters give, bit for bit, and it did mask
    (the passes' one supersampled raster: ``gpu_preview.supersampling``)."""
    from voxgi.render import gbuffer, gpu_preview

    scene = build()
    drawn, rasters = [], []
    draw = gbuffer.PixelMask.draw
    monkeypatch.setattr(gbuffer.PixelMask, "draw", lambda self: (drawn.append(1), draw(self)))
    rasterize = gpu_preview.rasterize
    monkeypatch.setattr(gpu_preview, "rasterize", lambda *a, **k: rasters.append(
        k.get("mask")) or rasterize(*a, **k))
    masked, _ = preview(scene)
    assert rasters and all(mask is not None for mask in rasters)  # every sub-pixel raster
    assert len(drawn) == len(rasters)  # masked its raster
    monkeypatch.setattr(gbuffer.PixelMask, "draw", lambda self: None)
    plain, _ = preview(scene)
    for name in PASSES:
        assert np.array_equal(masked[name], plain[name]), name


def build_two_texels(float_buffer: bool):
    """A plane filling an orthographic camera's view whose Base Color is a 4 × 1 image (dark,
    light, dark, light; Linear, Extend), each texel 16 pixels wide at 64 × 16: the blends
    between texels span pixels."""
    from gi_scenes import _camera, _finish, _light

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    image = bpy.data.images.new("Texels", 4, 1, alpha=False, float_buffer=float_buffer)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(np.float32([0.05, 0.05, 0.05, 1, 0.9, 0.9, 0.9, 1] * 2))
    image.pack()
    material = texture_scenes.image_material("Texels", image, scale=(1.0, 1.0, 1.0))
    material.node_tree.nodes["Image Texture"].extension = "EXTEND"
    texture_scenes.quad(scene, "Plane", [(-2, -0.5, 0), (2, -0.5, 0), (2, 0.5, 0), (-2, 0.5, 0)],
                        material)
    _light(scene, "Sun", "SUN", (0, 0, 5), direction=(0, 0, -1), energy=3.0)
    camera = _camera(scene, "Camera", (0, 0, 3), (0, 0, 0), lens=50.0)
    camera.data.type = "ORTHO"
    camera.data.ortho_scale = 4.0
    _finish(scene, {})
    return scene


@pytest.mark.parametrize("float_buffer", [False, True])
def test_texel_blends_match_cycles_for_byte_and_float_images(voxgi, float_buffer):
    """Cycles blends a byte sRGB image's encoded bytes and decodes the blend, a float image's
    linear values: across the blends between a dark and a light texel, VoxGI's Diffuse Color
    follows Cycles' for both (relative L1 ≤ 0.02). Blended linearly, the byte image read 0.36
    half-way between two texels where Cycles reads 0.17 (relative L1 0.35)."""

    width, height = 64, 16
    ours, _ = preview(build_two_texels(float_buffer), "AUTO", width, height)
    cycles = render_cycles_passes(build_two_texels(float_buffer), width, height, 16)
    row = slice(4, 12)
    mine, theirs = ours["Diffuse Color"][row, :, 0], cycles["Diffuse Color"][row, :, 0]
    mask = np.ones(mine.shape, bool)
    error = relative_l1(mine, theirs, mask)
    middle = theirs[:, 32].mean()  # half-way between the 2nd texel's centre and the 3rd's
    print({"relative L1": round(error, 4), "Cycles at a blend": round(float(middle), 3),
           "VoxGI": round(float(mine[:, 32].mean()), 3)})
    assert error <= 0.02
    assert abs(mine[:, 32].mean() - middle) <= 0.02
