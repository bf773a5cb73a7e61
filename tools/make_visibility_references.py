"""Cycles references of the ray-visibility room of issue 18 (tests/blender/visibility_scenes.py).

Usage: ``.venv/bin/python tools/make_visibility_references.py [--samples 2048]
[--out tests/data/visibility_refs]``

As ``make_light_references.py``: one bounce of either kind, 160 × 120, AO distance 1 m,
Cycles' default pixel filter (Blackman-Harris 1.5 px), film transparent (a holdout's pixels
have alpha 0 and Combined 0), float16 passes in ``<out>/<scene>.npz``;
``<out>/cycles_spp.json`` gets the reference's time and the relative L1 and time of Cycles
16 spp + OpenImageDenoise and of 64 spp, with another seed.
"""
from __future__ import annotations

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_light_references import make_references  # noqa: E402

CHECKED = ("Combined", "Diffuse Color", "Diffuse Direct", "Diffuse Indirect", "Glossy Indirect")


def main(argv=None):
    make_references(argv, "visibility_scenes", "visibility_refs", CHECKED,
                    __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
