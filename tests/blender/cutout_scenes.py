"""Alpha cut-outs (issue 22 point 2, acceptance (b)), for the tests against Cycles.

``fence_cards``: two upright fence cards in front of a red wall on a grey floor, lit by a low
sun from the front-left and an area light above; black world. Each card's Base Color and Alpha
come from one 8-bit sRGB image with an alpha channel (packed into the file): weathered-wood
slats and rails, the gaps between them fully transparent (Cycles shows the wall through about
half of each card and casts slatted shadows). The cards' material is a Principled BSDF whose
Alpha is the Image Texture's Alpha output, as artists and the glTF importer build cut-outs;
nothing in the scene is tuned for the preview. Built from code, deterministic, background-safe.
"""
from __future__ import annotations

import math

import bpy
import gi_scenes
import numpy as np
import texture_scenes

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
FENCE_SIZE = 64


def fence_pixels(size=FENCE_SIZE, slats=5, rails=(0.25, 0.7)):
    """(size, size, 4) float32 RGBA in Blender's image order (row 0 at the bottom), sRGB
    encoded: ``slats`` vertical slats half the card wide in all and two horizontal rails, a
    little grain across them; alpha 1 on the wood, 0 in the gaps."""
    y, x = np.mgrid[0:size, 0:size] / float(size)
    slat = (x * slats) % 1.0 < 0.5
    rail = np.zeros_like(slat)
    for r in rails:
        rail |= np.abs(y - r) < 0.05
    wood = slat | rail
    grain = 0.9 + 0.1 * np.sin(40.0 * y + 7.0 * x)
    rgb = np.array([0.62, 0.48, 0.3]) * grain[..., None]
    rgb = np.where(rail[..., None], np.array([0.5, 0.38, 0.24]), rgb)
    alpha = wood.astype(np.float64)[..., None]
    return np.concatenate([rgb, alpha], axis=-1).astype(np.float32)


def fence_image(name="Fence Image"):
    image = bpy.data.images.new(name, FENCE_SIZE, FENCE_SIZE, alpha=True, float_buffer=False)
    image.colorspace_settings.name = "sRGB"
    image.pixels.foreach_set(fence_pixels().ravel())
    image.pack()
    return image


def cutout_material(name, image):
    """Principled BSDF whose Base Color and Alpha are ``image``'s Color and Alpha (UV map)."""
    material = gi_scenes._material(name, (0.5, 0.5, 0.5))
    nodes, links = material.node_tree.nodes, material.node_tree.links
    bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    tex = nodes.new("ShaderNodeTexImage")
    tex.image = image
    links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    links.new(tex.outputs["Alpha"], bsdf.inputs["Alpha"])
    return material


def build_fence_cards(scene):
    grey = gi_scenes._material("Grey Floor", (0.5, 0.5, 0.5))
    red = gi_scenes._material("Red Wall", (0.7, 0.12, 0.08))
    fence = cutout_material("Fence", fence_image())
    gi_scenes._mesh(scene, "Floor", [(-4, -3, 0), (4, -3, 0), (4, 3, 0), (-4, 3, 0)],
                    [(0, 1, 2, 3)], (grey,))
    gi_scenes._mesh(scene, "Wall", [(-4, 1.5, 0), (4, 1.5, 0), (4, 1.5, 3), (-4, 1.5, 3)],
                    [(0, 1, 2, 3)], (red,))
    texture_scenes.quad(scene, "Fence Left", [(-2.4, 0.2, 0), (-0.3, 0.6, 0), (-0.3, 0.6, 1.8),
                                              (-2.4, 0.2, 1.8)], fence)
    texture_scenes.quad(scene, "Fence Right", [(0.2, -0.4, 0), (2.3, 0.1, 0), (2.3, 0.1, 1.8),
                                               (0.2, -0.4, 1.8)], fence)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.35, 0.8, -0.5), energy=2.5,
                     angle=math.radians(1.0))
    gi_scenes._light(scene, "Area", "AREA", (0.5, -1.0, 3.2), target=(0.0, 0.5, 0.0),
                     energy=300.0, size=1.0)
    gi_scenes._camera(scene, "Camera", (0.4, -6.0, 1.6), (0.0, 0.6, 0.9), lens=30.0)
    gi_scenes._finish(scene, {})


SCENES = {"fence_cards": build_fence_cards}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
