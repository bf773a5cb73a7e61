"""Bench section "viewport": runs tools/bench/bench_viewport_blender.py with the bpy venv."""
from __future__ import annotations

import bench_gi


def run(quick: bool = False, out=print) -> str:
    return bench_gi.run(quick, out, script="bench_viewport_blender.py")
