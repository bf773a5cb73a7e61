"""Fit the LTC table ``voxgi_addon/gi/ltc_ggx.npz`` for the Principled GGX lobe
(``voxgi_addon/gi/ltc.py``; docs/gi_pipeline.md "LTC: the glossy lobe over polygons").

Dev-only, numpy (no scipy), deterministic, a few minutes on one core:
``python tools/fit_ltc.py [--size 64]``; ``python tools/fit_ltc.py --report`` prints the accuracy
table of the docs (LTC triangle integrals against a visible-normal quadrature of the lobe).

The target, per cell (roughness r, α = r², view cos θ_v = μ in the x–z plane), is the lobe of
``principled._ggx_eval`` — D G2 / (4 μ), the Fresnel-less single-scattering GGX BSDF × cos (a
white metal's ``glossy_reflectance`` up to the constant Kulla–Conty factor) — divided by its
hemisphere integral E: ρ(ω), a density on the upper hemisphere. The model is D_o / N_H, the
LTC density restricted to the hemisphere and renormalised (``ltc.hemisphere_norm``).

Fit: M = R_φ [[s_x, 0, 0], [0, s_y, 0], [κ s_x, 0, 1]] (R_φ turns z toward the lobe: 4 unique
parameters log s_x, log s_y, κ, φ; M⁻¹ is stored scaled to M⁻¹₂₂ = 1). Objective: ∫_H |D_o/N_H − ρ|, the
L1 distance (twice the largest error any polygon's integral can have), estimated with fixed
stratified sample sets drawn from both densities and combined by the balance heuristic as Heitz
does (ρ by Heitz 2018's visible-normal sampling, D_o by transforming cosine samples with M).
Minimised by a Nelder–Mead written here. Cells are fitted from the roughest row down and, in each
row, from normal incidence to grazing; each starts from the best (by the objective) of: its
neighbour toward normal incidence, its neighbour one row rougher, and a moment estimate (mean
direction → φ, weighted median tangent spreads → s_x, s_y); the search is restarted once from its
result.
"""
from __future__ import annotations

import argparse
import math
import os
import pathlib
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # 3 × 3 inverses: threads only cost

import numpy as np  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))

from voxgi_addon.gi import ltc  # noqa: E402
from voxgi_addon.gi.principled import _ggx_eval, _ggx_lambda, _sample_vndf  # noqa: E402

ROUGH_MIN = 0.03      # the r = 0 row (a mirror) is fitted at this roughness (α = 9·10⁻⁴)
COS_MIN = 1e-3        # the grazing column (cos θ_v = 0) is fitted at this cos θ_v
FIT_SAMPLES = 32      # per technique: FIT_SAMPLES² stratified samples
NORM_SAMPLES = 256    # E by a NORM_SAMPLES² visible-normal quadrature
CHECK_SAMPLES = 96    # the stored L1 error, an independent, finer estimate


def grid_midpoints(n: int, shift: float = 0.5):
    u = (np.arange(n) + shift) / n
    a, b = np.meshgrid(u, u, indexing="ij")
    return a.ravel(), b.ravel()


def cosine_samples(n: int, shift: float = 0.5) -> np.ndarray:
    """(n², 3) stratified cosine-distributed directions (concentric-free polar map)."""
    u1, u2 = grid_midpoints(n, shift)
    r = np.sqrt(u1)
    phi = 2 * math.pi * u2
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(1 - u1, 0))], -1)


class Lobe:
    """ρ for one (α, μ): evaluation, the visible-normal pdf of reflected directions, samples."""

    def __init__(self, alpha: float, mu: float):
        self.alpha, self.mu = alpha, mu
        self.v = np.array([math.sqrt(max(1 - mu * mu, 0.0)), 0.0, mu])
        self.g1 = 1.0 / (1.0 + float(_ggx_lambda(alpha * alpha, mu)))
        _, wo, _ = _sample_vndf(mu, alpha, *grid_midpoints(NORM_SAMPLES))
        self.e = float(np.mean(self._ratio(wo)))

    def _ratio(self, w):
        """G2/G1 where w is above the horizon, else 0 (the visible-normal estimator of ∫ρ·E)."""
        a2 = self.alpha ** 2
        up = w[:, 2] > 0
        li = _ggx_lambda(a2, self.mu)
        lo = _ggx_lambda(a2, np.where(up, w[:, 2], 1.0))
        return np.where(up, (1 + li) / (1 + li + lo), 0.0)

    def _d(self, h):
        a2 = self.alpha ** 2
        c2 = np.minimum(h[:, 2] ** 2, 1.0)
        return np.where(h[:, 2] > 0, a2 / (math.pi * (1 - c2 + a2 * c2) ** 2), 0.0)

    def half(self, w):
        h = w + self.v
        return h / np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-300)

    def rho(self, w):
        up = w[:, 2] > 0
        h = self.half(w)
        value = _ggx_eval(self.alpha, self.mu, np.where(up, w[:, 2], 1.0), np.clip(h[:, 2], 0, 1))
        return np.where(up & (h[:, 2] > 0), value / self.e, 0.0)

    def pdf(self, w):
        """Density of the visible-normal reflected directions (whole sphere)."""
        return self.g1 * self._d(self.half(w)) / (4 * self.mu)

    def samples(self, n: int, shift: float = 0.5):
        _, wo, _ = _sample_vndf(self.mu, self.alpha, *grid_midpoints(n, shift))
        return wo


def params_to_minv(x) -> np.ndarray | None:
    """(3, 3) M⁻¹ scaled to M⁻¹₂₂ = 1 from (log s_x, log s_y, κ, φ); None if unusable.

    M = R_φ [[s_x, 0, 0], [0, s_y, 0], [κ s_x, 0, 1]]: the cosine's pole goes to the
    direction φ itself (a shear of x toward z keeps z), so the parameters are unique (an upper
    shear would trade off with φ — narrow lobes then fit equally well with different (φ, shear)
    and neighbouring cells need not agree, which the lookup's blend of parameters needs)."""
    sx, sy, kappa, phi = math.exp(x[0]), math.exp(x[1]), x[2], x[3]
    c, s = math.cos(phi), math.sin(phi)
    e = c + kappa * s
    if not (e > 1e-9) or not math.isfinite(e):
        return None
    # M⁻¹ = S⁻¹ R_φᵀ / e (ltc._abcd)
    return np.array([[c / (sx * e), 0.0, -s / (sx * e)], [0.0, 1.0 / (sy * e), 0.0],
                     [(s - kappa * c) / e, 0.0, 1.0]])


class Objective:
    """∫_H |D_o/N_H − ρ| by the balance heuristic over fixed sample sets of both densities."""

    def __init__(self, lobe: Lobe, n: int, shift: float = 0.5):
        self.lobe = lobe
        self.w_rho = lobe.samples(n, shift)
        self.rho_rho = lobe.rho(self.w_rho)
        self.pdf_rho = lobe.pdf(self.w_rho)
        self.cos = cosine_samples(n, shift)
        self.count = n * n

    def __call__(self, x) -> float:
        minv = params_to_minv(x)
        if minv is None:
            return math.inf
        m = np.linalg.inv(minv)
        w_o = self.cos @ m.T
        w_o /= np.linalg.norm(w_o, axis=1, keepdims=True)
        w = np.concatenate([self.w_rho, w_o])
        rho = np.concatenate([self.rho_rho, self.lobe.rho(w_o)])
        q_rho = np.concatenate([self.pdf_rho, self.lobe.pdf(w_o)])
        d_o = ltc.ltc_density(minv, w)
        norm = float(ltc.hemisphere_norm(minv))
        model = np.where(w[:, 2] > 0, d_o / norm, 0.0)
        total = q_rho + d_o
        f = np.abs(model - rho)
        return float(np.sum(np.divide(f, total, out=np.zeros_like(f), where=total > 0)) / self.count)


def nelder_mead(f, x0, step, max_evals=400, tol=1e-7):
    """Minimise f from x0 with an axis-aligned initial simplex of ``step``; standard
    coefficients (reflect 1, expand 2, contract 0.5, shrink 0.5)."""
    x0 = np.asarray(x0, np.float64)
    dim = len(x0)
    simplex = [x0] + [x0 + np.eye(dim)[i] * step[i] for i in range(dim)]
    values = [f(x) for x in simplex]
    evals = dim + 1
    while evals < max_evals:
        order = np.argsort(values)
        simplex = [simplex[i] for i in order]
        values = [values[i] for i in order]
        if abs(values[-1] - values[0]) <= tol * (abs(values[0]) + 1e-12):
            break
        centroid = np.mean(simplex[:-1], axis=0)
        xr = centroid + (centroid - simplex[-1])
        fr = f(xr)
        evals += 1
        if fr < values[0]:
            xe = centroid + 2 * (centroid - simplex[-1])
            fe = f(xe)
            evals += 1
            simplex[-1], values[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < values[-2]:
            simplex[-1], values[-1] = xr, fr
        else:
            outside = fr < values[-1]
            xc = centroid + 0.5 * ((xr if outside else simplex[-1]) - centroid)
            fc = f(xc)
            evals += 1
            if fc < (fr if outside else values[-1]):
                simplex[-1], values[-1] = xc, fc
            else:
                for i in range(1, dim + 1):
                    simplex[i] = simplex[0] + 0.5 * (simplex[i] - simplex[0])
                    values[i] = f(simplex[i])
                evals += dim
    best = int(np.argmin(values))
    return simplex[best], values[best]


_COS_MEDIAN = None


def moment_start(lobe: Lobe) -> np.ndarray:
    """(log s_x, log s_y, 0, φ) from the lobe's mean direction and weighted median tangents."""
    global _COS_MEDIAN
    if _COS_MEDIAN is None:
        c = cosine_samples(256)
        _COS_MEDIAN = float(np.median(np.abs(c[:, 0] / c[:, 2])))
    w = lobe.samples(64)
    g = lobe._ratio(w)
    mean = (g[:, None] * w).sum(0)
    phi = math.atan2(mean[0], mean[2])
    c, s = math.cos(phi), math.sin(phi)
    local = w @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # R^T w
    keep = (g > 0) & (local[:, 2] > 1e-6)

    def wmedian(values):
        order = np.argsort(values)
        cdf = np.cumsum(g[keep][order])
        return values[order][np.searchsorted(cdf, 0.5 * cdf[-1])]

    sx = wmedian(np.abs(local[keep, 0] / local[keep, 2])) / _COS_MEDIAN
    sy = wmedian(np.abs(local[keep, 1] / local[keep, 2])) / _COS_MEDIAN
    return np.array([math.log(max(sx, 1e-6)), math.log(max(sy, 1e-6)), 0.0, phi])


def fit_cell(lobe: Lobe, starts: list[np.ndarray]):
    objective = Objective(lobe, FIT_SAMPLES)
    values = [objective(x) for x in starts]
    x = starts[int(np.argmin(values))]
    if lobe.mu >= 1.0:
        # normal incidence: the lobe is rotationally symmetric, so is its fit (b = d = 0, a = c),
        # and the lookup does not depend on the tangent chosen there
        scale = (x[0] + x[1]) / 2
        (scale,), value = nelder_mead(lambda y: objective([y[0], y[0], 0.0, 0.0]), [scale], [0.3])
        (scale,), value = nelder_mead(lambda y: objective([y[0], y[0], 0.0, 0.0]), [scale], [0.05])
        return np.array([scale, scale, 0.0, 0.0]), value
    for scale in (0.3, 0.3, 0.1):
        width = math.exp(min(x[0], x[1]))
        step = np.array([scale, scale, scale, scale * width])
        x, value = nelder_mead(objective, x, step)
    return x, value


def l1_error(lobe: Lobe, minv: np.ndarray) -> float:
    """∫_H |D_o/N_H − ρ| on independent (shifted, finer) sample sets."""
    objective = Objective(lobe, CHECK_SAMPLES, shift=0.25)
    m = np.linalg.inv(minv)
    # the objective's parametrisation is not needed: evaluate with the matrix directly
    w_o = objective.cos @ m.T
    w_o /= np.linalg.norm(w_o, axis=1, keepdims=True)
    w = np.concatenate([objective.w_rho, w_o])
    rho = lobe.rho(w)
    d_o = ltc.ltc_density(minv, w)
    model = np.where(w[:, 2] > 0, d_o / float(ltc.hemisphere_norm(minv)), 0.0)
    total = lobe.pdf(w) + d_o
    f = np.abs(model - rho)
    return float(np.sum(np.divide(f, total, out=np.zeros_like(f), where=total > 0)) / objective.count)


def fit_table(size: int):
    rough = np.arange(size) / (size - 1)
    view_x = np.arange(size) / (size - 1)
    cos_view = np.maximum(1.0 - view_x ** 2, COS_MIN)
    params = np.zeros((size, size, 4))
    minv = np.zeros((size, size, 4))
    error = np.zeros((size, size))
    start = time.perf_counter()
    for i in range(size - 1, -1, -1):
        alpha = max(rough[i], ROUGH_MIN) ** 2
        for j in range(size):
            lobe = Lobe(alpha, float(cos_view[j]))
            starts = [moment_start(lobe)]
            if j > 0:
                starts.append(params[i, j - 1])
            if i < size - 1:
                above = params[i + 1, j].copy()
                # one row narrower: scale the spreads by the ratio of the α's
                ratio = alpha / max(rough[i + 1], ROUGH_MIN) ** 2
                above[:2] += math.log(ratio)
                starts.append(above)
            x, _ = fit_cell(lobe, starts)
            params[i, j] = x
            m = params_to_minv(x)
            minv[i, j] = (m[0, 0], m[0, 2], m[1, 1], m[2, 0])
            error[i, j] = l1_error(lobe, m)
        print(f"roughness {rough[i]:.3f}: L1 max {error[i].max():.4f} mean {error[i].mean():.4f}"
              f" ({time.perf_counter() - start:.0f} s)", flush=True)
    return {"minv": minv.astype(np.float32), "roughness": rough.astype(np.float32),
            "view_x": view_x.astype(np.float32), "error": error.astype(np.float32),
            "rough_min": np.float32(ROUGH_MIN), "cos_min": np.float32(COS_MIN)}


# --------------------------------------------------------------------------- report

def reference_integrals(rough: float, mu: float, tris: np.ndarray, n: int = 1024,
                        full=None) -> np.ndarray:
    """(T,) ∫_tri ρ by an n² visible-normal quadrature (local frame, view in x–z, triangles
    (T, 3, 3) of directions). ``full``: (base, metallic, level) — then ∫ glossy_reflectance /
    glossy_color of that Principled material instead (Fresnel included)."""
    from voxgi_addon.gi import principled as pr
    lobe = Lobe(max(rough, 1e-4) ** 2, mu)
    w = lobe.samples(n)
    weight = lobe._ratio(w) / lobe.e
    if full is not None:
        base, metallic, level = full
        up = w[:, 2] > 0
        refl = pr.glossy_reflectance(base, metallic, level, rough, np.array([0, 0, 1.0]), lobe.v,
                                     np.where(up[:, None], w, [0, 0, 1.0]))[:, 1]
        color = pr.glossy_color(base, metallic, level, rough, mu)[1]
        weight = np.where(up, refl / np.maximum(lobe.pdf(w), 1e-300) / color, 0.0)
    out = np.zeros(len(tris))
    for t, c in enumerate(tris):
        inside = np.ones(len(w), bool)
        sign = np.sign(np.dot(np.cross(c[0], c[1]), c[2]))
        for k in range(3):
            inside &= sign * (w @ np.cross(c[k], c[(k + 1) % 3])) >= 0
        out[t] = np.sum(weight * inside) / len(w)
    return out


def random_triangles(rng, lobe_dir: np.ndarray, count: int, spread: float) -> np.ndarray:
    """(count, 3, 3) triangles of unit corner directions: half centred on a direction near the
    lobe, half anywhere above (or across) the horizon, angular radii from tiny to large."""
    out = []
    for t in range(count):
        if t % 2 == 0:
            centre = lobe_dir + rng.normal(size=3) * spread
        else:
            centre = rng.normal(size=3)
            centre[2] = abs(centre[2])
        centre /= np.linalg.norm(centre)
        radius = math.exp(rng.uniform(math.log(max(0.3 * spread, 0.01)), math.log(1.2)))
        a = np.cross(centre, [0.3, 0.5, 0.8])
        a /= np.linalg.norm(a)
        b = np.cross(centre, a)
        angles = rng.uniform(0, 2 * math.pi) + np.array([0, 2, 4]) * math.pi / 3 \
            + rng.uniform(-0.6, 0.6, 3)
        corners = centre + radius * (np.cos(angles)[:, None] * a + np.sin(angles)[:, None] * b)
        out.append(corners / np.linalg.norm(corners, axis=1, keepdims=True))
    return np.array(out)


MATERIALS = (("white metal", ((1.0, 1.0, 1.0), 1.0, 0.5)),
             ("gold metal", ((1.0, 0.766, 0.336), 1.0, 0.5)),
             ("dielectric (level 0.5, F0 0.04)", ((0.8, 0.8, 0.8), 0.0, 0.5)))


def accuracy(roughs=(0.1, 0.2, 0.3, 0.5, 0.7, 1.0), views=8, tris=24, n=512, seed=5):
    """Per roughness: dicts of arrays over random (view, triangle): ``mu``, ``ltc``, ``ref``
    (∫ρ by quadrature) and, per ``MATERIALS`` name, the full Principled lobe's
    ∫ glossy_reflectance / glossy_color (green channel)."""
    rng = np.random.default_rng(seed)
    out = []
    for r in roughs:
        rows = {"mu": [], "ltc": [], "ref": [], **{name: [] for name, _ in MATERIALS}}
        for mu in np.linspace(0.05, 1.0, views):
            lobe = Lobe(r * r, mu)
            mirror = np.array([-lobe.v[0], 0, mu])
            corners = random_triangles(rng, mirror, tris, spread=max(2 * r * r, 0.02))
            rows["mu"].extend([mu] * tris)
            rows["ref"].extend(reference_integrals(r, mu, corners, n))
            rows["ltc"].extend(ltc.ltc_polygon_integral(np.zeros(3), [0, 0, 1.0], lobe.v, r, corners)[0])
            for name, full in MATERIALS:
                rows[name].extend(reference_integrals(r, mu, corners, n, full))
        out.append((r, {k: np.array(v) for k, v in rows.items()}))
    return out


def _stats(got, ref):
    err = np.abs(got - ref)
    big = ref >= 0.05
    rel = err[big] / ref[big]
    return (f"{err.mean():.4f} | {np.percentile(err, 95):.4f} | {err.max():.4f} | "
            f"{rel.mean():.3f} | {np.percentile(rel, 95):.3f}")


def report():
    results = accuracy()
    header = ("| roughness | views | \\|err\\| mean | p95 | max | rel. mean | rel. p95 |\n"
              "|---|---|---|---|---|---|---|")
    print("LTC against ∫ρ (quadrature), errors relative to 1 and (triangles ≥ 5% of the lobe) to "
          "the triangle's integral\n" + header)
    for r, rows in results:
        for label, keep in (("cos θ_v ≥ 0.3", rows["mu"] >= 0.3), ("cos θ_v < 0.3", rows["mu"] < 0.3)):
            print(f"| {r:.1f} | {label} | {_stats(rows['ltc'][keep], rows['ref'][keep])} |")
    for name, _ in MATERIALS:
        print(f"\nFresnel neglected, {name}: ∫ρ against ∫ glossy_reflectance / glossy_color (same "
              "columns), then the LTC against the latter\n" + header)
        for r, rows in results:
            print(f"| {r:.1f} | ρ | {_stats(rows['ref'], rows[name])} |")
            print(f"| {r:.1f} | LTC | {_stats(rows['ltc'], rows[name])} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--report", action="store_true")
    args = parser.parse_args()
    if args.report:
        report()
        return
    start = time.perf_counter()
    table = fit_table(args.size)
    np.savez_compressed(ltc.TABLE_PATH, **table)
    print(f"wrote {ltc.TABLE_PATH} ({ltc.TABLE_PATH.stat().st_size} bytes) in "
          f"{time.perf_counter() - start:.0f} s; L1 error max {table['error'].max():.4f}")


if __name__ == "__main__":
    main()
