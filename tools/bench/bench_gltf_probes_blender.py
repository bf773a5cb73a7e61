"""Light-probe export rows of bench section "probes", run with the bpy venv: ``.venv/bin/python
tools/bench/bench_gltf_probes_blender.py [--quick]`` (docs/gltf_probes.md "Blender").

One exact bake of the demo scene (k = 16, 256 rays per probe; k = 8 with --quick), then the same
grid written both ways: Blender's glTF exporter (GLB) with and without the
VOXGI_irradiance_volumes extension, and the GFG exporter with and without probes — the
difference is what the probes cost in time and bytes — and the formats alone, without the
scene: ``voxgi_addon.files.gltf_probes`` (extension JSON + binary, as a GLB) against a GFG file
holding only the PRBG section. Times are medians of repeated runs.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import statistics
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from bench_blender import demo_snapshot, load_addon, print_table  # noqa: E402

KIB = 1024


def _median(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def _enabled(package="voxgi"):
    """io_scene_gltf2 calls the hooks of add-ons listed in the preferences only."""
    import bpy

    addons = bpy.context.preferences.addons
    if package not in addons.keys():
        addons.new().module = package


def export_rows(scene, grid, repeats=5):
    """Rows (what, seconds, note) for ``grid`` kept as ``scene``'s probes."""
    import bpy

    from voxgi.blender import probe_store
    from voxgi.voxgi_addon.files import gltf_probes as fmt
    from voxgi.voxgi_addon.files.gfg import GFGScene, to_bytes

    _enabled()
    probe_store.save_grids(scene, [grid])
    rows = []
    with tempfile.TemporaryDirectory(prefix="voxgi-bench-gltf-") as tmp:
        sizes, times = {}, {}
        for probes in (True, False):
            scene.voxgi_gltf.export_probes = probes
            path = os.path.join(tmp, f"scene_{probes}.glb")
            times["gltf", probes] = _median(lambda: bpy.ops.export_scene.gltf(
                filepath=path, export_format="GLB"), repeats)
            sizes["gltf", probes] = os.path.getsize(path)
            path = os.path.join(tmp, f"scene_{probes}.gfg")
            times["gfg", probes] = _median(lambda: bpy.ops.export_scene.gfg(
                filepath=path, export_probes=probes), repeats)
            sizes["gfg", probes] = os.path.getsize(path)
        scene.voxgi_gltf.export_probes = True
        assert len(fmt.read_volumes(os.path.join(tmp, "scene_True.glb"))) == 1

    p, v = len(grid.positions), len(grid.volume_cells)
    what = f"{p} probes, {v} active volumes"
    for kind, label in (("gltf", "glTF GLB (export_scene.gltf)"), ("gfg", "GFG (export_scene.gfg)")):
        extra_t = times[kind, True] - times[kind, False]
        extra_b = sizes[kind, True] - sizes[kind, False]
        rows.append((f"{label}, demo scene with probes", times[kind, True],
                     f"{sizes[kind, True] / KIB:.1f} KiB; without probes {times[kind, False] * 1000:.1f} ms, "
                     f"{sizes[kind, False] / KIB:.1f} KiB: the probes add {extra_t * 1000:+.1f} ms, "
                     f"{extra_b / KIB:.1f} KiB ({what})"))

    def gltf_alone():
        document, binary = fmt.new_document(), bytearray()
        fmt.add_volumes(document, binary, [grid])
        return fmt.glb_bytes(document, binary)

    def gfg_alone():
        return to_bytes(GFGScene(probe_grids=[grid]))

    def gltf_read():
        fmt.decode_volumes(fmt.GltfFile(*_split_glb(data_gltf)))

    data_gltf, data_gfg = gltf_alone(), gfg_alone()
    empty = len(to_bytes(GFGScene()))
    rows.append(("VOXGI_irradiance_volumes alone (encode → GLB bytes, numpy)", _median(gltf_alone, 3 * repeats),
                 f"{len(data_gltf) / KIB:.1f} KiB (float accessors + uint32 bufferViews, no index arrays)"))
    rows.append(("GFG PRBG section alone (to_bytes, numpy)", _median(gfg_alone, 3 * repeats),
                 f"{(len(data_gfg) - empty) / KIB:.1f} KiB (with the SH and occlusion index arrays and checksums)"))
    rows.append(("VOXGI_irradiance_volumes decode (every check)", _median(gltf_read, 3 * repeats),
                 "GLB bytes → ProbeGrid"))
    return rows


def _split_glb(data):
    """(document, buffer getter) of GLB bytes."""
    import struct

    json_len = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + json_len])
    bin_len = struct.unpack_from("<I", data, 20 + json_len)[0]
    binary = data[28 + json_len:28 + json_len + bin_len]
    return document, (lambda i: binary)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    load_addon()
    import bpy

    from voxgi.voxgi_addon.probes.bake import ProbeSettings, bake_probe_grid

    scene, snapshot = demo_snapshot()
    k = 8 if args.quick else 16
    grid = bake_probe_grid(snapshot, ProbeSettings(resolution=k, directions=256)).grid
    grid.name = scene.name
    rows = export_rows(scene, grid, repeats=3 if args.quick else 5)
    print_table(f"### Light probes in files: demo scene, exact bake k = {k}, 256 rays per probe; "
                "the same grid through glTF (VOXGI_irradiance_volumes) and GFG", rows)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
