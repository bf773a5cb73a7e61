"""Bench section "viewport": runs tools/bench/bench_viewport_blender.py (view_draw, jobs, cancel,
debug view), tools/bench/bench_entering_blender.py (entering Rendered mode on the demo box: every
draw's main-thread time to the first image, then an orbit, a slider drag and an object move,
docs/gi_pipeline.md "Entering Rendered mode") and tools/bench/bench_viewport_converge_blender.py
(the view's time to Cycles 16 spp + OIDN's error against Cycles', docs/gi_pipeline.md "Where a
preview's time goes") and tools/bench/bench_viewport_bakes_blender.py (node-built materials baked in
the view's draws, docs/gi_pipeline.md "Bakes a slice at a time") with the bpy venv."""
from __future__ import annotations

import bench_gi

SCRIPTS = ("bench_viewport_blender.py", "bench_entering_blender.py",
           "bench_viewport_converge_blender.py", "bench_viewport_bakes_blender.py")


def run(quick: bool = False, out=print) -> str:
    """Both scripts (``bench_gi.run_scripts``)."""
    return bench_gi.run_scripts(SCRIPTS, quick, out)
