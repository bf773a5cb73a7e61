"""Viewport convergence against Cycles 16 spp + OIDN (docs/gi_pipeline.md "Where a preview's
time goes"), run with the bpy venv:
``.venv/bin/python tools/bench/bench_viewport_converge_blender.py [--quick]``.

"The viewport converges as fast": per interior scene of ``tests/blender/bounce_scenes.py``
(the Cornell box, the columned hall, the emissive room and the textured room; ``--quick``:
the box alone, one run each) with a
stored Cycles reference at 160 × 120 (tests/data/bounce_refs, Cycles at its default light
paths, 2048 spp):

1. F12's image at 160 × 120 (``render_scene_passes``, the default settings: Accurate, Follow
   Cycles bounces): the viewport's converged target;
2. Cycles 16 spp + OIDN at its default light paths (``bench_bounces_blender
   .cycles_default_paths``), its render time and its Combined error e16 — relative L1 against
   the stored reference over the reference's covered pixels (Alpha > 0.5);
3. the viewport: ``view_draw`` (the engine's hook, with a stand-in engine, the scene camera's
   view and projection matrices, a 640 × 480 region at the default Viewport Resolution ¼ —
   so the traced image is 160 × 120 — and the default Viewport Samples) into an offscreen,
   draw after draw, from a fresh view (a new ``ViewportRenderer``: its radiance cache built
   inside the draws, as when a 3D view is switched to Rendered after an edit), from a fresh
   view whose cache the session holds (a view switched off and on again, or entered after
   F12: ``gpu_gather.shared_cache``) and from a view change (a view
   converged 10° away turns to the camera: the radiance cache kept). After every draw that
   finished a slice the shown estimate is read back (``ProgressiveImage.read_image``, not
   timed) and its RGB compared with F12's Combined over the same pixels; the time until it is
   within e16 of F12's image is summed over the ``view_draw`` calls (and as wall time without
   the benchmark's read-backs), until it first is and from when it stays so, beside the time
   until the view stops asking for redraws (converged: the Viewport Samples in, the radiance
   cache built) and its error then.

Goal: the viewport's time to that error at most Cycles 16 spp + OIDN's F12 time at
the view's size. Medians of 2 runs (``--quick``: 1) after a warm-up (shaders compiled, the
slice sizer measured). Prints a markdown table; with VOXGI_BENCH_TRACE=1 each run's draws,
restarts, slices and errors over time go to stderr.
"""
from __future__ import annotations

import argparse
import math
import os
import pathlib
import statistics
import sys
import time

import numpy as np

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(ROOT / "tools"), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon  # noqa: E402
from bench_bounces_blender import REFS, cycles_default_paths, relative_l1  # noqa: E402
from bench_viewport_blender import timed_view_draw  # noqa: E402

REGION = (640, 480)  # at the default Viewport Resolution (¼): a 160 × 120 traced image
SCENES = ("cornell_box", "columned_hall", "emissive_room", "textured_room")


def med(values):
    return statistics.median(values) if values else float("nan")


class ViewRun:
    """One run of ``view_draw`` calls on one view until the view stops asking for redraws;
    per finished slice: the cumulative view_draw seconds, the wall seconds (without the
    benchmark's read-back and error), the draws so far and the shown image's error."""

    def __init__(self):
        self.points = []           # (view_draw seconds, wall seconds, draws, error)
        self.seconds = self.wall = 0.0
        self.draws = 0
        self.converged = False
        self.restarts = 0          # new image keys after the first draw (a completed cache…)
        self.cache_builds = 0      # radiance caches completed during the run

    def reached(self, threshold):
        """(first, stays): the points at which the error first is ≤ threshold and from which
        it stays so to the end (None: never)."""
        first = next((p for p in self.points if p[3] <= threshold), None)
        stays = None
        for p in reversed(self.points):
            if p[3] > threshold:
                break
            stays = p
        return first, stays


def view_runs(scene, depsgraph, f12, mask, repeats):
    """The fresh-view and view-change runs (module doc), ``repeats`` of each."""

    import gpu
    from mathutils import Matrix
    from stand_in_engine import StandInEngine

    from voxgi.blender import jobs
    from voxgi.blender.viewport_session import live_gi
    from voxgi.render import gpu_gather
    from voxgi.render.viewport import ViewportRenderer, viewport_size

    width, height = REGION
    traced = viewport_size(width, height, scene.voxgi_viewport.resolution_fraction)
    assert traced == f12.shape[1::-1], (traced, f12.shape)
    camera = scene.camera.evaluated_get(depsgraph)
    window = camera.calc_matrix_camera(depsgraph, x=width, y=height,
                                       scale_x=scene.render.pixel_aspect_x,
                                       scale_y=scene.render.pixel_aspect_y)
    view = camera.matrix_world.inverted()
    # 10° about the camera's own vertical axis: a view change that keeps the cache's focus
    away = Matrix.Rotation(math.radians(10.0), 4, "Y") @ view
    live = live_gi(scene.name_full)
    offscreen = gpu.types.GPUOffScreen(width, height)

    def call(engine, view_matrix):
        return timed_view_draw(engine, view_matrix, window, offscreen, depsgraph)

    def run(engine, view_matrix, measure=True):
        """view_draw until no redraw is asked for (module doc)."""
        result = ViewRun()
        renderer = engine.voxgi_viewport
        overhead, t0 = 0.0, time.perf_counter()
        traces, texture = renderer.traces, None
        generation, key = renderer.cache.generation, None
        while result.draws < 20000:
            redraws = engine.redraws
            result.seconds += call(engine, view_matrix)
            result.draws += 1
            jobs.drain()  # as the timer would
            asked = engine.redraws != redraws
            if renderer.progressive.key != key:
                result.restarts += key is not None
                key = renderer.progressive.key
            if measure and (renderer.traces != traces or renderer.texture is not texture):
                m0 = time.perf_counter()
                traces, texture = renderer.traces, renderer.texture
                image = renderer.progressive.read_image()
                error = relative_l1(image[..., :3], f12, mask)
                overhead += time.perf_counter() - m0
                result.points.append((result.seconds, time.perf_counter() - t0 - overhead,
                                      result.draws, error))
            if not asked:
                result.converged = renderer.progressive.converged
                break
        result.wall = time.perf_counter() - t0 - overhead
        if renderer.error:
            raise RuntimeError(renderer.error)
        result.cache_builds = renderer.cache.generation - generation
        if os.environ.get("VOXGI_BENCH_TRACE"):
            print(f"run: {result.draws} draws, {result.restarts} restarts, "
                  f"{result.cache_builds} caches, {renderer.traces} slices; errors "
                  + " ".join(f"{p[0]:.2f}:{p[3]:.3f}" for p in result.points[::10])
                  + f"; status {renderer.status!r}",
                  file=sys.stderr)
        return result

    def fresh():
        engine = StandInEngine()
        engine.voxgi_viewport = ViewportRenderer()
        return engine

    def unshared():  # as after an edit: no complete cache in the session for this scene
        gpu_gather.drop_shared_cache()
        return fresh()

    live.update(scene, depsgraph)
    assert jobs.wait_idle(600), "the viewport job did not finish"
    jobs.drain()
    run(unshared(), view, measure=False)  # warm-up: shaders compiled, the slice sizer learns
    runs = {"fresh view (radiance cache built in the draws)": [],
            "fresh view after F12 or another view (radiance cache shared)": [],
            "view change (radiance cache kept)": []}
    for _ in range(repeats):
        runs["fresh view (radiance cache built in the draws)"].append(run(unshared(), view))
        # the view just built it: a view switched off and on, or entered after F12, reads it
        runs["fresh view after F12 or another view (radiance cache shared)"].append(
            run(fresh(), view))
        engine = fresh()
        run(engine, away, measure=False)  # converged 10° away, then the view turns
        assert jobs.wait_idle(600), "a viewport job did not finish"
        jobs.drain()
        runs["view change (radiance cache kept)"].append(run(engine, view))
    offscreen.free()
    return runs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--scenes", nargs="*", help=f"of {', '.join(SCENES)} (default: all; "
                                                "--quick: cornell_box)")
    args = ap.parse_args(argv)
    load_addon()
    import bounce_scenes
    import bpy

    from voxgi.blender import jobs
    from voxgi.render.gpu_context import ensure_gpu_context
    from voxgi.render.pipeline import render_scene_passes

    repeats = 1 if args.quick else 2
    names = args.scenes or (["cornell_box"] if args.quick else list(SCENES))
    width, height = bounce_scenes.WIDTH, bounce_scenes.HEIGHT
    ready, why = ensure_gpu_context()
    if not ready:
        raise SystemExit(f"no GPU context: {why}")
    jobs.synchronous = False
    rows = []
    for name in names:
        print(f"{name}…", file=sys.stderr, flush=True)
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        bounce_scenes.build(name, scene)
        with np.load(REFS / f"{name}.npz") as data:
            reference = data["Combined"].astype(np.float64)
            mask = data["Alpha"].astype(np.float64) > 0.5
        f12_passes, _ = render_scene_passes(bpy.context, scene, None, width, height)
        f12 = np.asarray(f12_passes["Combined"], np.float64)[..., :3]
        f12_error = relative_l1(f12, reference[..., :3], mask)
        cycles = [cycles_default_paths(scene, width, height, 16, True) for _ in range(repeats)]
        cycles_seconds = med([seconds for _, seconds in cycles])
        e16 = med([relative_l1(passes["Combined"], reference, mask) for passes, _ in cycles])
        depsgraph = bpy.context.evaluated_depsgraph_get()
        runs = view_runs(scene, depsgraph, f12, mask, repeats)
        for what, results in runs.items():
            firsts = [r.reached(e16)[0] for r in results]
            stays = [r.reached(e16)[1] for r in results]

            def cell(points):
                if any(p is None for p in points):
                    return "not reached"
                return (f"{med([p[0] for p in points]):.2f} s, {med([p[1] for p in points]):.2f} "
                        f"s wall, {med([p[2] for p in points]):.0f} draws")

            reach = med([p[0] for p in stays]) if all(p is not None for p in stays) else None
            converged = all(r.converged for r in results)
            rows.append(
                f"| {name} | {width}×{height} traced ({REGION[0]}×{REGION[1]} region × "
                f"{scene.voxgi_viewport.resolution_fraction:g}) | {what} | {cell(firsts)} | "
                f"{cell(stays)} | {med([r.draws for r in results]):.0f} | "
                f"{med([r.seconds for r in results]):.2f} s ({med([r.wall for r in results]):.2f}"
                f" s wall){'' if converged else ', not converged'}, error "
                f"{med([r.points[-1][3] for r in results]):.4f}; "
                f"{med([r.cache_builds for r in results]):.0f} radiance cache built or taken "
                f"from the session, "
                f"{med([r.restarts for r in results]):.0f} image restart | "
                f"{cycles_seconds:.2f} s, "
                f"e16 {e16:.3f} (F12's {f12_error:.3f}) | "
                + ("not reached" if reach is None else
                   f"{'met' if reach <= cycles_seconds else 'not met'} "
                   f"({reach / cycles_seconds:.2f}×)") + " |")
            print(rows[-1], file=sys.stderr, flush=True)
    print(f"### Viewport convergence vs Cycles 16 spp + OIDN: view_draw at the "
          f"default settings (Accurate, Follow Cycles bounces, {scene.voxgi_viewport.samples} "
          f"Viewport Samples), Mesa llvmpipe ({os.cpu_count()} CPUs, load average "
          f"{os.getloadavg()[0]:.1f} at the end); medians of {repeats}\n")
    print("| scene | view size | view | view within e16 of F12's image: first "
          "(view_draw sum, wall, draws) | … and staying within | draws to converged "
          "| converged: view_draw sum (wall), error vs F12 | Cycles 16 spp + OIDN: F12 time, "
          "e16 vs reference | goal: staying within e16 ≤ Cycles' time |\n"
          "|---|---|---|---|---|---:|---|---|---|")
    for row in rows:
        print(row)
    print("\nNote: the view's error is the relative L1 of its shown estimate's RGB against "
          "F12's Combined at 160×120 over the Cycles reference's covered pixels (Alpha > 0.5); "
          "e16 is Cycles 16 spp + OIDN's Combined against the stored Cycles reference over the "
          "same pixels. Wall time leaves out the benchmark's read-backs; converged: the view "
          "stopped asking for redraws.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
