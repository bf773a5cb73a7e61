"""Scenes lit the way artists light them (issue 17), for the tests against Cycles and the
benchmark: an HDRI-lit courtyard, the same under a uniform sky plus a sun, a room lit by
emissive surfaces and a spot, and a room of glossy metals and plastics. Built from code (no
third-party files): the HDRI is a float equirect image made here — a sky gradient, a dark
ground and a small sun disc about 50 000 times brighter than the sky — turned by a Mapping
node as artists turn their HDRIs.
"""
from __future__ import annotations

import math

import bpy
import gi_scenes
import numpy as np

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
SUN_DIRECTION = (0.45, -0.35, 0.82)  # towards the HDRI's sun, before the Mapping's turn
HDRI_TURN = math.radians(30.0)       # the Mapping node's rotation about Z


def _principled(name, color, roughness=0.5, metallic=0.0, emission=None, strength=0.0):
    material = gi_scenes._material(name, color)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Roughness"].default_value = roughness
    bsdf.inputs["Metallic"].default_value = metallic
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return material


def hdri_pixels(width=256, height=128):
    """(height, width, 4) float32 RGBA in Blender's image order (row 0 at the bottom) of the
    synthetic HDRI: Cycles looks an equirect image up at u = 0.5 − φ/2π, v = 0.5 + el/π."""
    v = (np.arange(height) + 0.5) / height
    u = (np.arange(width) + 0.5) / width
    el = (v - 0.5) * math.pi
    phi = (0.5 - u) * 2 * math.pi
    cos_el = np.cos(el)[:, None]
    d = np.stack([cos_el * np.cos(phi)[None], cos_el * np.sin(phi)[None],
                  np.broadcast_to(np.sin(el)[:, None], (height, width))], axis=-1)
    up = np.clip(d[..., 2:], 0.0, 1.0)
    sky = (1.0 - up) * np.array([0.9, 0.95, 1.0]) + up * np.array([0.25, 0.45, 0.9])
    ground = np.array([0.12, 0.1, 0.08])
    rgb = np.where(d[..., 2:] > 0.0, sky * 0.6, ground)
    sun = np.asarray(SUN_DIRECTION) / np.linalg.norm(SUN_DIRECTION)
    disc = (d @ sun) > math.cos(math.radians(1.5))
    rgb = rgb + disc[..., None] * np.array([30000.0, 28000.0, 24000.0])
    return np.concatenate([rgb, np.ones((height, width, 1))], axis=-1).astype(np.float32)


def hdri_world(name="HDRI World"):
    image = bpy.data.images.new("Synthetic HDRI", 256, 128, float_buffer=True)
    image.pixels.foreach_set(hdri_pixels(256, 128).ravel())
    image.pack()
    world = bpy.data.worlds.new(name)
    if world.node_tree is None:  # Blender before 5.0 makes worlds without a node tree
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = next(n for n in nodes if n.type == "BACKGROUND")
    texture = nodes.new("ShaderNodeTexEnvironment")
    texture.image = image
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Rotation"].default_value = (0.0, 0.0, HDRI_TURN)
    coords = nodes.new("ShaderNodeTexCoord")
    links.new(coords.outputs["Generated"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    links.new(texture.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = 1.0
    return world


def _courtyard(scene):
    stone = _principled("Stone", (0.55, 0.5, 0.45), roughness=0.8)
    brick = _principled("Brick", (0.6, 0.3, 0.2), roughness=0.7)
    gi_scenes._mesh(scene, "Ground", [(-8, -8, 0), (8, -8, 0), (8, 8, 0), (-8, 8, 0)],
                    [(0, 1, 2, 3)], (stone,))
    gi_scenes._block(scene, "Back Wall", (7.0, 0.4, 3.0), (0.0, 3.0, 0.0), 0.0, brick)
    gi_scenes._block(scene, "Side Wall", (0.4, 5.0, 2.2), (-3.3, 0.6, 0.0), 0.0, brick)
    gi_scenes._block(scene, "Bench", (1.6, 0.6, 0.5), (1.2, 0.4, 0.0), 0.3, stone)
    gi_scenes._block(scene, "Pillar", (0.5, 0.5, 2.4), (-1.2, 1.4, 0.0), 0.0, stone)
    gi_scenes._camera(scene, "Camera", (1.5, -7.0, 2.2), (0.0, 1.0, 0.8), lens=30.0)


def build_hdri_courtyard(scene):
    """The courtyard lit only by the synthetic HDRI (sun disc included), turned 30° by a
    Mapping node."""
    _courtyard(scene)
    scene.world = hdri_world()
    bpy.context.view_layer.update()


def build_sky_courtyard(scene):
    """The courtyard under a uniform sky colour (Background strength 1) plus a sun lamp."""
    _courtyard(scene)
    world = bpy.data.worlds.new("Sky")
    if world.node_tree is None:  # Blender before 5.0 makes worlds without a node tree
        world.use_nodes = True
    background = next(n for n in world.node_tree.nodes if n.type == "BACKGROUND")
    background.inputs["Color"].default_value = (0.35, 0.5, 0.8, 1.0)
    background.inputs["Strength"].default_value = 1.0
    scene.world = world
    gi_scenes._light(scene, "Sun", "SUN", (0, 0, 10), direction=(-0.4, 0.5, -0.75), energy=3.0,
                     angle=math.radians(1.0))
    bpy.context.view_layer.update()


def build_emissive_room(scene):
    """A 5 × 4 × 2.6 m room open to the camera, lit by an emissive ceiling panel, a glowing
    sphere and a spot; black world."""
    white = _principled("White", (0.7, 0.7, 0.7))
    red = _principled("Red", (0.7, 0.15, 0.1))
    vertices, faces = gi_scenes._box((-2.5, -2, 0), (2.5, 2, 2.6), inwards=True)
    gi_scenes._mesh(scene, "Room", vertices, faces[:2] + faces[3:], (white,))
    gi_scenes._block(scene, "Box", (0.8, 0.8, 1.2), (0.7, 0.6, 0.0), 0.4, red)
    glow = _principled("Panel Glow", (0.8, 0.8, 0.8), emission=(1.0, 0.9, 0.8), strength=6.0)
    gi_scenes._mesh(scene, "Panel", [(-0.8, -0.4, 2.55), (0.8, -0.4, 2.55), (0.8, 0.6, 2.55),
                                     (-0.8, 0.6, 2.55)], [(3, 2, 1, 0)], (glow,))
    orb = _principled("Orb Glow", (0.8, 0.8, 0.8), emission=(0.3, 0.6, 1.0), strength=8.0)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=0.3,
                                         location=(-1.2, 0.8, 0.5))
    bpy.context.active_object.data.materials.append(orb)
    gi_scenes._light(scene, "Spot", "SPOT", (1.8, -1.5, 2.4), target=(-0.5, 1.0, 0.0),
                     energy=300.0, spot_size=math.radians(35), spot_blend=0.2)
    gi_scenes._camera(scene, "Camera", (0.0, -5.5, 1.4), (0.0, 0.5, 1.1), lens=24.0)
    gi_scenes._finish(scene, {})


def build_metal_room(scene):
    """Brushed-metal floor, a gold sphere, a copper wall and a plastic box, lit by an area
    light and a point light; black world."""
    steel = _principled("Brushed Steel", (0.6, 0.6, 0.62), roughness=0.3, metallic=1.0)
    gold = _principled("Gold", (1.0, 0.77, 0.34), roughness=0.2, metallic=1.0)
    copper = _principled("Copper", (0.95, 0.64, 0.54), roughness=0.35, metallic=1.0)
    plastic = _principled("Plastic", (0.1, 0.3, 0.7), roughness=0.4)
    wall = _principled("Wall", (0.7, 0.7, 0.68))
    gi_scenes._mesh(scene, "Floor", [(-3, -3, 0), (3, -3, 0), (3, 3, 0), (-3, 3, 0)],
                    [(0, 1, 2, 3)], (steel,))
    gi_scenes._mesh(scene, "Copper Wall", [(-3, 2.5, 0), (3, 2.5, 0), (3, 2.5, 3), (-3, 2.5, 3)],
                    [(0, 3, 2, 1)], (copper,))
    gi_scenes._mesh(scene, "Left Wall", [(-3, -3, 0), (-3, 2.5, 0), (-3, 2.5, 3), (-3, -3, 3)],
                    [(0, 1, 2, 3)], (wall,))
    gi_scenes._block(scene, "Box", (0.8, 0.8, 0.8), (1.0, 0.8, 0.0), 0.5, plastic)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16, radius=0.6,
                                         location=(-0.8, 0.6, 0.6))
    sphere = bpy.context.active_object
    sphere.data.materials.append(gold)
    sphere.data.shade_smooth()
    gi_scenes._light(scene, "Area", "AREA", (1.5, -1.0, 2.8), target=(0.0, 0.5, 0.0),
                     energy=500.0, size=1.2)
    gi_scenes._light(scene, "Point", "POINT", (-2.0, -1.5, 2.0), energy=200.0,
                     shadow_soft_size=0.3)
    gi_scenes._camera(scene, "Camera", (0.5, -5.0, 1.8), (0.0, 0.8, 0.6), lens=30.0)
    gi_scenes._finish(scene, {})


SCENES = {
    "hdri_courtyard": build_hdri_courtyard,
    "sky_courtyard": build_sky_courtyard,
    "emissive_room": build_emissive_room,
    "metal_room": build_metal_room,
}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
