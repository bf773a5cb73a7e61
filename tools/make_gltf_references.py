"""Cycles references of the glTF round-trip scene of issue 22 (tests/blender/gltf_scenes.py).

Usage: ``.venv/bin/python tools/make_gltf_references.py [--samples 2048]
[--out tests/data/gltf_refs]``

As ``make_light_references.py``: one bounce of either kind, Cycles' default transparent
bounces, 160 × 120, AO distance 1 m, Cycles' default pixel filter (Blackman-Harris 1.5 px),
float16 passes in ``<out>/<scene>.npz``; ``<out>/cycles_spp.json`` gets the reference's time
and the relative L1 and time of Cycles 16 spp + OpenImageDenoise and of 64 spp, with another
seed.
"""
from __future__ import annotations

import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_light_references import make_references  # noqa: E402

CHECKED = ("Combined", "Diffuse Color", "Diffuse Direct", "Diffuse Indirect", "Glossy Direct",
           "Glossy Indirect")


def main(argv=None):
    make_references(argv, "gltf_scenes", "gltf_refs", CHECKED, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
