"""Interior scenes of issue 20 (multi-bounce light), rendered by Cycles at its default light
paths (tools/make_bounce_references.py) and by the preview at its default Bounces
(tests/blender/test_multibounce.py). Built from the scenes of earlier tests, at 160 × 120 with
Cycles' default pixel filter."""
import bpy
import gi_scenes
import light_scenes
import scenes
import texture_scenes

WIDTH, HEIGHT = 160, 120


def build_cornell_box(scene):
    """The test Cornell box (scenes.build_test_cornell_box) lit by its 0.6 m area light."""
    scenes.build_test_cornell_box(scene, light="AREA")
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT


def build_emissive_room(scene):
    """The room lit by an emissive panel, a glowing sphere and a spot (light_scenes)."""
    light_scenes.build_emissive_room(scene)


def build_columned_hall(scene):
    """The closed hall lit by the sun through a roof opening (gi_scenes)."""
    gi_scenes.build_columned_hall(scene)


def build_textured_room(scene):
    """The room with an image-textured floor and a procedural wall, an area light and the sun
    through a window (texture_scenes)."""
    texture_scenes.build_textured_room(scene)


SCENES = {"cornell_box": build_cornell_box, "emissive_room": build_emissive_room,
          "columned_hall": build_columned_hall, "textured_room": build_textured_room}


def build(name, scene=None):
    SCENES[name](scene or bpy.context.scene)
