"""GI preview vs Cycles for the demo and the benchmark (run inside Blender / the bpy module).

``preview_and_cycles`` renders the scene camera with ``voxgi.render_preview`` (EXR) and with
Cycles (at the light paths the preview predicts, ``reference_bounces``, and the scene's pixel
filter), writes PNG strips (Combined, Diffuse Indirect, Ambient Occlusion) of both, and returns
the per-pass relative L1 errors over geometry pixels.
"""
from __future__ import annotations

import pathlib
import time

import numpy as np

STRIP_PASSES = ("Combined", "Diffuse Indirect", "Ambient Occlusion")
ERROR_PASSES = ("Diffuse Direct", "Diffuse Indirect", "Ambient Occlusion", "Combined")


def read_passes(path) -> dict[str, np.ndarray]:
    """A multilayer EXR's ``<Pass>.R/G/B`` channels as (H, W, 3) arrays."""
    from voxgi.voxgi_addon.files.exr import read_exr

    channels = read_exr(path)
    names = sorted({name.rsplit(".", 1)[0] for name in channels})
    return {n: np.stack([channels[f"{n}.{c}"] for c in "RGB"], axis=-1) for n in names}


def relative_l1(ours, reference, mask) -> float:
    total = np.abs(reference[mask]).sum()
    return float(np.abs(ours[mask] - reference[mask]).sum() / max(total, 1e-12))


def pass_errors(ours, cycles) -> dict[str, float]:
    """Relative L1 per pass over pixels where both renders see geometry."""
    mask = (ours["Diffuse Color"].sum(-1) > 0) & (cycles["Diffuse Color"].sum(-1) > 0)
    return {name: relative_l1(ours[name], cycles[name], mask) for name in ERROR_PASSES}


def write_strip(path, passes) -> None:
    from voxgi.voxgi_addon.files.png import image_strip, to_srgb8, write_png

    write_png(path, image_strip([to_srgb8(passes[name]) for name in STRIP_PASSES], scale=2))


def render_preview(scene, path, width, height) -> tuple[dict, float]:
    import bpy

    start = time.perf_counter()
    result = bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=width, resolution_y=height)
    if result != {"FINISHED"}:
        raise RuntimeError("the GI preview failed")
    return read_passes(path), time.perf_counter() - start


def reference_bounces(scene) -> tuple[int, int]:
    """(diffuse, glossy) bounces of the Cycles render a preview of ``scene`` predicts: the
    preview's Bounces (``settings.diffuse_bounces``: Cycles' Light Paths when it follows them,
    else its Manual count); one glossy bounce for a one-bounce preview, else the scene's."""
    from voxgi.blender.settings import diffuse_bounces

    diffuse = diffuse_bounces(scene.voxgi)
    if diffuse <= 1:
        return 1, 1
    return diffuse, int(getattr(scene.cycles, "glossy_bounces", 4))


def render_cycles(scene, width, height, samples, ao_distance) -> tuple[dict, float]:
    """Cycles' passes at the light paths the preview predicts (``reference_bounces``) and the
    scene's pixel filter (Cycles' default 1.5 px), as the preview renders them."""
    from cycles_passes import render_cycles_passes  # tools/ is the script's folder

    diffuse, glossy = reference_bounces(scene)
    start = time.perf_counter()
    passes = render_cycles_passes(scene, width, height, samples, diffuse_bounces=diffuse,
                                  glossy_bounces=glossy, ao_distance=ao_distance)
    return passes, time.perf_counter() - start


def preview_and_cycles(scene, out_dir, width=160, height=120, samples=256):
    """Render both, write ``preview.exr`` and the two strips into ``out_dir``; return a dict
    with the errors and times."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ours, ours_seconds = render_preview(scene, out / "preview.exr", width, height)
    cycles, cycles_seconds = render_cycles(scene, width, height, samples, scene.voxgi.ao_distance)
    write_strip(out / "preview_strip.png", ours)
    write_strip(out / "cycles_strip.png", cycles)
    return {"errors": pass_errors(ours, cycles), "preview_seconds": ours_seconds,
            "cycles_seconds": cycles_seconds, "samples": samples, "size": (width, height)}
