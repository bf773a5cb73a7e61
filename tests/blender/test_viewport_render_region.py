"""The Rendered view's Render Region, as Cycles' view takes it: in the camera view the scene's
region (Output › Format › Render Region, Ctrl B there) placed in the camera's frame, elsewhere
the view's own (View › Render Region). Only the region's pixels are traced, and drawn where
they lie; the rest of the view shows what it showed without an engine (the clear colour).
"""
from __future__ import annotations

import types

import bpy
import gpu
import numpy as np
import pytest
from test_viewport import (
    HEIGHT,
    WIDTH,
    camera_matrices,
    cornell,
    f12_combined,
    gpu_ready,
    live_view,
    one_shot,
    relative_l1,
)

BORDER = (0.2, 0.3, 0.7, 0.85)  # x0, y0, x1, y1: fractions from the bottom left
GREY = 0.5  # the offscreen's clear colour


def region_view(renderer, scene, depsgraph, context):
    """``draw_view`` of ``context``'s view with its Render Region into a float offscreen of
    the region's size; (H, W, 4), top row first."""
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.render.viewport import draw_view, render_border

    offscreen = gpu.types.GPUOffScreen(WIDTH, HEIGHT, format="RGBA32F")
    try:
        with offscreen.bind():
            gpu.state.active_framebuffer_get().clear(color=(GREY, GREY, GREY, 1.0))
            data = context.region_data
            drawn = draw_view(renderer, scene, depsgraph, data.view_matrix, data.window_matrix,
                              WIDTH, HEIGHT, border=render_border(context, scene, depsgraph))
        return drawn, np.flipud(read_texture(offscreen.texture_color))
    finally:
        offscreen.free()


def context_of(view, window, perspective, space_border=None):
    space = types.SimpleNamespace(use_render_border=space_border is not None)
    if space_border is not None:
        (space.render_border_min_x, space.render_border_min_y,
         space.render_border_max_x, space.render_border_max_y) = space_border
    return types.SimpleNamespace(
        region=types.SimpleNamespace(width=WIDTH, height=HEIGHT), space_data=space,
        region_data=types.SimpleNamespace(view_matrix=view, window_matrix=window,
                                          view_perspective=perspective))


@pytest.mark.parametrize("where", ["camera view, the scene's region", "free view, its own region"])
def test_the_rendered_view_traces_and_draws_only_its_render_region(voxgi, tmp_path, where):
    from voxgi.render.viewport import render_border

    scene = cornell()
    scene.voxgi_viewport.resolution_fraction = 1.0
    depsgraph, _, view, window = live_view(scene)
    scene.render.use_border, scene.render.use_crop_to_border = True, False
    (scene.render.border_min_x, scene.render.border_min_y,
     scene.render.border_max_x, scene.render.border_max_y) = BORDER
    if where.startswith("camera"):
        context = context_of(view, window, "CAMERA")
    else:  # the view's own region; the scene's is not the free view's
        scene.render.border_min_x = 0.0
        context = context_of(view, window, "PERSP", space_border=BORDER)
    assert render_border(context, scene, depsgraph) == pytest.approx(BORDER, abs=1e-6)

    renderer = one_shot()
    drawn, image = region_view(renderer, scene, depsgraph, context)
    assert drawn and renderer.traces == 1
    # F12's region, as Blender cuts it: rows 14–40 from the bottom, columns 12–44
    x0, x1, y0, y1 = 12, 44, 14, 40
    acc = renderer.progressive.accumulation
    assert (acc.width, acc.height) == (x1 - x0, y1 - y0)  # the region's pixels alone traced
    inside = np.zeros((HEIGHT, WIDTH), bool)
    inside[HEIGHT - y1:HEIGHT - y0, x0:x1] = True  # (rows top first)
    assert np.all(image[~inside, :3] == np.float32(GREY))  # the rest of the view as it was
    assert np.all(image[inside, 3] == 1.0)

    scene.render.border_min_x = BORDER[0]
    f12 = f12_combined(scene, tmp_path)  # the whole frame, black outside its region
    assert np.all(f12[~inside] == 0.0)
    error = relative_l1(image[inside, :3], f12[inside])
    print(f"{where}: region vs F12's region Combined relative L1 {error:.4f}")
    assert error <= 0.03


def test_the_camera_views_render_region_lies_in_the_camera_frame(voxgi):
    """Zoomed out in the camera view the camera's frame covers the middle half of the region:
    the scene's Render Region is a part of that frame, not of the region."""
    from voxgi.render.viewport import render_border

    scene = cornell()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    zoomed_out = np.diag([0.5, 0.5, 1.0, 1.0]) @ np.array(window, np.float64)
    scene.render.use_border = True
    (scene.render.border_min_x, scene.render.border_min_y,
     scene.render.border_max_x, scene.render.border_max_y) = BORDER
    border = render_border(context_of(view, zoomed_out, "CAMERA"), scene, depsgraph)
    assert border == pytest.approx([0.25 + 0.5 * b for b in BORDER], abs=1e-6)
    scene.render.use_border = False
    assert render_border(context_of(view, zoomed_out, "CAMERA"), scene, depsgraph) is None
    # the view's own region is the free view's, not the camera view's
    assert render_border(context_of(view, window, "CAMERA", space_border=BORDER), scene,
                         depsgraph) is None


def test_a_render_region_outside_the_view_draws_nothing_and_the_updates_go_on(voxgi):
    """Panned so that the region lies outside the view: nothing is traced or drawn and the
    header says why; the scene's mesh reads, which go on a slice a draw, still finish."""
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render.viewport import ViewportRenderer, draw_view

    scene = cornell()
    gpu_ready()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    view, window = camera_matrices(scene, depsgraph)
    live = live_gi(scene.name_full)
    live.read_slice = 1e-9  # a mesh a draw, as a view on a large scene reads them
    live.update(scene, depsgraph)
    assert live.reading is not None
    renderer = ViewportRenderer()
    for _ in range(50):
        drawn = draw_view(renderer, scene, depsgraph, view, window, WIDTH, HEIGHT,
                          border=(1.2, 0.2, 1.6, 0.8))
        assert not drawn and renderer.traces == 0
        if live.reading is None:
            break
    assert live.reading is None and live.latest_snapshot is not None
    assert renderer.status == "VoxGI | The Render Region is outside the view"
    drawn, image = region_view(one_shot(renderer), scene, depsgraph,
                               context_of(view, window, "PERSP", space_border=BORDER))
    assert drawn and renderer.traces == 1
