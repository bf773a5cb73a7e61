"""Bench section "imported": entering Rendered mode on the 140k-triangle imported diorama
(``bench_entering_blender.py --scene diorama``), run with the bpy venv."""
from __future__ import annotations

import sys

from bench_entering_blender import main

if __name__ == "__main__":
    sys.exit(main(["--scene", "diorama", *sys.argv[1:]]))
