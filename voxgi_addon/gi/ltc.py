"""Linearly Transformed Cosines (Heitz, Dupuy, Hill & Neubelt 2016) for the Principled GGX lobe:
the unshadowed glossy light of polygonal emitters, noise-free (docs/gi_pipeline.md "LTC: the
glossy lobe over polygons").

The lobe ρ(ω) = f_ggx(v, ω) cos(n, ω) / ∫_H f_ggx cos is the Fresnel-less GGX single-scattering
lobe of ``principled._ggx_eval`` (D G2 / (4 cos θ_v); a white metal's ``glossy_reflectance`` up
to a constant), normalised to integrate to 1 over the hemisphere: the shape the Glossy Direct
pass needs once the film has divided the Glossy Color out. Fresnel's variation across the lobe
is neglected.

It is approximated, in the local frame (z = normal, x = the view's tangent direction), by

    D_o(ω) = D_cos(M⁻¹ω / |M⁻¹ω|) |det M⁻¹| / |M⁻¹ω|³,   D_cos(ω) = max(ω_z, 0) / π,

with M⁻¹ = [[a, 0, b], [0, c, 0], [d, 0, 1]] read from ``ltc_ggx.npz`` (written by
``tools/fit_ltc.py``), restricted to the hemisphere and renormalised there: ``ρ ≈ D_o / N_H`` with
``N_H = ∫_H D_o = (1 + a / sqrt(a² + d²)) / 2`` (the clamped cosine over the half-space that
the horizon becomes under M⁻¹). The integral over a polygon is the clamped-cosine integral over
the polygon transformed by M⁻¹, clipped to the surface's horizon and to the cosine's: Lambert's
edge formula. So the hemisphere integrates to exactly 1 and a polygon below the horizon to 0.

Table: ``minv`` (n_rough, n_view, 4) float32 = (a, b, c, d) at the grid ``roughness`` (Principled
roughness, α = roughness²) × ``view_x`` = sqrt(1 − cos θ_v), both uniform on [0, 1]; lookups
clamp and blend the four cells in the fit's parameters (lobe direction, log spreads, shear),
linear in view_x and in log α (``_interp``). Pure numpy (no bpy, no gpu).
"""
from __future__ import annotations

import math
import pathlib

import numpy as np

from ..scene.short_axis import norm3

__all__ = ["TABLE_PATH", "load_table", "ltc_inverse", "view_x", "ltc_matrix", "hemisphere_norm",
           "ltc_density", "ltc_polygon_integral", "table_texels", "local_frame"]

TABLE_PATH = pathlib.Path(__file__).resolve().with_name("ltc_ggx.npz")
_table: dict[str, np.ndarray] | None = None


def load_table() -> dict[str, np.ndarray]:
    """The stored table as float64: ``minv`` (R, V, 4) = (a, b, c, d), ``roughness`` (R,),
    ``view_x`` (V,) = sqrt(1 − cos θ_v), plus the fit's diagnostics (``error`` (R, V))."""
    global _table
    if _table is None:
        with np.load(TABLE_PATH) as data:
            _table = {name: np.asarray(data[name], dtype=np.float64) for name in data.files}
    return _table


def table_texels() -> np.ndarray:
    """(R, V, 4) float32: one RGBA texel per cell = (a, b, c, d); texel x = view, y = roughness
    (render/shaders/ltc.glsl ``ltc_table``)."""
    return np.ascontiguousarray(load_table()["minv"], dtype=np.float32)


def _params(abcd: np.ndarray) -> np.ndarray:
    """(…, 4) (φ, log s_x, log s_y, κ) of (…, 4) (a, b, c, d), tools/fit_ltc.py's parameters:
    M = R_φ [[s_x, 0, 0], [0, s_y, 0], [κ s_x, 0, 1]], R_φ the rotation about y turning z
    toward (sin φ, 0, cos φ), and M⁻¹ scaled to M⁻¹₂₂ = 1 = S⁻¹ R_φᵀ / e, e = cos φ + κ sin φ:
    φ = atan2(−b, a), κ = (sin φ − d cos φ) / (cos φ + d sin φ), s_x = cos φ / (a e),
    s_y = 1 / (c e)."""
    a, b, c, d = np.moveaxis(abcd, -1, 0)
    phi = np.arctan2(-b, a)
    cos, sin = np.cos(phi), np.sin(phi)
    kappa = (sin - d * cos) / (cos + d * sin)
    e = cos + kappa * sin
    return np.stack([phi, np.log(cos / (a * e)), np.log(1.0 / (c * e)), kappa], -1)


def _abcd(params: np.ndarray) -> np.ndarray:
    """Inverse of ``_params``: a = cos φ / (s_x e), b = −sin φ / (s_x e), c = 1 / (s_y e),
    d = (sin φ − κ cos φ) / e."""
    phi, log_sx, log_sy, kappa = np.moveaxis(params, -1, 0)
    cos, sin = np.cos(phi), np.sin(phi)
    e = cos + kappa * sin
    sx, sy = np.exp(log_sx), np.exp(log_sy)
    return np.stack([cos / (sx * e), -sin / (sx * e), 1.0 / (sy * e), (sin - kappa * cos) / e], -1)


def _interp(values: np.ndarray, rough, view_x) -> np.ndarray:
    """(a, b, c, d) at roughness and view_x = sqrt(1 − cos θ_v) (clamped) from the table
    ``values`` (R, V, 4).

    The four cells are blended in the fit's parameters (``_params``: lobe direction φ, log
    spreads, skew), not as matrix entries: a blend of entries of two narrow lobes pointing in
    different directions is no lobe in between (L1 error ~1 at roughness 0.05, cos θ_v 0.2 on a
    32 × 32 table, 0.15 at roughness 0.1). Linear in sqrt(1 − cos θ_v) and in log α (α = r²)
    between rows, exact for a lobe that only narrows (s ∝ α)."""
    n_r, n_v = values.shape[:2]
    rough_min = float(load_table()["rough_min"])
    r = np.clip(np.nan_to_num(np.asarray(rough, np.float64)), 0.0, 1.0)
    x = np.clip(np.nan_to_num(np.asarray(view_x, np.float64)), 0.0, 1.0)
    r, x = np.broadcast_arrays(r, x)
    i = np.minimum((r * (n_r - 1)).astype(np.int64), n_r - 2)
    fv = x * (n_v - 1)
    j = np.minimum(fv.astype(np.int64), n_v - 2)
    t = (fv - j)[..., None]
    log0 = np.log(np.maximum(i / (n_r - 1), rough_min))
    log1 = np.log(np.maximum((i + 1) / (n_r - 1), rough_min))
    s = np.clip((np.log(np.maximum(r, rough_min)) - log0) / (log1 - log0), 0.0, 1.0)[..., None]
    params = _params(values)
    out = ((1 - s) * ((1 - t) * params[i, j] + t * params[i, j + 1])
           + s * ((1 - t) * params[i + 1, j] + t * params[i + 1, j + 1]))
    return _abcd(out)


def ltc_inverse(roughness, cos_view) -> np.ndarray:
    """(…, 3, 3) M⁻¹ = [[a, 0, b], [0, c, 0], [d, 0, 1]] for the view at cos θ_v = ``cos_view``
    in the x–z plane of the local frame (table lookup ``_interp``, coordinates clamped)."""
    x = np.sqrt(np.clip(1.0 - np.nan_to_num(np.asarray(cos_view, np.float64)), 0.0, 1.0))
    return _matrix(_interp(load_table()["minv"], roughness, x))


def view_x(n, v) -> np.ndarray:
    """(…) the table's view coordinate sqrt(1 − cos θ_v) of unit n, v (…, 3), from the view's
    tangential part |v − n (n·v)| = sin θ_v as sqrt(sin² / (1 + cos)): near normal incidence
    1 − n·v of rounded vectors loses θ_v (float32: ~3·10⁻⁴ rad), enough to move a narrow
    lobe's highlight; the shader does the same."""
    cos = np.sum(n * v, axis=-1)
    tangential = v - n * cos[..., None]
    return np.sqrt(np.clip(np.sum(tangential * tangential, axis=-1) / np.maximum(1.0 + cos, 1e-6),
                           0.0, 1.0))


def _matrix(abcd: np.ndarray) -> np.ndarray:
    a, b, c, d = np.moveaxis(abcd, -1, 0)
    zero, one = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([a, zero, b], -1), np.stack([zero, c, zero], -1),
                     np.stack([d, zero, one], -1)], -2)


def ltc_matrix(minv) -> np.ndarray:
    """M from M⁻¹ (…, 3, 3)."""
    return np.linalg.inv(np.asarray(minv, np.float64))


def hemisphere_norm(minv) -> np.ndarray:
    """(…) ∫_{z>0} D_o: the horizon z = 0 becomes, under M⁻¹, the plane of normal M^T e_z (the
    last row of M); a clamped cosine over a half-space tilted by β integrates to (1 + cos β)/2.
    For M⁻¹ = [[a, 0, b], [0, c, 0], [d, 0, e]] this is (1 + sign(ae − bd) a / sqrt(a² + d²)) / 2."""
    minv = np.asarray(minv, np.float64)
    a, b, d, e = minv[..., 0, 0], minv[..., 0, 2], minv[..., 2, 0], minv[..., 2, 2]
    # the last row of M is (−d, 0, a) / (a e − b d)
    return 0.5 * (1.0 + np.sign(a * e - b * d) * a / np.sqrt(a * a + d * d))


def ltc_density(minv, w) -> np.ndarray:
    """(…) D_o(ω) of an isotropic-form M⁻¹ (…, 3, 3) (zeros where the table's form has them)
    at unit directions w (…, 3) (whole sphere; not renormalised to the hemisphere)."""
    minv = np.asarray(minv, np.float64)
    wo = np.einsum("...ij,...j->...i", minv, w)
    length = norm3(wo)
    cos = np.maximum(wo[..., 2] / length, 0.0)
    det = minv[..., 1, 1] * (minv[..., 0, 0] * minv[..., 2, 2] - minv[..., 0, 2] * minv[..., 2, 0])
    return cos / math.pi * np.abs(det) / length ** 3


def local_frame(n, v) -> np.ndarray:
    """(N, 3, 3) rows (t, b, n): t the unit tangent toward the view ``v`` (any tangent when v is
    along n), b = n × t."""
    n = np.asarray(n, np.float64)
    v = np.asarray(v, np.float64)
    n, v = np.broadcast_arrays(n, v)
    t = v - n * np.sum(n * v, axis=-1, keepdims=True)
    length = norm3(t)[..., None]
    # fallback tangent: the axis least aligned with n, made orthogonal
    axis = np.eye(3)[np.argmin(np.abs(n), axis=-1)]
    fallback = axis - n * np.sum(n * axis, axis=-1, keepdims=True)
    fallback /= norm3(fallback)[..., None]
    t = np.where(length > 1e-6, t / np.maximum(length, 1e-300), fallback)
    return np.stack([t, np.cross(n, t), n], axis=-2)


def _clip(points: np.ndarray, h: np.ndarray):
    """Sutherland–Hodgman of the closed polygons ``points`` (…, K, 3) against h (…, K) ≥ 0,
    as 2K slots: (points (…, 2K, 3), valid (…, 2K)); unused slots repeat the previous valid
    corner (zero-length edges)."""
    k = points.shape[-2]
    slots, valid = [], []
    for i in range(k):
        j = (i + 1) % k
        hi, hj = h[..., i], h[..., j]
        slots.append(points[..., i, :])
        valid.append(hi >= 0)
        denom = hi - hj
        t = np.divide(hi, denom, out=np.zeros_like(hi), where=denom != 0)
        slots.append(points[..., i, :] + t[..., None] * (points[..., j, :] - points[..., i, :]))
        valid.append((hi >= 0) != (hj >= 0))
    points = np.stack(slots, axis=-2)
    valid = np.stack(valid, axis=-1)
    index = np.where(valid, np.arange(2 * k), -1)
    last_valid = np.max(index, axis=-1, keepdims=True)
    index = np.maximum.accumulate(index, axis=-1)
    index = np.maximum(np.where(index < 0, last_valid, index), 0)
    return np.take_along_axis(points, index[..., None], axis=-2), valid.any(axis=-1)


def _clamped_cosine_integral(points: np.ndarray, vector: bool = False):
    """(…) ∫ max(ω_z, 0)/π over the polygons (…, K, 3) seen from the origin, either
    orientation, those crossing z = 0 clipped: Lambert's |Σ_edges θ_k γ_k·z| / 2π. vector:
    also (…, 3) ±Σ_edges θ_k γ_k / 2π = ∫ ω dω / 2π over the clipped polygon (Stokes), signed
    so that its z ≥ 0: the polygon's mean direction, 0 where nothing is above z = 0."""
    points, any_above = _clip(points, points[..., 2])
    length = norm3(points)[..., None]
    a = np.divide(points, length, out=np.zeros_like(points), where=length > 0)
    b = np.roll(a, -1, axis=-2)
    cross = np.cross(a, b)
    sin = norm3(cross)
    angle = np.arctan2(sin, np.sum(a * b, axis=-1))
    gz = np.divide(cross[..., 2], sin, out=np.zeros_like(sin), where=sin > 0)
    signed = (angle * gz).sum(axis=-1) / (2.0 * math.pi)
    total = np.where(any_above, np.abs(signed), 0.0)
    if not vector:
        return total
    gamma = np.divide(cross, sin[..., None], out=np.zeros_like(cross), where=sin[..., None] > 0)
    mean = (angle[..., None] * gamma).sum(axis=-2) / (2.0 * math.pi)
    mean = np.where((any_above & (signed < 0))[..., None], -mean, mean)
    return total, np.where(any_above[..., None], mean, 0.0)


def ltc_lobe_density(n, v, roughness, directions) -> np.ndarray:
    """(N, T) ρ(ω) of the fitted lobe — the LTC's density D_o over its hemisphere integral,
    what ``ltc_polygon_integral`` integrates — at world unit directions ``directions`` (N, T, 3)
    for the points' unit normals n (N, 3), views v (N, 3) and Principled ``roughness`` (N,); 0
    below the horizon or where v is."""
    n = np.atleast_2d(np.asarray(n, np.float64))
    v = np.atleast_2d(np.asarray(v, np.float64))
    rough = np.broadcast_to(np.asarray(roughness, np.float64).reshape(-1), (len(n),))
    frame = local_frame(n, v)
    minv = _matrix(_interp(load_table()["minv"], rough, view_x(n, v)))
    local = np.einsum("nij,ntj->nti", frame, np.asarray(directions, np.float64))
    density = ltc_density(minv[:, None], local) / hemisphere_norm(minv)[:, None]
    ok = (local[..., 2] > 0.0) & (np.sum(n * v, axis=-1) > 0.0)[:, None]
    return np.where(ok, density, 0.0)


def ltc_polygon_integral(p, n, v, roughness, corners, chunk: int = 64, directions: bool = False):
    """(N, T) ∫ ρ over each triangle: the normalised GGX lobe of the points p (N, 3) with unit
    normals n (N, 3), unit directions toward the viewer v (N, 3) and Principled ``roughness``
    (N,) or scalar, over triangles ``corners`` (T, 3, 3), or each point's own (N, T, 3, 3)
    (either orientation; clipped to the point's horizon). 0 where the view is at or below the
    horizon. Sums over all triangles of a closed surface around p give 1.

    directions: also (N, T, 3) world unit directions where the lobe meets each triangle: the
    clipped polygon's mean direction in the cosine's space (``_clamped_cosine_integral``)
    carried back by M — for a small triangle its centre, for a large or near one the part of
    it the lobe reaches (what a Fresnel that varies over the lobe must be evaluated toward); 0
    where the integral is 0."""
    p = np.atleast_2d(np.asarray(p, np.float64))
    n = np.atleast_2d(np.asarray(n, np.float64))
    v = np.atleast_2d(np.asarray(v, np.float64))
    corners = np.asarray(corners, np.float64)
    corners = corners if corners.ndim == 4 else corners.reshape(-1, 3, 3)  # per point, or shared
    rough = np.asarray(roughness, np.float64).reshape(-1)
    count = max(len(p), len(n), len(v), len(rough))
    p, n, v = (np.broadcast_to(x, (count, 3)) for x in (p, n, v))
    rough = np.broadcast_to(rough, (count,))
    cos_view = np.sum(n * v, axis=-1)
    frame = local_frame(n, v)                                   # (N, 3, 3)
    minv = _matrix(_interp(load_table()["minv"], rough, view_x(n, v)))   # (N, 3, 3)
    norm = hemisphere_norm(minv)                                # (N,)
    triangles = corners.shape[-3]
    out = np.zeros((count, triangles))
    towards = np.zeros((count, triangles, 3)) if directions else None
    back = np.linalg.inv(minv) if directions else None       # M
    shared = corners.ndim == 3
    for start in range(0, triangles, chunk):
        part = corners[None, start:start + chunk] if shared else corners[:, start:start + chunk]
        rel = part - p[:, None, None]                                    # (N, t, 3, 3)
        local = np.einsum("nij,ntkj->ntki", frame, rel)
        # the surface's horizon first (ρ is 0 below it), then the transform
        clipped, _ = _clip(local, local[..., 2])                # (N, t, 6, 3)
        transformed = np.einsum("nij,ntkj->ntki", minv, clipped)
        if not directions:
            out[:, start:start + chunk] = _clamped_cosine_integral(transformed)
            continue
        out[:, start:start + chunk], mean = _clamped_cosine_integral(transformed, vector=True)
        world = np.einsum("nji,ntj->nti", frame, np.einsum("nij,ntj->nti", back, mean))
        length = norm3(world)[..., None]
        towards[:, start:start + chunk] = np.divide(world, length, out=np.zeros_like(world),
                                                    where=length > 0)
    out = np.where((cos_view > 0.0)[:, None], out / norm[:, None], 0.0)
    if directions:
        return out, np.where((out > 0.0)[..., None], towards, 0.0)
    return out
