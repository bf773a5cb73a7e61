"""Cycles references of the light scenes of issue 17 (tests/blender/light_scenes.py).

Usage: ``.venv/bin/python tools/make_light_references.py [--scenes NAME ...] [--samples 2048]
[--out tests/data/light_refs]`` — the stored emissive and metal rooms were made with
``--samples 8192`` (at 2048 their Diffuse Indirect was 0.045 and 0.128 off the 8192-spp one,
as much as the preview's own error); each scene's count is in ``cycles_spp.json``.

As ``make_gi_references.py`` (one bounce of either kind, 160 × 120, AO distance 1 m, float16
passes in ``<out>/<scene>.npz``) but with Cycles' **default** pixel filter (Blackman-Harris,
1.5 px) and the scenes' own worlds. ``<out>/cycles_spp.json`` gets, per scene, the reference's
time and the relative L1 and time of Cycles 16 spp + OpenImageDenoise (the quick preview artists
use) and of 64 spp, with another seed.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_gi_references import REPO_ROOT, STORED, load_addon, relative_l1  # noqa: E402

STORED_LIGHT = (*STORED, "Glossy Direct")
CHECKED = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct", "Glossy Indirect")


def render(scene, samples, seed, denoise=False):
    import light_scenes
    from cycles_passes import last_render_seconds, render_cycles_passes

    passes = render_cycles_passes(scene, light_scenes.WIDTH, light_scenes.HEIGHT, samples,
                                  diffuse_bounces=1, ao_distance=1.0, seed=seed,
                                  glossy_bounces=1, denoise=denoise)
    return passes, last_render_seconds()


def main(argv=None):
    load_addon()
    import bpy
    import light_scenes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(light_scenes.SCENES))
    parser.add_argument("--samples", type=int, default=2048)
    parser.add_argument("--out", type=pathlib.Path,
                        default=REPO_ROOT / "tests" / "data" / "light_refs")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "cycles_spp.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    for name in args.scenes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        light_scenes.build(name, scene)
        reference, seconds = render(scene, args.samples, seed=0)
        stored = {n: reference[n].astype(np.float16) for n in STORED_LIGHT}
        stored["Alpha"] = reference["Alpha"].astype(np.float16)
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **stored)
        print(f"{name}: {args.samples} spp in {seconds:.1f} s -> {path} "
              f"({path.stat().st_size / 1024:.0f} KB)", flush=True)
        mask = reference["Alpha"] > 0.5
        checks = {}
        for label, samples, denoise in (("16+OIDN", 16, True), ("64", 64, False)):
            passes, t = render(scene, samples, seed=1, denoise=denoise)
            checks[label] = {"seconds": round(t, 2), "relative_l1": {
                n: round(relative_l1(passes[n], reference[n], mask), 4) for n in CHECKED}}
        summary[name] = {"reference_samples": args.samples, "reference_seconds": round(seconds, 2),
                         "size": [light_scenes.WIDTH, light_scenes.HEIGHT], "checks": checks}
        summary_path.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
        print(f"  {checks}", flush=True)


if __name__ == "__main__":
    main()
