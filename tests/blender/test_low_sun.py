"""A real HDRI's sun is a few pixels a few degrees above the horizon: the ground's light under
it against Cycles (docs/gi_pipeline.md "The world's irradiance from where its light is").

The map is made here (a 1024 × 512 float image: a sky, a dark ground and a sun 0.3° wide 2.6°
above the horizon that brings about half the ground's light), laid out as Blender stores images
(row 0 at the bottom, u = 0.5 − φ / 2π). Until the irradiance table lit each of its boxes from
the box's luminous centroid, the ground read its Diffuse Direct 4–8.5% under Cycles' here.
"""
from __future__ import annotations

import math

import bpy
import numpy as np
from cycles_reference import render_cycles_passes

WIDTH, HEIGHT = 96, 72
SUN_ELEVATION = math.radians(2.6)
SUN_AZIMUTH = math.radians(-51.0)
SUN_RADIUS = math.radians(0.3)
SUN_RADIANCE = 200_000.0


def _low_sun_pixels(width=1024, height=512):
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    el = ((v - 0.5) * math.pi)[:, None]
    phi = ((0.5 - u) * 2 * math.pi)[None, :]
    d = np.stack(np.broadcast_arrays(np.cos(el) * np.cos(phi), np.cos(el) * np.sin(phi),
                                     np.sin(el)), axis=-1)
    sun = np.array([math.cos(SUN_ELEVATION) * math.cos(SUN_AZIMUTH),
                    math.cos(SUN_ELEVATION) * math.sin(SUN_AZIMUTH), math.sin(SUN_ELEVATION)])
    rgb = np.where(d[..., 2:] > 0.0, np.array([0.3, 0.35, 0.5]), np.array([0.05, 0.04, 0.03]))
    rgb = rgb + ((d @ sun) > math.cos(SUN_RADIUS))[..., None] * np.array([1.0, 0.8, 0.6]) * \
        SUN_RADIANCE
    return np.concatenate([rgb, np.ones((height, width, 1))], axis=-1).astype(np.float32)


def _ground_under_a_low_sun(scene):
    image = bpy.data.images.new("Low Sun", 1024, 512, float_buffer=True)
    image.pixels.foreach_set(_low_sun_pixels().ravel())
    image.pack()
    world = bpy.data.worlds.new("Low Sun")
    if world.node_tree is None:  # Blender before 5.0 makes worlds without a node tree
        world.use_nodes = True
    nodes = world.node_tree.nodes
    background = next(n for n in nodes if n.type == "BACKGROUND")
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    world.node_tree.links.new(texture.outputs["Color"], background.inputs["Color"])
    scene.world = world
    mesh = bpy.data.meshes.new("Ground")
    mesh.from_pydata([(-20, -20, 0), (20, -20, 0), (20, 20, 0), (-20, 20, 0)], [], [(0, 1, 2, 3)])
    material = bpy.data.materials.new("Stone")
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Base Color"].default_value = (0.55, 0.5, 0.45, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    mesh.materials.append(material)
    ground = bpy.data.objects.new("Ground", mesh)
    scene.collection.objects.link(ground)
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location = (0.0, -6.0, 4.0)
    camera.rotation_euler = (math.radians(50.0), 0.0, 0.0)  # looking down at the ground
    scene.collection.objects.link(camera)
    scene.camera = camera
    bpy.context.view_layer.update()


def test_a_low_suns_light_on_the_ground_is_cycles(voxgi):
    """The ground's Diffuse Direct, the image's mean over the pixels both see the ground,
    within 1% of Cycles' (measured within 0.02%; the boxes' centres read 8.5 / 6.7 / 4.2%
    under, r / g / b)."""
    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    _ground_under_a_low_sun(scene)
    passes, lines = render_scene_passes(bpy.context, scene, None, WIDTH, HEIGHT)
    cycles = render_cycles_passes(scene, WIDTH, HEIGHT, 256)
    ours = np.asarray(passes["Diffuse Direct"], np.float64)
    theirs = np.asarray(cycles["Diffuse Direct"], np.float64)[..., :3]
    seen = (np.asarray(passes["Alpha"]) > 0.99) & (np.asarray(cycles["Alpha"]) > 0.99)
    assert seen.mean() > 0.5, lines
    ratio = ours[seen].sum(axis=0) / theirs[seen].sum(axis=0)
    np.testing.assert_allclose(ratio, 1.0, atol=0.01, err_msg=str(lines))
