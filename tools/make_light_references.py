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


def render(scene, samples, seed, denoise=False, size=None):
    """(passes, seconds) of Cycles at ``size`` (the light scenes' when None)."""
    from cycles_passes import last_render_seconds, render_cycles_passes

    if size is None:
        import light_scenes
        size = (light_scenes.WIDTH, light_scenes.HEIGHT)
    passes = render_cycles_passes(scene, *size, samples, diffuse_bounces=1, ao_distance=1.0,
                                  seed=seed, glossy_bounces=1, denoise=denoise)
    return passes, last_render_seconds()


def make_references(argv, module_name: str, out_name: str, checked, description: str):
    """The command line of a reference maker: build each scene of the test module
    ``module_name`` (its SCENES, build, WIDTH, HEIGHT), store its Cycles reference in
    tests/data/``out_name``/<scene>.npz and, in cycles_spp.json there, the relative L1 of the
    ``checked`` passes of Cycles 16 spp + OIDN and 64 spp (another seed)."""
    load_addon()
    import importlib

    import bpy

    scenes = importlib.import_module(module_name)
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--scenes", nargs="*", default=list(scenes.SCENES))
    parser.add_argument("--samples", type=int, default=2048)
    parser.add_argument("--out", type=pathlib.Path, default=REPO_ROOT / "tests" / "data" / out_name)
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "cycles_spp.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    for name in args.scenes:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scenes.build(name, scene)
        size = (scenes.WIDTH, scenes.HEIGHT)
        reference, seconds = render(scene, args.samples, seed=0, size=size)
        stored = {n: reference[n].astype(np.float16) for n in STORED_LIGHT}
        stored["Alpha"] = reference["Alpha"].astype(np.float16)
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **stored)
        print(f"{name}: {args.samples} spp in {seconds:.1f} s -> {path} "
              f"({path.stat().st_size / 1024:.0f} KB)", flush=True)
        mask = reference["Alpha"] > 0.5
        checks = {}
        for label, samples, denoise in (("16+OIDN", 16, True), ("64", 64, False)):
            passes, t = render(scene, samples, seed=1, denoise=denoise, size=size)
            checks[label] = {"seconds": round(t, 2), "relative_l1": {
                n: round(relative_l1(passes[n], reference[n], mask), 4) for n in checked}}
        summary[name] = {"reference_samples": args.samples, "reference_seconds": round(seconds, 2),
                         "size": list(size), "checks": checks}
        summary_path.write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
        print(f"  {checks}", flush=True)


def main(argv=None):
    make_references(argv, "light_scenes", "light_refs", CHECKED, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
