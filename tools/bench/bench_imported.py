"""Bench section "imported": runs tools/bench/bench_imported_blender.py with the bpy venv (.venv)."""
from __future__ import annotations

from bench_gi import run as _run_blender_script


def run(quick: bool = False, out=print) -> str:
    return _run_blender_script(quick, out, "bench_imported_blender.py")
