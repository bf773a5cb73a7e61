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

Then the posed update of an imported rig (``posed_rows``, alone and beside an emissive panel;
``--rig`` runs only those tables and the playbacks): the
character of ``tests/blender/rig_scenes.py`` through Blender's glTF exporter and importer
(armature at 0.01, a textured skin) in its room, ``voxgi.update`` after each rotation of a bone
(the median of ``RIG_REPEATS``), split into its main-thread share — the operator until it
submits the job, and its report after — and the worker's stages, each beside its floor where
one can be measured: the snapshot beside the bpy reads a pose needs at least (the rig's bone
matrices and the objects' matrices), the injection beside an injection whose every shadow ray
is kept (nothing moved). Goal (docs/gi_pipeline.md "Posed updates"): ≤ 50 ms in all, ≤ 10 ms on
the main thread. Then the same rig played in the viewport at 24 fps (``playback_rows``): the
frames whose GI was shown, the main thread's share per frame and the lag of a shown frame.
"""
from __future__ import annotations

import argparse
import gc
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


RIG_REPEATS = 9
POSED_STAGES = ("view fit", "cascades", "transform", "merge", "occupancy", "inject", "svo",
                "ray views")


def _median(values):
    return sorted(values)[len(values) // 2]


def posed_rows(repeats: int = RIG_REPEATS, glow: bool = False):
    """The imported rig's posed update (module doc): prints its table, returns the medians
    {part: seconds}. glow : with an emissive panel on the room's back wall
    (``rig_scenes.add_glowing_panel``), a light the injection keeps as it keeps the lamps'."""
    import bpy
    import rig_scenes

    from voxgi.blender import jobs
    from voxgi.blender.session import scene_session
    from voxgi.blender.snapshot import snapshot_or_error
    from voxgi.blender.snapshot.skin import read_armature
    from voxgi.voxgi_addon.gi.light_injection import inject_direct_light
    from voxgi.voxgi_addon.gi.voxel_shadows import CascadeOccupancy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    built = rig_scenes.build_gltf_rig_room(scene)
    if glow:
        rig_scenes.add_glowing_panel(scene)
    session = scene_session(scene.name_full)
    assert bpy.ops.voxgi.voxelize() == {"FINISHED"}
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    bone = built["rig"].pose.bones["Forearm.L"]
    bone.rotation_mode = "XYZ"
    runs = []
    for i in range(repeats + 1):
        bone.rotation_euler.x += 0.15 * (1 if i % 2 else -1)
        start = time.perf_counter()
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        end = time.perf_counter()
        job = jobs.latest_job(scene.name_full)
        timings = session.gi_timings
        run = {"total": end - start,
               "main thread": (job.submitted_at - start) + (end - job.finished_at),
               "snapshot": timings.get("snapshot", 0.0),
               "worker": job.finished_at - job.submitted_at}
        run.update({name: timings.get(name, 0.0) for name in POSED_STAGES})
        if i:  # the first pose after the first update warms up
            runs.append(run)
    medians = {k: _median([r[k] for r in runs]) for k in runs[0]}

    depsgraph = bpy.context.evaluated_depsgraph_get()
    rig = built["rig"]
    objects = [o for o in scene.objects if o.type in ("MESH", "LIGHT", "CAMERA")]

    def reads():  # what a pose needs of bpy at least: bones and matrices
        read_armature(rig, rig.evaluated_get(depsgraph))
        for obj in objects:
            np.array(obj.evaluated_get(depsgraph).matrix_world)

    state = session.gi_state
    occupancy = CascadeOccupancy(state.cascades)
    snapshot, _ = snapshot_or_error(bpy.context)

    def kept():  # nothing moved: the injection's cost without lighting a voxel
        inject_direct_light(state.cascades, snapshot, occupancy, state.settings.light_samples,
                            rays=state.radiance.rays)

    floors = {"snapshot": median_seconds(reads, repeats),
              "inject": median_seconds(kept, repeats) if getattr(state.radiance, "rays", None)
              is not None else None}
    counts = " / ".join(f"{n:,}" for n in state.voxel_counts)
    radiance = state.radiance
    rays = "" if getattr(radiance, "rays", None) is None else (
        f"; voxels lit again {radiance.relit:,} of {sum(state.voxel_counts):,}, their shadow "
        f"rays marched {radiance.marched:,}, kept {radiance.reused:,}")
    print(f"### Posed update of an imported rig: the ~{len(built['body'].data.polygons):,}-face "
          f"character of tests/blender/rig_scenes.py through Blender's glTF exporter and "
          f"importer (armature at {rig.scale[0]:.2f})"
          f"{', beside an emissive panel' if glow else ''}, voxgi.update after a bone rotation, "
          f"medians of {repeats}; cascade voxels {counts}{rays}\n")
    print("| part | median | floor | notes |\n|---|---:|---:|---|")

    def ms(value):
        return "—" if value is None else f"{value * 1000:.1f} ms"

    rows = [("**total** (goal ≤ 50 ms)", medians["total"], None, "operator call to return"),
            ("**main thread** (goal ≤ 10 ms)", medians["main thread"], None,
             "until the job is submitted, and the report after it"),
            ("  snapshot", medians["snapshot"], floors["snapshot"],
             "floor: the rig's bone matrices and the objects' matrices read"),
            ("**worker**", medians["worker"], None, "the job, submitted to finished")]
    notes = {"view fit": "Auto's probe rays (on the worker after the first fit)",
             "inject": "floor: nothing moved (every voxel keeps its light)", "svo": "the octree"}
    rows += [(f"  {name}", medians[name], floors.get(name), notes.get(name, ""))
             for name in POSED_STAGES if medians[name] > 0 or name in ("inject", "svo")]
    for what, seconds, floor, note in rows:
        print(f"| {what} | {ms(seconds)} | {ms(floor)} | {note} |", flush=True)
    return medians


PLAYBACK_FPS = 24
PLAYBACK_FRAMES = 48


def playback_rows(frames: int = PLAYBACK_FRAMES, fps: int = PLAYBACK_FPS):
    """The imported rig played in the viewport (docs/gi_pipeline.md "Posed updates",
    "Playback"): its arms and legs keyframed on every frame, ``frames`` frames changed at
    ``fps`` in real time as Blender's playback does (``frame_set``, then the viewport's
    ``LiveGI.update`` with the frame's records, and the timer's ``jobs.drain`` between frames),
    the worker running as in a UI session. Prints the main thread's share per frame, the frames
    whose GI was shown (the others dropped, never queued), and how long after its frame change
    a shown frame's GI was in; returns the same as a dict."""
    import bpy
    import rig_scenes

    from voxgi.blender import jobs
    from voxgi.blender.updates import records_from_depsgraph
    from voxgi.blender.viewport_session import live_gi

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    built = rig_scenes.build_gltf_rig_room(scene)
    rig_scenes.keyframe_walk(built["rig"], frames=frames + 1, start=1)
    scene.frame_set(1)
    live = live_gi(scene.name_full)
    jobs.synchronous = True
    live.update(scene, bpy.context.evaluated_depsgraph_get())  # the first, full update
    jobs.synchronous = False
    records = []

    def record(_scene, depsgraph):
        records.extend(records_from_depsgraph(depsgraph, live.index))

    bpy.app.handlers.depsgraph_update_post.append(record)
    bpy.app.handlers.frame_change_post.append(record)
    ours, changed_at, shown, lags, work, relit = [], {}, [], [], [], []
    generation = live.generation
    start = time.perf_counter()
    try:
        for k, frame in enumerate(range(2, frames + 2)):
            wait = start + k / fps - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            scene.frame_set(frame)  # Blender's own work for the frame
            changed_at[frame] = time.perf_counter()
            t0 = time.perf_counter()
            live.update(scene, bpy.context.evaluated_depsgraph_get(), records[:])
            records.clear()
            jobs.drain()
            ours.append(time.perf_counter() - t0)
            if live.generation != generation:
                generation = live.generation
                shown.append(live.snapshot.frame)
                lags.append(time.perf_counter() - changed_at[live.snapshot.frame])
                work.append(dict(live.stats.timings))
                radiance = live.staged.state.radiance
                relit.append((getattr(radiance, "relit", 0), getattr(radiance, "marched", 0),
                              sum(live.staged.state.voxel_counts)))
        played = time.perf_counter() - start
        while live.pending is not None or jobs.running_job(scene.name_full) is not None:
            time.sleep(0.002)
            jobs.drain()
        if live.generation != generation:
            shown.append(live.snapshot.frame)
            lags.append(time.perf_counter() - changed_at[live.snapshot.frame])
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(record)
        bpy.app.handlers.frame_change_post.remove(record)
        jobs.synchronous = None
    first, last = changed_at[2], changed_at[frames + 1]  # the frame changes' own rate
    out = {"frames": frames, "fps": (frames - 1) / max(last - first, 1e-9), "shown": len(shown),
           "last": shown[-1] if shown else None, "main longest": max(ours),
           "main median": _median(ours), "lag median": _median(lags) if lags else None}
    print(f"\n### Playback of the imported rig in the viewport: {frames} frames at {fps} fps "
          f"(arms and legs keyframed on every frame), the viewport's LiveGI and worker\n")
    print("| what | value | notes |\n|---|---:|---|")
    print(f"| frames played | {frames} in {played:.2f} s | {out['fps']:.1f} fps "
          f"(goal: {fps}, the file's rate) |")
    print(f"| frames whose GI was shown | {len(shown)} of {frames} | the others dropped while "
          f"the worker was busy (never queued); the last shown: frame {out['last']} of "
          f"{frames + 1} |")
    print(f"| main thread per frame: median / longest | {out['main median'] * 1000:.1f} / "
          f"{out['main longest'] * 1000:.1f} ms | the frame's records, the posed snapshot, the "
          f"job's submission and the timer's drain (goal ≤ 10 ms) |")
    if work:
        parts = {k: _median([w.get(k, 0.0) for w in work]) for k in work[0]
                 if not k.startswith(" ")}
        steps = {k.strip(): _median([w.get(k, 0.0) for w in work]) for k in work[0]
                 if k.startswith("  ")}
        out["worker median"] = sum(parts.values())
        print(f"| a shown frame's job on the worker: median | {out['worker median'] * 1000:.1f} "
              f"ms | " + ", ".join(f"{k} {v * 1000:.1f}" for k, v in {**parts, **steps}.items()
                                   if v >= 0.0005) + " |")
    if relit:
        print(f"| a shown frame's voxels lit again, shadow rays marched: median | "
              f"{_median([r[0] for r in relit]):,} of {relit[-1][2]:,}, "
              f"{_median([r[1] for r in relit]):,} | the voxels and rays that meet what moved "
              f"(docs/gi_pipeline.md \"Posed updates\") |")
    if lags:
        print(f"| a shown frame's GI in after its frame change: median | "
              f"{out['lag median'] * 1000:.1f} ms | the frame's update on the worker, and the "
              f"one it waited behind |")
    return out


def view_playback_rows(frames: int = PLAYBACK_FRAMES, fps: int = PLAYBACK_FPS):
    """The rig played in the Rendered view (Accurate, the default): Rendered mode entered and
    its first GI image drawn, then ``frames`` frames changed at ``fps`` in real time, each
    handed to the engine's ``view_update``, the view drawn between frames as Blender's loop
    redraws it (``bench_entering_blender.Session``: a 1280 × 720 region). A frame counts as
    shown when a draw showed an image of its own snapshot (the quick image or a traced one).
    Prints the frames shown, the main thread's share per frame and the longest draw; returns
    the same as a dict."""
    import bpy
    import rig_scenes
    from bench_entering_blender import Session

    from voxgi.blender import jobs
    from voxgi.render.gpu_context import ensure_gpu_context

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    built = rig_scenes.build_gltf_rig_room(scene)
    rig_scenes.keyframe_walk(built["rig"], frames=frames + 1, start=1)
    scene.frame_set(1)
    ready, why = ensure_gpu_context()
    if not ready:
        print(f"\n(no GPU context for the view's playback: {why})")
        return {}
    jobs.synchronous = False
    session = Session(scene)
    bpy.app.handlers.frame_change_post.append(session.handler)
    shown_as = ("Quick", "Coarse", "Refining", "Converged")
    try:
        session.update()  # entering Rendered mode
        started = time.perf_counter()
        while time.perf_counter() - started < 120.0:
            _, renderer = session.draw()
            if renderer.traces:
                break
        version, ours, draws, seen, lags = {}, [], [], set(), []
        live = session.live
        # the cyclic garbage of the glTF imports before (tens of thousands of the importer's
        # objects) collected now, not by a gen-2 collection inside the timed frames: Python's
        # full collection scans every tracked object (~100k here, 22–34 ms on this machine)
        gc.collect()
        start = time.perf_counter()
        for k, frame in enumerate(range(2, frames + 2)):
            scene.frame_set(frame)
            changed = time.perf_counter()
            records, session.records = session.records, []
            ours.append(session.update(records))
            version[live.snapshots] = (frame, changed)
            while time.perf_counter() < start + (k + 1) / fps:
                seconds, renderer = session.draw()
                draws.append(seconds)
                key = renderer.progressive.key
                if renderer.shown in shown_as and key is not None and key[0][0] == "snapshot":
                    shown = version.get(key[0][1])
                    if shown is not None and shown[0] not in seen:
                        seen.add(shown[0])
                        lags.append(time.perf_counter() - shown[1])
        played = time.perf_counter() - start
    finally:
        bpy.app.handlers.frame_change_post.remove(session.handler)
        jobs.cancel_all()
        jobs.wait_idle(60.0)
        session.close()
        jobs.synchronous = None
    out = {"frames": frames, "shown": len(seen), "main median": _median(ours),
           "main longest": max(ours), "draw longest": max(draws), "draws": len(draws),
           "lag median": _median(lags) if lags else None, "played": played}
    print(f"\n### The rig played in the Rendered view (Accurate): {frames} frames at {fps} fps, "
          f"each frame's view_update, the view drawn between frames (1280 × 720)\n")
    print("| what | value | notes |\n|---|---:|---|")
    print(f"| frames whose own image was drawn | {len(seen)} of {frames} | the quick image or a "
          f"traced one of the frame's snapshot; the view finishes the frame it prepares, then "
          f"the newest (the ones between dropped, never queued) |")
    print(f"| view_update per frame: median / longest | {out['main median'] * 1000:.1f} / "
          f"{out['main longest'] * 1000:.1f} ms | the posed snapshot, the hooks and the "
          f"job's submission (main thread) |")
    print(f"| view_draw while playing: longest | {out['draw longest'] * 1000:.1f} ms | goal ≤ "
          f"30 ms; {len(draws)} draws in {played:.2f} s |")
    if lags:
        print(f"| a shown frame's image after its frame change: median | "
              f"{out['lag median'] * 1000:.1f} ms | |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--rig", action="store_true", help="only the posed update of the rig")
    args = ap.parse_args(argv)
    load_addon()
    if args.rig:
        posed_rows(3 if args.quick else RIG_REPEATS)
        posed_rows(3 if args.quick else RIG_REPEATS, glow=True)
        playback_rows(12 if args.quick else PLAYBACK_FRAMES)
        view_playback_rows(12 if args.quick else PLAYBACK_FRAMES)
        return 0
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
    print()
    posed_rows(3 if args.quick else RIG_REPEATS)
    posed_rows(3 if args.quick else RIG_REPEATS, glow=True)
    playback_rows(12 if args.quick else PLAYBACK_FRAMES)
    view_playback_rows(12 if args.quick else PLAYBACK_FRAMES)
    return 0


if __name__ == "__main__":
    sys.exit(main())
