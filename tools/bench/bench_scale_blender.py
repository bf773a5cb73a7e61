"""Scale benchmark rows (issue 18 point 3), run with the bpy venv:
``.venv/bin/python tools/bench/bench_scale_blender.py [--quick]``.

The city block of ``scale_scene.py`` (676 box buildings, each crowned by a linked duplicate of
one dome mesh: 1.06M triangles; ``--quick``: 64 buildings, 101k): the snapshot, the world-space
triangles, the BVH build (once per instanced mesh, ``bvh.build_scene_bvh``, beside the SAH
build over all triangles, ``build_bvh``) and its packing, the whole default (Accurate) preview
at 160×120 and 640×480 with its stages (BVH build + upload, gathers, sub-pixel passes), the
GPU bytes of the BVH (flattened, and what a two-level BVH of the same meshes would hold), the
voxelization (Fast quality's caches), and the process's peak memory after each step; beside
Cycles 16 spp + OpenImageDenoise (one bounce of either kind, as the preview) at both sizes in
the same run, and at 160×120 both against Cycles 256 spp. Prints markdown tables.
"""
from __future__ import annotations

import argparse
import pathlib
import resource
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))
from bench_blender import load_addon  # noqa: E402


def peak_mb() -> float:
    """The process's peak resident memory so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def timed(fn):
    t0 = time.perf_counter()
    value = fn()
    return value, time.perf_counter() - t0


def relative_l1(ours, reference, mask):
    return float(np.abs(ours[mask] - reference[mask]).sum() / max(np.abs(reference[mask]).sum(), 1e-12))


def combined_error(combined, reference) -> float:
    """Relative L1 of a Combined pass against the reference's, over its covered pixels."""
    return relative_l1(np.asarray(combined)[..., :3], reference["Combined"][..., :3],
                       reference["Alpha"] > 0.5)


def node_visits(bvh, origins, directions) -> float:
    """Mean BVH nodes a closest-hit ray visits (the threaded traversal of bvh_common.glsl,
    counted in numpy; the hit distance from ``bvh.traverse`` bounds it as the search does)."""
    from voxgi.voxgi_addon.scene.bvh import traverse

    o, d = np.asarray(origins, np.float64), np.asarray(directions, np.float64)
    best = traverse(bvh, visits_tris[0], o, d)[0]
    inv = 1.0 / np.where(np.abs(d) > 1e-30, d, 1e-30)
    node, count, live = np.zeros(len(o), np.int64), np.zeros(len(o), np.int64), np.arange(len(o))
    while len(live):
        k = node[live]
        count[live] += 1
        t0, t1 = (bvh.lo[k] - o[live]) * inv[live], (bvh.hi[k] - o[live]) * inv[live]
        enter = np.maximum(np.minimum(t0, t1).max(axis=1), 0.0)
        leave = np.minimum(np.maximum(t0, t1).min(axis=1), best[live])
        node[live] = np.where((enter <= leave) & (bvh.first[k] < 0), k + 1, bvh.miss[k])
        live = live[node[live] >= 0]
    return float(count.mean())


visits_tris = [None]


def two_level_bytes(tris, pack_bvh, build_bvh, instance_groups, soup) -> int:
    """Texture bytes of a two-level BVH of ``tris``: the one-off triangles' BVH, one BVH per
    instanced mesh, and a top level over the placements (nodes only; each placement would
    add a 3 × 4 matrix, 48 bytes)."""
    found = instance_groups(tris)
    positions = np.asarray(tris.positions)
    if found is None:
        return 0
    groups, rest = found
    total = 0
    if len(rest):
        part = soup(positions[rest])
        total += pack_bvh(build_bvh(part), part).nbytes
    for starts, size in groups:
        part = soup(positions[starts[0]:starts[0] + size])
        total += pack_bvh(build_bvh(part), part).nbytes + 48 * len(starts)
    placements = 1 + sum(len(s) for s, _ in groups)
    return total + 2 * 16 * 2 * placements  # top nodes: ~2 per placement, 2 texels each


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy
    import scale_scene
    from cycles_passes import last_render_seconds, render_cycles_passes

    from voxgi.blender.session import scene_session
    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.render.gpu_bvh import GPUBVH, trace_rays
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.gpu_scene import peek_scene
    from voxgi.render.gpu_volume import float_texture
    from voxgi.render.pipeline import render_scene_passes
    from voxgi.voxgi_addon.scene.bvh import (
        _soup,
        build_bvh,
        build_scene_bvh,
        instance_groups,
        pack_bvh,
    )
    from voxgi.voxgi_addon.scene.camera import camera_rays
    from voxgi.voxgi_addon.scene.geometry import world_triangles

    side = 8 if args.quick else 26
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    triangles = scale_scene.city_block(scene, side)
    # Cycles runs with one bounce of either kind below: the preview at Bounces 1 too
    scene.voxgi.bounce_source, scene.voxgi.bounces = "MANUAL", 1
    ready, why = ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    rows = []  # (what, seconds or None, peak MB, notes)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    snapshot, seconds = timed(lambda: take_snapshot(scene, depsgraph))
    shared = sum(1 for o in snapshot.objects if o.mesh == "Dome")
    rows.append(("snapshot", seconds, peak_mb(),
                 f"{len(snapshot.objects)} objects, {len(snapshot.meshes)} meshes read "
                 f"(the dome once for its {shared} users)"))
    tris, seconds = timed(lambda: world_triangles(snapshot))
    rows.append(("world-space triangles", seconds, peak_mb(), f"{len(tris):,} triangles"))
    visits_tris[0] = tris
    sample = np.random.default_rng(0).choice(512 * 384, 4000, replace=False)
    origins, directions = camera_rays(snapshot.camera, 512, 384)
    origins, directions = origins[sample], directions[sample]
    bvh, seconds = timed(lambda: build_scene_bvh(tris))
    rows.append(("BVH build, once per instanced mesh", seconds, peak_mb(),
                 f"{len(bvh):,} nodes, depth {bvh.depth}; "
                 f"{node_visits(bvh, origins, directions):.1f} nodes visited per camera ray"))
    sah, seconds = timed(lambda: build_bvh(tris))
    rows.append(("BVH build, SAH over all triangles", seconds, peak_mb(),
                 f"{len(sah):,} nodes, depth {sah.depth}; "
                 f"{node_visits(sah, origins, directions):.1f} nodes visited per camera ray "
                 "(what the preview built before)"))
    sah = None  # noqa: F841 - free it before packing
    packed, seconds = timed(lambda: pack_bvh(bvh, tris))
    flat = packed.nbytes
    rows.append(("BVH packing (textures)", seconds, peak_mb(),
                 f"flattened: {flat / 1e6:.0f} MB on the GPU; a two-level BVH of the same meshes: "
                 f"{two_level_bytes(tris, pack_bvh, build_bvh, instance_groups, _soup) / 1e6:.1f} MB"))
    textures, seconds = timed(lambda: [float_texture(t, (t.shape[1], t.shape[0]))
                                       for t in (packed.nodes, packed.triangles, packed.normals)])
    rows.append(("BVH upload (3 RGBA32F textures)", seconds, peak_mb(), f"{flat / 1e6:.0f} MB"))
    gpu_bvh = GPUBVH()
    gpu_bvh.nodes, gpu_bvh.triangles, gpu_bvh.normals = textures
    origins, directions = camera_rays(snapshot.camera, 512, 384)
    trace_rays(gpu_bvh, origins[:64], directions[:64])  # compile the kernel first
    (t, _, _, _), seconds = timed(lambda: trace_rays(gpu_bvh, origins, directions))
    rows.append(("GPU closest hits, 512×384 camera rays", seconds, peak_mb(),
                 f"{len(origins) / seconds / 1e6:.2f} M rays/s, {np.isfinite(t).mean():.0%} hit"))
    packed = bvh = tris = textures = gpu_bvh = None  # noqa: F841 - free them before the previews

    cycles_rows = []
    sizes = [(160, 120)] if args.quick else [(160, 120), (640, 480)]
    reference = None
    if not args.quick:
        reference = render_cycles_passes(scene, 160, 120, 256, diffuse_bounces=1,
                                          glossy_bounces=1, seed=0)
        cycles_rows.append(("Cycles 256 spp, 160×120 (reference)", last_render_seconds(), ""))
    for width, height in sizes:
        scene.voxgi.quality = "ACCURATE"
        (passes, lines), seconds = timed(
            lambda: render_scene_passes(bpy.context, scene, None, width, height))
        timings = scene_session(scene.name_full).gi_timings
        gpu = peek_scene()
        if gpu is None or scene_session(scene.name_full).tracer_used != "GPU":
            raise SystemExit(f"the preview did not run on the GPU: {lines}")
        stages = ", ".join(f"{k} {v:.1f} s" for k, v in timings.items()
                           if k != "total" and v >= 0.05)
        error = ""
        if reference is not None and width == 160:
            off = combined_error(passes["Combined"], reference)
            error = f"; Combined {off:.3f} off 256 spp"
        rows.append((f"preview (Accurate), {width}×{height}", seconds, peak_mb(),
                     f"{stages}; BVH build {gpu.bvh.build_seconds:.1f} s, "
                     f"{gpu.bvh.resident_bytes / 1e6:.0f} MB on the GPU{error}"))
        quick = render_cycles_passes(scene, width, height, 16, diffuse_bounces=1, glossy_bounces=1,
                                     seed=1, denoise=True)
        note = ""
        if reference is not None and width == 160:
            note = f"Combined {combined_error(quick['Combined'], reference):.3f} off 256 spp"
        cycles_rows.append((f"Cycles 16 spp + OIDN, {width}×{height}", last_render_seconds(), note))
    scene.voxgi.quality = "FAST"
    _, seconds = timed(lambda: bpy.ops.voxgi.voxelize())
    rows.append(("voxelize (Fast quality's caches)", seconds, peak_mb(), ""))

    print(f"### Scale: city block, {side * side} buildings + {side * side} dome instances, "
          f"{triangles:,} triangles\n")
    print("| step | time | peak memory | notes |\n|---|---:|---:|---|")
    for what, seconds, peak, note in rows:
        print(f"| {what} | {seconds:.2f} s | {peak:.0f} MB | {note} |")
    print("\n| Cycles (CPU, same run) | time | notes |\n|---|---:|---|")
    for what, seconds, note in cycles_rows:
        print(f"| {what} | {seconds:.2f} s | {note} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
