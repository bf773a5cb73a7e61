"""Cycles references of the glass scenes of issue 22 (tests/blender/glass_scenes.py) at Cycles'
**default** light paths — a one-bounce reference has no transmission bounce, so glass is black
there.

Usage: ``.venv/bin/python tools/make_glass_references.py [--samples 4096]
[--out tests/data/glass_refs]``. As ``make_light_references.py`` (160 × 120, Cycles' default
pixel filter, float16 passes in ``<out>/<scene>.npz``, and in ``<out>/cycles_spp.json`` per scene
the reference's time and the relative L1 and time of Cycles 16 spp + OpenImageDenoise and of
64 spp with another seed), except that every light path setting is the new scene's own: Total
12, Diffuse 4, Glossy 4, Transmission 12, Transparent 8 bounces, Caustics on, Filter Glossy 1.
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

CHECKED = ("Combined", "Diffuse Color", "Diffuse Direct")
# what cycles_passes sets for its one-bounce references; left at the scene's defaults here
LIGHT_PATHS = ("max_bounces", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
               "blur_glossy")


def render(scene, samples, seed, denoise=False):
    """(passes, seconds) of Cycles at the scene's own (default) light paths."""
    import cycles_passes
    import glass_scenes

    settings = cycles_passes._render_settings

    def defaults(*args, **kwargs):
        return [(owner, name, value) for owner, name, value in settings(*args, **kwargs)
                if name not in LIGHT_PATHS]

    cycles_passes._render_settings = defaults
    try:
        passes = cycles_passes.render_cycles_passes(
            scene, glass_scenes.WIDTH, glass_scenes.HEIGHT, samples, ao_distance=1.0, seed=seed,
            denoise=denoise)
    finally:
        cycles_passes._render_settings = settings
    return passes, cycles_passes.last_render_seconds()


def main(argv=None):
    load_addon()
    import bpy
    import glass_scenes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(glass_scenes.SCENES))
    parser.add_argument("--samples", type=int, default=4096)
    parser.add_argument("--no-checks", action="store_true", help="skip 16 + OIDN and 64 spp")
    parser.add_argument("--out", type=pathlib.Path,
                        default=REPO_ROOT / "tests" / "data" / "glass_refs")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "cycles_spp.json"
    for name in args.scenes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        glass_scenes.build(name, scene)
        cycles = scene.cycles
        paths = {key: getattr(cycles, key) for key in (*LIGHT_PATHS, "transparent_max_bounces",
                                                        "caustics_reflective",
                                                        "caustics_refractive")}
        reference, seconds = render(scene, args.samples, seed=0)
        stored = {n: reference[n].astype(np.float16) for n in STORED_LIGHT}
        stored["Alpha"] = reference["Alpha"].astype(np.float16)
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **stored)
        print(f"{name}: {args.samples} spp in {seconds:.1f} s -> {path} "
              f"({path.stat().st_size / 1024:.0f} KB)", flush=True)
        mask = reference["Alpha"] > 0.5
        checks = {}
        for label, samples, denoise in (() if args.no_checks else
                                        (("16+OIDN", 16, True), ("64", 64, False))):
            passes, t = render(scene, samples, seed=1, denoise=denoise)
            checks[label] = {"seconds": round(t, 2), "relative_l1": {
                n: round(relative_l1(passes[n], reference[n], mask), 4) for n in CHECKED}}
        summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
        summary[name] = {"reference_samples": args.samples, "reference_seconds": round(seconds, 2),
                         "light_paths": paths,
                         "size": [glass_scenes.WIDTH, glass_scenes.HEIGHT], "checks": checks}
        summary_path.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
        print(f"  {checks}", flush=True)


if __name__ == "__main__":
    main()
