"""The Rendered view's film (issue 19 leftovers): the world behind the geometry, as F12's.

The HDRI courtyard drawn by ``view_draw`` (the stand-in engine) into an offscreen buffer until
its samples converge: where camera rays miss every surface the view shows the HDRI — F12's
film (``voxgi_addon/preview/film.py``) within tolerance, not black — from the very first
(coarse) draw on; with Film › Transparent it shows the viewport's own background there and its
alpha is F12's coverage.
"""
from __future__ import annotations

import bpy
import light_scenes
import numpy as np
from stand_in_engine import StandInEngine
from test_viewport import HEIGHT, WIDTH, engine_view, gpu_ready, live_view

SAMPLES = 16  # the strata of F12's 4 × 4 sub-pixel passes
GREY = 0.5    # engine_view's clear colour: what an empty viewport shows


def f12_rgba(scene, path, transparent):
    """F12's Combined RGBA (row 0 on top) with the film opaque or transparent."""
    from voxgi.render.engine import enable_passes
    from voxgi.voxgi_addon.files.exr import read_exr

    scene.render.film_transparent = transparent
    for view_layer in scene.view_layers:
        enable_passes(view_layer)
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    channels = read_exr(str(path))
    return np.stack([next(v for k, v in channels.items() if k.endswith(f"Combined.{c}"))
                     for c in "RGBA"], axis=-1).astype(np.float64)


def courtyard():
    scene = bpy.context.scene
    light_scenes.build("hdri_courtyard", scene)
    scene.render.engine = "VOXGI"
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.voxgi_viewport.resolution_fraction = 1.0
    scene.voxgi_viewport.coarse_first = True
    scene.voxgi_viewport.samples = SAMPLES
    return scene


def converge(engine, scene, depsgraph, view, window):
    """view_draw until the engine stops asking for redraws: the draws' images."""
    images = []
    for _ in range(3 * SAMPLES):
        redraws = engine.redraws
        images.append(engine_view(engine, scene, depsgraph, view, window))
        if engine.redraws == redraws:
            return images
    raise AssertionError("the view never converged")


def stand_in_view(scene):
    """(depsgraph, live, view, window, engine, renderer): the scene's ``LiveGI`` updated, its
    camera's matrices, and a stand-in engine whose renderer traces a whole sample a draw."""
    from voxgi.render.viewport import ViewportRenderer

    depsgraph, live, view, window = live_view(scene)
    engine = StandInEngine()
    renderer = engine.voxgi_viewport = ViewportRenderer()
    renderer.progressive.fixed_pixels = WIDTH * HEIGHT  # a sample a draw (not timed)
    renderer.progressive.stage_budget = None
    return depsgraph, live, view, window, engine, renderer


def rel(ours, reference):
    return float(np.abs(ours - reference).sum() / max(np.abs(reference).sum(), 1e-12))


def test_the_rendered_view_shows_the_world_behind_the_geometry_as_f12(voxgi, tmp_path):
    scene = courtyard()
    gpu_ready()
    f12 = f12_rgba(scene, tmp_path / "f12.exr", transparent=False)
    f12_clear = f12_rgba(scene, tmp_path / "f12_t.exr", transparent=True)
    sky = f12_clear[..., 3] < 0.01  # F12 met no surface there
    assert 0.1 < sky.mean() < 0.9, "the camera should see sky and courtyard"
    assert f12[sky, :3].mean() > 0.05  # F12's film shows the HDRI there

    scene.render.film_transparent = False
    depsgraph, live, view, window, engine, renderer = stand_in_view(scene)
    images = converge(engine, scene, depsgraph, view, window)
    assert renderer.progressive.converged and len(images) == 1 + SAMPLES

    # the very first draw (the coarse image) already shows the sky, not the clear colour
    first = images[0][..., :3]
    assert np.abs(first[sky] - GREY).sum(-1).min() > 1e-3
    assert rel(first[sky], f12[sky, :3]) < 0.15
    # converged: F12's film in the sky and over the whole image; opaque
    view_rgb = images[-1][..., :3]
    sky_error, whole = rel(view_rgb[sky], f12[sky, :3]), rel(view_rgb, f12[..., :3])
    black_sky = rel(np.zeros_like(f12[sky, :3]), f12[sky, :3])  # what the view drew before
    print(f"viewport vs F12 film: sky {sky_error:.4f}, whole image {whole:.4f} "
          f"(a black sky {black_sky:.2f}); first draw sky {rel(first[sky], f12[sky, :3]):.4f}")
    assert sky_error < 0.02 and whole < 0.03
    assert np.all(images[-1][..., 3] == 1.0)
    assert np.allclose(renderer.progressive.read_image()[..., 3], 1.0)

    # Film › Transparent restarts the image: no world, the view's own background shows
    # through by the coverage, which is F12's alpha
    scene.render.film_transparent = True
    images = converge(engine, scene, depsgraph, view, window)
    alpha = renderer.progressive.read_image()[..., 3]
    alpha_error = np.abs(alpha - f12_clear[..., 3])
    print(f"transparent: alpha vs F12 mean abs {alpha_error.mean():.4f}")
    assert alpha_error.mean() < 0.02
    through = np.abs(images[-1][sky, :3] - GREY)
    print(f"transparent: sky off the clear colour mean {through.mean():.4f}, "
          f"max {through.max():.4f}")
    assert through.mean() < 0.005  # the clear colour, no sky (but edge tails)
    assert rel(renderer.progressive.read_image()[..., :3], f12_clear[..., :3]) < 0.03


def test_a_view_layer_without_meshes_shows_its_world_as_f12_and_cycles_do(voxgi, tmp_path):
    """The artist deletes every mesh in the Rendered view (or shows a world-only layer): the
    view shows the world alone — F12's image — where it kept the deleted meshes' last image
    and said "Nothing to voxelize"; with Film › Transparent the view's own background; a mesh
    added back is traced again."""
    scene = courtyard()
    depsgraph, live, view, window, engine, renderer = stand_in_view(scene)
    with_meshes = converge(engine, scene, depsgraph, view, window)[-1]

    meshes = [o for o in scene.objects if o.type == "MESH"]
    kept = meshes[0].data
    for obj in meshes:
        bpy.data.objects.remove(obj)
    scene.render.film_transparent = False
    f12 = f12_rgba(scene, tmp_path / "world.exr", transparent=False)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live.update(scene, depsgraph)  # what view_update does after the deletion
    assert live.error == "" and live.world_only is not None
    images = converge(engine, scene, depsgraph, view, window)
    world = images[-1]
    error = rel(world[..., :3], f12[..., :3])
    print(f"world alone: view vs F12 {error:.5f}; vs the deleted meshes' image "
          f"{rel(world[..., :3], with_meshes[..., :3]):.3f}")
    assert f12[..., :3].mean() > 0.05 and np.all(world[..., 3] == 1.0)
    assert error < 0.005
    assert rel(world[..., :3], with_meshes[..., :3]) > 0.1  # not the meshes' last image
    assert "world alone" in engine.stats[-1]
    from voxgi.ui.viewport_panel import view_state_line

    assert view_state_line(live) == "The world alone: the view layer shows no mesh"

    scene.render.film_transparent = True
    clear = converge(engine, scene, depsgraph, view, window)[-1]
    assert np.all(np.abs(clear[..., :3] - GREY) < 1e-6)

    scene.render.film_transparent = False
    obj = bpy.data.objects.new("back", kept)
    scene.collection.objects.link(obj)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live.update(scene, depsgraph)
    assert live.world_only is None
    again = converge(engine, scene, depsgraph, view, window)[-1]
    assert "world alone" not in engine.stats[-1]
    assert renderer.world.key is None  # its lookups cancelled: the preparing thread is free
    print(f"a mesh back: {kept.name}, the view vs the world alone {rel(again, world):.3f}")
    assert rel(again[..., :3], world[..., :3]) > 0.05  # the mesh is drawn over the world
