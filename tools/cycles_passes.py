"""Cycles ground truth: render a scene's passes with Cycles and return them as numpy arrays.

Used by the tests (``tests/blender/cycles_reference.py``), the demo and the benchmark, so it
has no pytest dependency. Main thread only (it renders).

What "one diffuse bounce" means here (Cycles' light path settings while rendering):
``max_bounces = max(diffuse_bounces, glossy_bounces)``, ``diffuse_bounces`` as asked (1), one
glossy bounce so that ``Glossy Indirect`` shows the directly lit scene in reflections,
transmission and volume bounces 0, transparent bounces left as they are. No clamping, no
Filter Glossy, no adaptive sampling, no denoising, a fixed seed, CPU device, transparent film
(so ``Alpha`` is the geometry coverage and the background of every pass is 0). The AO pass
uses the world's AO distance (``World.light_settings.distance``), set from ``ao_distance``.

Passes come back with Cycles' names and meanings (docs/blender_facts.md "Cycles' radiometry"): ``Diffuse Direct``,
``Diffuse Indirect`` (light without albedo), ``Diffuse Color``, ``Ambient Occlusion``,
``Glossy Direct``, ``Glossy Indirect``, ``Glossy Color`` (Glossy Direct/Indirect are light without
the glossy colour, like the diffuse ones), ``Combined`` (RGB, premultiplied) and ``Alpha`` (H, W). The multilayer EXR
is written to a temporary file with ZIP compression and read back with ``voxgi_addon.exr``.
Every setting touched is restored afterwards, also when the render fails.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
import time

import bpy
import numpy as np

from voxgi.voxgi_addon.files.exr import group_passes, read_exr

__all__ = ["PASSES", "render_cycles_passes", "last_render_seconds", "relative_l1", "coverage_agreement"]

# Cycles pass name → ViewLayer property that enables it.
PASSES = {
    "Diffuse Direct": "use_pass_diffuse_direct",
    "Diffuse Indirect": "use_pass_diffuse_indirect",
    "Diffuse Color": "use_pass_diffuse_color",
    "Ambient Occlusion": "use_pass_ambient_occlusion",
    "Glossy Direct": "use_pass_glossy_direct",
    "Glossy Indirect": "use_pass_glossy_indirect",
    "Glossy Color": "use_pass_glossy_color",
    "Combined": "use_pass_combined",
}

_last_seconds = 0.0


def last_render_seconds() -> float:
    """Wall time of the last ``render_cycles_passes`` call's Cycles render (excluding EXR I/O)."""
    return _last_seconds


@contextlib.contextmanager
def _temporarily(settings):
    """Set ``(owner, attribute, value)`` triples; restore the old values on exit (reverse order)."""
    saved = []
    try:
        for owner, attribute, value in settings:
            saved.append((owner, attribute, getattr(owner, attribute)))
            setattr(owner, attribute, value)
        yield
    finally:
        for owner, attribute, value in reversed(saved):
            setattr(owner, attribute, value)


_IMAGE_FORMAT = ("media_type", "file_format", "color_mode", "color_depth", "exr_codec", "use_exr_interleave")


@contextlib.contextmanager
def _multilayer_exr_output(image_settings):
    """Output 32-bit float, ZIP multilayer EXR; restore the format afterwards.

    Restored in the order set, not reversed: assigning ``media_type`` resets ``file_format``,
    which in turn limits the valid depths and codecs.
    """
    saved = [(name, getattr(image_settings, name)) for name in _IMAGE_FORMAT]
    try:
        image_settings.media_type = "MULTI_LAYER_IMAGE"
        image_settings.file_format = "OPEN_EXR_MULTILAYER"
        image_settings.color_depth = "32"
        image_settings.exr_codec = "ZIP"
        yield
    finally:
        for name, value in saved:
            with contextlib.suppress(TypeError, ValueError, AttributeError):
                setattr(image_settings, name, value)


@contextlib.contextmanager
def _ao_world(scene, ao_distance):
    """The scene's world (a temporary empty one when it has none and an AO distance is asked)."""
    if scene.world is not None or ao_distance is None:
        yield scene.world
        return
    world = bpy.data.worlds.new("VoxGI Reference World")
    world.color = (0.0, 0.0, 0.0)
    scene.world = world
    try:
        yield world
    finally:
        scene.world = None
        bpy.data.worlds.remove(world)


def _render_settings(scene, view_layer, width, height, samples, diffuse_bounces, glossy_bounces,
                     seed, filter_width, path, denoise=False):
    render, cycles = scene.render, scene.cycles
    settings = [
        (render, "engine", "CYCLES"),
        (render, "resolution_x", int(width)),
        (render, "resolution_y", int(height)),
        (render, "resolution_percentage", 100),
        (render, "pixel_aspect_x", 1.0),
        (render, "pixel_aspect_y", 1.0),
        (render, "use_border", False),
        (render, "film_transparent", True),
        (render, "use_compositing", False),
        (render, "use_sequencer", False),
        (render, "filepath", path),
        (render, "use_file_extension", True),
        (cycles, "device", "CPU"),
        (cycles, "samples", int(samples)),
        (cycles, "use_adaptive_sampling", False),
        (cycles, "use_denoising", bool(denoise)),
        (cycles, "seed", int(seed)),
        (cycles, "use_animated_seed", False),
        (cycles, "max_bounces", max(int(diffuse_bounces), int(glossy_bounces))),
        (cycles, "diffuse_bounces", int(diffuse_bounces)),
        (cycles, "glossy_bounces", int(glossy_bounces)),
        (cycles, "transmission_bounces", 0),
        (cycles, "volume_bounces", 0),
        (cycles, "sample_clamp_direct", 0.0),
        (cycles, "sample_clamp_indirect", 0.0),
        (cycles, "blur_glossy", 0.0),
    ]
    if denoise:  # the quick preview artists use: OpenImageDenoise with albedo and normal
        settings += [(cycles, "denoiser", "OPENIMAGEDENOISE"),
                     (cycles, "denoising_input_passes", "RGB_ALBEDO_NORMAL")]
    if filter_width is not None:
        settings += [(cycles, "pixel_filter_type", "BLACKMAN_HARRIS"),
                     (cycles, "filter_width", float(filter_width))]
    settings += [(view_layer, prop, True) for prop in PASSES.values()]
    return settings


def render_cycles_passes(scene, width: int, height: int, samples: int, diffuse_bounces: int = 1,
                         ao_distance: float | None = None, seed: int = 0, *,
                         glossy_bounces: int = 1, filter_width: float | None = None,
                         view_layer=None, extra_passes: dict[str, str] | None = None,
                         denoise: bool = False) -> dict[str, np.ndarray]:
    """Render ``scene``'s camera with Cycles and return its passes.

    Parameters
    ----------
    scene : ``bpy.types.Scene`` with a camera.
    width, height : output size in pixels (keep it small: Cycles runs on the CPU).
    samples : samples per pixel.
    diffuse_bounces : Cycles' diffuse bounce limit (1 = one indirect diffuse bounce).
    ao_distance : AO pass distance in metres; None keeps the world's setting (10 m by default).
    seed : Cycles' sampling seed.
    glossy_bounces : glossy bounce limit (1 lets ``Glossy Indirect`` see the lit scene).
    filter_width : Blackman-Harris pixel filter width in pixels; None keeps the scene's
        (Cycles' default is 1.5). Use a tiny width (0.01) for point samples at pixel centres.
    view_layer : the view layer to render; default ``scene.view_layers[0]``.
    extra_passes : more passes to return, name → the ViewLayer property enabling it (e.g.
        ``{"Position": "use_pass_position"}``).
    denoise : run OpenImageDenoise on Combined (the other passes stay noisy, as in Cycles).

    Returns
    -------
    dict: pass name (``PASSES``) → (H, W, 3) float32 linear, row 0 = top; plus ``Alpha`` (H, W).
    """
    global _last_seconds
    if scene.camera is None:
        raise ValueError(f"scene '{scene.name}' has no camera to render")
    view_layer = view_layer or scene.view_layers[0]
    with tempfile.TemporaryDirectory(prefix="voxgi-cycles-") as tmp:
        path = os.path.join(tmp, "passes.exr")
        settings = _render_settings(scene, view_layer, width, height, samples, diffuse_bounces,
                                    glossy_bounces, seed, filter_width, path, denoise)
        settings += [(view_layer, prop, True) for prop in (extra_passes or {}).values()]
        with _ao_world(scene, ao_distance) as world:
            if ao_distance is not None:
                settings.append((world.light_settings, "distance", float(ao_distance)))
            with _multilayer_exr_output(scene.render.image_settings), _temporarily(settings):
                start = time.perf_counter()
                bpy.ops.render.render(write_still=True, scene=scene.name, layer=view_layer.name)
                _last_seconds = time.perf_counter() - start
        if not os.path.exists(path):
            raise RuntimeError(f"Cycles did not write {path}")
        channels = read_exr(path)
    grouped = group_passes(channels)
    passes = {name: grouped[name] for name in [*PASSES, *(extra_passes or {})]}
    alpha = [plane for name, plane in channels.items() if name.endswith("Combined.A")]
    passes["Alpha"] = alpha[0] if alpha else (passes["Diffuse Color"].max(axis=2) > 0).astype(np.float32)
    return passes


# --------------------------------------------------------------------------- comparisons

def relative_l1(ours: np.ndarray, reference: np.ndarray, mask: np.ndarray) -> float:
    """Σ|ours − reference| / Σ|reference| over the (H, W) ``mask`` pixels, all channels."""
    mask = np.asarray(mask, dtype=bool)
    a = np.asarray(ours, dtype=np.float64)[mask]
    b = np.asarray(reference, dtype=np.float64)[mask]
    total = np.abs(b).sum()
    error = np.abs(a - b).sum()
    if total > 0:
        return float(error / total)
    return 0.0 if error == 0 else float("inf")


def coverage_agreement(ours: np.ndarray, passes: dict[str, np.ndarray]) -> float:
    """Share of pixels where the (H, W) bool coverage ``ours`` equals Cycles' (``Alpha`` > ½)."""
    return float((np.asarray(ours, dtype=bool) == (passes["Alpha"] > 0.5)).mean())
