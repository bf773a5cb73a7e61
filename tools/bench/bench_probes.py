"""Bench section "probes": runs tools/bench/bench_probes_blender.py with the bpy venv (.venv):
bake time and memory for k = 8, 16, 32 (exact numpy and GPU octree bakes), query time per
million points, EEVEE's volume-probe bake of the same box, and irradiance against Cycles."""
from __future__ import annotations

from bench_gi import run as run_blender_script


def run(quick: bool = False, out=print) -> str:
    return run_blender_script(quick, out, script="bench_probes_blender.py")
