"""Imported-scene benchmark rows (issue 22, section "imported"), run with the bpy venv:
``.venv/bin/python tools/bench/bench_imported_blender.py [--quick]``.

The glTF round-trip scene of ``tests/blender/gltf_scenes.py`` (a textured metallic-roughness
room built in code, exported through Blender's own glTF exporter and imported back with default
settings, here in the run, as tests/blender/test_gltf_round_trip.py does): the round trip's
time, then through the operators in background mode (synchronous) ``voxgi.voxelize`` and
``voxgi.update`` (full: the previous state dropped before each run; and with nothing changed),
then the preview (GPU, Accurate, ``render_scene_passes`` as F12) at 160 × 120 with Bounces = 1
— the light paths of the stored Cycles reference (tests/data/gltf_refs, 8192 spp, one bounce of
either kind, Cycles' default pixel filter and transparent bounces) — and its Combined error
(relative L1 over the reference's covered pixels, as the test), beside Cycles 16 spp +
OpenImageDenoise and 64 spp at the same light paths, rendered in the same run. The preview at
the default Bounces (Follow Cycles) is timed too; no reference at Cycles' default light paths is
stored for this scene, so it has no error.

``--quick`` checks the tooling: 80 × 60, one timed run each, errors against the stored reference
averaged over 2 × 2 pixels (Cycles at 80 × 60 compared the same way).
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(ROOT / "tools"), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon, median_seconds  # noqa: E402
from bench_bounces_blender import downsample, relative_l1, timed_previews  # noqa: E402

REFS = ROOT / "tests" / "data" / "gltf_refs"
SCENE = "gltf_room"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy
    import gltf_scenes
    from cycles_passes import last_render_seconds, render_cycles_passes

    from voxgi.blender.session import scene_session
    from voxgi.blender.settings import diffuse_bounces

    factor = 2 if args.quick else 1
    width, height = gltf_scenes.WIDTH // factor, gltf_scenes.HEIGHT // factor
    repeats = 1 if args.quick else 3

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    t0 = time.perf_counter()
    gltf_scenes.build(SCENE, scene)
    round_trip = time.perf_counter() - t0
    meshes = [o for o in scene.objects if o.type == "MESH"]
    triangles = sum(len(p.vertices) - 2 for o in meshes for p in o.data.polygons)
    with np.load(REFS / f"{SCENE}.npz") as data:
        reference = downsample(data["Combined"].astype(np.float64), factor)
        mask = downsample(data["Alpha"].astype(np.float64), factor) > 0.5
    stored = json.loads((REFS / "cycles_spp.json").read_text())[SCENE]

    def error(passes):
        return relative_l1(passes["Combined"], reference, mask)

    session = scene_session(scene.name_full)
    rows = [("glTF export + import (Blender's own, default settings)", round_trip, "—",
             f"{len(meshes)} meshes, {triangles:,} triangles")]

    def voxelize():
        assert bpy.ops.voxgi.voxelize() == {"FINISHED"}

    seconds = median_seconds(voxelize, repeats)
    caches = " / ".join(f"{s.voxel_count:,}" for s in session.caches.cascade_stats)
    rows.append(("voxgi.voxelize", seconds, "—", f"cache voxels per cascade {caches}"))
    full = []
    for _ in range(repeats):
        session.gi_state = None  # nothing to reuse: the whole update
        t0 = time.perf_counter()
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        full.append(time.perf_counter() - t0)
    full_s = sorted(full)[len(full) // 2]
    counts = " / ".join(f"{c:,}" for c in session.gi_state.voxel_counts)
    rows.append(("voxgi.update (full: cascades, injection, octree)", full_s, "—",
                 f"cascade voxels {counts}"))

    def unchanged():
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        assert session.gi_state.reused == "all"

    seconds = median_seconds(unchanged, repeats)
    rows.append(("voxgi.update, nothing changed", seconds, "—", f"{seconds / full_s:.1%} of a full one"))

    settings = scene.voxgi
    settings.bounce_source = "CYCLES"
    bounces = diffuse_bounces(settings)
    default_s, _ = timed_previews(scene, width, height, repeats)
    settings.bounce_source, settings.bounces = "MANUAL", 1
    one_s, ours = timed_previews(scene, width, height, repeats)
    rows.append((f"VoxGI preview {width}×{height}, Bounces 1 (GPU, Accurate)", one_s,
                 f"{error(ours):.3f}", f"tracer {session.tracer_used}"))
    rows.append((f"VoxGI preview {width}×{height}, default Bounces (Follow Cycles: {bounces})",
                 default_s, "—", "no reference at Cycles' default light paths is stored"))
    for samples, denoise in ((16, True), (64, False)):
        passes = render_cycles_passes(scene, width, height, samples, diffuse_bounces=1,
                                      ao_distance=1.0, seed=1, glossy_bounces=1, denoise=denoise)
        rows.append((f"Cycles {samples} spp{' + OIDN' if denoise else ''} {width}×{height}, "
                     "one bounce of either kind", last_render_seconds(), f"{error(passes):.3f}",
                     "render alone"))

    size_note = (" (quick: errors against the 160×120 reference averaged 2×2, a check of the "
                 "tooling, not the measurement)" if args.quick else "")
    print(f"### Imported scene (issue 22): the glTF round trip of tests/blender/gltf_scenes.py"
          f"{size_note}; Combined relative L1 against the stored Cycles "
          f"{stored['reference_samples']} spp reference ({stored['reference_seconds']:.0f} s, one "
          f"bounce of either kind); medians of {repeats}\n")
    print("| what | median time | Combined error | notes |\n|---|---:|---:|---|")
    for what, seconds, err, note in rows:
        print(f"| {what} | {seconds * 1000:.0f} ms | {err} | {note} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
