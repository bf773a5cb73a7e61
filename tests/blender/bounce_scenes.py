"""Interior scenes of issue 20 (multi-bounce light), rendered by Cycles at its default light
paths (tools/make_bounce_references.py) and by the preview at its default Bounces
(tests/blender/test_multibounce.py). Built from the scenes of earlier tests, at 160 × 120 with
Cycles' default pixel filter."""
import bpy
import light_scenes
import scenes

WIDTH, HEIGHT = 160, 120


def build_cornell_box(scene):
    """The test Cornell box (scenes.build_test_cornell_box) lit by its 0.6 m area light."""
    scenes.build_test_cornell_box(scene, light="AREA")
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT


def build_emissive_room(scene):
    """The room lit by an emissive panel, a glowing sphere and a spot (light_scenes)."""
    light_scenes.build_emissive_room(scene)


SCENES = {"cornell_box": build_cornell_box, "emissive_room": build_emissive_room}


def build(name, scene=None):
    SCENES[name](scene or bpy.context.scene)
