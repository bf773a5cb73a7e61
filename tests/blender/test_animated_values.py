"""Keyframed material and world values in animation renders (blender/snapshot/animated.py).

A render's depsgraph evaluates animation on its own copies; the user's datablocks keep the UI
frame's values. Materials and worlds were read from the user's datablocks, so every frame of
an animation render showed the UI frame's colours, emission and sky (Cycles shows each
frame's)."""
from __future__ import annotations

import bpy
import gi_scenes
import numpy as np
from cycles_reference import render_cycles_passes
from test_final_renders import HEIGHT, WIDTH, prepare_f12, read_passes


def _keyed(socket, first, last):
    """Keyframe ``socket`` 's default value: ``first`` at frame 1, ``last`` at frame 3."""
    socket.default_value = first
    socket.keyframe_insert("default_value", frame=1)
    socket.default_value = last
    socket.keyframe_insert("default_value", frame=3)


def build_animated(scene):
    """A floor and two panels seen from above, lit by a world alone: the floor's Base Color
    keyframed (read from its nodes), the left panel's Base Color a Checker whose first colour
    is keyframed (baked by Cycles), the world a Gradient (baked) whose Strength is keyframed."""
    floor = gi_scenes._material("Keyed Floor", (0.5, 0.5, 0.5))
    _keyed(next(n for n in floor.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
           .inputs["Base Color"], (0.8, 0.1, 0.1, 1.0), (0.1, 0.2, 0.8, 1.0))
    gi_scenes._mesh(scene, "Floor", [(-3, -2, 0), (3, -2, 0), (3, 2, 0), (-3, 2, 0)],
                    [(0, 1, 2, 3)], (floor,))
    checker = gi_scenes._material("Keyed Checker", (0.5, 0.5, 0.5))
    tree = checker.node_tree
    node = tree.nodes.new("ShaderNodeTexChecker")
    node.inputs["Scale"].default_value = 3.0
    node.inputs["Color2"].default_value = (0.05, 0.05, 0.05, 1.0)
    _keyed(node.inputs["Color1"], (0.9, 0.8, 0.1, 1.0), (0.1, 0.9, 0.3, 1.0))
    tree.links.new(node.outputs["Color"], next(
        n for n in tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"])
    panel = gi_scenes._mesh(scene, "Panel", [(-2.5, -1.5, 0.05), (-0.5, -1.5, 0.05),
                                             (-0.5, 1.5, 0.05), (-2.5, 1.5, 0.05)],
                            [(0, 1, 2, 3)], (checker,))
    layer = panel.data.uv_layers.new(name="UVMap")
    layer.data.foreach_set("uv", [0, 0, 1, 0, 1, 1, 0, 1])
    world = bpy.data.worlds.new("Keyed Sky")
    tree = world.node_tree
    gradient = tree.nodes.new("ShaderNodeTexGradient")
    background = tree.nodes["Background"]
    tree.links.new(gradient.outputs["Color"], background.inputs["Color"])
    _keyed(background.inputs["Strength"], 0.5, 2.0)
    scene.world = world
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 6.2
    camera.location = (0.0, 0.0, 4.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)


def test_an_animation_render_takes_each_frames_keyed_values_as_cycles(voxgi, tmp_path):
    scene = bpy.context.scene
    build_animated(scene)
    scene.cycles.filter_width = 0.01
    prepare_f12(scene, tmp_path / "frame_####")
    bpy.ops.render.render(animation=True)  # the UI's frame stays 1 throughout
    ours = [read_passes(tmp_path / f"frame_{k:04d}.exr") for k in (1, 2, 3)]
    assert scene.frame_current == 1
    for k in (1, 3):
        scene.frame_set(k)
        cycles = render_cycles_passes(scene, WIDTH, HEIGHT, 64, filter_width=0.01)
        mine = ours[k - 1]
        colour = np.abs(np.asarray(mine["Diffuse Color"]) - np.asarray(cycles["Diffuse Color"]))
        # the world's light on the floor (Diffuse Direct: the world is the only light)
        lit = [float(np.asarray(p["Diffuse Direct"]).mean()) for p in (mine, cycles)]
        print(f"frame {k}: Diffuse Color off Cycles' {colour.mean():.4f}; world light on the "
              f"floor {lit[0]:.4f} against Cycles' {lit[1]:.4f}")
        assert colour.mean() < 0.02, k  # the floor's and the checker's colours of this frame
        assert abs(lit[0] - lit[1]) < 0.05 * lit[1], k  # the sky's strength of this frame
    first, last = (np.asarray(ours[i]["Diffuse Color"]) for i in (0, 2))
    assert np.abs(first - last).mean() > 0.2  # the frames differ, as the keys say
    scene.frame_set(1)


def test_an_image_sequence_shows_each_frames_picture_as_cycles(voxgi, tmp_path):
    """An Image Texture playing an image sequence (a screen, an animated decal): Cycles shows
    each frame's picture; the preview's bake rendered its scene at frame 1, so every frame of
    an animation render (and the viewport at any frame) showed the first picture."""
    colours = [(0.8, 0.1, 0.1), (0.1, 0.8, 0.1), (0.1, 0.1, 0.8)]
    for k, colour in enumerate(colours, start=1):
        image = bpy.data.images.new(f"Picture {k}", 8, 8)
        image.pixels.foreach_set(np.tile([*colour, 1.0], 64).astype(np.float32))
        image.filepath_raw, image.file_format = str(tmp_path / f"screen_{k:04d}.png"), "PNG"
        image.save()
        bpy.data.images.remove(image)
    scene = bpy.context.scene
    screen = gi_scenes._material("Screen", (0.5, 0.5, 0.5))
    tree = screen.node_tree
    node = tree.nodes.new("ShaderNodeTexImage")
    node.image = bpy.data.images.load(str(tmp_path / "screen_0001.png"))
    node.image.source = "SEQUENCE"
    node.image_user.frame_duration, node.image_user.frame_start = 3, 1
    node.image_user.use_auto_refresh = True
    tree.links.new(node.outputs["Color"], next(
        n for n in tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"])
    plane = gi_scenes._mesh(scene, "Screen", [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)],
                            [(0, 1, 2, 3)], (screen,))
    plane.data.uv_layers.new(name="UVMap").data.foreach_set("uv", [0, 0, 1, 0, 1, 1, 0, 1])
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 2.5
    camera.location = (0.0, 0.0, 3.0)
    scene.collection.objects.link(camera)
    scene.camera = camera
    # the sky plays the same sequence (an Environment Texture: the world's bake, per frame too)
    world = bpy.data.worlds.new("Playing Sky")
    sky = world.node_tree.nodes.new("ShaderNodeTexEnvironment")
    sky.image = bpy.data.images.load(str(tmp_path / "screen_0001.png"))
    sky.image.source = "SEQUENCE"
    sky.image_user.frame_duration, sky.image_user.frame_start = 3, 1
    sky.image_user.use_auto_refresh = True
    world.node_tree.links.new(sky.outputs["Color"],
                              world.node_tree.nodes["Background"].inputs["Color"])
    scene.world = world
    scene.frame_start, scene.frame_end = 1, 3
    scene.frame_set(1)
    prepare_f12(scene, tmp_path / "frame_####")
    bpy.ops.render.render(animation=True)
    centre = (HEIGHT // 2, WIDTH // 2)
    for k, colour in enumerate(colours, start=1):
        mine = read_passes(tmp_path / f"frame_{k:04d}.exr")
        scene.frame_set(k)
        theirs = render_cycles_passes(scene, WIDTH, HEIGHT, 16)
        ours, cycles = (np.asarray(p["Diffuse Color"])[centre] for p in (mine, theirs))
        lit = [np.asarray(p["Diffuse Direct"])[centre] for p in (mine, theirs)]
        print(f"frame {k}: screen {np.round(ours, 3)} against Cycles' {np.round(cycles, 3)}; "
              f"the sky's light on it {np.round(lit[0], 3)} against {np.round(lit[1], 3)}")
        np.testing.assert_allclose(ours, cycles, atol=0.01)
        np.testing.assert_allclose(lit[0], lit[1], atol=0.05 * lit[1].max())
    scene.frame_set(1)


def test_keyframes_inside_a_node_group_follow_the_frame(voxgi):
    """A material built of a node group whose own nodes are keyframed (a Checker colour):
    what a bake of the depsgraph's frame renders — a copy of the user's material whose group
    is a copy with the frame's values — even where the user's group holds another value (as in
    Blender's UI, where the user's datablocks keep the UI frame's values while a render's
    depsgraph evaluates its own)."""
    from voxgi.blender.snapshot import animated

    scene = bpy.context.scene
    build_animated(scene)
    group = bpy.data.node_groups.new("Keyed Look", "ShaderNodeTree")
    group.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    out = group.nodes.new("NodeGroupOutput")
    checker = group.nodes.new("ShaderNodeTexChecker")
    group.links.new(checker.outputs["Color"], out.inputs[0])
    color1 = checker.inputs["Color1"]
    path = f'nodes["{checker.name}"].inputs[1].default_value'
    color1.default_value = (0.9, 0.1, 0.1, 1.0)
    group.keyframe_insert(path, frame=1)
    color1.default_value = (0.1, 0.3, 0.9, 1.0)
    group.keyframe_insert(path, frame=3)
    panel = bpy.data.materials["Keyed Checker"]
    node = panel.node_tree.nodes.new("ShaderNodeGroup")
    node.node_tree = group
    panel.node_tree.links.new(node.outputs["Color"], next(
        n for n in panel.node_tree.nodes if n.type == "BSDF_PRINCIPLED").inputs["Base Color"])
    scene.frame_set(3)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = bpy.data.objects["Panel"].evaluated_get(depsgraph).material_slots[0].material
    color1.default_value = (0.2, 0.9, 0.2, 1.0)  # the user's group moves on, unevaluated
    assert animated.reads_evaluated(evaluated)  # (only its group is animated)
    values = animated.frame_values(evaluated)
    copy = panel.copy()
    made = animated.apply(copy, values)
    try:
        assert len(made) == 1 and made[0] is not group
        inner = next(n for n in copy.node_tree.nodes if n.type == "GROUP")
        assert inner.node_tree is made[0] and made[0].animation_data is None
        shown = inner.node_tree.nodes[checker.name].inputs["Color1"].default_value
        np.testing.assert_allclose(tuple(shown), (0.1, 0.3, 0.9, 1.0), atol=1e-6)  # frame 3's
        np.testing.assert_allclose(tuple(color1.default_value), (0.2, 0.9, 0.2, 1.0))  # theirs
    finally:
        bpy.data.materials.remove(copy)
        for made_group in made:
            bpy.data.node_groups.remove(made_group)
    scene.frame_set(1)
