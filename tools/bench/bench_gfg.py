"""Benchmark: GFG file write/read throughput against numpy.save / numpy.load (dev-only).

Run through ``tools/bench/bench.py`` (``make bench``), or alone:
``.venv-bench/bin/python tools/bench/bench_gfg.py [--repeats 5] [--voxels 10000000] [--triangles 200000]``.

The data, generated here with numpy: a 200k-triangle grid mesh (float32 positions, normals and
UVs, uint32 indices) and 10 M voxels in ten packed caches of 1 M (three u32 words each; the
last two caches skinned, two more words each). The GFG file holds exactly these arrays (the
mesh interleaved into one vertex buffer); numpy gets the same arrays, one ``.npy`` file each.

What is timed (median of ``repeats`` after one warm-up, GFG and numpy runs alternating, files
in one temporary folder, so both sides read from the page cache):
* write — ``write_gfg(path, scene)`` (CRC-32 of every section included) vs ``numpy.save`` of
  every array;
* read — ``read_gfg(path)``: memory-map, check every checksum and bound, map every array (zero
  copy) vs ``numpy.load`` of every array (into memory). Also shown: GFG reading the file into
  memory first (``read_gfg(open(path).read())``) and mapping without checksums.
MB/s = file bytes / seconds (both sides write about the same number of bytes).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

_TOOLS = str(Path(__file__).resolve().parent)
if _TOOLS not in sys.path:
    sys.path.insert(0, _TOOLS)
from bench_common import engine_module  # noqa: E402

DEFAULT_VOXELS = 10_000_000
DEFAULT_TRIANGLES = 200_000
DEFAULT_REPEATS = 5
CACHES = 10


def make_scene(gfg, voxels: int, triangles: int, seed: int = 0):
    """(GFGScene, {name: array}) with the same arrays on both sides."""
    model = engine_module("files.gfg.model")
    spec = engine_module("files.gfg.spec")
    code_of = engine_module("files.gfg.data_types").code_of
    VoxelCache = engine_module("voxelize.cache").VoxelCache
    rng = np.random.default_rng(seed)
    nx = 400
    ny = max(1, triangles // (2 * nx))
    x, y = np.meshgrid(np.linspace(0, 1, nx + 1), np.linspace(0, 1, ny + 1))
    positions = np.stack([x, y, 0.05 * np.sin(9 * x) * np.cos(7 * y)], -1).reshape(-1, 3).astype(np.float32)
    normals = rng.normal(size=positions.shape).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    uvs = np.stack([x, y], -1).reshape(-1, 2).astype(np.float32)
    idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    indices = np.concatenate([np.stack([a, b, d], -1), np.stack([a, d, c], -1)]).reshape(-1).astype(np.uint32)
    mesh = model.Mesh("grid", [model.VertexComponent(spec.Logic.POSITION, code_of("FLOAT_3"), positions),
                               model.VertexComponent(spec.Logic.NORMAL, code_of("FLOAT_3"), normals),
                               model.VertexComponent(spec.Logic.UV, code_of("FLOAT_2"), uvs)],
                      indices, np.stack([positions.min(0), positions.max(0)]))
    arrays = {"positions": positions, "normals": normals, "uvs": uvs, "indices": indices}
    caches, per = [], voxels // CACHES
    for i in range(CACHES):
        count = per if i < CACHES - 1 else voxels - per * (CACHES - 1)
        words = [rng.integers(0, 2**32, count, dtype=np.uint32) for _ in range(5 if i >= CACHES - 2 else 3)]
        caches.append(VoxelCache(f"mesh{i}", 0, 0.25, np.zeros(3, np.int64), np.full(3, 1024, np.int64),
                                 *words[:3], *(words[3:] or [None, None])))
        for name, w in zip(("positions", "normals", "colors", "weights", "bone_indices"), words):
            arrays[f"cache{i}_{name}"] = w
    voxel_set = model.VoxelSet(0.25, 1, [c.key for c in caches], caches)
    return model.GFGScene(meshes=[mesh], voxels=voxel_set), arrays


def _paired_medians(ours, theirs, repeats: int) -> tuple[float, float]:
    """Median seconds of two functions run alternately (after one warm-up each), so drifts of
    the page cache or the machine hit both alike."""
    ours(), theirs()
    times = ([], [])
    for _ in range(repeats):
        for fn, out in ((ours, times[0]), (theirs, times[1])):
            start = time.perf_counter()
            fn()
            out.append(time.perf_counter() - start)
    return statistics.median(times[0]), statistics.median(times[1])


def run(quick: bool = False, out=print, repeats: int | None = None, voxels: int | None = None,
        triangles: int | None = None) -> str:
    """Time GFG against numpy; return (and ``out``) the markdown table."""
    gfg = engine_module("files.gfg")
    repeats = repeats or (2 if quick else DEFAULT_REPEATS)
    voxels = voxels or (1_000_000 if quick else DEFAULT_VOXELS)
    triangles = triangles or (20_000 if quick else DEFAULT_TRIANGLES)
    scene, arrays = make_scene(gfg, voxels, triangles)
    with tempfile.TemporaryDirectory(prefix="voxgi-bench-gfg-") as tmp:
        path = Path(tmp) / "scene.gfg"
        npy = {name: Path(tmp) / f"{name}.npy" for name in arrays}

        def numpy_write():
            for name, a in arrays.items():
                np.save(npy[name], a)

        def numpy_read():
            return [np.load(p) for p in npy.values()]

        def gfg_read_bytes():
            with open(path, "rb") as f:
                return gfg.read_gfg(f.read())

        rows = [("write", *_paired_medians(lambda: gfg.write_gfg(path, scene), numpy_write, repeats))]
        gfg_bytes = path.stat().st_size
        npy_bytes = sum(p.stat().st_size for p in npy.values())
        back = gfg.read_gfg(path)
        assert np.array_equal(back.voxels.caches[-1].bone_indices, scene.voxels.caches[-1].bone_indices)
        assert np.array_equal(back.meshes[0].indices, arrays["indices"])
        for label, fn in (("read: mmap, verify every CRC, map arrays", lambda: gfg.read_gfg(path)),
                          ("read: into memory, verify, map arrays", gfg_read_bytes),
                          ("read: mmap, map arrays (no CRC)", lambda: gfg.read_gfg(path, verify=False))):
            rows.append((label, *_paired_medians(fn, numpy_read, repeats)))
    lines = [
        f"GFG I/O: {voxels / 1e6:g} M voxels in {CACHES} caches + a {len(arrays['indices']) // 3 / 1e3:g}k-triangle "
        f"mesh; GFG file {gfg_bytes / 1e6:.1f} MB, {len(arrays)} .npy files {npy_bytes / 1e6:.1f} MB; "
        f"median of {repeats}",
        "",
        "| operation | GFG s | GFG MB/s | numpy s | numpy MB/s | GFG time / numpy time |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for label, ours, theirs in rows:
        lines.append(f"| {label} | {ours:.3f} | {gfg_bytes / ours / 1e6:,.0f} | {theirs:.3f} | "
                     f"{npy_bytes / theirs / 1e6:,.0f} | {ours / theirs:.2f} |")
    table = "\n".join(lines)
    out(table)
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=DEFAULT_REPEATS)
    ap.add_argument("--voxels", type=int, default=DEFAULT_VOXELS)
    ap.add_argument("--triangles", type=int, default=DEFAULT_TRIANGLES)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    run(quick=args.quick, repeats=args.repeats, voxels=args.voxels, triangles=args.triangles)


if __name__ == "__main__":
    main()
