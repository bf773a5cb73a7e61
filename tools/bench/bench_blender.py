"""Helpers shared by the benchmark scripts that run inside the bpy venv (``bench_*_blender.py``).

``load_addon`` imports the repository as the add-on package ``voxgi`` (through a symlink, as
the tests do) and registers it; ``demo_snapshot`` builds the demo scene in a factory-empty
file; ``median_seconds`` times a call; ``print_table`` prints the rows as markdown.
"""
from __future__ import annotations

import importlib
import pathlib
import statistics
import sys
import tempfile
import time

REPO_ROOT = pathlib.Path(__file__).resolve().parents[2]


def median_seconds(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def load_addon():
    """The registered add-on package ``voxgi`` (importing bpy)."""
    tmp = tempfile.mkdtemp(prefix="voxgi-bench-")
    (pathlib.Path(tmp) / "voxgi").symlink_to(REPO_ROOT, target_is_directory=True)
    sys.path.insert(0, tmp)
    voxgi = importlib.import_module("voxgi")
    voxgi.register()
    return voxgi


def demo_snapshot():
    """(scene, snapshot) of the demo scene built in a factory-empty file."""
    import bpy

    from voxgi.blender.demo_scene import build_demo_scene
    from voxgi.blender.snapshot.scene import take_snapshot

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    build_demo_scene(scene)
    return scene, take_snapshot(bpy.context, bpy.context.evaluated_depsgraph_get())


def print_table(title: str, rows) -> None:
    """rows : (what, seconds or 0 for none, notes)."""
    print(f"{title}\n")
    print("| what | median time | notes |\n|---|---:|---|")
    for name, seconds, note in rows:
        shown = f"{seconds * 1000:.1f} ms" if seconds else "—"
        print(f"| {name} | {shown} | {note} |")
