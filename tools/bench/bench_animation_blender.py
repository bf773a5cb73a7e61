"""Animation render benchmark rows, run with the bpy venv:
``.venv/bin/python tools/bench/bench_animation_blender.py``.

The walking skinned figure of the tests (``tests/blender/animation_scenes.py``, 12 frames) rendered
as a farm renders it, ``bpy.ops.render.render(animation=True)`` writing multilayer EXRs: the VoxGI
engine at its defaults beside Cycles 16 spp + OpenImageDenoise (default pixel filter, its default
light paths) on the same frames in the same run, each frame's time and the mean frame-to-frame
change of Combined in the regions that do not move (flicker). Prints a markdown table.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parents[1] / "tests" / "blender"))
from bench_blender import load_addon, print_table  # noqa: E402


def render_animation(scene, directory, engine):
    """Seconds per frame of an animation render with ``engine``; the frames' passes."""
    import bpy

    from voxgi.render.engine import enable_passes
    from voxgi.voxgi_addon.files.exr import read_exr_passes

    scene.render.engine = engine
    scene.render.image_settings.media_type = "MULTI_LAYER_IMAGE"
    scene.render.image_settings.file_format = "OPEN_EXR_MULTILAYER"
    enable_passes(scene.view_layers[0])
    scene.render.filepath = str(pathlib.Path(directory) / f"{engine}_####")
    t0 = time.perf_counter()
    bpy.ops.render.render(animation=True)
    seconds = (time.perf_counter() - t0) / (scene.frame_end - scene.frame_start + 1)
    files = sorted(pathlib.Path(directory).glob(f"{engine}_*.exr"))
    return seconds, [read_exr_passes(str(f)) for f in files]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy
    from animation_scenes import FRAMES, mean_change, walking_rig

    rows = []
    sizes = [(160, 120)] if args.quick else [(160, 120), (640, 480)]
    for width, height in sizes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        walking_rig(scene)
        scene.render.resolution_x, scene.render.resolution_y = width, height
        cycles = scene.cycles
        cycles.samples, cycles.use_adaptive_sampling = 16, False
        cycles.use_denoising, cycles.denoiser = True, "OPENIMAGEDENOISE"
        cycles.device = "CPU"
        with tempfile.TemporaryDirectory() as tmp:
            ours_seconds, ours = render_animation(scene, tmp, "VOXGI")
            cycles_seconds, theirs = render_animation(scene, tmp, "CYCLES")
        colour = np.stack([p["Diffuse Color"] for p in ours])
        moving = np.abs(np.diff(colour, axis=0)).sum(-1).max(axis=0) > 1e-3
        near = moving.copy()
        for axis in (0, 1):
            for shift in range(-3, 4):
                near |= np.roll(moving, shift, axis=axis)
        still = ~near & (colour[0].sum(-1) > 0)
        flicker = mean_change([p["Combined"] for p in ours], still)
        cycles_flicker = mean_change([p["Combined"] for p in theirs], still)
        rows.append((f"VoxGI F12 animation, {width}×{height}, per frame", ours_seconds,
                     f"{len(ours)} frames written; still-region flicker {flicker:.5f}; "
                     f"Cycles takes {cycles_seconds / ours_seconds:.2f}× this time"))
        rows.append((f"Cycles 16 spp + OIDN, {width}×{height}, per frame", cycles_seconds,
                     f"{len(theirs)} frames written; still-region flicker {cycles_flicker:.5f}"))
    print_table(f"### Animation render: the walking skinned figure, {FRAMES} frames "
                "(`render(animation=True)`, multilayer EXR); time per frame includes writing "
                "the file; flicker = mean |Combined(k+1) − Combined(k)| where nothing moves", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
