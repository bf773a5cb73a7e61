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

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_bounce_references import make_references  # noqa: E402
from make_gi_references import load_addon  # noqa: E402

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


def light_paths(scene) -> dict:
    """The scene's own Cycles light path settings, as the reference used them."""
    return {key: getattr(scene.cycles, key)
            for key in (*LIGHT_PATHS, "transparent_max_bounces", "caustics_reflective",
                        "caustics_refractive")}


def main(argv=None):
    load_addon()
    import glass_scenes

    make_references(argv, glass_scenes, "glass_refs", render, CHECKED, light_paths,
                    __doc__.splitlines()[0], samples=4096)


if __name__ == "__main__":
    main()
