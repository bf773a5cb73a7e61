"""``make bench``: run every benchmark section and print its markdown table (dev-only).

Usage: ``.venv-bench/bin/python tools/bench/bench.py [SECTION ...] [--quick]``

Each section lives in its own module ``tools/bench/bench_<name>.py`` and exposes
``run(quick: bool = False, out=print) -> str``: it prints its table through ``out`` and returns
it. To add a section (per-update time, preview vs Cycles, GFG I/O, ...) write the module and add
one line to ``SECTIONS``. Sections run one after another, never in parallel (2-core machines).
"""
from __future__ import annotations

import argparse
import importlib
import os
import platform
import sys
import time
from pathlib import Path

TOOLS = Path(__file__).resolve().parent
if str(TOOLS) not in sys.path:
    sys.path.insert(0, str(TOOLS))

# name -> (module in tools/, one-line description)
SECTIONS = {
    "preview": ("bench_preview", "one preview vs Cycles 16/64 spp + OIDN on six scenes at two sizes "
                                 "(first and warm), split into stages against the machine's floor"),
    "voxelize": ("bench_voxelize", "surface voxelization vs trimesh and Open3D"),
    "gfg": ("bench_gfg", "GFG file write/read throughput vs numpy.save/numpy.load"),
    "gi": ("bench_gi", "per-update time, preview time and Cycles time/error; multi-bounce "
                       "interiors vs Cycles 16/64 spp ± OIDN at its default light paths (.venv)"),
    "gpu": ("bench_gpu", "GPU tracer: filtered samples/s and preview times vs numpy and Cycles"),
    "viewport": ("bench_viewport", "live viewport GI: main-thread stall, move → GI latency, cancel, "
                                   "debug-view draw of 1M voxels; time until the view is within "
                                   "Cycles 16 spp + OIDN's error of F12's image"),
    "probes": ("bench_probes", "light-probe bake time/memory (numpy, GPU), queries, EEVEE, Cycles; "
                               "glTF (VOXGI_irradiance_volumes) vs GFG export time and size"),
    "animation": ("bench_animation", "F12 animation render of a walking rig vs Cycles 16 spp + OIDN"),
    "lights": ("bench_lights", "HDRI, sky, emissive and metal scenes: preview vs Cycles 16/64 spp "
                               "with and without OIDN"),
    "scale": ("bench_scale", "a 1.06M-triangle city block of instanced domes: snapshot, BVH build, "
                             "upload, trace, peak memory vs Cycles 16 spp + OIDN"),
    "imported": ("bench_imported", "the glTF round-trip scene: voxelize, update, preview and its "
                                   "error vs Cycles 16 spp + OIDN"),
}


def _versions() -> str:
    parts = [f"Python {platform.python_version()}"]
    for mod in ("numpy", "trimesh", "open3d"):
        try:
            parts.append(f"{mod} {importlib.import_module(mod).__version__}")
        except Exception as exc:  # noqa: BLE001 - report, don't fail the header
            parts.append(f"{mod} unavailable ({type(exc).__name__})")
    parts.append(f"{os.cpu_count()} CPUs")
    blas = {k: os.environ[k] for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE") if k in os.environ}
    if blas:
        parts.append(f"env {blas}")
    return ", ".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="VoxGI benchmarks (dev-only).")
    ap.add_argument("sections", nargs="*", metavar="SECTION",
                    help=f"sections to run (default: all): {', '.join(SECTIONS)}")
    ap.add_argument("--quick", action="store_true",
                    help="smaller inputs and fewer repeats, for checking the tooling itself")
    args = ap.parse_args(argv)
    unknown = [n for n in args.sections if n not in SECTIONS]
    if unknown:
        ap.error(f"unknown section(s) {unknown}; known: {', '.join(SECTIONS)}")
    names = args.sections or list(SECTIONS)

    print(f"## VoxGI benchmarks\n\n{_versions()}\n", flush=True)
    failed = []
    for name in names:
        module_name, description = SECTIONS[name]
        print(f"<!-- section {name}: {description} -->", flush=True)
        t0 = time.perf_counter()
        try:
            module = importlib.import_module(module_name)
            module.run(quick=args.quick, out=lambda text: print(text, flush=True))
        except Exception as exc:  # noqa: BLE001 - one broken section must not hide the others
            failed.append(name)
            print(f"**section {name} failed:** {type(exc).__name__}: {exc}", flush=True)
        print(f"\n_({name}: {time.perf_counter() - t0:.0f} s)_\n", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
