"""Light-scene benchmark rows (issue 17), run with the bpy venv:
``.venv/bin/python tools/bench/bench_lights_blender.py [--quick]``.

Per scene of ``tests/blender/light_scenes.py`` (HDRI courtyard, sky + sun, emissive room, metal
room; 160 × 120): the default preview's time (GPU, Accurate) and its Combined error against the
stored Cycles 2048 spp reference (``tests/data/light_refs``, default pixel filter, one bounce
of either kind), beside Cycles 16 and 64 spp with and without OpenImageDenoise rendered the
same way in the same run. Prints a markdown table.
"""
from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests" / "blender"))
sys.path.insert(0, str(ROOT / "tools"))
from bench_blender import load_addon  # noqa: E402


def relative_l1(ours, reference, mask):
    a, b = np.asarray(ours, np.float64)[mask], np.asarray(reference, np.float64)[mask]
    return float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-30))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy
    import light_scenes
    from cycles_passes import last_render_seconds, render_cycles_passes

    from voxgi.render.pipeline import render_scene_passes

    w, h = light_scenes.WIDTH, light_scenes.HEIGHT
    repeats = 1 if args.quick else 3
    print("### Light scenes (issue 17): default preview vs Cycles, 160×120; Combined relative L1 "
          "against Cycles 2048 spp (default pixel filter, one bounce of either kind)\n")
    print("| scene | VoxGI | Cycles 16 spp | Cycles 16 spp + OIDN | Cycles 64 spp | "
          "Cycles 64 spp + OIDN |\n|---|---|---|---|---|---|")
    for name in light_scenes.SCENES:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        light_scenes.build(name, scene)
        scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 1  # one-bounce references
        with np.load(ROOT / "tests" / "data" / "light_refs" / f"{name}.npz") as data:
            reference = data["Combined"].astype(np.float64)
            mask = data["Alpha"].astype(np.float64) > 0.5
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            ours, _ = render_scene_passes(bpy.context, scene, None, w, h)
            times.append(time.perf_counter() - t0)
        cells = [f"{statistics.median(times):.2f} s, {relative_l1(ours['Combined'], reference, mask):.3f}"]
        for samples, denoise in ((16, False), (16, True), (64, False), (64, True)):
            passes = render_cycles_passes(scene, w, h, samples, ao_distance=1.0, seed=1,
                                          denoise=denoise)
            cells.append(f"{last_render_seconds():.2f} s, "
                         f"{relative_l1(passes['Combined'], reference, mask):.3f}")
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
