"""Bench section "probes": runs tools/bench/bench_probes_blender.py with the bpy venv (.venv):
bake time and memory for k = 8, 16, 32 (exact numpy and GPU octree bakes), query time per
million points, EEVEE's volume-probe bake of the same box, and irradiance against Cycles; then
tools/bench/bench_gltf_probes_blender.py: export time and file size of one bake through glTF
(VOXGI_irradiance_volumes) beside GFG; then bench_web_probes.py: the three.js reader's load to
first frame in headless Chromium."""
from __future__ import annotations

import bench_web_probes
from bench_gi import run_scripts


def run(quick: bool = False, out=print) -> str:
    tables = []
    try:
        tables.append(run_scripts(("bench_probes_blender.py", "bench_gltf_probes_blender.py"), quick, out))
    finally:  # the browser's table even when a Blender script failed
        tables.append(bench_web_probes.run(quick, out))
    return "\n".join(tables)
