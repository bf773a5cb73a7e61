"""Bench section "imported": runs tools/bench/bench_imported_blender.py (the glTF round-trip room:
voxelize, update and preview against Cycles) and tools/bench/bench_entering_imported_blender.py
(entering Rendered mode on a 140k-triangle imported diorama: every draw's main-thread time to the
first image, then an orbit, a slider drag and an object move, docs/gi_pipeline.md "Entering
Rendered mode") and tools/bench/bench_view_update_blender.py (``view_update`` per kind of edit
on the diorama, docs/gi_pipeline.md "Snapshots that read only what changed") with the bpy venv
(.venv)."""
from __future__ import annotations

from bench_gi import run_scripts

SCRIPTS = ("bench_imported_blender.py", "bench_entering_imported_blender.py",
           "bench_view_update_blender.py")


def run(quick: bool = False, out=print) -> str:
    return run_scripts(SCRIPTS, quick, out)
