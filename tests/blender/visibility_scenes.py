"""A room whose objects use Cycles' ray visibility and holdouts (issue 18 point 1), for the
tests against Cycles (tests/data/visibility_refs, made by tools/make_visibility_references.py).

``visibility_room``: a 6 × 5 × 3 m room open to the camera (white walls, a grey floor), lit by
a low sun through the open front and an area light under the ceiling; black world. In it:

* ``Ghost`` — an orange pillar camera rays do not see (``visible_camera`` off): its shadow and
  its orange light on the floor stay, the wall behind it shows;
* ``Shadowless`` — a blue block that casts no shadow (``visible_shadow`` off);
* ``Unbounced`` — a bright red panel beside the right wall that bounce rays do not see
  (``visible_diffuse`` off): no red light on the wall and floor around it;
* ``Unreflected`` — a green block in front of a mirror-like metal panel, which glossy rays do
  not see (``visible_glossy`` off): the mirror shows the wall behind it;
* ``Holdout Box`` (``is_holdout``) and ``Holdout Plate`` (a Holdout shader): camera rays that
  meet them see nothing (Cycles: Combined 0, alpha 0); they still cast shadows.

``TOGGLES`` says what each object turns off, so a test can turn it back on. Built from code,
deterministic, background-safe.
"""
from __future__ import annotations

import math

import bpy
import gi_scenes

WIDTH, HEIGHT = gi_scenes.WIDTH, gi_scenes.HEIGHT

# object → (property, value) set on it by the builder
TOGGLES = {
    "Ghost": ("visible_camera", False),
    "Shadowless": ("visible_shadow", False),
    "Unbounced": ("visible_diffuse", False),
    "Unreflected": ("visible_glossy", False),
    "Holdout Box": ("is_holdout", True),
}


def holdout_material(name="Holdout"):
    """A material whose Surface is a Holdout shader."""
    material = bpy.data.materials.new(name)
    tree = material.node_tree
    tree.nodes.clear()
    holdout = tree.nodes.new("ShaderNodeHoldout")
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(holdout.outputs["Holdout"], output.inputs["Surface"])
    return material


def build_visibility_room(scene):
    white = gi_scenes._material("White", (0.7, 0.7, 0.7))
    grey = gi_scenes._material("Floor Grey", (0.5, 0.5, 0.5))
    orange = gi_scenes._material("Orange", (0.9, 0.4, 0.05))
    blue = gi_scenes._material("Blue", (0.1, 0.2, 0.8))
    red = gi_scenes._material("Bright Red", (0.95, 0.05, 0.03))
    green = gi_scenes._material("Green", (0.1, 0.7, 0.15))
    mirror = gi_scenes._material("Mirror", (0.9, 0.9, 0.9))
    bsdf = next(n for n in mirror.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    bsdf.inputs["Metallic"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.1
    gi_scenes._mesh(scene, "Floor", [(-3, -2.5, 0), (3, -2.5, 0), (3, 2.5, 0), (-3, 2.5, 0)],
                    [(0, 1, 2, 3)], (grey,))
    gi_scenes._mesh(scene, "Back Wall", [(-3, 2.5, 0), (3, 2.5, 0), (3, 2.5, 3), (-3, 2.5, 3)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Left Wall", [(-3, -2.5, 0), (-3, 2.5, 0), (-3, 2.5, 3), (-3, -2.5, 3)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Right Wall", [(3, -2.5, 0), (3, -2.5, 3), (3, 2.5, 3), (3, 2.5, 0)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Ceiling", [(-3, -2.5, 3), (-3, 2.5, 3), (3, 2.5, 3), (3, -2.5, 3)],
                    [(0, 1, 2, 3)], (white,))
    gi_scenes._mesh(scene, "Mirror Panel", [(-1.2, 2.45, 0.3), (0.4, 2.45, 0.3), (0.4, 2.45, 1.9),
                                            (-1.2, 2.45, 1.9)], [(0, 1, 2, 3)], (mirror,))
    ghost = gi_scenes._block(scene, "Ghost", (0.6, 0.6, 2.2), (-2.0, 0.6, 0.0), 0.3, orange)
    shadowless = gi_scenes._block(scene, "Shadowless", (0.8, 0.8, 1.0), (0.5, -0.3, 0.0), 0.5, blue)
    unbounced = gi_scenes._block(scene, "Unbounced", (0.1, 2.0, 2.0), (2.4, 0.8, 0.0), 0.0, red)
    unreflected = gi_scenes._block(scene, "Unreflected", (0.5, 0.5, 0.8), (-0.4, 1.3, 0.0), 0.2,
                                   green)
    holdout_box = gi_scenes._block(scene, "Holdout Box", (0.7, 0.7, 0.7), (1.6, -1.3, 0.0), -0.4,
                                   white)
    gi_scenes._mesh(scene, "Holdout Plate", [(-2.2, -1.6, 0.01), (-1.2, -1.6, 0.01),
                                             (-1.2, -1.6, 1.0), (-2.2, -1.6, 1.0)],
                    [(0, 1, 2, 3)], (holdout_material(),))
    for obj in (ghost, shadowless, unbounced, unreflected, holdout_box):
        setattr(obj, *TOGGLES[obj.name])
    gi_scenes._light(scene, "Area", "AREA", (0.0, 0.0, 2.9), target=(0.0, 0.0, 0.0),
                     energy=300.0, size=1.0)
    gi_scenes._light(scene, "Sun", "SUN", (0, -6, 6), direction=(0.45, 0.75, -0.5), energy=3.0,
                     angle=math.radians(1.0))
    gi_scenes._camera(scene, "Camera", (0.3, -6.5, 1.8), (0.0, 0.5, 0.9), lens=28.0)
    gi_scenes._finish(scene, {})


SCENES = {"visibility_room": build_visibility_room}


def build(name, scene=None):
    return SCENES[name](scene or bpy.context.scene)
