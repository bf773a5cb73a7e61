"""A room lit by an emissive panel whose Emission Color is an image (issue 18 point 2, issue 22
point 3: emissive textures), for the tests against Cycles.

``emission_panel_room``: a 6 × 5 m floor with a back wall and a left wall (white and pale grey),
black world, no lamp. The only light is a 2 × 1.2 m panel standing on a low base at the back of
the floor, facing the camera: a Principled BSDF whose Emission Color is an 8-bit sRGB image
(packed into the file) through the panel's UV map — its left half orange, its right half blue,
with a white horizontal band — at Strength 6; its Base Color is dark grey. A grey box stands in
front of the panel's blue half. Built from code, deterministic, background-safe.
"""
from __future__ import annotations

import bpy
import gi_scenes
import numpy as np

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
IMAGE_SIZE = (64, 32)  # width, height
ORANGE = (0.95, 0.45, 0.12)  # sRGB-encoded
BLUE = (0.15, 0.45, 0.95)
WHITE = (0.95, 0.95, 0.95)
STRENGTH = 6.0


def panel_pixels(size=IMAGE_SIZE):
    """(height, width, 4) float32 RGBA in Blender's image order (row 0 at the bottom), sRGB
    encoded: left half orange, right half blue, a white band across rows 40–55% of the height."""
    w, h = size
    x = np.arange(w)[None, :].repeat(h, axis=0)
    y = np.arange(h)[:, None].repeat(w, axis=1)
    rgb = np.where((x < w // 2)[..., None], np.array(ORANGE), np.array(BLUE))
    band = (y >= int(0.40 * h)) & (y < int(0.55 * h))
    rgb = np.where(band[..., None], np.array(WHITE), rgb)
    return np.concatenate([rgb, np.ones((h, w, 1))], axis=-1).astype(np.float32)


def panel_image(name="Panel Pattern"):
    w, h = IMAGE_SIZE
    image = bpy.data.images.new(name, w, h, alpha=False, float_buffer=False)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(panel_pixels().ravel())
    image.pack()
    return image


def emissive_image_material(name, image, strength=STRENGTH):
    """Principled BSDF, dark grey Base Color, Emission Color = ``image`` through the UV map."""
    material = gi_scenes._material(name, (0.05, 0.05, 0.05))
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    links.new(tex.outputs["Color"], bsdf.inputs["Emission Color"])
    bsdf.inputs["Emission Strength"].default_value = strength
    return material


def build_emission_panel_room(scene):
    white = gi_scenes._material("White", (0.75, 0.75, 0.75))
    pale = gi_scenes._material("Pale Grey", (0.55, 0.55, 0.55))
    grey = gi_scenes._material("Grey", (0.4, 0.4, 0.4))
    glow = emissive_image_material("Panel Glow", panel_image())
    gi_scenes._mesh(scene, "Floor", [(-3, -2.5, 0), (3, -2.5, 0), (3, 2.5, 0), (-3, 2.5, 0)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Back Wall", [(-3, 2.5, 0), (3, 2.5, 0), (3, 2.5, 3), (-3, 2.5, 3)],
                    [(0, 3, 2, 1)], (pale,))
    gi_scenes._mesh(scene, "Left Wall", [(-3, -2.5, 0), (-3, 2.5, 0), (-3, 2.5, 3), (-3, -2.5, 3)],
                    [(0, 1, 2, 3)], (pale,))
    gi_scenes._block(scene, "Base", (2.2, 0.3, 0.3), (0.0, 1.2, 0.0), 0.0, grey)
    panel = gi_scenes._mesh(scene, "Panel", [(-1, 1.2, 0.3), (1, 1.2, 0.3), (1, 1.2, 1.5),
                                             (-1, 1.2, 1.5)], [(0, 1, 2, 3)], (glow,))
    layer = panel.data.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", np.array([0, 0, 1, 0, 1, 1, 0, 1], np.float32))
    gi_scenes._block(scene, "Box", (0.5, 0.5, 0.6), (0.7, -0.2, 0.0), 0.4, grey)
    gi_scenes._camera(scene, "Camera", (0.4, -6.0, 2.4), (0.0, 0.6, 0.6), lens=30.0)
    gi_scenes._finish(scene, {})


SCENES = {"emission_panel_room": build_emission_panel_room}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
