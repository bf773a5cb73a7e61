"""GI benchmark rows, run with the bpy venv: ``.venv/bin/python tools/bench/bench_gi_blender.py``.

Per-update time (cascades + SVO + injection) against re-voxelizing every object each frame,
preview times, and Cycles at 16/64/256 spp with each one's time and Diffuse Indirect error
against a high-spp Cycles reference of the same view. Prints a markdown table.
"""
from __future__ import annotations

import argparse
import pathlib
import sys

sys.path[:0] = [str(pathlib.Path(__file__).resolve().parent),
                str(pathlib.Path(__file__).resolve().parents[1])]  # tools/: gi_compare, cycles_passes
from bench_blender import demo_snapshot, load_addon, median_seconds, print_table  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()

    import gi_compare

    from voxgi.blender.settings import cone_settings
    from voxgi.voxgi_addon.gi.update import GISettings, update_gi
    from voxgi.voxgi_addon.preview.passes import render_passes
    from voxgi.voxgi_addon.voxelize.scene_caches import build_scene_caches

    scene, snapshot = demo_snapshot()
    span, cascades = scene.voxgi.base_span, scene.voxgi.cascade_count
    caches = build_scene_caches(snapshot, span, cascades)
    repeats = 3 if args.quick else 7
    rows = []
    for res in (64, 128):
        settings = GISettings(resolution=res)
        update = median_seconds(lambda: update_gi(snapshot, caches, settings), repeats)
        revox = median_seconds(lambda: update_gi(snapshot, build_scene_caches(snapshot, span, cascades),
                                                 settings), repeats)
        rows.append((f"per-update, demo scene, 3×{res}³ (cascades+SVO+injection)", update,
                     f"re-voxelizing every object each frame: {revox * 1000:.1f} ms ({revox / update:.1f}× slower)"))
    state = update_gi(snapshot, caches, GISettings(resolution=64))
    cones = cone_settings(scene.voxgi)
    sizes = [(160, 120), (320, 240)]
    for w, h in sizes:
        seconds = median_seconds(lambda: render_passes(snapshot, state, w, h, cones), 1 if args.quick else 3)
        rows.append((f"preview {w}×{h} (numpy tracer, after the update)", seconds, ""))

    w, h = sizes[0]
    ours, _ = render_passes(snapshot, state, w, h, cones)
    ref_spp = 256 if args.quick else 2048
    reference, ref_seconds = gi_compare.render_cycles(scene, w, h, ref_spp, scene.voxgi.ao_distance)
    mask = (ours["Diffuse Color"].sum(-1) > 0) & (reference["Diffuse Color"].sum(-1) > 0)
    err = gi_compare.relative_l1(ours["Diffuse Indirect"], reference["Diffuse Indirect"], mask)
    ours_seconds = rows[2][1] + rows[0][1]
    rows.append((f"VoxGI preview {w}×{h} incl. update", ours_seconds,
                 f"Diffuse Indirect error {err:.3f}"))
    for spp in (16, 64, 256):
        passes, seconds = gi_compare.render_cycles(scene, w, h, spp, scene.voxgi.ao_distance)
        e = gi_compare.relative_l1(passes["Diffuse Indirect"], reference["Diffuse Indirect"], mask)
        rows.append((f"Cycles {spp} spp {w}×{h}, one diffuse bounce", seconds,
                     f"Diffuse Indirect error {e:.3f}"))
    print_table(f"### GI: demo scene ({len(snapshot.objects)} objects), base span {span:g} m, "
                f"{cascades} cascades; errors are relative L1 over geometry pixels against "
                f"Cycles {ref_spp} spp ({ref_seconds:.1f} s); medians of {repeats}", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
