"""Error budget of VoxGI's Diffuse Indirect: wrong geometry or wrong radiance?

Usage: ``.venv/bin/python tools/gi_diagnose.py [--scenes NAME ...] [--pixels 300] [--rays 1024]
[--lambert SPP] [--variants] [--json tests/data/gi_refs/gi_diagnosis.json]``

For each scene of ``tests/blender/gi_scenes.py`` (references from ``tools/make_gi_references.py``)
this renders the GI preview with default settings (``voxgi.render_preview``), keeps the
session's voxel state, and at ``--pixels`` random geometry pixels estimates Diffuse Indirect
(= mean incoming radiance of cosine-distributed rays around the shading normal; stratified
directions, ``--rays`` per pixel) three ways:

(i)   exact ray hits (``raycast.closest_hits`` on the scene triangles), shaded with exact direct
      light at the hit (``direct_light.diffuse_direct`` with shadow rays) × the hit's albedo;
(ii)  the same exact hits shaded with the injected voxel radiance there: the leaf of the finest
      cascade holding a voxel at the hit, read through its directional faces as a cone
      travelling along the ray reads them (``VoxelOctree.lookup_directional``, faces weighted
      by d²); (ii-iso) the isotropic leaf radiance instead;
(iii) thin rays marched through the finest voxel occupancy (steps of ¼ local voxel), ignoring
      occupied cells until the ray is higher above the pixel's tangent plane than a cell
      touching that plane can reach (span · Σ|n_a|), shaded with the voxel radiance as (ii).

Each is compared with Cycles' Diffuse Indirect at those pixels (relative L1). Rays are binned
by exact hit distance in voxels of the finest cascade at the pixel (< 1, 1–2, 2–4, 4–8, > 8,
miss) to show where (ii) and (iii) lose their accuracy, and two hybrids are scored:
``exact<N + (ii)`` (exact radiance for hits nearer than N voxels, voxel radiance beyond) and
``exact<N + (iii)`` (exact rays up to N voxels, then a voxel march from there).

``--lambert SPP`` also renders the scene with Lambert materials and compares (i) with it (units);
``--variants`` re-traces the whole preview (numpy tracer) with the voxel radiance injected with
lights evaluated at the voxel centres (``inject_at_centres``), and that × 0.93 (Cycles' diffuse
weight of a default Principled BSDF), and scores them against Cycles.
"""
from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from make_gi_references import REPO_ROOT, build_scene, load_addon, load_reference, relative_l1  # noqa: E402

BINS = (0.0, 1.0, 2.0, 4.0, 8.0, math.inf)
BIN_NAMES = ("<1", "1-2", "2-4", "4-8", ">8", "miss")
HYBRID_VOXELS = (1, 2, 4, 8)
PREVIEW_PASSES = ("Diffuse Direct", "Diffuse Indirect", "Ambient Occlusion", "Combined")
SURFACE_EPSILON = 1e-4


# --------------------------------------------------------------------------- sampling

def cosine_directions(normals, rays, rng):
    """(P, R, 3) stratified cosine-distributed unit directions around (P, 3) unit normals
    (R rounded down to a square; a random rotation of the pattern per pixel)."""
    from voxgi.voxgi_addon.gi.conetrace import _tangent_frame

    m = int(math.isqrt(rays))
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    u = (i.ravel()[None] + rng.random((len(normals), m * m))) / m
    v = (j.ravel()[None] + rng.random((len(normals), m * m))) / m
    r, phi = np.sqrt(u), 2.0 * math.pi * v
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1.0 - u, 0.0))], -1)
    t, s = _tangent_frame(normals)
    return (local[..., :1] * t[:, None] + local[..., 1:2] * s[:, None]
            + local[..., 2:] * normals[:, None])


def hit_surfaces(tris, origins, dirs, t, tri, u, v):
    """Hit position, normal (shading, turned against the ray) and material of each hit."""
    hit = tri >= 0
    index = np.where(hit, tri, 0)
    position = origins + dirs * np.where(hit, t, 0.0)[:, None]
    face = np.asarray(tris.normals)[index]
    normal = face
    if tris.corner_normals is not None:
        corners = np.asarray(tris.corner_normals)[index]
        smooth = ((1 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1]
                  + v[:, None] * corners[:, 2])
        length = np.linalg.norm(smooth, axis=1, keepdims=True)
        normal = np.where(length > 1e-12, smooth / np.maximum(length, 1e-12), face)
    sign = np.where((face * dirs).sum(1) > 0, -1.0, 1.0)[:, None]
    return hit, position, normal * sign, face * sign, np.asarray(tris.materials)[index]


# --------------------------------------------------------------------------- voxel state

class VoxelScene:
    """The GI state's cascades as dense occupancy + leaf lookups (finest cascade first)."""

    def __init__(self, state, octree=None):
        self.octree = octree or state.octree
        self.cascades = state.cascades
        self.grids = []
        for cv in state.cascades:
            g = cv.grid
            index = np.full((g.resolution,) * 3, -1, np.int64)
            if len(cv.cells):
                index[tuple(np.asarray(cv.cells, np.int64).T)] = np.arange(len(cv.cells))
            self.grids.append((np.asarray(g.origin, np.float64), float(g.span), g.resolution, index))

    def locate(self, points):
        """(span (N,) of the finest cascade containing each point (inf outside all), cascade
        (N,) of the finest cascade with a voxel there (−1: none), that cell (N, 3) int64)."""
        span_out = np.full(len(points), np.inf)
        which = np.full(len(points), -1, np.int64)
        cell = np.zeros((len(points), 3), np.int64)
        for i in reversed(range(len(self.grids))):  # finest last, so it wins
            origin, span, res, index = self.grids[i]
            c = np.floor((points - origin) / span).astype(np.int64)
            inside = ((c >= 0) & (c < res)).all(1)
            span_out[inside] = span
            cc = np.clip(c, 0, res - 1)
            present = inside & (index[cc[:, 0], cc[:, 1], cc[:, 2]] >= 0)
            which[present], cell[present] = i, c[present]
        return span_out, which, cell

    def local_span(self, points):
        return self.locate(points)[0]

    def voxel_at(self, points):
        return self.locate(points)[1:]

    def radiance(self, which, cell, dirs):
        """(N, 3) directional (as cones read leaves) and isotropic leaf radiance of the voxels
        (``which``, ``cell``) seen by rays travelling along ``dirs``; 0 where which = −1."""
        directional = np.zeros((len(which), 3))
        isotropic = np.zeros((len(which), 3))
        for i in range(len(self.grids)):
            sel = np.flatnonzero(which == i)
            if not len(sel):
                continue
            level = self.octree.cascade_levels[i]
            nodes = cell[sel] + self.octree.cascade_offsets[i]
            faces = self.octree.lookup_directional(level, nodes)  # (n, 6, 4) premultiplied
            d = dirs[sel]
            for a in range(3):  # a ray travelling −a reads the face seen from +a (face 2a)
                face = np.where(d[:, a] < 0, 2 * a, 2 * a + 1)
                directional[sel] += d[:, a:a + 1] ** 2 * faces[np.arange(len(sel)), face, :3]
            isotropic[sel], _, _ = self.octree.lookup(level, nodes)
        return directional, isotropic

    def march(self, origins, dirs, normals, origin_span, starts):
        """First occupied voxel along thin rays from ``origins`` (N, 3) along ``dirs`` beyond
        each of the distances ``starts`` (K,) in voxels of ``origin_span`` (N,), in one march
        from the origin in steps of ¼ of the local voxel. Occupied cells are ignored while the
        sample is not above what a cell touching the origin's tangent plane (normal
        ``normals``) can reach (span · Σ|n_a|): the surface's own voxels. Rays stop when they
        leave every cascade. Returns (which (K, N), cell (K, N, 3)) as ``voxel_at``."""
        n, k = len(origins), len(starts)
        starts = np.asarray(starts, np.float64)
        which = np.full((k, n), -1, np.int64)
        cell = np.zeros((k, n, 3), np.int64)
        t = np.zeros(n)
        rise = (dirs * normals).sum(1)
        clear = np.abs(normals).sum(1) * origin_span
        found = np.zeros((k, n), bool)
        active = np.arange(n)
        while len(active):
            p = origins[active] + dirs[active] * t[active, None]
            span, w, c = self.locate(p)
            ok = (w >= 0) & (t[active] * rise[active] > clear[active])
            if ok.any():
                for j in range(k):
                    new = ok & ~found[j, active] & (t[active] >= starts[j] * origin_span[active])
                    idx = active[new]
                    which[j, idx], cell[j, idx], found[j, idx] = w[new], c[new], True
            t[active] += 0.25 * span
            keep = ~found[-1, active] & np.isfinite(span)
            active = active[keep]
        return which, cell


def inject_at_centres(state, snapshot, samples=1):
    """Radiance (per cascade (N, 3)) injected as ``voxel_lighting.inject_direct_light`` does —
    shadow rays through the voxel occupancy from 1.5 voxels off the surface — but with each
    light's unshadowed model evaluated at the voxel centre instead of at that offset point."""
    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
    from voxgi.voxgi_addon.gi.light_injection import SHADOW_START_VOXELS, voxel_centres
    from voxgi.voxgi_addon.gi.voxel_shadows import CascadeOccupancy

    occupancy = CascadeOccupancy(state.cascades)
    out = []
    for cv in state.cascades:
        if cv.voxel_count == 0:
            out.append(np.zeros((0, 3), np.float32))
            continue
        normals = np.asarray(cv.normal, np.float64)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        centres = voxel_centres(cv)
        start = centres + normals * (SHADOW_START_VOXELS * cv.grid.span)
        direct = np.zeros((len(centres), 3))
        for light in snapshot.lights:
            shadowed = diffuse_direct(start, normals, [light], occupancy, samples=samples)
            free = diffuse_direct(start, normals, [light], None, samples=samples)
            at_centre = diffuse_direct(centres, normals, [light], None, samples=samples)
            share = np.divide(shadowed, free, out=np.zeros_like(shadowed), where=free > 0)
            direct += at_centre * share
        out.append((np.asarray(cv.albedo, np.float64) * direct).astype(np.float32))
    return out


# --------------------------------------------------------------------------- preview

def render_preview(scene, width, height):
    """Default-settings GI preview passes and the session's voxel GI state."""
    import bpy

    from voxgi.blender.session import scene_session
    from voxgi.voxgi_addon.files.exr import group_passes, read_exr

    with tempfile.TemporaryDirectory(prefix="voxgi-diag-") as tmp:
        path = pathlib.Path(tmp) / "preview.exr"
        start = time.perf_counter()
        if bpy.ops.voxgi.render_preview(filepath=str(path), resolution_x=width,
                                        resolution_y=height) != {"FINISHED"}:
            raise RuntimeError("the GI preview failed")
        seconds = time.perf_counter() - start
        passes = group_passes(read_exr(path))
    # The default (Accurate) preview builds no voxels: one GI update gives the voxel state the
    # estimates (ii) and (iii) read.
    if bpy.ops.voxgi.update() != {"FINISHED"}:
        raise RuntimeError("the GI update failed")
    session = scene_session(scene.name_full)
    return passes, session.gi_state, session.tracer_used, seconds


# --------------------------------------------------------------------------- diagnosis

def binned(values, bins):
    """Sum of (P, R, ...) values per bin index (P, R) → (len(BIN_NAMES), P, ...)."""
    return np.stack([(values * (bins == b)[..., None]).sum(1) for b in range(len(BIN_NAMES))])


def diagnose(name, pixels, rays, seed=0, refs=REPO_ROOT / "tests" / "data" / "gi_refs",
             lambert_samples=0, variants=False):
    import bpy
    import gi_scenes

    from voxgi.blender.snapshot.scene import take_snapshot
    from voxgi.voxgi_addon.gi.direct_light import diffuse_direct
    from voxgi.voxgi_addon.preview.passes import material_table
    from voxgi.voxgi_addon.scene.geometry import world_triangles
    from voxgi.voxgi_addon.scene.raycast import closest_hits, primary_visibility

    reference = load_reference(pathlib.Path(refs) / f"{name}.npz")
    scene = build_scene(name)
    w, h = gi_scenes.WIDTH, gi_scenes.HEIGHT
    preview, state, tracer, preview_seconds = render_preview(scene, w, h)
    snapshot = take_snapshot(scene, bpy.context.evaluated_depsgraph_get())
    tris = world_triangles(snapshot)
    albedo_table = material_table(snapshot)[0]
    albedo_table[-1] = 0.8
    seen = primary_visibility(tris, snapshot.camera, w, h)
    both = seen.hit & (reference["Alpha"] > 0.5) & (preview["Diffuse Color"].sum(-1) > 0)
    preview_errors = {p: relative_l1(preview[p], reference[p], both) for p in PREVIEW_PASSES}
    preview_errors["indirect mean / Cycles"] = float(preview["Diffuse Indirect"][both].sum()
                                                     / reference["Diffuse Indirect"][both].sum())

    rng = np.random.default_rng(seed)
    flat = np.flatnonzero(both.ravel())
    chosen = np.sort(rng.choice(flat, size=min(pixels, len(flat)), replace=False))
    p = seen.position.reshape(-1, 3)[chosen]
    n = seen.normal.reshape(-1, 3)[chosen]
    nf = seen.face_normal.reshape(-1, 3)[chosen]
    cycles = reference["Diffuse Indirect"].reshape(-1, 3)[chosen].astype(np.float64)
    cycles_color = reference["Diffuse Color"].reshape(-1, 3)[chosen]
    voxels = VoxelScene(state)
    span = voxels.local_span(p)

    dirs = cosine_directions(n, rays, rng)  # (P, R, 3)
    P, R = dirs.shape[:2]
    origins = np.repeat(p + nf * SURFACE_EPSILON, R, axis=0)
    d = dirs.reshape(-1, 3)
    timings = {}
    t0 = time.perf_counter()
    t, tri, u, v = closest_hits(tris, origins, d, 0.0, np.inf)
    hit, hp, hn, hf, hmat = hit_surfaces(tris, origins, d, t, tri, u, v)
    timings["exact rays"] = time.perf_counter() - t0

    # (i) exact hits × exact direct light × albedo
    t0 = time.perf_counter()
    L_i = np.zeros((len(d), 3))
    idx = np.flatnonzero(hit)
    direct = diffuse_direct(hp[idx] + hf[idx] * SURFACE_EPSILON, hn[idx], snapshot.lights, tris,
                            samples=4, seed=seed + 1)
    albedo = albedo_table[np.where((hmat[idx] >= 0) & (hmat[idx] < len(albedo_table) - 1),
                                   hmat[idx], len(albedo_table) - 1)]
    L_i[idx] = albedo * direct
    timings["exact shading"] = time.perf_counter() - t0

    # (ii) exact hits × voxel radiance at the hit
    which, cell = voxels.voxel_at(hp)
    which[~hit] = -1
    missing = hit & (which < 0)
    if missing.any():  # a hit cell without a voxel (patch shrink): nearest present neighbour
        best = np.full(len(d), np.inf)
        for off in np.stack(np.meshgrid(*[[-1, 0, 1]] * 3, indexing="ij"), -1).reshape(-1, 3):
            if not off.any():
                continue
            mi = np.flatnonzero(missing)
            sp = voxels.local_span(hp[mi])
            ww, cc = voxels.voxel_at(hp[mi] + off * sp[:, None] * 0.999)
            better = (ww >= 0) & (np.linalg.norm(off) < best[mi])
            which[mi[better]], cell[mi[better]], best[mi[better]] = ww[better], cc[better], \
                np.linalg.norm(off)
    L_ii, L_ii_iso = voxels.radiance(which, cell, d)
    from voxgi.voxgi_addon.gi.svo import build_octree

    centred_radiance = inject_at_centres(state, snapshot)
    centred = build_octree(state.cascades, centred_radiance, state.octree.dense_depth,
                           one_sided_leaves=True)
    L_ii_c = VoxelScene(state, centred).radiance(which, cell, d)[0]
    no_voxel_share = float(((which < 0) & hit).sum() / max(hit.sum(), 1))

    # (iii) and hybrids: first voxel hit beyond 0 and beyond N voxels, one march
    normals_r = np.repeat(n, R, axis=0)
    span_r = np.repeat(span, R)
    t0 = time.perf_counter()
    starts = (0,) + HYBRID_VOXELS
    mw, mc = voxels.march(origins, d, normals_r, span_r, starts)
    marched = {s: voxels.radiance(mw[j], mc[j], d)[0] for j, s in enumerate(starts)}
    timings["voxel march"] = time.perf_counter() - t0
    L_iii = marched[0]

    dist = np.where(hit, t / span_r, np.inf)
    bins = np.digitize(dist, BINS[1:-1])
    bins[~hit] = len(BIN_NAMES) - 1
    shape = (P, R, 3)

    def per_pixel(L):
        return L.reshape(shape).mean(1)

    est = {"(i) exact": per_pixel(L_i), "(ii) voxel radiance at exact hits": per_pixel(L_ii),
           "(ii-iso) isotropic leaf radiance": per_pixel(L_ii_iso),
           "(ii-c) lights evaluated at voxel centres": per_pixel(L_ii_c),
           "(iii) voxel-marched hits": per_pixel(L_iii)}
    total = np.abs(cycles).sum()
    errors = {k: float(np.abs(e - cycles).sum() / total) for k, e in est.items()}
    errors_vs_i = {k: float(np.abs(e - est["(i) exact"]).sum() / np.abs(est["(i) exact"]).sum())
                   for k, e in est.items()}
    errors_vs_i["preview at these pixels"] = float(
        np.abs(preview["Diffuse Indirect"].reshape(-1, 3)[chosen] - est["(i) exact"]).sum()
        / np.abs(est["(i) exact"]).sum())
    errors["preview at these pixels"] = float(
        np.abs(preview["Diffuse Indirect"].reshape(-1, 3)[chosen] - cycles).sum() / total)
    bins_r = bins.reshape(P, R)
    share = binned(L_i.reshape(shape), bins_r).sum((1, 2)) / max(L_i.sum(), 1e-30)
    ray_share = np.bincount(bins, minlength=len(BIN_NAMES)) / len(bins)
    per_bin = {}
    for label, L in (("ii", L_ii), ("ii-iso", L_ii_iso), ("ii-c", L_ii_c), ("iii", L_iii)):
        diff = binned((L - L_i).reshape(shape), bins_r) / R  # (bins, P, 3) per-pixel sums
        energy = binned(L_i.reshape(shape), bins_r).sum((1, 2))
        per_bin[label] = {
            "l1_share": [float(np.abs(x).sum() / total) for x in diff],
            "bias": [float(x.sum() * R / e) if e > 0 else None
                     for x, e in zip(diff, energy)],
        }
    hybrids = {}
    for N in HYBRID_VOXELS:
        near = (hit & (t < N * span_r))[:, None]
        h2 = np.where(near, L_i, L_ii)
        h3 = np.where(near, L_i, marched[N])
        exact = est["(i) exact"]
        hybrids[N] = {"exact<N + (ii)": float(np.abs(per_pixel(h2) - cycles).sum() / total),
                      "exact<N + (iii)": float(np.abs(per_pixel(h3) - cycles).sum() / total),
                      "exact<N + (ii) vs (i)": float(np.abs(per_pixel(h2) - exact).sum()
                                                     / np.abs(exact).sum()),
                      "exact<N + (iii) vs (i)": float(np.abs(per_pixel(h3) - exact).sum()
                                                      / np.abs(exact).sum())}
    # Cycles' Diffuse Color against the materials' base colours at the chosen pixels.
    mat = seen.material.ravel()[chosen]
    base = albedo_table[np.where((mat >= 0) & (mat < len(albedo_table) - 1), mat,
                                 len(albedo_table) - 1)]
    color_ratio = float(cycles_color.sum() / max(base.sum(), 1e-30))
    preview_variants = {}
    if variants:  # the whole preview again (numpy tracer) with other voxel radiance
        from voxgi.voxgi_addon.gi.conetrace import ConeSettings
        from voxgi.voxgi_addon.gi.update import GIState
        from voxgi.voxgi_addon.preview.passes import render_passes

        for label, scale in (("numpy tracer, as injected", None),
                             ("lights at voxel centres", 1.0),
                             ("lights at voxel centres, albedo x 0.93", 0.93)):
            if scale is None:
                octree = state.octree
            else:
                octree = build_octree(state.cascades, [r * scale for r in centred_radiance],
                                      state.octree.dense_depth, one_sided_leaves=True)
            variant = GIState(state.grids, state.cascades, state.radiance, octree)
            t1 = time.perf_counter()
            passes, _ = render_passes(snapshot, variant, w, h, ConeSettings(), light_samples=16)
            preview_variants[label] = {
                "Diffuse Indirect": relative_l1(passes["Diffuse Indirect"],
                                                reference["Diffuse Indirect"], both),
                "Combined": relative_l1(passes["Combined"], reference["Combined"], both),
                "indirect mean / Cycles": float(passes["Diffuse Indirect"][both].sum()
                                                / reference["Diffuse Indirect"][both].sum()),
                "seconds": round(time.perf_counter() - t1, 1)}
    lambert = {}
    if lambert_samples:  # units check: the same scene with Lambert materials, Cycles vs (i)
        from make_gi_references import render

        gi_scenes.use_lambert_materials()
        flat_ref, _ = render(scene, lambert_samples, seed=2)
        lam = flat_ref["Diffuse Indirect"].reshape(-1, 3)[chosen].astype(np.float64)
        lam_direct = flat_ref["Diffuse Direct"].reshape(-1, 3)[chosen].astype(np.float64)
        ours_direct = preview["Diffuse Direct"].reshape(-1, 3)[chosen]
        lambert = {"samples": lambert_samples,
                   "(i) vs Lambert Cycles": float(np.abs(est["(i) exact"] - lam).sum()
                                                  / np.abs(lam).sum()),
                   "Principled Cycles vs Lambert Cycles": float(np.abs(cycles - lam).sum()
                                                                / np.abs(lam).sum()),
                   "mean Lambert Cycles": float(lam.mean()),
                   "preview direct vs Lambert direct": float(np.abs(ours_direct - lam_direct).sum()
                                                             / np.abs(lam_direct).sum())}
    return {
        "scene": name, "pixels": int(P), "rays": int(R), "tracer": tracer, "lambert": lambert,
        "preview_variants": preview_variants,
        "preview_seconds": round(preview_seconds, 2),
        "voxel_span_at_pixels": {"median": float(np.median(span)), "min": float(span.min()),
                                 "max": float(span.max())},
        "spans": [float(g[1]) for g in voxels.grids],
        "preview_errors": preview_errors, "errors": errors, "errors_vs_exact": errors_vs_i,
        "energy_share": [float(x) for x in share], "ray_share": [float(x) for x in ray_share],
        "per_bin": per_bin, "hybrids": {str(k): v for k, v in hybrids.items()},
        "no_voxel_at_exact_hit": no_voxel_share,
        "cycles_diffuse_color_over_base_color": color_ratio,
        "mean_indirect": {"cycles": float(cycles.mean()), **{k: float(e.mean()) for k, e in est.items()}},
        "timings": {k: round(x, 1) for k, x in timings.items()},
    }


def print_report(result):
    r = result
    print(f"\n## {r['scene']}  ({r['pixels']} px × {r['rays']} rays, voxel at pixels "
          f"{r['voxel_span_at_pixels']['median']:.2f} m, tracer {r['tracer']})")
    print("preview (all pixels): " + ", ".join(f"{k} {v:.3f}" for k, v in r["preview_errors"].items()))
    print("rel L1 vs Cycles: " + ", ".join(f"{k} {v:.3f}" for k, v in r["errors"].items()))
    print("rel L1 vs (i): " + ", ".join(f"{k} {v:.3f}" for k, v in r["errors_vs_exact"].items()))
    print("mean indirect: " + ", ".join(f"{k} {v:.4f}" for k, v in r["mean_indirect"].items()))
    print("| bin (voxels) | " + " | ".join(BIN_NAMES) + " |")
    print("|---" * (len(BIN_NAMES) + 1) + "|")
    print("| rays | " + " | ".join(f"{x:.0%}" for x in r["ray_share"]) + " |")
    print("| energy (i) | " + " | ".join(f"{x:.0%}" for x in r["energy_share"]) + " |")
    for label in ("ii", "ii-iso", "ii-c", "iii"):
        b = r["per_bin"][label]
        print(f"| ({label}) L1 share | " + " | ".join(f"{x:.3f}" for x in b["l1_share"]) + " |")
        print(f"| ({label}) bias | " + " | ".join("—" if x is None else f"{x:+.0%}" for x in b["bias"]) + " |")
    print("hybrids: " + "; ".join(f"N={k}: " + ", ".join(f"{a} {b:.3f}" for a, b in v.items())
                                  for k, v in r["hybrids"].items()))
    for label, v in r.get("preview_variants", {}).items():
        print(f"preview variant '{label}': " + ", ".join(f"{k} {x:.3f}" for k, x in v.items()))
    if r["lambert"]:
        print("Lambert check: " + ", ".join(f"{k} {v:.4g}" for k, v in r["lambert"].items()))
    print(f"no voxel at exact hit: {r['no_voxel_at_exact_hit']:.3%}; Cycles Diffuse Color / base "
          f"colour {r['cycles_diffuse_color_over_base_color']:.3f}; timings {r['timings']}")


def main(argv=None):
    load_addon()
    import gi_scenes

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="*", default=list(gi_scenes.SCENES))
    parser.add_argument("--pixels", type=int, default=300)
    parser.add_argument("--rays", type=int, default=1024)
    parser.add_argument("--variants", action="store_true",
                        help="re-trace the preview with the injection variants (numpy tracer)")
    parser.add_argument("--json", type=pathlib.Path)
    parser.add_argument("--lambert", type=int, default=0, metavar="SPP",
                        help="also render the scene with Lambert materials at SPP samples and "
                             "compare (i) with it (units check)")
    parser.add_argument("--refs", type=pathlib.Path, default=REPO_ROOT / "tests" / "data" / "gi_refs")
    args = parser.parse_args(argv)
    results = {}
    if args.json and args.json.exists():
        results = json.loads(args.json.read_text())
    for name in args.scenes:
        result = diagnose(name, args.pixels, args.rays, refs=args.refs,
                          lambert_samples=args.lambert, variants=args.variants)
        print_report(result)
        results[name] = result
        if args.json:
            args.json.write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
