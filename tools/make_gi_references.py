"""Cycles references of the four GI scenes (tests/blender/gi_scenes.py).

Usage: ``.venv/bin/python tools/make_gi_references.py [--scenes NAME ...] [--samples 2048]
[--out tests/data/gi_refs] [--png DIR]``

Per scene: Cycles at ``--samples`` spp (2048), one bounce (one diffuse, one glossy, at most one
in total: why both, docs/gi_pipeline.md "What one bounce means in Cycles"), 160 × 120,
Cycles' default pixel filter (Blackman-Harris, 1.5 px: what artists render with, and what
VoxGI's anti-aliased preview reproduces), black world,
AO distance 1 m (``Scene.voxgi.ao_distance``'s default). Stored in ``<out>/<scene>.npz``
(compressed) as float16 (H, W, 3) arrays named after the passes — ``Diffuse Direct``,
``Diffuse Indirect``, ``Diffuse Color``, ``Ambient Occlusion``, ``Glossy Indirect``,
``Glossy Color``, ``Combined`` — plus ``Alpha``
(H, W). ``<out>/cycles_spp.json`` gets, per scene, the reference's render time and the relative
L1 (over Alpha > ½ pixels) and render time of 16, 64 and 256 spp renders with another seed
against it. ``--png DIR`` also writes an sRGB strip (Combined, Direct, Indirect) per scene.
"""
from __future__ import annotations

import argparse
import importlib
import json
import pathlib
import sys
import tempfile

import numpy as np

REPO_ROOT = pathlib.Path(__file__).resolve().parent.parent
STORED = ("Diffuse Direct", "Diffuse Indirect", "Diffuse Color", "Ambient Occlusion", "Glossy Indirect",
          "Glossy Color", "Combined")
CHECK_SAMPLES = (16, 64, 256)
AO_DISTANCE = 1.0
DEFAULT_FILTER_WIDTH = 1.5  # Cycles' default Filter Size (pixels)


def load_addon():
    """Register the repository as the add-on package ``voxgi`` (as the Blender tests do)."""
    tmp = tempfile.mkdtemp(prefix="voxgi-refs-")
    (pathlib.Path(tmp) / "voxgi").symlink_to(REPO_ROOT, target_is_directory=True)
    sys.path.insert(0, tmp)
    sys.path.insert(0, str(REPO_ROOT / "tests" / "blender"))
    package = importlib.import_module("voxgi")
    package.register()
    return package


def build_scene(name):
    """A factory-empty file with GI scene ``name`` built into its scene; returns the scene."""
    import bpy
    import gi_scenes

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    gi_scenes.build(name, scene)
    return scene


def render(scene, samples, seed):
    """(passes, seconds) of a Cycles render as the references are made."""
    import gi_scenes
    from cycles_passes import last_render_seconds, render_cycles_passes

    passes = render_cycles_passes(scene, gi_scenes.WIDTH, gi_scenes.HEIGHT, samples,
                                  diffuse_bounces=1, ao_distance=AO_DISTANCE, seed=seed,
                                  glossy_bounces=1, filter_width=DEFAULT_FILTER_WIDTH)
    return passes, last_render_seconds()


def load_reference(path) -> dict[str, np.ndarray]:
    """A stored reference as float32 arrays (pass name → (H, W, 3), ``Alpha`` → (H, W))."""
    with np.load(path) as data:
        return {name: data[name].astype(np.float32) for name in data.files}


def relative_l1(ours, reference, mask) -> float:
    a, b = np.asarray(ours, np.float64)[mask], np.asarray(reference, np.float64)[mask]
    return float(np.abs(a - b).sum() / max(np.abs(b).sum(), 1e-30))


def write_png(path, passes):
    from voxgi.voxgi_addon.files.png import image_strip, to_srgb8
    from voxgi.voxgi_addon.files.png import write_png as write

    write(path, image_strip([to_srgb8(passes[n]) for n in ("Combined", "Diffuse Direct",
                                                           "Diffuse Indirect")], scale=2))


def main(argv=None):
    load_addon()
    import gi_scenes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(gi_scenes.SCENES))
    parser.add_argument("--samples", type=int, default=2048)
    parser.add_argument("--out", type=pathlib.Path, default=REPO_ROOT / "tests" / "data" / "gi_refs")
    parser.add_argument("--png", type=pathlib.Path, help="also write PNG strips here")
    parser.add_argument("--no-checks", action="store_true", help="skip the 16/64/256 spp renders")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "cycles_spp.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    for name in args.scenes:
        scene = build_scene(name)
        reference, seconds = render(scene, args.samples, seed=0)
        stored = {n: reference[n].astype(np.float16) for n in STORED}
        stored["Alpha"] = reference["Alpha"].astype(np.float16)
        path = args.out / f"{name}.npz"
        np.savez_compressed(path, **stored)
        print(f"{name}: {args.samples} spp in {seconds:.1f} s → {path} "
              f"({path.stat().st_size / 1024:.0f} KB)", flush=True)
        if args.png:
            args.png.mkdir(parents=True, exist_ok=True)
            write_png(args.png / f"{name}_cycles.png", reference)
        entry = {"reference_samples": args.samples, "reference_seconds": round(seconds, 2),
                 "size": [gi_scenes.WIDTH, gi_scenes.HEIGHT], "checks": {}}
        if not args.no_checks:
            mask = reference["Alpha"] > 0.5
            for samples in CHECK_SAMPLES:
                passes, t = render(scene, samples, seed=1)
                errors = {n: round(relative_l1(passes[n], reference[n], mask), 4)
                          for n in ("Diffuse Direct", "Diffuse Indirect", "Ambient Occlusion",
                                    "Combined")}
                entry["checks"][str(samples)] = {"seconds": round(t, 2), "relative_l1": errors}
                print(f"  {samples} spp: {t:.1f} s, {errors}", flush=True)
        summary[name] = entry
        summary_path.write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    main()
