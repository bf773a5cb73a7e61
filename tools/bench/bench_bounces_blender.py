"""Multi-bounce benchmark rows (issue 20, section "gi"), run with the bpy venv:
``.venv/bin/python tools/bench/bench_bounces_blender.py [--quick]``.

Per interior scene of ``tests/blender/bounce_scenes.py`` (the scenes of
tests/blender/test_multibounce.py: Cornell box, emissive room, columned hall, textured room;
160 × 120): the preview (GPU, Accurate, ``render_scene_passes`` as F12) at the default Bounces
(Follow Cycles: 4 diffuse bounces in a new scene) — timed with its radiance cache built in every
run, as after any edit, and with the cache kept, as when nothing changed — and at Bounces = 1
(the one-bounce preview the goal's 1.3× is measured against), each with its Combined error
(relative L1 over the reference's covered pixels, as the test computes it) against the stored
Cycles reference at its **default** light paths (tests/data/bounce_refs: Total 12, Diffuse 4,
Glossy 4, 2048/4096 spp). Beside them Cycles 16 and 64 spp, with and without OpenImageDenoise,
at the same default light paths, rendered in the same run. Goal (issue 20): an error below
Cycles 16 spp + OIDN's in at most 1.3× the one-bounce preview's time.

``--quick`` checks the tooling: the Cornell box at 80 × 60, one timed run each, errors against
the stored reference averaged over 2 × 2 pixels (Cycles at 80 × 60 is compared the same way),
so its numbers are not the measurement.
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
sys.path[:0] = [str(HERE), str(ROOT / "tools"), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon  # noqa: E402

REFS = ROOT / "tests" / "data" / "bounce_refs"
# Cycles' default Light Paths (a new scene's scene.cycles), as tools/make_bounce_references.py
MAX_BOUNCES, DIFFUSE_BOUNCES, GLOSSY_BOUNCES = 12, 4, 4
GOAL_TIME_RATIO = 1.3
CYCLES_RUNS = ((16, False), (16, True), (64, False), (64, True))


def relative_l1(ours, reference, mask):
    a, b = np.asarray(ours, np.float64)[mask], np.asarray(reference, np.float64)[mask]
    return float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-12))


def downsample(image, factor):
    """Mean over ``factor`` × ``factor`` pixel blocks (the quick mode's smaller image)."""
    if factor == 1:
        return image
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return image.reshape(h, factor, w, factor, *image.shape[2:]).mean(axis=(1, 3))


def cycles_default_paths(scene, width, height, samples, denoise, seed=1):
    """(passes, seconds): Cycles at its default light paths, as the stored references
    (``cycles_passes`` sets Total to the larger of Diffuse and Glossy; put back to 12), with
    ``seed`` (another one gives a second, independent reference)."""
    import cycles_passes

    settings = cycles_passes._render_settings

    def default_total(*args, **kwargs):
        return [(owner, name, MAX_BOUNCES if name == "max_bounces" else value)
                for owner, name, value in settings(*args, **kwargs)]

    cycles_passes._render_settings = default_total
    try:
        passes = cycles_passes.render_cycles_passes(
            scene, width, height, samples, diffuse_bounces=DIFFUSE_BOUNCES, ao_distance=1.0,
            seed=seed, glossy_bounces=GLOSSY_BOUNCES, denoise=denoise)
    finally:
        cycles_passes._render_settings = settings
    return passes, cycles_passes.last_render_seconds()


def timed_previews(scene, width, height, repeats, before=None, warm=True):
    """(median seconds, passes of the last run) of ``repeats`` previews, after a warm-up one
    (shaders, BVH upload) when ``warm``; ``before`` runs ahead of each timed preview, untimed."""
    import bpy

    from voxgi.render.pipeline import render_scene_passes

    passes = None
    if warm:
        passes, _ = render_scene_passes(bpy.context, scene, None, width, height)
    times = []
    for _ in range(repeats):
        if before is not None:
            before()
        t0 = time.perf_counter()
        passes, _ = render_scene_passes(bpy.context, scene, None, width, height)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), passes


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--scenes", nargs="*", help="scenes of bounce_scenes.SCENES (default: all; "
                                                "--quick: cornell_box)")
    args = ap.parse_args(argv)
    load_addon()
    import bounce_scenes
    import bpy

    from voxgi.blender.settings import diffuse_bounces
    from voxgi.render import gpu_gather

    factor = 2 if args.quick else 1
    width, height = bounce_scenes.WIDTH // factor, bounce_scenes.HEIGHT // factor
    repeats = 1 if args.quick else 3
    names = args.scenes or (["cornell_box"] if args.quick else list(bounce_scenes.SCENES))

    def drop_cache():
        # as after an edit: the next preview builds its radiance cache again
        gpu_gather.drop_shared_cache()

    size_note = (f"{width}×{height} (quick: errors against the 160×120 reference averaged 2×2, "
                 "a check of the tooling, not the measurement)" if args.quick
                 else f"{width}×{height}")
    print(f"### Multi-bounce (issue 20): preview vs Cycles at its default light paths "
          f"(Total {MAX_BOUNCES}, Diffuse {DIFFUSE_BOUNCES}, Glossy {GLOSSY_BOUNCES}), "
          f"{size_note}; cells: median time of {repeats}, Combined relative L1 against the "
          f"stored Cycles reference (tests/data/bounce_refs)\n")
    print("| scene | VoxGI default Bounces, cache built | VoxGI, cache kept | VoxGI Bounces 1 "
          "| built / Bounces 1 | Cycles 16 spp | Cycles 16 spp + OIDN | Cycles 64 spp "
          "| Cycles 64 spp + OIDN | goal: error < 16 + OIDN's, time ≤ 1.3× |\n"
          "|---|---|---|---|---:|---|---|---|---|---|")
    for name in names:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        bounce_scenes.build(name, scene)
        with np.load(REFS / f"{name}.npz") as data:
            reference = downsample(data["Combined"].astype(np.float64), factor)
            mask = downsample(data["Alpha"].astype(np.float64), factor) > 0.5

        def error(passes):
            return relative_l1(passes["Combined"], reference, mask)

        settings = scene.voxgi
        settings.bounce_source = "CYCLES"
        bounces = diffuse_bounces(settings)
        built, ours = timed_previews(scene, width, height, repeats, before=drop_cache)
        kept, _ = timed_previews(scene, width, height, repeats, warm=False)  # the last one's cache
        ours_error = error(ours)
        settings.bounce_source, settings.bounces = "MANUAL", 1
        one, one_passes = timed_previews(scene, width, height, repeats)
        cells = [f"{built:.2f} s, {ours_error:.3f} ({bounces} bounces)", f"{kept:.2f} s",
                 f"{one:.2f} s, {error(one_passes):.3f}", f"{built / one:.2f}×"]
        cycles = {}
        for samples, denoise in CYCLES_RUNS:
            passes, seconds = cycles_default_paths(scene, width, height, samples, denoise)
            cycles[samples, denoise] = (seconds, error(passes))
            cells.append(f"{seconds:.2f} s, {error(passes):.3f}")
        target = cycles[16, True][1]
        met = (ours_error < target, built / one <= GOAL_TIME_RATIO)
        cells.append({(True, True): "met", (True, False): "error met, time not",
                      (False, True): "time met, error not", (False, False): "not met"}[met])
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    print("\nNote: cache built: the radiance cache's texture is dropped before each timed preview "
          "(as after an edit); cache kept: it is reused (nothing changed). Every time includes "
          "the snapshot; the Cycles times are its render alone.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
