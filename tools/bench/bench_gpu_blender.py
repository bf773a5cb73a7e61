"""GPU tracer benchmark rows, run with the bpy venv:
``.venv/bin/python tools/bench/bench_gpu_blender.py [--quick]``.

Filtered octree samples per second (the GLSL sampler vs ``VoxelOctree.sample_directional``),
GI preview time with the GPU tracer at 160×120, 320×240 and 640×480 (and the numpy tracer at
160×120) for the demo scene, beside Cycles' time and Diffuse Indirect error at 64 and 256 spp
against a high-spp Cycles reference of the same view. Prints a markdown table of medians.
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_blender import demo_snapshot, load_addon, median_seconds, print_table  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import gi_compare
    import numpy as np

    from voxgi.blender.settings import cone_settings, gi_settings
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_preview import render_passes_gpu
    from voxgi.render.gpu_tracer import dispatch, read_texture
    from voxgi.render.gpu_volume import GPUVolume, float_texture
    from voxgi.voxgi_addon.gi.morton import morton_decode
    from voxgi.voxgi_addon.gi.update import update_gi
    from voxgi.voxgi_addon.preview.passes import render_passes
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    scene, snapshot = demo_snapshot()
    ready, why = ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    caches = build_scene_caches(snapshot, scene.voxgi.base_span, scene.voxgi.cascade_count)
    state = update_gi(snapshot, caches, gi_settings(scene.voxgi))
    cones = cone_settings(scene.voxgi)
    octree = state.octree
    repeats = 3 if args.quick else 5
    rows = []

    # Filtered samples: one anisotropic octree sample at a fractional level (2 levels × 3 faces).
    side = 512
    n = side * side
    rng = np.random.default_rng(0)
    keys = octree.levels[-1].keys
    leaves = morton_decode(keys[rng.integers(0, len(keys), n)])
    points = octree.root_origin + (leaves + rng.uniform(-4, 5, (n, 3))) * octree.node_size(octree.depth)
    level = rng.uniform(0, octree.depth, n)
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    volume = GPUVolume()
    t0 = time.perf_counter()
    volume.update(octree, cones)
    upload = time.perf_counter() - t0
    inputs = {"gbuffer_position": float_texture(np.c_[points, level].reshape(side, side, 4), (side, side)),
              "gbuffer_normal": float_texture(np.c_[dirs, np.ones(n)].reshape(side, side, 4), (side, side)),
              "gbuffer_view": float_texture(np.zeros((side, side, 4)), (side, side))}
    read_texture(dispatch("probe", volume, inputs, side, side))  # compile
    gpu_s = median_seconds(lambda: read_texture(dispatch("probe", volume, inputs, side, side)), repeats)
    m = n // 8
    numpy_s = median_seconds(lambda: octree.sample_directional(points[:m], level[:m], dirs[:m]), repeats) * 8
    rows.append(("filtered octree samples/s, GPU (GLSL, llvmpipe)", gpu_s,
                 f"{n / gpu_s / 1e6:.1f} M/s = {numpy_s / gpu_s:.0f}× numpy ({n / numpy_s / 1e6:.2f} M/s)"))
    rows.append(("atlas upload (demo scene, 3×64³)", upload, f"{volume.uploaded_bytes / 2**20:.1f} MB RGBA16F"))

    sizes = [(160, 120), (320, 240), (640, 480)]
    results = {}
    for w, h in sizes:
        render_passes_gpu(snapshot, state, w, h, cones, volume=volume)  # warm: shaders, upload
        timings = []

        def once():
            passes, t = render_passes_gpu(snapshot, state, w, h, cones, volume=volume)
            results[(w, h)] = passes
            timings.append(t)

        seconds = median_seconds(once, 1 if (args.quick and w > 160) else repeats)
        stages = timings[len(timings) // 2]
        rows.append((f"GPU preview {w}×{h} (after the update)", seconds,
                     f"direct (GPU shadow rays) {stages['direct'] * 1000:.0f} ms, cones "
                     f"{(stages['diffuse+ao cones (GPU)'] + stages['glossy cones (GPU)']) * 1000:.0f} ms, "
                     f"visibility {stages['visibility (GPU)'] * 1000:.0f} ms"))
    for stride, label in ((1, "full"), (4, "quarter")):
        for w, h in sizes:
            stages = {}

            def fast_once():
                passes, t = render_passes_gpu(snapshot, state, w, h, cones, volume=volume,
                                              shadows="CONES", gi_stride=stride)
                stages.update(t)
                results[(w, h, stride)] = passes

            fast_once()
            seconds = median_seconds(fast_once, 1 if (args.quick and w > 160) else repeats)
            rows.append((f"GPU preview {w}×{h}, soft-shadow cones, GI resolution {label}", seconds,
                         f"direct {stages['direct'] * 1000:.0f} ms, cones "
                         f"{(stages['diffuse+ao cones (GPU)'] + stages['glossy cones (GPU)']) * 1000:.0f} ms"))
    numpy_preview = median_seconds(lambda: render_passes(snapshot, state, 160, 120, cones), 1 if args.quick else 3)
    rows.append(("numpy preview 160×120 (after the update)", numpy_preview,
                 f"GPU is {numpy_preview / rows[2][1]:.1f}× faster"))

    w, h = sizes[0]
    ref_spp = 512 if args.quick else 2048
    reference, ref_seconds = gi_compare.render_cycles(scene, w, h, ref_spp, scene.voxgi.ao_distance)
    ours = results[(w, h)]
    mask = (ours["Diffuse Color"].sum(-1) > 0) & (reference["Diffuse Color"].sum(-1) > 0)
    for key, label in (((w, h), "exact shadow rays, full"), ((w, h, 1), "shadow cones, full"),
                       ((w, h, 4), "shadow cones, quarter")):
        err = gi_compare.relative_l1(results[key]["Diffuse Indirect"],
                                     reference["Diffuse Indirect"], mask)
        direct = gi_compare.relative_l1(results[key]["Diffuse Direct"],
                                        reference["Diffuse Direct"], mask)
        rows.append((f"GPU preview {w}×{h} ({label}): errors", 0.0,
                     f"Diffuse Indirect {err:.3f}, Diffuse Direct {direct:.3f}"))
    for spp in (64, 256):
        passes, seconds = gi_compare.render_cycles(scene, w, h, spp, scene.voxgi.ao_distance)
        e = gi_compare.relative_l1(passes["Diffuse Indirect"], reference["Diffuse Indirect"], mask)
        rows.append((f"Cycles {spp} spp {w}×{h}, one diffuse bounce", seconds, f"error {e:.3f}"))
    print_table(f"### GPU tracer: demo scene ({len(snapshot.objects)} objects), "
                f"3×{octree.resolution}³, {cones.diffuse_cones} cones of {cones.cone_angle:g}°; "
                f"errors: relative L1 over geometry pixels vs Cycles {ref_spp} spp "
                f"({ref_seconds:.1f} s); medians of {repeats}", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
