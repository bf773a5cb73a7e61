"""Cycles 5.0's Principled BSDF for opaque dielectrics and metals: the parts the GI preview
needs (docs/gi_pipeline.md "Principled materials").

What Cycles builds from a Principled BSDF with no coat, sheen, transmission, subsurface,
anisotropy or thin film, Specular Tint white and the default "Multiscatter GGX" distribution
(kernel ``svm_node_closure_bsdf``):

* a metal lobe, weight ``metallic``: GGX (α = roughness²) with the F82-tint Fresnel, which for a
  white tint is Schlick's ``F0 + (1 − F0)(1 − cos)^5`` with ``F0`` = base colour clamped to 1;
* the remaining ``1 − metallic`` goes to a dielectric layer: a GGX lobe whose Fresnel is the
  real dielectric Fresnel of the IOR ``η`` that Specular IOR Level remaps (``F0(1.5) = 0.04``
  scaled by ``2 × level``; level 0 leaves no specular lobe at all), over a Lambertian base whose
  weight is ``base × (1 − metallic) × (1 − A_spec(μ))``, ``A_spec`` being the specular lobe's
  albedo *seen from the view direction* (μ = cos(normal, view));
* both GGX lobes carry the multiple-scattering energy compensation: the single-scattering BSDF
  scaled by ``1/E(μ)`` and weighted by ``E(μ) + F_ms (1 − E(μ))`` (Kulla–Conty), ``E`` the GGX
  directional albedo without Fresnel, ``F_ms = F_ss E_avg / (1 − F_ss (1 − E_avg))``.

Cycles' passes then are: ``Diffuse Color`` = the Lambertian weight; ``Glossy Color`` = Σ over the
GGX lobes of weight × their estimated albedo; ``Glossy Direct`` = glossy radiance from the lights
divided by ``Glossy Color`` (the film divides the colour out), so that
``Combined = DiffCol (DiffDir + DiffInd) + GlossCol (GlossDir + GlossInd)``.

Tables (``principled_luts.npz`` beside this file, written by ``tools/make_principled_luts.py``
with ``compute_luts``; they are defined exactly as Cycles' precomputed ones, but integrated here
by deterministic quadrature over the GGX visible normals):

* ``ggx_E`` (32 μ × 32 roughness): GGX directional albedo without Fresnel;
* ``ggx_Eavg`` (32 roughness): its cosine-weighted average ``∫ 2μ E dμ``;
* ``ior_s`` (16 z × 16 μ × 16 roughness), z = sqrt((η − 1)/(η + 1)): the mean over the visible
  normals of the Fresnel interpolation factor ``s`` with ``F = F0 + (1 − F0) s`` (directions
  reflected below the horizon count 0); albedo estimate of the dielectric lobe = F0 + (1 − F0) s;
* ``metal_s`` (16 μ × 16 roughness): the same for Schlick's ``(1 − cos)^e``, already blended
  half-way between Cycles' exponent slices 40/7 and 35/8 (where Cycles reads its table for F82).

Lookups are the piecewise-linear ones of Cycles' ``lookup_table_read*`` (grid points at
``i/(n − 1)``, coordinates clamped to [0, 1]). Every function here is vectorised: parameters
broadcast against each other; colours have a trailing axis of 3.
"""
from __future__ import annotations

import pathlib

import numpy as np

__all__ = [
    "DEFAULT_IOR", "specular_f0_eta", "diffuse_weight", "glossy_color", "glossy_reflectance",
    "glossy_direct", "outgoing_radiance", "load_luts", "compute_luts", "lookup", "lut_texels",
    "LUT_ROWS",
]

DEFAULT_IOR = 1.5
# Cycles: BSDF_ROUGHNESS_SQ_THRESH (α_x α_y at or below it is a mirror: sampled, never evaluated)
# and CLOSURE_WEIGHT_CUTOFF.
ROUGHNESS_SQ_THRESHOLD = 2e-10
WEIGHT_CUTOFF = 1e-5
LUT_PATH = pathlib.Path(__file__).resolve().with_name("principled_luts.npz")
_luts: dict[str, np.ndarray] | None = None


# --------------------------------------------------------------------------- tables

def lookup(table: np.ndarray, *coords) -> np.ndarray:
    """Cycles' ``lookup_table_read`` / ``_2D`` / ``_3D``: ``table`` indexed [z][y][x] (as many
    axes as ``coords``), coordinates (x, y[, z]) in [0, 1] (clamped), linear between grid points
    ``i / (n − 1)``."""
    table = np.asarray(table, dtype=np.float64)
    if len(coords) != table.ndim:
        raise ValueError(f"{table.ndim}-D table needs {table.ndim} coordinates")
    coords = np.broadcast_arrays(*[np.asarray(c, dtype=np.float64) for c in coords])
    result = np.zeros(coords[0].shape)
    # Axis k of ``coords`` (x first) is table axis ndim − 1 − k.
    corners = [()]
    weights = [np.ones(coords[0].shape)]
    for axis in range(table.ndim - 1, -1, -1):
        n = table.shape[axis]
        f = np.clip(np.nan_to_num(coords[table.ndim - 1 - axis]), 0.0, 1.0) * (n - 1)
        i = np.minimum(f.astype(np.int64), n - 1)
        j = np.minimum(i + 1, n - 1)
        t = f - i
        corners = [(k,) + c for c in corners for k in (i, j)]
        weights = [w * s for w in weights for s in (1.0 - t, t)]
    for index, w in zip(corners, weights):
        result += w * table[index]
    return result


def load_luts() -> dict[str, np.ndarray]:
    """The stored tables (float64 copies): ``ggx_E`` (32, 32), ``ggx_Eavg`` (32,), ``ior_s``
    (16, 16, 16), ``metal_s`` (16, 16); see the module doc."""
    global _luts
    if _luts is None:
        with np.load(LUT_PATH) as data:
            _luts = {name: np.asarray(data[name], dtype=np.float64) for name in data.files}
    return _luts


# First row of each table in ``lut_texels`` (render/shaders/principled.glsl reads them).
LUT_ROWS = {"PR_ROW_E": 0, "PR_ROW_EAVG": 32, "PR_ROW_IOR_S": 33, "PR_ROW_METAL_S": 33 + 256}
LUT_TEXELS_WIDE = 32


def lut_texels() -> np.ndarray:
    """The tables packed for the GPU: (305, 32, 4) float32, values in the red channel, one table
    row per texel row from ``LUT_ROWS`` (16-wide tables fill columns 0–15)."""
    luts = load_luts()
    texels = np.zeros((LUT_ROWS["PR_ROW_METAL_S"] + 16, LUT_TEXELS_WIDE, 4), np.float32)
    texels[0:32, :, 0] = luts["ggx_E"]
    texels[32, :, 0] = luts["ggx_Eavg"]
    rows = LUT_ROWS["PR_ROW_IOR_S"]
    texels[rows:rows + 256, :16, 0] = luts["ior_s"].reshape(256, 16)
    rows = LUT_ROWS["PR_ROW_METAL_S"]
    texels[rows:rows + 16, :16, 0] = luts["metal_s"]
    return texels


def _vndf_grid(n: int):
    """(n², 2) midpoints of an n × n grid over the unit square."""
    u = (np.arange(n) + 0.5) / n
    a, b = np.meshgrid(u, u, indexing="ij")
    return a.ravel(), b.ravel()


def _sample_vndf(mu: float, alpha: float, u1: np.ndarray, u2: np.ndarray):
    """GGX visible-normal samples (Heitz 2018) for the view (sqrt(1 − μ²), 0, μ): the half
    vectors (n, 3) and the reflected directions (n, 3)."""
    wi = np.array([np.sqrt(max(1.0 - mu * mu, 0.0)), 0.0, mu])
    vh = np.array([alpha * wi[0], 0.0, wi[2]])
    vh /= np.linalg.norm(vh)
    lensq = vh[0] ** 2 + vh[1] ** 2
    if lensq > 1e-7:
        t1 = np.array([-vh[1], vh[0], 0.0]) / np.sqrt(lensq)
        t2 = np.cross(vh, t1)
    else:
        t1, t2 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = p1[:, None] * t1 + p2[:, None] * t2 + p3[:, None] * vh
    h = np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(nh[:, 2], 0.0)], axis=1)
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    cos_hi = h @ wi
    wo = 2.0 * cos_hi[:, None] * h - wi
    return h, wo, cos_hi


def _ggx_lambda(alpha2, cos):
    cos = np.asarray(cos, dtype=np.float64)
    tan2 = np.maximum(1.0 / np.maximum(cos * cos, 1e-300) - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha2 * tan2) - 1.0)


def _cell(rough: float, mu: float, n: int, fresnel_s=None) -> float:
    """One table cell, as Cycles' precomputation defines it: the mean over GGX visible normals
    of ``G2/G1`` (``fresnel_s`` None: the albedo E) or of ``fresnel_s(cos_hi)`` (the Fresnel
    interpolation factor); reflections below the horizon count 0. Roughness at or below the
    mirror threshold reflects about the normal."""
    alpha = rough * rough
    if alpha * alpha <= ROUGHNESS_SQ_THRESHOLD:
        return 1.0 if fresnel_s is None else float(np.clip(fresnel_s(np.array([mu])), 0, 1)[0])
    u1, u2 = _vndf_grid(n)
    _, wo, cos_hi = _sample_vndf(mu, alpha, u1, u2)
    valid = wo[:, 2] > 0.0
    if fresnel_s is None:
        alpha2 = alpha * alpha
        li = _ggx_lambda(alpha2, mu)
        lo = _ggx_lambda(alpha2, np.where(valid, wo[:, 2], 1.0))
        value = (1.0 + li) / (1.0 + li + lo)
    else:
        value = np.clip(fresnel_s(cos_hi), 0.0, 1.0)
    return float(np.clip(np.where(valid, value, 0.0).mean(), 0.0, 1.0))


def _grid(n: int) -> np.ndarray:
    """Cycles' table coordinates ``clamp(i / (n − 1), 1e-4, 1)``."""
    return np.clip(np.arange(n) / (n - 1), 1e-4, 1.0)


def _ior_of_z(z: float) -> float:
    """Cycles' IOR parametrisation of the ``z`` table axis: ``ior_from_F0(z⁴)``."""
    return float(_ior_from_f0(min(max(z, 1e-4), 0.99) ** 4))


def _ior_s(eta: float):
    f0 = _f0_from_ior(eta)
    return lambda c: (_fresnel_dielectric(c, eta) - f0) / (1.0 - f0)


def compute_luts(n: int = 256, mu_steps: int = 256) -> dict[str, np.ndarray]:
    """The tables of the module doc, integrated over an ``n`` × ``n`` grid of visible normals per
    cell (``ggx_Eavg`` integrates E over ``mu_steps`` midpoints in μ with ``n/2`` × ``n/2``
    normals each). Deterministic; minutes of numpy at the default size."""
    rough32, rough16 = _grid(32), _grid(16)
    ggx_e = np.array([[_cell(r, m, n) for r in rough32] for m in _grid(32)])
    mus = (np.arange(mu_steps) + 0.5) / mu_steps
    ggx_eavg = np.array([np.mean([2.0 * m * _cell(r, m, n // 2) for m in mus])
                         for r in np.clip(np.arange(32) / 31, 1e-4, 1.0)])
    zs = np.clip(np.arange(16) / 15, 1e-4, 0.99)
    ior_s = np.array([[[_cell(r, m, n, _ior_s(_ior_of_z(z))) for r in rough16]
                       for m in _grid(16)] for z in zs])
    # Metals read Cycles' generalized-Schlick table at z = 0.5: half-way between the slices
    # z = 7/15 and 8/15, exponents 5 (1 − z)/z = 40/7 and 35/8.
    metal_s = 0.5 * sum(np.array([[_cell(r, m, n, lambda c, e=e: (1.0 - c) ** e) for r in rough16]
                                  for m in _grid(16)]) for e in (40.0 / 7.0, 35.0 / 8.0))
    return {"ggx_E": ggx_e, "ggx_Eavg": ggx_eavg, "ior_s": ior_s, "metal_s": metal_s}


# --------------------------------------------------------------------------- Fresnel

def _f0_from_ior(ior):
    return ((np.asarray(ior, dtype=np.float64) - 1.0) / (np.asarray(ior, dtype=np.float64) + 1.0)) ** 2


def _ior_from_f0(f0):
    r = np.sqrt(np.clip(np.asarray(f0, dtype=np.float64), 0.0, 0.99))
    return (1.0 + r) / (1.0 - r)


def _fresnel_dielectric(cos_i, eta):
    """Cycles' unpolarised dielectric Fresnel (1 on total internal reflection)."""
    cos_i = np.abs(np.asarray(cos_i, dtype=np.float64))
    eta = np.asarray(eta, dtype=np.float64)
    g = eta * eta - (1.0 - cos_i * cos_i)
    ok = g > 0.0
    cos_t = -np.sqrt(np.where(ok, g, 1.0)) / eta
    rs = (cos_i + eta * cos_t) / (cos_i - eta * cos_t)
    rp = (cos_t + eta * cos_i) / (eta * cos_i - cos_t)
    return np.where(ok, 0.5 * (rs * rs + rp * rp), 1.0)


def _fresnel_dielectric_fss(eta):
    """Cycles' fit of the cosine-weighted mean dielectric Fresnel (Kulla–Conty)."""
    eta = np.asarray(eta, dtype=np.float64)
    return np.where(eta < 1.0, 0.997118 + eta * (0.1014 - eta * (0.965241 + eta * 0.130607)),
                    (eta - 1.0) / (4.08567 + 1.00071 * eta))


def specular_f0_eta(specular_ior_level, ior=DEFAULT_IOR):
    """(F0, η) of the dielectric lobe: ``F0 = ((ior − 1)/(ior + 1))² × 2 × level`` and the IOR
    that has that F0 (level 0.5 keeps ``ior``); η == 1 means no specular lobe (level 0)."""
    level = np.maximum(np.asarray(specular_ior_level, dtype=np.float64), 0.0)
    ior = np.maximum(np.asarray(ior, dtype=np.float64), 1e-5)
    f0 = _f0_from_ior(ior)
    remapped = f0 * 2.0 * level
    eta = _ior_from_f0(remapped)
    eta = np.where(ior < 1.0, 1.0 / eta, eta)
    keep = level == 0.5
    return np.clip(np.where(keep, f0, remapped), 0.0, 1.0), np.where(keep, ior, eta)


# --------------------------------------------------------------------------- lobes

def _saturate(x):
    return np.clip(x, 0.0, 1.0)


def _energy(rough, mu, fss):
    """(1/E, the lobe weight factor E + F_ms (1 − E) written as Cycles' ``darkening``) of a GGX
    lobe with mean single-scattering Fresnel ``fss`` (broadcasts; colours allowed)."""
    luts = load_luts()
    e = lookup(luts["ggx_E"], rough, mu)
    e_avg = lookup(luts["ggx_Eavg"], rough)
    if np.ndim(fss) > np.ndim(e):
        e, e_avg = e[..., None], e_avg[..., None]
    missing = (1.0 - e) / e
    fms = fss * e_avg / (1.0 - fss * (1.0 - e_avg))
    darkening = np.where(fss == 1.0, 1.0, (1.0 + fms * missing) * e)
    return 1.0 / e, darkening


def _dielectric(rough, mu, specular_ior_level, ior):
    """Per the dielectric lobe: F0, η, present mask, energy scale, darkening, albedo estimate."""
    f0, eta = specular_f0_eta(specular_ior_level, ior)
    present = eta != 1.0
    safe_eta = np.where(present, eta, 1.5)
    f0_real = _f0_from_ior(safe_eta)
    s_avg = _saturate((_fresnel_dielectric_fss(safe_eta) - f0_real) / (1.0 - f0_real))
    fss = f0 + (1.0 - f0) * s_avg
    scale, darkening = _energy(rough, mu, fss)
    z = np.sqrt(np.abs((safe_eta - 1.0) / (safe_eta + 1.0)))
    s = lookup(load_luts()["ior_s"], rough, mu, z)
    albedo = darkening * (f0 + (1.0 - f0) * s)
    return f0, safe_eta, present, scale, darkening, albedo


def _metal(base, rough, mu):
    """Per the metal lobe: F0 (…, 3), energy scale (…, 3), darkening (…, 3), albedo (…, 3)."""
    f0 = np.clip(base, 0.0, 1.0)
    fss = f0 + (1.0 - f0) / 21.0  # F82 with a white tint: mix(F0, 1, 1/21)
    scale, darkening = _energy(rough[..., None], mu[..., None], fss)
    s = lookup(load_luts()["metal_s"], rough, mu)[..., None]
    return f0, scale, darkening, darkening * (f0 + (1.0 - f0) * s)


def _params(base, metallic, specular_ior_level, roughness, cos_view):
    base = np.maximum(np.asarray(base, dtype=np.float64), 0.0)
    metallic = _saturate(np.asarray(metallic, dtype=np.float64))
    rough = _saturate(np.asarray(roughness, dtype=np.float64))
    mu = np.asarray(cos_view, dtype=np.float64)
    shape = np.broadcast_shapes(base.shape[:-1], metallic.shape, np.shape(specular_ior_level),
                                rough.shape, mu.shape)
    return (np.broadcast_to(base, shape + (3,)), np.broadcast_to(metallic, shape),
            np.broadcast_to(np.asarray(specular_ior_level, dtype=np.float64), shape),
            np.broadcast_to(rough, shape), np.broadcast_to(mu, shape))


def diffuse_weight(base, metallic, specular_ior_level, roughness, cos_view, ior=DEFAULT_IOR):
    """Cycles' ``Diffuse Color`` pass: ``base × (1 − metallic) × (1 − A_spec(μ))``.

    base : (…, 3) linear RGB base colour; metallic, specular_ior_level, roughness : (…) or
    scalars; cos_view : (…) μ = cos(shading normal, direction to the viewer), the table lookups
    clamp it to [0, 1]; ior : the node's IOR (1.5). Returns (…, 3) float64.
    """
    base, metallic, level, rough, mu = _params(base, metallic, specular_ior_level, roughness,
                                               cos_view)
    _, _, present, _, _, albedo = _dielectric(rough, mu, level, ior)
    layer = np.where(present, _saturate(1.0 - albedo), 1.0)
    weight = np.where(metallic > WEIGHT_CUTOFF, 1.0 - metallic, 1.0)
    return base * (weight * layer)[..., None]


def glossy_color(base, metallic, specular_ior_level, roughness, cos_view, ior=DEFAULT_IOR):
    """Cycles' ``Glossy Color`` pass: Σ over the GGX lobes of weight × albedo estimate. Same
    arguments and shapes as ``diffuse_weight``; returns (…, 3)."""
    base, metallic, level, rough, mu = _params(base, metallic, specular_ior_level, roughness,
                                               cos_view)
    _, _, present, _, _, albedo = _dielectric(rough, mu, level, ior)
    has_metal = metallic > WEIGHT_CUTOFF
    weight = np.where(has_metal, 1.0 - metallic, 1.0)
    out = np.where(present, weight * albedo, 0.0)[..., None] * np.ones(3)
    _, _, _, metal_albedo = _metal(base, rough, mu)
    return out + np.where(has_metal, metallic, 0.0)[..., None] * metal_albedo


def _ggx_eval(alpha, cos_ni, cos_no, cos_nh):
    """``D / (4 cos_ni (1 + Λ_i + Λ_o))``: the GGX BSDF × cos_no without Fresnel."""
    alpha2 = alpha * alpha
    c2 = np.minimum(cos_nh * cos_nh, 1.0)
    d = alpha2 / (np.pi * (1.0 - c2 + alpha2 * c2) ** 2)
    return d / (4.0 * cos_ni * (1.0 + _ggx_lambda(alpha2, cos_ni) + _ggx_lambda(alpha2, cos_no)))


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def glossy_reflectance(base, metallic, specular_ior_level, roughness, normal, view, light,
                       ior=DEFAULT_IOR):
    """The glossy lobes' BSDF × cos(normal, light) (Cycles' ``eval``) for light arriving from
    ``light`` and leaving toward ``view``: a sun of strength S (W/m²) adds ``S × this`` to the
    glossy radiance (``Glossy Color × Glossy Direct``).

    normal, view, light : (…, 3) directions away from the surface (normalised here); other
    arguments as ``diffuse_weight``. Returns (…, 3); 0 where the view or the light is below the
    surface or the roughness is a mirror's (Cycles does not evaluate those).
    """
    n, v, l_ = _unit(normal), _unit(view), _unit(light)
    directions = np.broadcast_shapes(n.shape, v.shape, l_.shape)[:-1]
    cos_ni = np.broadcast_to(np.sum(n * v, axis=-1), directions)
    cos_no = np.sum(n * l_, axis=-1)
    base, metallic, level, rough, mu = _params(base, metallic, specular_ior_level, roughness,
                                               cos_ni)
    shape = mu.shape
    h = _unit(v + l_)
    cos_nh = np.broadcast_to(np.sum(n * h, axis=-1), shape)
    cos_hi = np.broadcast_to(np.sum(h * v, axis=-1), shape)
    cos_no = np.broadcast_to(cos_no, shape)
    alpha = rough * rough
    valid = (mu > 0.0) & (cos_no > 0.0) & (alpha * alpha > ROUGHNESS_SQ_THRESHOLD)
    safe_ni = np.where(valid, mu, 1.0)
    safe_no = np.where(valid, cos_no, 1.0)
    common = np.where(valid, _ggx_eval(np.where(valid, alpha, 0.5), safe_ni, safe_no, cos_nh), 0.0)

    f0, eta, present, scale, darkening, _ = _dielectric(rough, safe_ni, level, ior)
    f0_real = _f0_from_ior(eta)
    s = _saturate((_fresnel_dielectric(cos_hi, eta) - f0_real) / (1.0 - f0_real))
    fresnel = f0 + (1.0 - f0) * s
    has_metal = metallic > WEIGHT_CUTOFF
    weight = np.where(has_metal, 1.0 - metallic, 1.0)
    dielectric = np.where(present, weight * darkening * scale * fresnel * common, 0.0)

    m_f0, m_scale, m_darkening, _ = _metal(base, rough, safe_ni)
    s5 = _saturate(1.0 - cos_hi)[..., None] ** 5
    m_fresnel = _saturate(m_f0 + (1.0 - m_f0) * s5)
    metal = (np.where(has_metal, metallic, 0.0) * common)[..., None] * m_darkening * m_scale * m_fresnel
    return dielectric[..., None] + metal


def glossy_direct(base, metallic, specular_ior_level, roughness, normal, view, light,
                  ior=DEFAULT_IOR):
    """Cycles' ``Glossy Direct`` pass per unit light strength (the glossy radiance without the
    glossy colour): ``glossy_reflectance / glossy_color`` (0 where the colour is 0). Multiply
    by a sun's strength; (…, 3)."""
    reflect = glossy_reflectance(base, metallic, specular_ior_level, roughness, normal, view,
                                 light, ior)
    mu = np.sum(_unit(normal) * _unit(view), axis=-1)
    color = glossy_color(base, metallic, specular_ior_level, roughness, mu, ior)
    return np.where(color > 0.0, reflect / np.where(color > 0.0, color, 1.0), 0.0)


def outgoing_radiance(base, metallic, specular_ior_level, roughness, normal, view, light,
                      irradiance, ior=DEFAULT_IOR):
    """Radiance a Principled surface point sends toward ``view`` when a light from direction
    ``light`` gives ``irradiance`` on a plane facing the light (a sun's strength; a point
    light's P / (4π² d²) per docs/blender_facts.md "Cycles' radiometry"; 0 when shadowed):
    ``irradiance × (Diffuse Color(μ_view) × max(0, n·l)/π + glossy_reflectance)``.

    The shading of a bounce hit: ``view`` points from the hit back toward the receiver, so the
    diffuse weight is the one the receiver sees. irradiance : (…) or (…, 3); others as
    ``glossy_reflectance``. Returns (…, 3).
    """
    n, v, l_ = _unit(normal), _unit(view), _unit(light)
    mu = np.sum(n * v, axis=-1)
    cos_l = np.maximum(np.sum(n * l_, axis=-1), 0.0)
    diffuse = diffuse_weight(base, metallic, specular_ior_level, roughness, mu, ior)
    diffuse = diffuse * np.where(mu > 0.0, cos_l / np.pi, 0.0)[..., None]
    glossy = glossy_reflectance(base, metallic, specular_ior_level, roughness, n, v, l_, ior)
    irradiance = np.asarray(irradiance, dtype=np.float64)
    if irradiance.ndim == 0 or irradiance.shape[-1:] != (3,):
        irradiance = irradiance[..., None]
    return irradiance * (diffuse + glossy)
