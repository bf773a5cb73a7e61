"""Glass panes (issue 22 point 2, acceptance (b)), for the tests against Cycles at its default
light paths.

``glass_panes``: two upright glass panes in front of a blue wall on a grey floor, a red block
behind them, lit by a low sun from the front-left and an area light above; black world. Each
pane is a quad given 1 cm of thickness by a Solidify modifier (as artists model windows), with a
Principled BSDF at Transmission Weight 1, Roughness 0 and Blender's default IOR: one clear (white
Base Color), one tinted green. Cycles renders the wall and the block through the panes, a little
dimmed by the glass' Fresnel reflection, the green pane tinting them; a one-bounce reference has
no transmission bounce, so the references are made at Cycles' default light paths
(tools/make_glass_references.py). ``glass_panes_no_caustics``: the same with Refractive
Caustics off. Built from code, deterministic, background-safe.
"""
from __future__ import annotations

import math

import bpy
import gi_scenes

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT
THICKNESS = 0.01


def glass_material(name, color):
    """Principled BSDF: Transmission Weight 1, Roughness 0, this Base Color (the glass' tint)."""
    material = gi_scenes._material(name, color)
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.0
    return material


def pane(scene, name, corners, material):
    obj = gi_scenes._mesh(scene, name, corners, [(0, 1, 2, 3)], (material,))
    solidify = obj.modifiers.new("Solidify", "SOLIDIFY")
    solidify.thickness = THICKNESS
    solidify.offset = 0.0
    return obj


def build_glass_panes(scene):
    grey = gi_scenes._material("Grey Floor", (0.5, 0.5, 0.5))
    blue = gi_scenes._material("Blue Wall", (0.1, 0.25, 0.6))
    red = gi_scenes._material("Red Block", (0.7, 0.1, 0.06))
    clear = glass_material("Clear Glass", (1.0, 1.0, 1.0))
    green = glass_material("Green Glass", (0.45, 0.85, 0.5))
    gi_scenes._mesh(scene, "Floor", [(-4, -3, 0), (4, -3, 0), (4, 3, 0), (-4, 3, 0)],
                    [(0, 1, 2, 3)], (grey,))
    gi_scenes._mesh(scene, "Wall", [(-4, 1.5, 0), (4, 1.5, 0), (4, 1.5, 3), (-4, 1.5, 3)],
                    [(0, 1, 2, 3)], (blue,))
    gi_scenes._block(scene, "Block", (0.8, 0.8, 0.9), (-0.6, 1.0, 0.0), 0.4, red)
    pane(scene, "Clear Pane", [(-2.4, 0.2, 0), (-0.3, 0.6, 0), (-0.3, 0.6, 1.8),
                               (-2.4, 0.2, 1.8)], clear)
    pane(scene, "Green Pane", [(0.2, -0.4, 0), (2.3, 0.1, 0), (2.3, 0.1, 1.8),
                               (0.2, -0.4, 1.8)], green)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.35, 0.8, -0.5), energy=2.5,
                     angle=math.radians(1.0))
    gi_scenes._light(scene, "Area", "AREA", (0.5, -1.0, 3.2), target=(0.0, 0.5, 0.0),
                     energy=300.0, size=1.0)
    gi_scenes._camera(scene, "Camera", (0.4, -6.0, 1.6), (0.0, 0.6, 0.9), lens=30.0)
    gi_scenes._finish(scene, {})


def build_glass_panes_no_caustics(scene):
    """``glass_panes`` with Cycles' Light Paths › Caustics › Refractive off: no light reaches
    a diffuse surface through glass, so the panes cast full shadows."""
    build_glass_panes(scene)
    scene.cycles.caustics_refractive = False


SCENES = {"glass_panes": build_glass_panes,
          "glass_panes_no_caustics": build_glass_panes_no_caustics}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
