"""The film (voxgi_addon/preview/film.py): the world behind the geometry and alpha, as Cycles'.

F12 of the HDRI courtyard against Cycles rendered with Film › Transparent off and on (not the
film-transparent references of the other tests): the sky pixels' Combined is the HDRI and the
alpha 1; with Film › Transparent the sky is 0 and the alpha follows the geometry's edges.
"""
from __future__ import annotations

import bpy
import light_scenes
import numpy as np
import pytest

WIDTH, HEIGHT = 96, 72
CYCLES_SAMPLES = 256


def _exr_rgba(path):
    from voxgi.voxgi_addon.files.exr import read_exr

    channels = read_exr(str(path))
    rgba = [next(v for k, v in channels.items() if k.endswith(f"Combined.{c}")) for c in "RGBA"]
    return np.stack(rgba, axis=-1).astype(np.float64)


def _output(scene, path):
    scene.render.resolution_x, scene.render.resolution_y = WIDTH, HEIGHT
    scene.render.resolution_percentage = 100
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    scene.render.image_settings.color_depth = "32"
    scene.render.filepath = str(path)


def cycles_rgba(scene, path, transparent):
    """Cycles' Combined RGBA (row 0 on top) at the scene's film."""
    scene.render.engine = "CYCLES"
    scene.render.film_transparent = transparent
    scene.cycles.device = "CPU"
    scene.cycles.samples = CYCLES_SAMPLES
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.max_bounces = scene.cycles.diffuse_bounces = scene.cycles.glossy_bounces = 1
    _output(scene, path)
    bpy.ops.render.render(write_still=True)
    return _exr_rgba(path)


def voxgi_rgba(scene, path, transparent):
    """F12 with the VoxGI engine: Combined RGBA (row 0 on top)."""
    from voxgi.render.engine import enable_passes

    scene.render.engine = "VOXGI"
    scene.render.film_transparent = transparent
    for view_layer in scene.view_layers:
        enable_passes(view_layer)
    _output(scene, path)
    bpy.ops.render.render(write_still=True)
    return _exr_rgba(path)


def rel(ours, reference):
    return float(np.abs(ours - reference).sum() / max(np.abs(reference).sum(), 1e-12))


@pytest.fixture
def courtyard(voxgi):
    scene = bpy.context.scene
    light_scenes.build("hdri_courtyard", scene)
    return scene


def test_f12_shows_the_hdri_behind_the_geometry(courtyard, tmp_path):
    reference = cycles_rgba(courtyard, tmp_path / "cycles.exr", transparent=False)
    ours = voxgi_rgba(courtyard, tmp_path / "voxgi.exr", transparent=False)
    with_film = cycles_rgba(courtyard, tmp_path / "cycles_t.exr", transparent=True)
    sky = with_film[..., 3] < 0.01  # Cycles saw no surface there
    assert sky.mean() > 0.1, "the camera should see some sky"
    assert reference[sky, :3].mean() > 0.05  # Cycles' Combined shows the HDRI there
    error = rel(ours[sky, :3], reference[sky, :3])
    print("sky Combined relative L1", round(error, 4))
    assert error < 0.05
    assert np.all(ours[..., 3] == 1.0) and np.all(reference[..., 3] > 0.999)
    # the whole image: surfaces as before, the sky and the edges blended like Cycles'
    print("whole Combined relative L1", round(rel(ours[..., :3], reference[..., :3]), 4))


def test_film_transparent_gives_cycles_alpha_and_no_sky(courtyard, tmp_path):
    reference = cycles_rgba(courtyard, tmp_path / "cycles.exr", transparent=True)
    ours = voxgi_rgba(courtyard, tmp_path / "voxgi.exr", transparent=True)
    sky = reference[..., 3] < 0.01
    assert sky.mean() > 0.1
    # no world behind the geometry: where no camera sample met a surface, nothing at all
    empty = ours[..., 3] == 0.0
    assert np.all(ours[empty, :3] == 0.0), "Film › Transparent: no world behind the geometry"
    assert empty[sky].mean() > 0.9
    edges = (reference[..., 3] > 0.01) & (reference[..., 3] < 0.99)
    assert edges.sum() > 20
    alpha_error = np.abs(ours[..., 3] - reference[..., 3])
    print("alpha mean abs", round(alpha_error.mean(), 4), "at edges", round(alpha_error[edges].mean(), 4))
    assert alpha_error.mean() < 0.02
    assert alpha_error[edges].mean() < 0.05


def test_numpy_and_gpu_agree_on_coverage(courtyard):
    from voxgi.blender.session import scene_session
    from voxgi.render.pipeline import render_scene_passes

    alphas = {}
    for tracer in ("AUTO", "NUMPY"):
        courtyard.voxgi.tracer = tracer
        passes, lines = render_scene_passes(bpy.context, courtyard, None, 64, 48)
        assert scene_session(courtyard.name_full).tracer_used == ("GPU" if tracer == "AUTO" else "numpy"), lines
        alphas[tracer] = np.asarray(passes["Alpha"], np.float64)
        assert alphas[tracer].shape == (48, 64)
    assert 0.1 < alphas["NUMPY"].mean() < 0.95
    assert np.abs(alphas["AUTO"] - alphas["NUMPY"]).mean() < 0.005


def test_a_holdout_object_gives_alpha_0_as_in_cycles(courtyard, tmp_path):
    """The pillar made a holdout (Object › Visibility › Holdout): where the camera sees it,
    neither it nor the sky behind it, Combined 0 and alpha 0 with the opaque film too."""
    bpy.data.objects["Pillar"].is_holdout = True
    reference = cycles_rgba(courtyard, tmp_path / "cycles.exr", transparent=False)
    ours = voxgi_rgba(courtyard, tmp_path / "voxgi.exr", transparent=False)
    held = reference[..., 3] < 0.01
    assert held.sum() > 30, "the camera should see the pillar"
    assert ours[held, 3].max() < 0.05
    # nothing but the filter's tails of the surfaces and sky beside it, as in Cycles
    print("held Combined mean", ours[held, :3].mean(), "Cycles", reference[held, :3].mean())
    assert np.abs(ours[held, :3] - reference[held, :3]).mean() < 0.01
    assert ours[held, :3].mean() < 0.01
    alpha_error = np.abs(ours[..., 3] - reference[..., 3])
    edges = (reference[..., 3] > 0.01) & (reference[..., 3] < 0.99)
    print("holdout alpha mean abs", round(alpha_error.mean(), 4), "at its edges",
          round(alpha_error[edges].mean(), 4))
    assert alpha_error.mean() < 0.02 and alpha_error[edges].mean() < 0.05
    print("Combined relative L1 with the holdout", round(rel(ours[..., :3], reference[..., :3]), 4))


def test_numpy_and_gpu_agree_on_the_holdout_share(courtyard):
    from voxgi.render.pipeline import render_scene_passes

    bpy.data.objects["Pillar"].is_holdout = True
    held = {}
    for tracer in ("AUTO", "NUMPY"):
        courtyard.voxgi.tracer = tracer
        passes, _ = render_scene_passes(bpy.context, courtyard, None, 64, 48)
        held[tracer] = np.asarray(passes["_holdout"], np.float64)
        assert np.asarray(passes["Combined"])[held[tracer] > 0.999].max() < 0.02
    assert held["NUMPY"].max() > 0.99 and held["NUMPY"].sum() > 20
    assert np.abs(held["AUTO"] - held["NUMPY"]).mean() < 0.005


def test_fast_quality_gives_the_film_its_coverage_and_holdouts(courtyard):
    """Fast quality (cones; the pixel centres' hits, no sub-pixel passes): the same Alpha and
    holdout share from the GPU G-buffer and the numpy rays."""
    from voxgi.render.pipeline import render_scene_passes

    bpy.data.objects["Pillar"].is_holdout = True
    courtyard.voxgi.quality = "FAST"
    out = {}
    for tracer in ("AUTO", "NUMPY"):
        courtyard.voxgi.tracer = tracer
        passes, _ = render_scene_passes(bpy.context, courtyard, None, 64, 48)
        out[tracer] = (np.asarray(passes["Alpha"], np.float64),
                       np.asarray(passes["_holdout"], np.float64))
    alpha, held = out["NUMPY"]
    assert 0.1 < alpha.mean() < 0.95 and held.sum() > 20
    assert not np.any((alpha > 0) & (held > 0))  # one ray per pixel: a surface or a holdout
    for gpu, numpy_ in zip(out["AUTO"], out["NUMPY"]):
        assert np.abs(gpu - numpy_).mean() < 0.01
