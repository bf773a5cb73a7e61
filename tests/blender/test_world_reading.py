"""The world as an equirect radiance map (blender/snapshot/world_map.py) against Cycles.

References are Cycles renders independent of our map convention: a perspective camera with a
tiny field of view looking along a direction, point-sampled at its centre, sees the world's
radiance in that direction.
"""
from __future__ import annotations

import importlib
import math
import os
import tempfile

import bpy
import numpy as np
import pytest
from mathutils import Vector

from voxgi.voxgi_addon.files.exr import read_exr
from voxgi.voxgi_addon.scene import equirect

SUN = (math.radians(30.0), math.radians(60.0))  # elevation, azimuth of the sun disc in the image
SUN_RADIUS = math.radians(4.0)
SUN_VALUE = 40.0


@pytest.fixture
def world_map(voxgi):
    module = importlib.import_module("voxgi.blender.snapshot.world_map")
    module.clear_cache()
    return module


def _direction(el, phi):
    return np.array([math.cos(el) * math.cos(phi), math.cos(el) * math.sin(phi), math.sin(el)])


def _sky_image(width=128, height=64):
    """A float equirect image: a smooth sky varying with azimuth and elevation plus a bright
    disc, laid out as Blender stores images (row 0 = bottom, u = 0.5 - phi / 2pi)."""
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    phi = (0.5 - u)[None, :] * 2 * np.pi
    el = (v - 0.5)[:, None] * np.pi
    px = np.ones((height, width, 4), np.float32)
    px[..., 0] = 0.5 + 0.2 * np.cos(phi) + 0.2 * np.sin(el)
    px[..., 1] = 0.4 + 0.2 * np.sin(phi) + 0.0 * el
    px[..., 2] = 0.8 + 0.3 * np.sin(el) + 0.0 * phi
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi), np.sin(el)), -1)
    px[np.arccos(np.clip(d @ _direction(*SUN), -1, 1)) < SUN_RADIUS, :3] = SUN_VALUE
    image = bpy.data.images.new("Sky", width, height, float_buffer=True)
    image.pixels.foreach_set(px.ravel())
    return image


def _image_world(strength=2.0):
    world = bpy.data.worlds.new("HDRI")
    tree = world.node_tree
    background = tree.nodes["Background"]
    background.inputs["Strength"].default_value = strength
    env = tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = _sky_image()
    tree.links.new(env.outputs["Color"], background.inputs["Color"])
    bpy.context.scene.world = world
    return world, env


def _cycles_view(world, direction, size=24, fov=math.radians(100.0)):
    """Cycles' radiance of ``world`` in a perspective camera looking along ``direction``,
    point-sampled at the pixel centres: (directions (N, 3), radiance (N, 3))."""
    scene = bpy.data.scenes.new("Reference")
    camera = bpy.data.cameras.new("Reference")
    camera.angle = fov
    obj = bpy.data.objects.new("Reference", camera)
    obj.rotation_euler = Vector(direction).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(obj)
    scene.camera, scene.world = obj, world
    render = scene.render
    render.engine, render.resolution_x, render.resolution_y = "CYCLES", size, size
    render.film_transparent = render.use_compositing = render.use_sequencer = False
    render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    render.image_settings.color_depth = "32"
    scene.cycles.device, scene.cycles.samples = "CPU", 1
    scene.cycles.use_denoising = scene.cycles.use_adaptive_sampling = False
    scene.cycles.pixel_filter_type, scene.cycles.filter_width = "BOX", 0.01
    try:
        with tempfile.TemporaryDirectory() as tmp:
            render.filepath, render.use_file_extension = os.path.join(tmp, "r.exr"), False
            bpy.ops.render.render(write_still=True, scene=scene.name)
            channels = read_exr(render.filepath)
        radiance = np.stack([channels[f"ViewLayer.Combined.{c}"] for c in "RGB"], -1).reshape(-1, 3)
        half = math.tan(fov / 2)
        centres = (np.arange(size) + 0.5) / size * 2 - 1
        x, y = np.meshgrid(centres * half, -centres * half)  # EXR row 0 is the top
        local = np.stack([x, y, -np.ones_like(x)], -1).reshape(-1, 3)
        local /= np.linalg.norm(local, axis=-1, keepdims=True)
        rotation = np.array(obj.rotation_euler.to_matrix())
        return local @ rotation.T, radiance
    finally:
        bpy.data.scenes.remove(scene)
        bpy.data.objects.remove(obj)
        bpy.data.cameras.remove(camera)


def _assert_matches_cycles(world, radiance, direction, rtol):
    directions, theirs = _cycles_view(world, direction)
    np.testing.assert_allclose(equirect.sample_bilinear(radiance, directions), theirs, rtol=rtol)


# looking away from the sun disc (its edge is a discontinuity no interpolation matches)
AWAY = -_direction(*SUN)


def _snapshot_world(voxgi):
    from voxgi.blender.snapshot.environment import read_world

    warnings: list[str] = []
    return read_world(bpy.context.scene, warnings), warnings


def _sun_direction(radiance):
    lum = radiance.sum(axis=-1)
    rows, cols = np.nonzero(lum > 0.5 * lum.max())
    weights = equirect.row_solid_angles(*radiance.shape[:2])[rows]
    dirs = equirect.pixel_directions(*radiance.shape[:2])[rows, cols]
    mean = (dirs * weights[:, None]).sum(axis=0)
    return mean / np.linalg.norm(mean)


def _angle(a, b):
    return math.degrees(math.acos(np.clip(np.dot(a, b), -1, 1)))


def test_environment_texture_matches_cycles(voxgi, world_map):
    world, _ = _image_world(strength=2.0)
    bakes = world_map.bake_count()
    data, warnings = _snapshot_world(voxgi)
    assert warnings == [] and world_map.bake_count() == bakes  # read directly
    assert data.radiance.shape == (64, 128, 3) and data.radiance.dtype == np.float32
    _assert_matches_cycles(world, data.radiance, AWAY, rtol=0.01)
    assert _angle(_sun_direction(data.radiance), _direction(*SUN)) < 1.0
    # the ambient term is the solid-angle mean radiance
    assert data.strength == 1.0
    np.testing.assert_allclose(data.color, equirect.mean_radiance(data.radiance), rtol=1e-6)


@pytest.mark.parametrize("vector_type, source", [("POINT", "Generated"), ("TEXTURE", "Object")])
def test_mapped_environment_texture_matches_cycles(voxgi, world_map, vector_type, source):
    world, env = _image_world(strength=1.5)
    tree = world.node_tree
    mapping = tree.nodes.new("ShaderNodeMapping")
    mapping.vector_type = vector_type
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, math.radians(45.0))
    coords = tree.nodes.new("ShaderNodeTexCoord")
    tree.links.new(coords.outputs[source], mapping.inputs["Vector"])
    tree.links.new(mapping.outputs["Vector"], env.inputs["Vector"])
    bakes = world_map.bake_count()
    data, warnings = _snapshot_world(voxgi)
    assert warnings == [] and world_map.bake_count() == bakes
    # a texture rotated +45 deg about Z (POINT: t = R d) shows the sun at R^-1 sun
    turn = -45.0 if vector_type == "POINT" else 45.0
    expected = _direction(SUN[0], SUN[1] + math.radians(turn))
    assert _angle(_sun_direction(data.radiance), expected) < 1.5
    if source == "Object":  # an object's inverse transform, then location and scale
        empty = bpy.data.objects.new("Frame", None)
        bpy.context.scene.collection.objects.link(empty)
        empty.rotation_euler = (math.radians(20.0), 0.0, math.radians(-30.0))
        coords.object = empty
        mapping.inputs["Location"].default_value = (0.1, -0.2, 0.05)
        mapping.inputs["Scale"].default_value = (1.0, 1.5, 0.8)
        bpy.context.view_layer.update()
        data, warnings = _snapshot_world(voxgi)
        assert warnings == [] and world_map.bake_count() == bakes
    _assert_matches_cycles(world, data.radiance, AWAY, rtol=0.03)


def test_byte_image_is_made_linear_like_cycles(voxgi, world_map):
    world = bpy.data.worlds.new("Byte")
    env = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    env.image = bpy.data.images.new("Byte", 64, 32)  # 8-bit sRGB
    px = np.ones((32, 64, 4), np.float32)
    px[..., :3] = np.linspace(0.1, 0.9, 64)[None, :, None]
    env.image.pixels.foreach_set(px.ravel())
    world.node_tree.links.new(env.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    bpy.context.scene.world = world
    data, _ = _snapshot_world(voxgi)
    _assert_matches_cycles(world, data.radiance, (1.0, 0.0, 0.0), rtol=0.01)
    assert data.radiance.max() < 0.8  # linear, not the encoded values


def test_uniform_colour_times_strength(voxgi, world_map):
    world = bpy.data.worlds.new("Uniform")
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.1, 0.2, 0.3, 1.0)
    background.inputs["Strength"].default_value = 2.5
    bpy.context.scene.world = world
    data, warnings = _snapshot_world(voxgi)
    assert warnings == []
    np.testing.assert_allclose(data.color, (0.1, 0.2, 0.3), rtol=1e-6)
    assert data.strength == pytest.approx(2.5)
    assert data.radiance.shape[1] == 2 * data.radiance.shape[0]
    np.testing.assert_allclose(data.radiance.reshape(-1, 3) - (0.25, 0.5, 0.75), 0.0, atol=1e-7)
    _assert_matches_cycles(world, data.radiance, (0.0, 0.0, 1.0), rtol=1e-4)
    first = data.key
    background.inputs["Strength"].default_value = 2.0
    assert _snapshot_world(voxgi)[0].key != first
    background.inputs["Strength"].default_value = 2.5
    assert _snapshot_world(voxgi)[0].key == first


def test_black_worlds(voxgi, world_map):
    assert bpy.context.scene.world is None  # the factory-empty file has none
    data, warnings = _snapshot_world(voxgi)
    assert data.radiance is None and warnings == [] and not np.any(data.color * data.strength)
    world, _ = _image_world(strength=0.0)
    data, warnings = _snapshot_world(voxgi)
    assert data.radiance is None and warnings == [] and not np.any(data.color * data.strength)
    # a world whose output shows nothing
    world.node_tree.links.remove(world.node_tree.nodes["World Output"].inputs["Surface"].links[0])
    data, warnings = _snapshot_world(voxgi)
    assert data.radiance is None
    np.testing.assert_array_equal(_cycles_view(world, (1.0, 0.0, 0.0), size=4)[1], 0.0)


def test_bake_follows_the_convention(voxgi, world_map):
    """A world whose colour is its own view direction, baked: every pixel holds its direction."""
    world = bpy.data.worlds.new("Directions")
    tree = world.node_tree
    coords = tree.nodes.new("ShaderNodeTexCoord")
    remap = tree.nodes.new("ShaderNodeVectorMath")
    remap.operation = "MULTIPLY_ADD"  # Cycles clamps negative background colours to 0
    remap.inputs[1].default_value = remap.inputs[2].default_value = (0.5, 0.5, 0.5)
    tree.links.new(coords.outputs["Generated"], remap.inputs[0])
    tree.links.new(remap.outputs["Vector"], tree.nodes["Background"].inputs["Color"])
    image = world_map.bake_world(world, height=32, samples=4)
    assert image.shape == (32, 64, 3)
    directions = image * 2 - 1
    error = np.linalg.norm(directions - equirect.pixel_directions(32, 64), axis=-1)
    assert error.max() < 0.02, error.max()  # pixel means around the centres


def test_sky_texture_is_baked_once(voxgi, world_map):
    world = bpy.data.worlds.new("Sky")
    tree = world.node_tree
    sky = tree.nodes.new("ShaderNodeTexSky")
    sky.sun_elevation, sky.sun_rotation = math.radians(40.0), math.radians(30.0)
    tree.links.new(sky.outputs["Color"], tree.nodes["Background"].inputs["Color"])
    bpy.context.scene.world = world
    sampling = world.cycles.sampling_method
    before = len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras), len(bpy.data.worlds)
    bakes = world_map.bake_count()
    data, warnings = _snapshot_world(voxgi)
    assert warnings == [] and world_map.bake_count() == bakes + 1
    # (the bake renders a copy of the world without its importance map: nothing of it stays)
    assert (len(bpy.data.scenes), len(bpy.data.objects), len(bpy.data.cameras),
            len(bpy.data.worlds)) == before and world.cycles.sampling_method == sampling
    assert data.radiance.shape == (world_map.BAKE_HEIGHT, 2 * world_map.BAKE_HEIGHT, 3)
    # blue above the horizon away from the sun, and what Cycles shows there
    directions, theirs = _cycles_view(world, _direction(math.radians(50.0), math.radians(-150.0)),
                                      size=16, fov=math.radians(60.0))
    ours = equirect.sample_bilinear(data.radiance, directions)
    assert np.all(ours[:, 2] > ours[:, 0]) and np.all(ours > 0)
    np.testing.assert_allclose(ours, theirs, rtol=0.03)
    # the sun disc is at the elevation it was given
    row, col = np.unravel_index(np.argmax(data.radiance.sum(-1)), data.radiance.shape[:2])
    el = np.pi / 2 - (row + 0.5) * np.pi / data.radiance.shape[0]
    assert math.degrees(el) == pytest.approx(40.0, abs=1.0)
    again, warnings = _snapshot_world(voxgi)
    assert world_map.bake_count() == bakes + 1 and again.key == data.key and warnings == []
    np.testing.assert_array_equal(again.radiance, data.radiance)
    sky.sun_elevation = math.radians(20.0)
    changed, _ = _snapshot_world(voxgi)
    assert world_map.bake_count() == bakes + 2 and changed.key != data.key


def test_f12_and_render_preview_bake_a_sky_world(voxgi, world_map, tmp_path):
    """F12 in background mode calls the engine on the main thread: the nested Cycles bake of
    the world runs inside it, leaves no datablock behind, and the F12 still renders."""
    from voxgi.render.engine import enable_passes
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=4.0)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    camera.location, camera.rotation_euler = (0.0, -4.0, 3.0), (math.radians(55.0), 0.0, 0.0)
    scene.camera = camera
    world = bpy.data.worlds.new("Sky")
    sky = world.node_tree.nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs["Color"], world.node_tree.nodes["Background"].inputs["Color"])
    scene.world = world
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 32, 24, 100
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    enable_passes(scene.view_layers[0])
    scene.render.filepath = str(tmp_path / "f12.exr")

    def counts():
        return {name: len(getattr(bpy.data, name)) for name in ("scenes", "objects", "cameras", "worlds")} | {
            "images": sorted(i.name for i in bpy.data.images if i.type != "RENDER_RESULT")}

    before, bakes = counts(), world_map.bake_count()
    bpy.ops.render.render(write_still=True)
    assert world_map.bake_count() == bakes + 1
    assert counts() == before
    passes = read_exr_passes(str(tmp_path / "f12.exr"))
    assert passes["Diffuse Color"].max() > 0  # the plane was rendered
    assert bpy.ops.voxgi.render_preview(filepath=str(tmp_path / "preview.exr"), resolution_x=32,
                                        resolution_y=24) == {"FINISHED"}
    assert world_map.bake_count() == bakes + 1  # the same world: cached
    assert counts() == before
