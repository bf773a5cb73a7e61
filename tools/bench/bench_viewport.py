"""Bench section "viewport": runs tools/bench/bench_viewport_blender.py (view_draw, jobs, cancel,
debug view) and tools/bench/bench_viewport_converge_blender.py (the view's time to Cycles 16 spp
+ OIDN's error against Cycles', issue 31) with the bpy venv."""
from __future__ import annotations

import bench_gi

SCRIPTS = ("bench_viewport_blender.py", "bench_viewport_converge_blender.py")


def run(quick: bool = False, out=print) -> str:
    """Every script runs; one that fails does not hide the others' tables (as bench_gi)."""
    tables, failed = [], []
    for name in SCRIPTS:
        try:
            tables.append(bench_gi.run(quick, out, script=name))
        except RuntimeError as exc:
            failed.append(str(exc))
            out(f"**{name} failed** (the section goes on): {str(exc)[-600:]}\n")
    if failed:
        raise RuntimeError("; ".join(f.splitlines()[0] for f in failed))
    return "\n".join(tables)
