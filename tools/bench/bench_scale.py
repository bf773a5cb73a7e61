"""Bench section "scale": runs tools/bench/bench_scale_blender.py with the bpy venv."""
from __future__ import annotations

import bench_gi


def run(quick: bool = False, out=print) -> str:
    return bench_gi.run(quick, out, script="bench_scale_blender.py")
