"""Cycles references of the multi-bounce scenes of issue 20 (tests/blender/bounce_scenes.py) at
Cycles' **default** light paths (Total 12, Diffuse 4, Glossy 4 bounces).

Usage: ``.venv/bin/python tools/make_bounce_references.py [--scenes NAME ...] [--samples 2048]
[--out tests/data/bounce_refs]``. As ``make_light_references.py`` (160 × 120, Cycles' default
pixel filter, float16 passes in ``<out>/<scene>.npz``, and in ``<out>/cycles_spp.json`` per scene
the reference's time and the relative L1 and time of Cycles 16 spp + OpenImageDenoise and of
64 spp with another seed, at the same light paths).
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_gi_references import REPO_ROOT, load_addon, relative_l1  # noqa: E402
from make_light_references import STORED_LIGHT  # noqa: E402

CHECKED = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect")
# Cycles' default Light Paths (a new scene's scene.cycles)
MAX_BOUNCES, DIFFUSE_BOUNCES, GLOSSY_BOUNCES = 12, 4, 4


def render(scene, samples, seed, denoise=False):
    """(passes, seconds) of Cycles at the default light paths. ``cycles_passes`` sets Total to
    the larger of Diffuse and Glossy; here it is put back to Cycles' default 12."""
    import bounce_scenes
    import cycles_passes

    settings = cycles_passes._render_settings

    def default_total(*args, **kwargs):
        return [(owner, name, MAX_BOUNCES if name == "max_bounces" else value)
                for owner, name, value in settings(*args, **kwargs)]

    cycles_passes._render_settings = default_total
    try:
        passes = cycles_passes.render_cycles_passes(
            scene, bounce_scenes.WIDTH, bounce_scenes.HEIGHT, samples,
            diffuse_bounces=DIFFUSE_BOUNCES, ao_distance=1.0, seed=seed,
            glossy_bounces=GLOSSY_BOUNCES, denoise=denoise)
    finally:
        cycles_passes._render_settings = settings
    return passes, cycles_passes.last_render_seconds()


def make_references(argv, scenes, out_name: str, render, checked, light_paths, description,
                    samples: int = 2048):
    """The command line of a default-light-path reference maker: build each scene of the test
    module ``scenes`` (its SCENES, build, WIDTH, HEIGHT), store ``render``'s reference
    (``render(scene, samples, seed, denoise=False)`` → (passes, seconds)) in
    tests/data/``out_name``/<scene>.npz and, in cycles_spp.json there, its time, the light paths
    it used (``light_paths(scene)`` → dict) and the relative L1 of the ``checked`` passes of
    Cycles 16 spp + OIDN and 64 spp (another seed)."""
    import bpy

    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--scenes", nargs="*", default=list(scenes.SCENES))
    parser.add_argument("--samples", type=int, default=samples)
    parser.add_argument("--no-checks", action="store_true", help="skip 16 + OIDN and 64 spp")
    parser.add_argument("--out", type=pathlib.Path, default=REPO_ROOT / "tests" / "data" / out_name)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "cycles_spp.json"
    for name in args.scenes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scenes.build(name, scene)
        paths = light_paths(scene)
        reference, seconds = render(scene, args.samples, seed=0)
        stored = {n: reference[n].astype(np.float16) for n in STORED_LIGHT}
        stored["Alpha"] = reference["Alpha"].astype(np.float16)
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **stored)
        print(f"{name}: {args.samples} spp in {seconds:.1f} s -> {path} "
              f"({path.stat().st_size / 1024:.0f} KB)", flush=True)
        mask = reference["Alpha"] > 0.5
        checks = {}
        for label, count, denoise in (() if args.no_checks else
                                      (("16+OIDN", 16, True), ("64", 64, False))):
            passes, t = render(scene, count, seed=1, denoise=denoise)
            checks[label] = {"seconds": round(t, 2), "relative_l1": {
                n: round(relative_l1(passes[n], reference[n], mask), 4) for n in checked}}
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
        summary[name] = {"reference_samples": args.samples, "reference_seconds": round(seconds, 2),
                         "light_paths": paths, "size": [scenes.WIDTH, scenes.HEIGHT],
                         "checks": checks}
        summary_path.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
        print(f"  {checks}", flush=True)


def main(argv=None):
    load_addon()
    import bounce_scenes

    make_references(argv, bounce_scenes, "bounce_refs", render, CHECKED,
                    lambda scene: {"total": MAX_BOUNCES, "diffuse": DIFFUSE_BOUNCES,
                                   "glossy": GLOSSY_BOUNCES},
                    __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
