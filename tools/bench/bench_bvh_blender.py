"""Exact-ray (BVH) benchmark rows, run with the bpy venv: ``.venv/bin/python tools/bench/bench_bvh_blender.py``.

BVH build time (demo scene and a 100k-triangle soup), rays per second of the GPU any-hit and
closest-hit traversal on the demo scene (random rays from inside the box; llvmpipe without a
GPU), Diffuse Direct with shadow rays at 640×480 on the GPU against the numpy reference (time
and relative L1), the AO + one-bounce indirect kernel, and the whole GPU preview at 640×480.
Prints a markdown table of medians (not a test).
"""
from __future__ import annotations

import argparse
import pathlib
import sys
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_blender import demo_snapshot, load_addon, median_seconds, print_table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cycles", type=int, default=0, metavar="SPP",
                    help="also compare the exact AO + one-bounce estimate at 160×120 with Cycles "
                         "(one diffuse bounce, SPP samples)")
    args = ap.parse_args(argv)
    load_addon()
    import numpy as np

    from voxgi.blender.settings import cone_settings, gi_settings
    from voxgi.render.gbuffer import rasterize, read_gbuffer
    from voxgi.render.gpu_bvh import (
        GPUBVH,
        direct_light_texture,
        trace_rays,
    )
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_gather import gather
    from voxgi.render.gpu_preview import render_passes_gpu
    from voxgi.render.gpu_tracer import read_texture
    from voxgi.voxgi_addon.gi.update import update_gi
    from voxgi.voxgi_addon.preview.gather import GatherSettings
    from voxgi.voxgi_addon.preview.passes import direct_light, material_table, principled_table
    from voxgi.voxgi_addon.scene.bvh import build_bvh
    from voxgi.voxgi_addon.scene.geometry import SceneTriangles, world_triangles
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    scene, snapshot = demo_snapshot()
    ready, why = ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    repeats = 3 if args.quick else 5
    rows = []
    tris = world_triangles(snapshot)
    build = median_seconds(lambda: build_bvh(tris), repeats)
    bvh = build_bvh(tris)
    rows.append((f"BVH build, demo scene ({len(tris):,} triangles)", build,
                 f"{len(bvh):,} nodes, depth {bvh.depth}"))
    rng = np.random.default_rng(0)
    count = 100_000
    soup = rng.uniform(-5, 5, (count, 1, 3)) + rng.normal(scale=0.05, size=(count, 3, 3))
    big = SceneTriangles(soup, np.zeros((count, 3)), np.zeros(count, np.int32), np.zeros(count, np.int32))
    big_bvh = build_bvh(big)
    t0 = time.process_time()
    build_bvh(big)
    cpu = time.process_time() - t0
    rows.append(("BVH build, 100k-triangle soup", median_seconds(lambda: build_bvh(big), 1 if args.quick else 3),
                 f"{len(big_bvh):,} nodes, depth {big_bvh.depth}; {cpu * 1000:.0f} ms CPU"))

    gpu_bvh = GPUBVH()
    t0 = time.perf_counter()
    gpu_bvh.update(tris)
    rows.append(("BVH build + upload (GPUBVH.update)", time.perf_counter() - t0,
                 f"{gpu_bvh.uploaded_bytes / 2**20:.2f} MB RGBA32F"))
    n = 512 * 512
    lo, hi = tris.bounds
    o = rng.uniform(lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo), (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    trace_rays(gpu_bvh, o[:64], d[:64])  # compile
    for label, any_hit, t_max in (("any hit (shadow rays, max 2 m)", True, 2.0),
                                  ("closest hit (unbounded)", False, np.inf)):
        seconds = median_seconds(lambda t_max=t_max, any_hit=any_hit: trace_rays(
            gpu_bvh, o, d, 0.0, t_max, any_hit=any_hit), repeats)
        rows.append((f"GPU {label}, {n:,} random rays", seconds,
                     f"{n / seconds / 1e6:.2f} M rays/s (upload + dispatch + read back)"))

    w, h = 640, 480
    _, rough, _, emission = material_table(snapshot)
    principled = principled_table(snapshot)
    gbuffer = rasterize(tris, snapshot.camera, rough, w, h)
    seen = read_gbuffer(gbuffer)
    hit = seen["hit"]
    samples = scene.voxgi.light_samples
    read_texture(direct_light_texture(gpu_bvh, gbuffer.inputs, snapshot.lights, samples))
    images = []

    def gpu_direct():
        images.append(read_texture(direct_light_texture(gpu_bvh, gbuffer.inputs, snapshot.lights,
                                                        samples)))

    seconds = median_seconds(gpu_direct, repeats)
    gpu = np.flipud(images[-1])[..., :3][hit]
    p, nrm = seen["position"][hit].astype(np.float64), seen["normal"][hit].astype(np.float64)
    ids = np.flatnonzero(hit.ravel())
    t0 = time.perf_counter()
    ref = direct_light(None, p, nrm, snapshot.lights, tris, None, samples, "RAYS", sample_ids=ids)
    numpy_seconds = time.perf_counter() - t0
    error = float(np.abs(gpu - ref).sum() / np.abs(ref).sum())
    hard = [(light.type == "POINT" and light.radius == 0) or (light.type == "SUN" and light.angle == 0)
            for light in snapshot.lights]
    rays_cast = len(ids) * sum(1 if is_hard else samples for is_hard in hard)
    rows.append((f"Diffuse Direct {w}×{h}, GPU shadow rays ({samples} per light with an extent)", seconds,
                 (f"numpy {numpy_seconds:.2f} s ({numpy_seconds / seconds:.0f}×); relative L1 vs numpy "
                 f"{error:.5f}; ≤ {rays_cast / seconds / 1e6:.1f} M shadow rays/s")))
    for rays in (4, 16):
        settings = GatherSettings(rays=rays, ao_distance=scene.voxgi.ao_distance)
        seconds = median_seconds(lambda settings=settings: read_texture(gather(
            gpu_bvh, gbuffer.inputs, snapshot.lights, principled, emission, settings, 1, w,
            h)[0]), 1 if args.quick else 3)
        rows.append((f"AO + one-bounce indirect {w}×{h}, {rays} rays/pixel (GPU)", seconds,
                     f"{len(ids) * rays / seconds / 1e6:.2f} M paths/s (closest hit + shadow ray(s) per light)"))

    caches = build_scene_caches(snapshot, scene.voxgi.base_span, scene.voxgi.cascade_count)
    state = update_gi(snapshot, caches, gi_settings(scene.voxgi))
    cones = cone_settings(scene.voxgi)
    render_passes_gpu(snapshot, state, w, h, cones, samples)
    stages = {}

    def preview():
        stages.update(render_passes_gpu(snapshot, state, w, h, cones, samples)[1])

    seconds = median_seconds(preview, 1 if args.quick else 3)
    rows.append((f"GPU preview {w}×{h}, shadows RAYS (after the update)", seconds,
                 ", ".join(f"{k} {v * 1000:.0f} ms" for k, v in stages.items())))
    if args.cycles:
        import gi_compare

        cw, ch = 160, 120
        small = rasterize(tris, snapshot.camera, rough, cw, ch)
        cycles, cycles_seconds = gi_compare.render_cycles(scene, cw, ch, args.cycles,
                                                          scene.voxgi.ao_distance)
        seen_small = read_gbuffer(small)
        mask = seen_small["hit"] & (cycles["Diffuse Color"].sum(-1) > 0)
        preview = render_passes_gpu(snapshot, state, cw, ch, cones, samples)[0]
        for name, cycles_name in (("Diffuse Direct", "Diffuse Direct"),
                                  ("Diffuse Indirect", "Diffuse Indirect"),
                                  ("Ambient Occlusion", "Ambient Occlusion")):
            error = gi_compare.relative_l1(preview[name], cycles[cycles_name], mask)
            rows.append((f"GPU preview {cw}×{ch} {name} vs Cycles {args.cycles} spp", 0.0,
                         f"relative L1 {error:.3f} (cones for indirect/AO)"))
        for rays in (16, 64):
            t0 = time.perf_counter()
            settings = GatherSettings(rays=rays, ao_distance=scene.voxgi.ao_distance)
            out = np.flipud(read_texture(gather(gpu_bvh, small.inputs, snapshot.lights,
                                                principled, emission, settings, 1, cw, ch)[0]))
            seconds = time.perf_counter() - t0
            indirect = gi_compare.relative_l1(out[..., :3], cycles["Diffuse Indirect"], mask)
            ao = gi_compare.relative_l1(np.repeat(out[..., 3:], 3, axis=-1),
                                        cycles["Ambient Occlusion"], mask)
            rows.append((f"exact AO + one bounce {cw}×{ch}, {rays} rays/pixel vs Cycles", seconds,
                         (f"Diffuse Indirect {indirect:.3f}, AO {ao:.3f} relative L1 "
                         f"(Cycles {cycles_seconds:.1f} s)")))
    print_table((f"### Exact rays on the GPU (llvmpipe): demo scene, {len(snapshot.lights)} light(s); "
                 f"medians of {repeats}"), rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
