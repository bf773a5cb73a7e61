"""Cycles references of the emissive-texture room of issues 18 / 22 (tests/blender/emission_scenes.py).

Usage: ``.venv/bin/python tools/make_emission_references.py [--samples 4096]
[--out tests/data/emission_refs]``

As ``make_light_references.py``: one bounce of either kind, 160 × 120, AO distance 1 m,
Cycles' default pixel filter (Blackman-Harris 1.5 px), float16 passes in
``<out>/<scene>.npz``; ``<out>/cycles_spp.json`` gets the reference's time and the relative L1
and time of Cycles 16 spp + OpenImageDenoise and of 64 spp, with another seed.
"""
from __future__ import annotations

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_light_references import make_references  # noqa: E402

CHECKED = ("Combined", "Diffuse Color", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct")


def main(argv=None):
    make_references(argv, "emission_scenes", "emission_refs", CHECKED, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
