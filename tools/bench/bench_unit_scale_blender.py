"""Voxelize and Update of a unit-scaled rig beside the same rig with its scale applied (issue 22),
run with the bpy venv: ``.venv/bin/python tools/bench/bench_unit_scale_blender.py [--quick]``.

The character of ``tests/blender/unit_scale_scenes.py`` (~11k triangles, 11 bones, posed) in a
6 × 5 × 3 m room, once as Blender's glTF/FBX importers leave Mixamo-style rigs (armature object
at scale 0.01, mesh vertices and bones in centimetres) and once with the scale applied. Per
variant, through the operators in background mode (synchronous): ``voxgi.voxelize`` (snapshot,
view fit and every cache), ``voxgi.update`` after posing a bone (only the character is
transformed again; light and octree are rebuilt) and ``voxgi.update`` with nothing changed
(the previous state is kept), each the median of ``repeats``; the voxels per cascade of the
caches and of the cascades. Goals: the two variants within 20% of each other, an unchanged
Update at most 5% of a posed one. Prints a markdown table.
"""
from __future__ import annotations

import argparse
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path[:0] = [str(HERE), str(ROOT / "tests" / "blender")]
from bench_blender import load_addon, median_seconds  # noqa: E402

DETAIL = 1.1  # ~11k triangles, as the character measured in issue 22


def _median(fn, repeats):
    return median_seconds(fn, repeats)


def measure(voxgi, unit, repeats):
    import bpy
    import unit_scale_scenes as scenes

    from voxgi.blender.session import scene_session

    bpy.ops.wm.read_factory_settings(use_empty=True)
    if not hasattr(bpy.types.Scene, "voxgi"):
        voxgi.register()
    scene = bpy.context.scene
    built = scenes.build_character_room(scene, unit, DETAIL)
    triangles = sum(len(p.vertices) - 2 for p in built["body"].data.polygons)
    session = scene_session(scene.name_full)

    def voxelize():
        assert bpy.ops.voxgi.voxelize() == {"FINISHED"}

    voxelize_s = _median(voxelize, repeats)
    caches = [s.voxel_count for s in session.caches.cascade_stats]
    assert bpy.ops.voxgi.update() == {"FINISHED"}
    bone = built["rig"].pose.bones["Forearm.L"]
    sign = [1.0]

    def posed():
        sign[0] = -sign[0]
        bone.rotation_euler.x += 0.2 * sign[0]
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        assert session.gi_state.placed_objects == (built["body"].name,)

    posed_s = _median(posed, repeats)
    posed_timings = dict(session.gi_timings)

    def unchanged():
        assert bpy.ops.voxgi.update() == {"FINISHED"}
        assert session.gi_state.reused == "all"

    unchanged_s = _median(unchanged, repeats)
    unchanged_timings = dict(session.gi_timings)
    return {"triangles": triangles, "voxelize": voxelize_s, "caches": caches,
            "cascades": session.gi_state.voxel_counts, "posed": posed_s, "unchanged": unchanged_s,
            "posed_transform": posed_timings.get("transform", 0.0),
            "posed_snapshot": posed_timings.get("snapshot", 0.0),
            "unchanged_snapshot": unchanged_timings.get("snapshot", 0.0)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    voxgi = load_addon()
    repeats = 3 if args.quick else 7
    rows = {"armature at 0.01, mesh and bones in cm": measure(voxgi, 0.01, repeats),
            "scale applied (metres)": measure(voxgi, 1.0, repeats)}

    def counts(values):
        return " / ".join(f"{v:,}" for v in values)

    print(f"### Unit-scaled rig: the ~{next(iter(rows.values()))['triangles']:,}-triangle "
          f"character in a 6 × 5 × 3 m room, operators in background mode, medians of "
          f"{repeats}\n")
    print("| rig | cache voxels per cascade | Voxelize | Update, bone posed (transform) "
          "| Update, nothing changed (snapshot) | unchanged / posed (without the snapshots) "
          "| cascade voxels |\n"
          "|---|---:|---:|---:|---:|---:|---:|")
    for name, r in rows.items():
        print(f"| {name} | {counts(r['caches'])} | {r['voxelize'] * 1000:.0f} ms | "
              f"{r['posed'] * 1000:.0f} ms ({r['posed_transform'] * 1000:.0f} ms) | "
              f"{r['unchanged'] * 1000:.1f} ms ({r['unchanged_snapshot'] * 1000:.1f} ms) | "
              f"{r['unchanged'] / r['posed']:.1%} "
              f"({(r['unchanged'] - r['unchanged_snapshot']) / (r['posed'] - r['posed_snapshot']):.1%})"
              f" | {counts(r['cascades'])} |")
    cm, m = rows.values()
    print(f"| cm / applied | {sum(cm['caches']) / sum(m['caches']):.3f} | "
          f"{cm['voxelize'] / m['voxelize']:.2f} | {cm['posed'] / m['posed']:.2f} | "
          f"{cm['unchanged'] / m['unchanged']:.2f} | | "
          f"{sum(cm['cascades']) / max(sum(m['cascades']), 1):.3f} |")
    print("\nGoals: cm / applied within 0.8–1.2; an unchanged Update ≤ 5% of a posed one. "
          "The unchanged Update is mostly the scene snapshot, which a full snapshot of a "
          "skinned mesh needs to see that nothing changed.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
