"""Light-probe benchmark rows, run with the bpy venv: ``.venv/bin/python
tools/bench/bench_probes_blender.py [--quick]`` (docs/probes.md).

On the demo scene: the exact bake (numpy: rays against the triangles, direct light with shadow
rays at every hit) and the GPU bake (cones through the voxel octree) for k = 8, 16, 32 — time,
probes, Bowald's runtime memory and the bake's peak traced memory; query time per million
points; EEVEE's volume-probe bake of the same box with (k+1)³ probes as the peer; and the baked
irradiance against Cycles equirectangular renders at a few probes.
"""
from __future__ import annotations

import argparse
import math
import pathlib
import sys
import time
import tracemalloc

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # tools/: cycles_passes
from bench_blender import demo_snapshot, load_addon, print_table  # noqa: E402

KIB = 1024


def _bake(snapshot, k, directions=256, sh_fn=None, trace_memory=True):
    """(result, seconds, peak traced bytes or None). The time comes from an untraced run
    (tracemalloc slows numpy-heavy code about 3×); the peak from a second, traced one."""
    from voxgi.voxgi_addon.probes.bake import ProbeSettings, bake_probe_grid

    settings = ProbeSettings(resolution=k, directions=directions)
    t0 = time.perf_counter()
    result = bake_probe_grid(snapshot, settings, sh_fn=sh_fn)
    seconds = time.perf_counter() - t0
    peak = None
    if trace_memory:
        tracemalloc.start()
        bake_probe_grid(snapshot, settings, sh_fn=sh_fn)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return result, seconds, peak


def _note(result, peak):
    from voxgi.voxgi_addon.probes.grid import memory_report

    g, mem = result.grid, memory_report(result.grid)
    stages = ", ".join(f"{k} {v:.2f} s" for k, v in result.timings.items())
    return (f"{len(g.positions)} probes ({result.relocated} relocated, {result.disabled} disabled), "
            f"{len(g.volume_cells)} volumes; runtime arrays {mem['total'] / KIB:.0f} KiB (masks "
            f"{mem['occlusion_masks'] / KIB:.0f} KiB); "
            f"{'' if peak is None else f'peak traced {peak / 2**20:.0f} MiB; '}{stages}")


def _eevee_bake(scene, lo, hi, resolution, samples):
    import bpy

    scene.render.engine = "BLENDER_EEVEE"
    probe = bpy.data.objects.new("Bench Volume", bpy.data.lightprobes.new("Bench Volume", "VOLUME"))
    scene.collection.objects.link(probe)
    probe.location = tuple((lo + hi) / 2)
    probe.scale = tuple((hi - lo) / 2)
    probe.data.resolution_x = probe.data.resolution_y = probe.data.resolution_z = resolution
    probe.data.bake_samples = samples
    bpy.context.view_layer.objects.active = probe
    t0 = time.perf_counter()
    bpy.ops.object.lightprobe_cache_bake(subset="ALL")
    seconds = time.perf_counter() - t0
    bpy.data.objects.remove(probe)
    return seconds


def _cycles_error(scene, k, count):
    """Worst relative error of the 6 axis irradiances of ``count`` interior probes of a k-grid
    against Cycles equirectangular renders (one bounce), as in tests/blender/test_probe_authoring.py.
    The world is made black for it: Cycles' Diffuse Direct holds the world's light, the bake's
    direct light does not (it sees the world colour only where its rays leave the scene)."""
    import bpy
    import cycles_passes

    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.probes import sh

    background = next(n for n in scene.world.node_tree.nodes if n.type == "BACKGROUND")
    strength = background.inputs["Strength"].default_value
    background.inputs["Strength"].default_value = 0.0
    snapshot = take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())
    grid = _bake(snapshot, k, trace_memory=False)[0].grid
    p = np.asarray(grid.positions, np.float64)
    inside = (np.abs(p[:, 0]) < 0.8) & (np.abs(p[:, 1]) < 0.8) & (p[:, 2] > 0.3) & (p[:, 2] < 1.7)
    candidates = np.flatnonzero(inside & (grid.flags == 0) & (grid.validity == 0))
    chosen = candidates[np.linspace(0, len(candidates) - 1, count).astype(int)]
    data = bpy.data.cameras.new("Bench Pano")
    data.type, data.panorama_type, data.clip_start = "PANO", "EQUIRECTANGULAR", 1e-4
    camera = bpy.data.objects.new("Bench Pano", data)
    scene.collection.objects.link(camera)
    old_camera, scene.camera = scene.camera, camera
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    worst, mean = 0.0, []
    for index in chosen:
        camera.location = tuple(p[index])
        passes = cycles_passes.render_cycles_passes(scene, 128, 64, 256, diffuse_bounces=0,
                                                    filter_width=0.01,
                                                    extra_passes={"Position": "use_pass_position"})
        h, w = passes["Diffuse Color"].shape[:2]
        radiance = (passes["Diffuse Color"] * passes["Diffuse Direct"] +  # what the seen
                    passes["Glossy Color"] * passes["Glossy Direct"]).reshape(-1, 3)  # surface sends
        offset = passes["Position"].reshape(-1, 3) - p[index]
        length = np.linalg.norm(offset, axis=1, keepdims=True)
        seen = (length[:, 0] > 1e-6) & (passes["Alpha"].reshape(-1) > 0.5)
        dirs = np.where(seen[:, None], offset / np.maximum(length, 1e-9), 0.0)
        edges = math.pi / 2 - np.arange(h + 1) * math.pi / h
        solid = np.repeat((np.sin(edges[:-1]) - np.sin(edges[1:])) * (2 * math.pi / w), w)
        cycles = np.maximum(axes @ dirs.T, 0.0) @ (radiance * (solid * seen)[:, None])
        ours = sh.irradiance(np.asarray(grid.sh[index], np.float64), axes)
        error = np.abs(ours - cycles).max(axis=1) / np.maximum(cycles.max(axis=1), 0.1 * cycles.max())
        print(f"probes bench: Cycles probe {index} at {np.round(p[index], 2)}: relative error "
              f"{np.round(error, 3)}", file=sys.stderr, flush=True)
        worst = max(worst, float(error.max()))
        mean.append(float(np.abs(ours - cycles).sum() / np.abs(cycles).sum()))
    scene.camera = old_camera
    background.inputs["Strength"].default_value = strength
    return worst, float(np.mean(mean)), len(chosen)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy

    from voxgi.blender.settings import cone_settings, gi_settings
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_probes import gpu_probe_sh
    from voxgi.render.gpu_volume import GPUVolume
    from voxgi.voxgi_addon.gi.update import update_gi
    from voxgi.voxgi_addon.probes.placement import scene_box
    from voxgi.voxgi_addon.probes.query import query_irradiance
    from voxgi.voxgi_addon.scene.geometry import world_triangles
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    scene, snapshot = demo_snapshot()
    ks = (8, 16) if args.quick else (8, 16, 32)
    grids = {}

    class Rows(list):
        def append(self, row):  # progress on stderr while the section runs
            print(f"probes bench: {row[0]}: {row[1]:.2f} s; {row[2]}", file=sys.stderr, flush=True)
            super().append(row)

    rows = Rows()
    for k in ks:
        result, seconds, peak = _bake(snapshot, k, trace_memory=k <= 16)
        grids[k] = result.grid
        rows.append((f"exact bake (numpy), k = {k}, 256 rays/probe", seconds, _note(result, peak)))

    ready, why = ensure_gpu_context()
    if ready:
        t0 = time.perf_counter()
        caches = build_scene_caches(snapshot, scene.voxgi.base_span, scene.voxgi.cascade_count)
        state = update_gi(snapshot, caches, gi_settings(scene.voxgi))
        update = time.perf_counter() - t0
        cones = cone_settings(scene.voxgi)
        volume = GPUVolume()
        volume.update(state.octree, cones)
        rows.append(("voxelize + GI update (the GPU bake's octree, once)", update, ""))
        for k in ks:
            def sh_fn(positions, dirs):
                return gpu_probe_sh(volume, positions, dirs, np.zeros(3), cones)
            result, seconds, peak = _bake(snapshot, k, sh_fn=sh_fn, trace_memory=False)
            rows.append((f"GPU bake (octree cones, llvmpipe), k = {k}", seconds, _note(result, peak)))
    else:
        rows.append(("GPU bake", 0, f"skipped: {why}"))

    grid = grids[16]
    rng = np.random.default_rng(0)
    lo, hi = grid.origin, grid.origin + grid.dims * grid.volume_size
    points = rng.uniform(lo, hi, (1_000_000, 3))
    normals = rng.normal(size=(1_000_000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    t0 = time.perf_counter()
    query_irradiance(grid, points, normals)
    rows.append(("query, 1 M random points and normals, k = 16 (numpy, 2 cores)",
                 time.perf_counter() - t0, "O(1) per point through the index arrays"))

    worst, mean, count = _cycles_error(scene, 16, 3 if args.quick else 5)
    rows.append((f"k = 16 probe irradiance vs Cycles panoramas ({count} probes, 6 normals each)", 0,
                 f"worst {worst:.3f}, mean relative L1 {mean:.3f}"))

    tris = world_triangles(snapshot)
    box_lo, box_hi = scene_box(tris.positions)
    samples = 64 if args.quick else 256
    for k in ((8,) if args.quick else (16,)):
        try:
            seconds = _eevee_bake(scene, box_lo, box_hi, k + 1, samples)
            ours = next(r[1] for r in rows if r[0].startswith(f"exact bake (numpy), k = {k},"))
            rows.append((f"EEVEE volume-probe bake, same box, {k + 1}³ probes, {samples} samples",
                         seconds, f"VoxGI exact bake k = {k} is {seconds / ours:.1f}× faster"))
        except Exception as error:  # noqa: BLE001 - report, do not lose the other rows
            rows.append(("EEVEE volume-probe bake", 0, f"failed: {error}"))
    print_table("### Light probes: demo scene, 256 rays per probe, masks on, one shadow ray per hit; single runs", rows)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
