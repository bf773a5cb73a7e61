"""F12 with a Render Region traces the region alone (with its filters' margin), as Cycles
renders a region: the region's image is the whole frame's there, up to the preview's noise,
and the work is the region's."""
from __future__ import annotations

import pathlib
import re

import bounce_scenes
import bpy
import numpy as np
import pytest
from test_final_renders import f12, rel
from test_multibounce import relative_l1

from voxgi.voxgi_addon.preview.region import ALIGN_CELLS, MARGIN_CELLS

REFS = pathlib.Path(__file__).resolve().parents[1] / "data" / "bounce_refs"
WIDTH, HEIGHT = 160, 120
# (x0, y0, x1, y1) fractions of the frame from the bottom left: columns 60-99, rows 42-71
BORDER = (0.375, 0.35, 0.625, 0.6)
ROWS, COLUMNS = slice(HEIGHT - 72, HEIGHT - 42), slice(60, 100)  # row 0 on top
DETERMINISTIC = ("Diffuse Color", "Glossy Color")  # no random numbers in them


def _frame(scene, path, seed=0, border=None):
    scene.voxgi.seed = seed
    scene.render.use_border = border is not None
    if border is not None:
        (scene.render.border_min_x, scene.render.border_min_y,
         scene.render.border_max_x, scene.render.border_max_y) = border
        scene.render.use_crop_to_border = True
    f12(scene, path)
    from test_final_renders import read_passes

    return read_passes(path)


@pytest.mark.parametrize("border, rect", [
    ((0.375, 0.35, 0.625, 0.6), (60, 42, 40, 30)),  # the middle
    ((0.0625, 0.6667, 0.9375, 0.7667), (10, 80, 140, 12)),  # a strip along the back wall
])
def test_f12_traces_a_render_region_alone_as_close_to_cycles_as_the_whole_frame(
        voxgi, tmp_path, border, rect):
    """Cornell box, 160 × 120, Bounces following Cycles: the region's passes without random
    numbers are the whole frame's there exactly; its Combined is as close to Cycles' (the
    stored 2,048-spp reference) as the whole frame's is there (1.1 × the larger of two seeds'
    errors) and no farther from the whole frame's than another seed's whole frame (1.5 ×, or
    1%); and what was traced is the region with its margin, not the frame (the line F12 shows,
    from ``render_scene_passes``)."""
    import test_final_renders

    from voxgi.render.pipeline import render_scene_passes

    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    scene.voxgi.bounce_source = "CYCLES"
    test_final_renders.WIDTH, test_final_renders.HEIGHT = WIDTH, HEIGHT
    try:
        whole = _frame(scene, tmp_path / "whole.exr")
        other = _frame(scene, tmp_path / "other.exr", seed=7)
        part = _frame(scene, tmp_path / "part.exr", border=border)
    finally:
        test_final_renders.WIDTH, test_final_renders.HEIGHT = 64, 48
    x0, y0, w, h = rect
    rows, columns = slice(HEIGHT - y0 - h, HEIGHT - y0), slice(x0, x0 + w)  # row 0 on top
    with np.load(REFS / "cornell_box.npz") as data:
        reference = {key: data[key].astype(np.float64)[rows, columns] for key in data.files}
    mask = reference["Alpha"] > 0.5
    assert mask.mean() > 0.9 and whole["Combined"][rows, columns].mean() > 0.05
    for name in DETERMINISTIC:
        assert part[name].shape == (h, w, 3), (name, part[name].shape)
        assert rel(part[name], whole[name][rows, columns]) < 1e-3, name
    errors = [relative_l1(image["Combined"][rows, columns], reference["Combined"], mask)
              for image in (whole, other)]
    ours = relative_l1(part["Combined"], reference["Combined"], mask)
    assert ours <= 1.1 * max(errors), (ours, errors)
    noise = rel(other["Combined"][rows, columns], whole["Combined"][rows, columns])
    assert rel(part["Combined"], whole["Combined"][rows, columns]) <= max(1.5 * noise, 0.01)

    scene.render.use_border = False
    _, lines = render_scene_passes(bpy.context, scene, None, WIDTH, HEIGHT, region=rect)
    said = [line for _, line in lines if "Render Region" in line]
    assert len(said) == 1, lines
    tw, th = (int(v) for v in re.search(r"\((\d+) × (\d+) with", said[0]).groups())
    assert w <= tw <= w + 2 * MARGIN_CELLS + ALIGN_CELLS and h <= th <= h + 2 * MARGIN_CELLS + \
        ALIGN_CELLS and tw * th < WIDTH * HEIGHT / 2, said


def test_a_render_region_of_a_layer_without_meshes_is_its_world(voxgi, tmp_path):
    """A layer that shows no mesh, with a Render Region: the region of the world alone, as the
    whole frame's world there."""
    import test_final_renders

    scene = bpy.context.scene
    bounce_scenes.build("cornell_box", scene)
    world = bpy.data.worlds.new("Sky")
    if world.node_tree is None:  # Blender before 5.0 makes worlds without a node tree
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.4, 0.8, 1.0)
    scene.world = world
    for obj in [o for o in scene.objects if o.type == "MESH"]:
        bpy.data.objects.remove(obj)
    test_final_renders.WIDTH, test_final_renders.HEIGHT = WIDTH, HEIGHT
    try:
        whole = _frame(scene, tmp_path / "whole.exr")
        part = _frame(scene, tmp_path / "part.exr", border=BORDER)
    finally:
        test_final_renders.WIDTH, test_final_renders.HEIGHT = 64, 48
    assert part["Combined"].shape == (30, 40, 3)
    assert np.abs(part["Combined"] - np.array([0.2, 0.4, 0.8])).max() < 1e-3
    assert rel(part["Combined"], whole["Combined"][ROWS, COLUMNS]) < 1e-3
