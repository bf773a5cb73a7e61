"""A room with textured materials (issue 18 point 2), for the tests against Cycles.

``textured_room``: a 6 × 5 × 3 m room open to the camera, lit by an area light under the
ceiling and a low sun through the open front; black world. The floor's Base Color is an
8-bit sRGB image of a checker (8 × 8 cells with a gradient across them, packed into the file)
looked up through its UV map and a Mapping node scaling it 3 × 2; the back wall's comes from
a procedural Checker Texture node (Generated coordinates, which Cycles must bake); the side
walls and a box are plain colours. Built from code, deterministic, background-safe.
"""
from __future__ import annotations

import math

import bpy
import gi_scenes
import numpy as np

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
IMAGE_SIZE = 64


def checker_pixels(size=IMAGE_SIZE, cells=8):
    """(size, size, 4) float32 RGBA in Blender's image order (row 0 at the bottom): sRGB-encoded
    terracotta and cream cells, each cell a little lighter towards its top."""
    y, x = np.mgrid[0:size, 0:size]
    cell = size // cells
    odd = ((x // cell) + (y // cell)) % 2 == 1
    ramp = 0.85 + 0.15 * ((y % cell) / max(cell - 1, 1))
    dark = np.array([0.72, 0.36, 0.25])
    light = np.array([0.93, 0.88, 0.76])
    rgb = np.where(odd[..., None], dark, light) * ramp[..., None]
    return np.concatenate([rgb, np.ones((size, size, 1))], axis=-1).astype(np.float32)


def checker_image(name="Checker Image"):
    image = bpy.data.images.new(name, IMAGE_SIZE, IMAGE_SIZE, alpha=False, float_buffer=False)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(checker_pixels().ravel())
    image.pack()
    return image


def image_material(name, image, scale=(3.0, 2.0, 1.0)):
    """Principled BSDF whose Base Color is ``image`` through UV → Mapping (scale) → Image."""
    material = gi_scenes._material(name, (0.5, 0.5, 0.5))
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    coords = nodes.new("ShaderNodeTexCoord")
    mapping = nodes.new("ShaderNodeMapping")
    mapping.inputs["Scale"].default_value = scale
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    links.new(coords.outputs["UV"], mapping.inputs["Vector"])
    links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def procedural_material(name, scale=6.0):
    """Principled BSDF whose Base Color is a Checker Texture (Generated coordinates)."""
    material = gi_scenes._material(name, (0.5, 0.5, 0.5))
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    checker = nodes.new("ShaderNodeTexChecker")
    checker.inputs["Scale"].default_value = scale
    checker.inputs["Color1"].default_value = (0.15, 0.3, 0.6, 1.0)
    checker.inputs["Color2"].default_value = (0.8, 0.8, 0.75, 1.0)
    links.new(checker.outputs["Color"], bsdf.inputs["Base Color"])
    return material


def quad(scene, name, corners, material, uv_scale=(1.0, 1.0)):
    """A one-face mesh with a UV map spanning [0, su] × [0, sv] over its corners."""
    obj = gi_scenes._mesh(scene, name, corners, [(0, 1, 2, 3)], (material,))
    layer = obj.data.uv_layers.new(name="UVMap")
    su, sv = uv_scale
    layer.data.foreach_set("uv", np.array([0, 0, su, 0, su, sv, 0, sv], np.float32))
    return obj


def build_textured_room(scene):
    white = gi_scenes._material("White", (0.7, 0.7, 0.7))
    red = gi_scenes._material("Red", (0.7, 0.15, 0.1))
    floor = image_material("Checker Floor", checker_image())
    wall = procedural_material("Checker Wall")
    quad(scene, "Floor", [(-3, -2.5, 0), (3, -2.5, 0), (3, 2.5, 0), (-3, 2.5, 0)], floor)
    quad(scene, "Back Wall", [(-3, 2.5, 0), (3, 2.5, 0), (3, 2.5, 3), (-3, 2.5, 3)], wall)
    gi_scenes._mesh(scene, "Left Wall", [(-3, -2.5, 0), (-3, 2.5, 0), (-3, 2.5, 3), (-3, -2.5, 3)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Right Wall", [(3, -2.5, 0), (3, -2.5, 3), (3, 2.5, 3), (3, 2.5, 0)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Ceiling", [(-3, -2.5, 3), (-3, 2.5, 3), (3, 2.5, 3), (3, -2.5, 3)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._block(scene, "Box", (0.9, 0.9, 1.1), (1.2, 0.6, 0.0), 0.5, red)
    gi_scenes._light(scene, "Area", "AREA", (-0.5, -0.5, 2.9), target=(-0.5, -0.5, 0.0),
                     energy=400.0, size=1.0)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.3, 0.8, -0.45), energy=2.0,
                     angle=math.radians(1.0))
    gi_scenes._camera(scene, "Camera", (0.3, -6.5, 1.7), (0.0, 0.5, 0.9), lens=28.0)
    gi_scenes._finish(scene, {})


def tile_normal_pixels(size=128, tiles=4, bevel=0.2, tilt=0.6, ripple=0.25):
    """(size, size, 4) float32 RGBA tangent-space normal map (row 0 at the bottom, Non-Color):
    ``tiles`` × ``tiles`` tiles whose borders (``bevel`` of a tile) lean out by ``tilt`` and
    whose faces ripple by ``ripple`` — grout and hand-made tiles."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * tiles
    fx, fy = x % 1.0, y % 1.0
    nx = np.where(fx < bevel, -tilt, np.where(fx > 1 - bevel, tilt, 0.0))
    ny = np.where(fy < bevel, -tilt, np.where(fy > 1 - bevel, tilt, 0.0))
    nx = nx + ripple * np.sin(6.0 * np.pi * x)
    ny = ny + ripple * np.cos(6.0 * np.pi * y)
    n = np.stack([nx, ny, np.ones_like(nx)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return np.concatenate([0.5 * n + 0.5, np.ones((size, size, 1))], axis=-1).astype(np.float32)


def build_normal_mapped_room(scene):
    """The textured room with a tangent-space normal map on its floor (Image Texture, Non-Color,
    through the floor's Mapping → Normal Map node → the Principled BSDF's Normal)."""
    build_textured_room(scene)
    size = 128
    image = bpy.data.images.new("Tile Normals", size, size, alpha=False, float_buffer=False)
    image.colorspace_settings.name = "Non-Color"
    image.pixels.foreach_set(tile_normal_pixels(size).ravel())
    image.pack()
    tree = bpy.data.materials["Checker Floor"].node_tree
    bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
    mapping = next(n for n in tree.nodes if n.type == "MAPPING")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tree.links.new(mapping.outputs["Vector"], tex.inputs["Vector"])
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], bsdf.inputs["Normal"])
    bpy.context.view_layer.update()


SCENES = {"textured_room": build_textured_room, "normal_mapped_room": build_normal_mapped_room}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
