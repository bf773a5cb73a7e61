"""``view_update`` on the 142k-triangle imported diorama (``diorama_scene.py``): the main
thread's time from the depsgraph's updates to the job submitted, per kind of edit, and where it
goes (docs/gi_pipeline.md "Snapshots that read only what changed"). Run by the ``imported``
section (``bench_imported.py``); standalone: ``.venv/bin/python
tools/bench/bench_view_update_blender.py [--quick] [--profile]``.

Each edit is made, the view layer updated, and the depsgraph's updates (collected by a
``depsgraph_update_post`` handler, as ``view_update`` reads them) handed to the scene's
``LiveGI``; the worker's job is left to finish before the next edit, so every row times the
main thread alone. Medians over rounds; the load average is printed, as the machine is shared.
"""
from __future__ import annotations

import argparse
import cProfile
import io
import os
import pathlib
import pstats
import statistics
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parents[1] / "tests" / "blender")]


def edits(scene):
    """(what, edit) pairs: each changes the scene a little (and back, over rounds)."""
    import bpy
    import numpy as np

    lamp = next(o for o in scene.objects if o.type == "LIGHT" and o.data.type == "POINT")
    rock = next(o for o in scene.objects if o.name.startswith("Rock"))
    camera = scene.camera
    material = rock.material_slots[0].material
    bsdf = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    sign = [1.0]

    def light():
        lamp.data.energy *= 1.05

    def move():
        rock.location.x += 0.05 * sign[0]

    def view():
        camera.location.x += 0.05 * sign[0]

    def colour():
        bsdf.inputs["Roughness"].default_value = 0.3 + 0.2 * (sign[0] > 0)

    def vertices():
        mesh = rock.data
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        mesh.vertices.foreach_set("co", co * (1.01 if sign[0] > 0 else 1 / 1.01))
        mesh.update()
        sign[0] = -sign[0]

    def hide():
        other = bpy.data.objects[rock.name.replace("0", "1", 1)] if "0" in rock.name else rock
        other.hide_render = not other.hide_render

    return [("a light's power", light), ("an object moved", move),
            ("the camera moved", view), ("a material's roughness", colour),
            ("one rock's vertices", vertices), ("an object hidden / shown", hide)]


def measure(rounds: int, profile: bool, faceless: bool = False) -> list:
    import bpy
    from bench_entering_blender import build

    from voxgi.blender import jobs
    from voxgi.blender.updates import records_from_depsgraph
    from voxgi.blender.viewport_session import READ_SLICE, live_gi

    jobs.synchronous = False
    scene = build("diorama")
    if faceless:  # a visible mesh object without faces (a guide line, a point cloud)
        mesh = bpy.data.meshes.new("Guide Line")
        mesh.from_pydata([(0.0, 0.0, 0.0), (1.0, 0.0, 0.0)], [(0, 1)], [])
        scene.collection.objects.link(bpy.data.objects.new("Guide Line", mesh))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    live = live_gi(scene.name_full)
    records = []

    def handler(_scene, graph):
        records.extend(records_from_depsgraph(graph, live.index))

    bpy.app.handlers.depsgraph_update_post.append(handler)
    t0 = time.perf_counter()
    live.update(scene, depsgraph)
    entering = time.perf_counter() - t0
    jobs.wait_idle(600)
    # the edits as the render engine's view_update hands them over: a full snapshot first
    # reads ahead what it would read, a slice at most (viewport_session.READ_SLICE)
    live.read_slice = READ_SLICE
    times: dict[str, list[float]] = {}
    profiler = cProfile.Profile() if profile else None
    try:
        for _ in range(rounds):
            for what, edit in edits(scene):
                records.clear()
                edit()
                bpy.context.view_layer.update()
                batch = list(records)
                if profiler is not None:
                    profiler.enable()
                t0 = time.perf_counter()
                live.update(scene, depsgraph, batch)
                times.setdefault(what, []).append(time.perf_counter() - t0)
                if profiler is not None:
                    profiler.disable()
                jobs.wait_idle(600)
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(handler)
    if profiler is not None:
        out = io.StringIO()
        pstats.Stats(profiler, stream=out).sort_stats("cumulative").print_stats(40)
        print(out.getvalue())
    rows = [("entering (the first view_update: every mesh read)", entering, "once")]
    rows += [(f"view_update: {what}", statistics.median(t),
              f"median of {len(t)}; longest {max(t) * 1000:.1f} ms") for what, t in times.items()]
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--profile", action="store_true", help="print a cProfile of the edits")
    ap.add_argument("--faceless", action="store_true",
                    help="add a visible mesh object without faces (an edge) to the diorama")
    args = ap.parse_args(argv)
    from bench_blender import load_addon, print_table

    load_addon()
    rows = measure(3 if args.quick else 9, args.profile, args.faceless)
    extra = " + a faceless object" if args.faceless else ""
    print_table(f"### view_update on the imported diorama{extra} (main thread; {os.cpu_count()} CPUs, "
                f"load average {os.getloadavg()[0]:.1f} at the end)", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
