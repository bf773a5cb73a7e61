"""GI benchmark on the four issue scenes (tests/blender/gi_scenes.py), run with the bpy venv:
``.venv/bin/python tools/bench/bench_scenes_blender.py [--quick]``.

Per scene at 160×120: the default preview (GPU, Accurate), a draft of it and the Fast (cone)
preview (``VARIANTS``) — median time and relative L1 of each pass against the stored Cycles
2048-spp one-bounce reference (tests/data/gi_refs) — beside Cycles at 16/64/256 spp rendered
in the same run, with their times and errors against the same reference. Then the default 640×480 preview of the demo
scene. Prints markdown tables.
"""
from __future__ import annotations

import argparse
import pathlib
import statistics
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(ROOT / "tools"), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon  # noqa: E402

PASSES = ("Diffuse Direct", "Diffuse Indirect", "Ambient Occlusion", "Glossy Indirect", "Combined")
# Preview variants: label → settings over the defaults. "Draft" spends a quarter of everything:
# GI Resolution Half, a quarter of the GI rays and of the light samples.
VARIANTS = {
    "VoxGI Accurate (GPU, defaults)": {},
    "VoxGI Accurate draft (GPU: Half, 16 rays, 4 light samples)":
        {"gi_resolution": "2", "gi_rays": 16, "light_samples": 4},
    "VoxGI Fast (GPU, cones)": {"quality": "FAST"},
}


def relative_l1(ours, reference, mask):
    import numpy as np

    return float(np.abs(ours[mask] - reference[mask]).sum() / np.abs(reference[mask]).sum())


def timed(fn, repeats):
    times, value = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), value


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy
    import gi_scenes
    import numpy as np
    from cycles_passes import render_cycles_passes

    from voxgi.blender.demo_scene import build_demo_scene
    from voxgi.render.pipeline import render_scene_passes

    repeats = 1 if args.quick else 3
    spps = (16, 64) if args.quick else (16, 64, 256)
    names = ["cornell_far"] if args.quick else sorted(gi_scenes.SCENES)
    print("### GI scenes at 160×120 vs Cycles 2048 spp, one bounce (relative L1)\n")
    print("| scene | renderer | median time | Direct | Indirect | AO | Glossy Ind. | Combined |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for name in names:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        gi_scenes.build(name, scene)
        # the references have one bounce of either kind: the preview at Bounces 1 too
        scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 1
        with np.load(ROOT / "tests" / "data" / "gi_refs" / f"{name}.npz") as data:
            reference = {k: data[k].astype(np.float64) for k in data.files}
        mask = reference["Alpha"] > 0.5
        w, h = gi_scenes.WIDTH, gi_scenes.HEIGHT
        rows = []
        defaults = {k: getattr(scene.voxgi, k) for k in ("quality", "gi_resolution", "gi_rays",
                                                          "light_samples")}
        for label, variant in VARIANTS.items():
            for key, value in {**defaults, **variant}.items():
                setattr(scene.voxgi, key, value)
            render_scene_passes(bpy.context, scene, None, w, h)  # warm: caches, shaders, BVH
            seconds, (passes, _) = timed(
                lambda: render_scene_passes(bpy.context, scene, None, w, h), repeats)
            rows.append((label, seconds, passes))
        for key, value in defaults.items():
            setattr(scene.voxgi, key, value)
        for spp in spps:
            seconds, passes = timed(lambda: render_cycles_passes(
                scene, w, h, spp, diffuse_bounces=1, ao_distance=1.0, glossy_bounces=1,
                filter_width=0.01), 1)
            rows.append((f"Cycles {spp} spp", seconds, passes))
        for label, seconds, passes in rows:
            errors = [relative_l1(np.asarray(passes[p], np.float64), reference[p], mask)
                      for p in PASSES]
            print(f"| {name} | {label} | {seconds * 1000:.0f} ms | "
                  + " | ".join(f"{e:.3f}" for e in errors) + " |", flush=True)

    print("\n### Default preview of the demo scene (GPU, Accurate)\n")
    print("| size | median time | stages (last run) |\n|---|---:|---|")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build_demo_scene(scene)
    from voxgi.blender.session import scene_session

    for w, h in ((160, 120), (640, 480)):
        render_scene_passes(bpy.context, scene, None, w, h)
        seconds, _ = timed(lambda: render_scene_passes(bpy.context, scene, None, w, h), repeats)
        timings = scene_session(scene.name_full).gi_timings
        stages = ", ".join(f"{k} {v * 1000:.0f}" for k, v in timings.items() if v > 0.005)
        print(f"| {w}×{h} | {seconds * 1000:.0f} ms | {stages} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
