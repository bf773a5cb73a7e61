"""Benchmark: surface voxelization, ours against trimesh and Open3D (dev-only); then Voxelize and
Update of a centimetre rig at scale 0.01 beside the same rig with its scale applied
(``bench_unit_scale_blender.py``, run with the bpy venv).

Run through ``tools/bench/bench.py`` (``make bench``), or alone:
``.venv-bench/bin/python tools/bench/bench_voxelize.py [--repeats 5] [--triangles 100000]``.

The mesh is generated here, deterministically, with numpy alone: a closed tube (genus 1) around
a trefoil knot, with its radius modulated by sine bumps and its parameters warped so triangle
sizes vary ~6x and orientations cover the sphere; it is rotated off the axes. Nothing is
downloaded.

What is compared
----------------
* ``ours``    — ``voxgi_addon.voxelize.voxelize_triangles`` (exact closed triangle/box test).
* ``trimesh`` — ``Trimesh(v, f, process=False).voxelized(pitch)`` (default method
  ``subdivide``: split triangles until edges < pitch/2, then round the vertices to cells).
* ``open3d``  — ``VoxelGrid.create_from_triangle_mesh(mesh, voxel_size)`` (SAT per candidate
  cell, closed boxes).

Each time is the median of ``repeats`` runs after one warm-up, from numpy arrays to the tool's
voxel object (the peers' mesh objects are built inside the timed call; turning their results
into index arrays is not timed).

One lattice for all
-------------------
Our cell ``c`` is ``[(c - ε)·s, (c + 1 - ε)·s]`` per axis (``ε = LATTICE_OFFSET`` voxel).
* Open3D's grid origin is ``AABB min - s/2`` and its voxel ``g`` is
  ``[origin + g·s, origin + (g + 1)·s]``; the mesh is translated so that its AABB min is
  ``(1/2 - ε)·s``, which puts Open3D's origin at ``-ε·s``: Open3D voxel ``g`` is our cell ``g``.
* trimesh rounds ``v / pitch`` to the nearest integer (voxel ``n`` is centred on ``n·pitch``);
  it gets the mesh translated by ``-(1/2 - ε)·s`` so its voxel ``n`` is our cell ``n``.
A small mesh is checked first against an independent brute force so a change of convention in
a peer shows up as a failed self-check instead of silently wrong "missed" numbers.

"missed" = cells of the exact set (ours) a tool lacks; "extra" = a tool's cells not in it.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

_TOOLS = str(Path(__file__).resolve().parent)
if _TOOLS not in sys.path:
    sys.path.insert(0, _TOOLS)
from bench_common import engine_module  # noqa: E402

GRIDS = (128, 256)
DEFAULT_TRIANGLES = 100_000
DEFAULT_REPEATS = 5
AROUND = 50  # vertices around the tube


# --------------------------------------------------------------------------- the mesh

def _rotation(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def knot_tube_mesh(triangles: int = DEFAULT_TRIANGLES, around: int = AROUND):
    """A closed, bumpy tube around a trefoil knot with about ``triangles`` triangles.

    Returns positions (V, 3) float64 and triangles (T, 3) int32; T = 2 · along · around.
    Every edge is shared by exactly two triangles.
    """
    along = max(8, int(round(triangles / (2 * around))))
    u = 2 * np.pi * np.arange(along) / along
    w = 2 * np.pi * np.arange(around) / around
    t = u + 0.7 / 3 * np.sin(3 * u)          # warped: segment lengths vary ~5.7x along
    phi = w + 0.5 / 2 * np.sin(2 * w)        # and ~3x around

    p, q, big_r, a = 2, 3, 1.0, 0.45
    r = big_r + a * np.cos(q * t)
    dr = -a * q * np.sin(q * t)
    centre = np.stack([r * np.cos(p * t), r * np.sin(p * t), a * np.sin(q * t)], axis=1)
    tangent = np.stack([dr * np.cos(p * t) - r * p * np.sin(p * t),
                        dr * np.sin(p * t) + r * p * np.cos(p * t),
                        a * q * np.cos(q * t)], axis=1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, [0.0, 0.0, 1.0])  # the tangent is never vertical for this knot
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)

    tt, pp = t[:, None], phi[None, :]
    radius = 0.16 * (1 + 0.35 * np.sin(5 * tt)) * (1 + 0.12 * np.sin(3 * pp + 4 * tt))
    offset = (np.cos(pp)[..., None] * normal[:, None, :] + np.sin(pp)[..., None] * binormal[:, None, :])
    positions = (centre[:, None, :] + radius[..., None] * offset).reshape(-1, 3)
    positions = positions @ _rotation([1.0, 2.0, 0.5], 0.6).T

    i, j = np.meshgrid(np.arange(along), np.arange(around), indexing="ij")
    i1, j1 = (i + 1) % along, (j + 1) % around
    a00, a10, a11, a01 = i * around + j, i1 * around + j, i1 * around + j1, i * around + j1
    flip = ((i + j) % 2 == 1)[..., None]  # alternate the quad diagonal
    first = np.where(flip, np.stack([a00, a10, a01], -1), np.stack([a00, a10, a11], -1))
    second = np.where(flip, np.stack([a10, a11, a01], -1), np.stack([a00, a11, a01], -1))
    tris = np.concatenate([first.reshape(-1, 3), second.reshape(-1, 3)]).astype(np.int32)
    return positions, tris


def place_on_lattice(positions, span, offset):
    """Translate so the AABB min is at ``(1/2 - offset) · span`` on every axis (see module doc)."""
    return positions - positions.min(axis=0) + (0.5 - offset) * span


# --------------------------------------------------------------------------- brute force

def overlaps(tri, cells):
    """Closed triangle / unit-cell overlap, pairwise, by the 13 SAT axes (independent oracle).

    tri : (M, 3, 3) vertices in grid units; cells : (M, 3) int, cell c = [c, c+1]^3.
    """
    v = tri - (cells + 0.5)[:, None, :]
    ok = (v.min(axis=1) <= 0.5).all(axis=1) & (v.max(axis=1) >= -0.5).all(axis=1)
    e = (v[:, 1] - v[:, 0], v[:, 2] - v[:, 1], v[:, 0] - v[:, 2])
    axes = [np.cross(e[0], e[1])] + [np.cross(np.eye(3)[k], ej) for k in range(3) for ej in e]
    for ax in axes:
        proj = np.einsum("mvc,mc->mv", v, ax)
        rad = 0.5 * np.abs(ax).sum(axis=1)
        ok &= (proj.min(axis=1) <= rad) & (proj.max(axis=1) >= -rad)
    return ok


def brute_force_cells(tri_grid):
    """Every cell touched by triangles given in grid units (T, 3, 3): (N, 3) int64 unique."""
    lo = np.ceil(tri_grid.min(axis=1)).astype(np.int64) - 1
    hi = np.floor(tri_grid.max(axis=1)).astype(np.int64)
    ext = hi - lo + 1
    counts = ext.prod(axis=1)
    tri_idx = np.repeat(np.arange(len(tri_grid)), counts)
    local = np.arange(len(tri_idx)) - np.repeat(np.cumsum(counts) - counts, counts)
    e = ext[tri_idx]
    cells = lo[tri_idx] + np.stack([local // (e[:, 1] * e[:, 2]), (local // e[:, 2]) % e[:, 1],
                                    local % e[:, 2]], axis=1)
    hit = overlaps(tri_grid[tri_idx], cells)
    return np.unique(cells[hit], axis=0)


# --------------------------------------------------------------------------- set compare

def _keys(cells):
    c = np.asarray(cells, dtype=np.int64) + (1 << 20)
    return np.unique((c[:, 0] << 42) | (c[:, 1] << 21) | c[:, 2])


def compare(exact, other):
    """(missed, extra): exact cells ``other`` lacks, and ``other`` cells not in ``exact``."""
    a, b = _keys(exact), _keys(other)
    return len(np.setdiff1d(a, b, assume_unique=True)), len(np.setdiff1d(b, a, assume_unique=True))


# --------------------------------------------------------------------------- the tools

def run_ours(voxelize, positions, tris, span):
    return voxelize(positions, tris, span)


def cells_ours(result, span):
    return np.asarray(result.cells)


def run_trimesh(positions, tris, span, offset):
    import trimesh
    shifted = positions - (0.5 - offset) * span
    return trimesh.Trimesh(vertices=shifted, faces=tris, process=False).voxelized(span)


def cells_trimesh(vg, span):
    origin = vg.transform[:3, 3] / span
    if not np.allclose(origin, np.round(origin), atol=1e-6) or not np.allclose(
            np.diag(vg.transform)[:3], span):
        raise RuntimeError(f"trimesh VoxelGrid transform is not on the pitch lattice:\n{vg.transform}")
    return np.asarray(vg.sparse_indices, dtype=np.int64) + np.round(origin).astype(np.int64)


def run_open3d(positions, tris, span):
    import open3d as o3d
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(positions),
                                     o3d.utility.Vector3iVector(tris))
    return o3d.geometry.VoxelGrid.create_from_triangle_mesh(mesh, span)


def cells_open3d(vg, span, offset):
    origin = np.asarray(vg.origin) / span + offset  # an integer when aligned with our lattice
    if not np.allclose(origin, np.round(origin), atol=1e-6) or not np.isclose(vg.voxel_size, span):
        raise RuntimeError(f"Open3D grid origin {vg.origin} is not on our lattice (span {span})")
    idx = np.array([v.grid_index for v in vg.get_voxels()], dtype=np.int64).reshape(-1, 3)
    return idx + np.round(origin).astype(np.int64)


def _median_time(fn, repeats):
    fn()  # warm-up (imports, caches, page faults)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def load_voxelizer():
    """``voxelize_triangles`` and its lattice offset (in voxels)."""
    voxelize = engine_module("voxelize.surface")
    return voxelize.voxelize_triangles, float(getattr(voxelize, "LATTICE_OFFSET", 2.0**-16))


# --------------------------------------------------------------------------- checks

def self_check(voxelize, offset):
    """Small mesh: Open3D and ours must equal the brute force, trimesh must be a subset.

    Returns a list of problem strings (empty when all conventions line up).
    """
    positions0, tris = knot_tube_mesh(triangles=800, around=10)
    problems = []
    for n in (12, 23):
        span = float(np.ptp(positions0, axis=0).max()) / n
        positions = place_on_lattice(positions0, span, offset)
        exact = brute_force_cells(positions[tris] / span + offset)
        for name, cells in (
                ("ours", cells_ours(run_ours(voxelize, positions, tris, span), span)),
                ("open3d", cells_open3d(run_open3d(positions, tris, span), span, offset)),
                ("trimesh", cells_trimesh(run_trimesh(positions, tris, span, offset), span))):
            missed, extra = compare(exact, cells)
            if name == "trimesh":
                bad = extra > 0  # trimesh may miss cells but must not invent any
            else:
                bad = missed or extra
            if bad:
                problems.append(f"{name} at {n}^3: {missed} missed / {extra} extra vs brute force")
    return problems


def spot_check_ours(result, positions, tris, span, offset, rng, samples=2000):
    """On the big mesh: sampled triangles' brute-force cells ⊆ ours; sampled pairs really touch."""
    tri_ids = rng.choice(len(tris), size=min(samples, len(tris)), replace=False)
    bf = brute_force_cells(positions[tris[tri_ids]] / span + offset)
    missing = len(np.setdiff1d(_keys(bf), _keys(result.cells), assume_unique=True))
    pair_ids = rng.choice(len(result.cell_of_pair), size=min(5 * samples, len(result.cell_of_pair)),
                          replace=False)
    tri = positions[tris[result.triangle_of_pair[pair_ids]]] / span + offset
    false_pairs = int((~overlaps(tri, result.cells[result.cell_of_pair[pair_ids]])).sum())
    return missing, false_pairs


# --------------------------------------------------------------------------- the section

def run(quick: bool = False, out=print, repeats: int | None = None, triangles: int | None = None,
        grids=None) -> str:
    """Time every tool at every grid size; return (and ``out``) the markdown table.

    ``quick`` (tooling checks only): 20k triangles, grids 64^3 and 128^3, 3 repeats.
    Raises RuntimeError after printing the table when the small-mesh self-check failed.
    """
    repeats = repeats or (3 if quick else DEFAULT_REPEATS)
    triangles = triangles or (20_000 if quick else DEFAULT_TRIANGLES)
    grids = tuple(grids or ((64, 128) if quick else GRIDS))
    voxelize, offset = load_voxelizer()
    problems = self_check(voxelize, offset)
    for p in problems:
        out(f"SELF-CHECK FAILED: {p}")

    positions0, tris = knot_tube_mesh(triangles)
    t_count = len(tris)
    extent = np.ptp(positions0, axis=0)
    rng = np.random.default_rng(1234)
    header = ("| grid | tool | median s | triangles/s | voxels | missed | extra | time / ours |\n"
              "|---|---|---:|---:|---:|---:|---:|---:|")
    rows, notes = [], []
    for n in grids:
        span = float(extent.max()) / n
        positions = place_on_lattice(positions0, span, offset)
        tools = (
            ("ours", lambda: run_ours(voxelize, positions, tris, span), lambda r: cells_ours(r, span)),
            ("trimesh", lambda: run_trimesh(positions, tris, span, offset), lambda r: cells_trimesh(r, span)),
            ("open3d", lambda: run_open3d(positions, tris, span), lambda r: cells_open3d(r, span, offset)),
        )
        exact, ours_time = None, None
        for name, fn, to_cells in tools:
            seconds, result = _median_time(fn, repeats)
            cells = to_cells(result)
            if name == "ours":
                exact, ours_time = cells, seconds
                missing, false_pairs = spot_check_ours(result, positions, tris, span, offset, rng)
                notes.append(f"{n}^3 spot check of ours: {missing} brute-force cells of 2000 sampled "
                             f"triangles absent, {false_pairs} of 10000 sampled pairs not touching")
            missed, extra = compare(exact, cells)
            rows.append(f"| {n}^3 | {name} | {seconds:.3f} | {t_count / seconds:,.0f} | "
                        f"{len(np.unique(cells, axis=0)):,} | {missed:,} | {extra:,} | "
                        f"{seconds / ours_time:.2f}x |")
    title = (f"### Voxelization: {t_count:,}-triangle closed knot tube, "
             f"AABB {extent[0]:.2f} x {extent[1]:.2f} x {extent[2]:.2f}, span = longest side / N, "
             f"median of {repeats} after a warm-up")
    table = "\n".join([title, "", header, *rows, "", *[f"- {x}" for x in notes],
                       f"- self-check vs brute force on a small mesh: "
                       f"{'OK' if not problems else 'FAILED'}"])
    out(table)
    if problems:
        raise RuntimeError("voxelization self-check failed: " + "; ".join(problems))
    return table + "\n\n" + run_unit_scale(quick, out)


def run_unit_scale(quick: bool = False, out=print) -> str:
    """The unit-scaled rig beside the applied one (``bench_unit_scale_blender.py``, run with
    the bpy venv .venv, since it goes through the add-on's operators)."""
    root = Path(__file__).resolve().parents[2]
    python = root / ".venv" / "bin" / "python"
    if not python.exists():
        raise RuntimeError("the bpy venv .venv is missing: run `make venv` (make bench does)")
    cmd = [str(python), str(root / "tools" / "bench" / "bench_unit_scale_blender.py")]
    done = subprocess.run(cmd + (["--quick"] if quick else []), capture_output=True, text=True,
                          cwd=root)
    if done.returncode != 0:
        raise RuntimeError(f"bench_unit_scale_blender.py failed:\n{done.stderr[-2000:]}")
    table = "\n".join(line for line in done.stdout.splitlines()
                      if line.startswith(("|", "###", "Goals")) or not line.strip()).strip()
    out(table + "\n")
    return table


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int)
    ap.add_argument("--triangles", type=int)
    ap.add_argument("--grids", type=int, nargs="+")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    run(args.quick, print, args.repeats, args.triangles, args.grids)


if __name__ == "__main__":
    main()
