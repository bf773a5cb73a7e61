"""Light arriving at a probe straight from the world and the emissive surfaces, by next-event
estimation with multiple importance sampling (docs/probes.md "Lights at the probe").

A probe's SH coefficients are ``c = ∫ L(ω) Y(ω) dω`` over the sphere. The bake's N uniform
directions (``sh.sample_directions``, density p_u = 1/4π) estimate the part of L that comes
off surfaces (one bounce). The world and the emitters are lights: uniform directions find a
small HDRI sun or a small glowing panel rarely, so their part is estimated with rays drawn from
the lights themselves, combined with the uniform rays by the balance heuristic (with sample
counts: a direction ω sampled by either technique weighs f(ω) / (N p_u(ω) + K p_l(ω))).

* **World** (``gi.world_light.WorldLight``): the unshadowed projection ``∫ L_w Y dω`` of the
  whole map is exact (``world_sh``: the map is piecewise constant over its pixels, and each
  basis function integrates in closed form over a pixel's band of z = sin el and azimuth); what
  the scene hides of it is subtracted, estimated by MIS from the uniform rays that hit geometry
  and ``samples`` shadow rays drawn by the map's importance (``world_light.sample_world``, its
  luminance CDF; hashed strata of the probe's id, ``WORLD_STREAM``) that are occluded:

      c_world = world_sh − Σ_{rays blocked} L_w(ω) Y(ω) / (N/4π + K p_w(ω)),

  where a map ray's Y is the mean of the basis over its pixel (the ray tells whether the pixel
  is hidden; Y's spread inside a sun's pixel, times a sun 10⁴–10⁵ times the sky, would be
  noise as large as a shaded probe's light; the price is a bias where an edge crosses a pixel).

  A control variate: a probe that sees the whole sky gets it exactly, and a small bright sun,
  nearly all the map's samples land in, is seen or hidden with almost no noise.
* **Emitters** (``gi.emitters.EmitterLight``): ``samples`` points drawn by power
  (``emitters.sample_points``, ``EMITTER_STREAM``), p_e(ω) = p_area r² / |cos_l|, unoccluded
  and on a side that emits, plus the uniform rays landing on an emissive triangle's emitting
  side, both weighed by the balance heuristic; a uniform ray landing on a side that cannot be
  sampled (the inside of a closed emitter) keeps its plain weight 4π/N.

Lamps are not added at the probe: their direct light is computed per pixel wherever probes are
used (docs/probes.md "Bake"); they light the bounce hits.
"""
from __future__ import annotations

import math

import numpy as np

from ..gi.emitters import emitting_sides, sample_points
from ..gi.sampling import hashed_square
from ..gi.world_light import LUMINANCE, sample_world, world_pdf, world_radiance
from ..scene.equirect import direction_to_pixel
from ..scene.raycast import occluded
from ..scene.short_axis import norm3
from .sh import sh_basis

__all__ = ["WORLD_STREAM", "EMITTER_STREAM", "world_sh", "world_probe_sh", "emitter_probe_sh",
           "emitter_hit_pdf", "emissive_sides"]

WORLD_STREAM = 0x9B0E    # hash stream of the world's samples at a probe
EMITTER_STREAM = 0x9B0F  # hash stream of the emitters' samples at a probe

_C0 = 0.5 * math.sqrt(1.0 / math.pi)
_C1 = math.sqrt(3.0 / (4.0 * math.pi))
_C2 = 0.5 * math.sqrt(15.0 / math.pi)
_C20 = 0.25 * math.sqrt(5.0 / math.pi)
_C22 = 0.25 * math.sqrt(15.0 / math.pi)
_CACHE_SIZE = 8
_world_cache: dict[tuple, tuple[object, np.ndarray]] = {}  # per WorldLight (kept alive here)


def _pixel_basis_integrals(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """(R (H, 9), Q (W, 9)): ∫ over pixel (i, j) of basis k = R[i, k] · Q[j, k] (each real SH
    function up to l = 2 is a product of a polynomial in z and √(1 − z²) and one in cos φ,
    sin φ). Row i spans polar angles [iπ/H, (i + 1)π/H], column j azimuths
    [−π + 2πj/W, −π + 2π(j + 1)/W] (``scene.equirect``, ``world_light.sample_world``)."""
    theta = np.arange(height + 1) * math.pi / height
    z = np.cos(theta)
    z0, z1 = z[:-1], z[1:]  # top and bottom of each row (z0 > z1)
    r0, r1 = np.sqrt(np.maximum(0.0, 1 - z0 * z0)), np.sqrt(np.maximum(0.0, 1 - z1 * z1))

    i1 = z0 - z1
    ir = 0.5 * (z0 * r0 + np.arcsin(z0)) - 0.5 * (z1 * r1 + np.arcsin(z1))
    iz = 0.5 * (z0 * z0 - z1 * z1)
    izr = (r1 ** 3 - r0 ** 3) / 3.0
    izz = (z0 ** 3 - z1 ** 3) / 3.0
    i1mz2 = i1 - izz
    phi = -math.pi + np.arange(width + 1) * 2 * math.pi / width
    p0, p1 = phi[:-1], phi[1:]
    q1 = p1 - p0
    qc = np.sin(p1) - np.sin(p0)
    qs = np.cos(p0) - np.cos(p1)
    qsc = 0.5 * (np.sin(p1) ** 2 - np.sin(p0) ** 2)
    qc2 = 0.5 * (np.sin(2 * p1) - np.sin(2 * p0))
    rows = np.stack([_C0 * i1, _C1 * ir, _C1 * iz, _C1 * ir, _C2 * i1mz2, _C2 * izr,
                     _C20 * (3 * izz - i1), _C2 * izr, _C22 * i1mz2], axis=1)
    cols = np.stack([q1, qs, q1, qc, qsc, qs, q1, qc, qc2], axis=1)
    return rows, cols


def _pixel_mean_basis(world, directions) -> np.ndarray:
    """(M, 9) the mean of each basis function over the map pixel holding each direction."""
    h, w = world.radiance.shape[:2]
    rows, cols = _pixel_basis_integrals(h, w)
    r, c = direction_to_pixel(directions, h, w)
    i = np.clip(np.floor(r).astype(np.int64), 0, h - 1)
    j = np.floor(c).astype(np.int64) % w
    integral = rows[i] * cols[j]
    return integral / (integral[:, :1] / _C0)


def world_sh(world) -> np.ndarray:
    """(9, 3) exact SH projection ∫ L_w Y dω of the world's map (nearest-pixel radiance, as
    ``world_light.world_radiance`` reads it); cached per ``WorldLight``."""
    key = ("sh", id(world))
    cached = _world_cache.get(key)
    if cached is not None and cached[0] is world:
        return cached[1]
    h, w = world.radiance.shape[:2]
    rows, cols = _pixel_basis_integrals(h, w)
    out = np.einsum("ik,jk,ijc->kc", rows, cols, np.asarray(world.radiance, np.float64))
    _remember(key, world, out)
    return out


def _by_map(world, directions, n_uniform: int, k_light: int) -> np.ndarray:
    """(M,) bool: is the map pixel of each direction the map's rays' to estimate (K p_w > N p_u,
    the maximum heuristic)?"""
    return k_light * world_pdf(world, directions) > n_uniform / (4.0 * math.pi)


def _map_share(world, n_uniform: int, k_light: int) -> np.ndarray:
    """(3,) the DC coefficient ∫ L Y_0 dω of the pixels the map's rays estimate (``_by_map``),
    exact; cached per (``WorldLight``, N, K)."""
    key = ("share", id(world), n_uniform, k_light)
    cached = _world_cache.get(key)
    if cached is not None and cached[0] is world:
        return cached[1]
    h, w = world.radiance.shape[:2]
    rows, cols = _pixel_basis_integrals(h, w)
    radiance = np.asarray(world.radiance, np.float64)
    mine = k_light * (radiance @ LUMINANCE / world.total) > n_uniform / (4.0 * math.pi)
    out = np.einsum("i,j,ijc->c", rows[:, 0], cols[:, 0], radiance * mine[..., None])
    _remember(key, world, out)
    return out


def _remember(key, world, value) -> None:
    while len(_world_cache) >= _CACHE_SIZE:
        _world_cache.pop(next(iter(_world_cache)))
    _world_cache[key] = (world, value)


def _balance(n_uniform: int, k_light: int, pdf_light) -> np.ndarray:
    """1 / (N p_u + K p_l): the balance heuristic's weight over f for either technique."""
    return 1.0 / (n_uniform / (4.0 * math.pi) + k_light * np.asarray(pdf_light, np.float64))


def world_probe_sh(tris, world, positions, directions, ray_triangles, ids, samples: int = 64,
                   seed: int = 0) -> np.ndarray:
    """(P, 9, 3) the world's light arriving at each probe: ``world_sh`` less the occluded part
    (module doc). directions (N, 3): the bake's uniform set; ray_triangles (P, N): the closest
    hit of each of them (−1: the ray leaves the scene); ids (P,) the probes' sample ids."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    count, n = len(p), len(d)
    out = np.broadcast_to(world_sh(world), (count, 9, 3)).copy()
    if count == 0:
        return out
    square = hashed_square(np.asarray(ids), WORLD_STREAM, samples, seed)  # (P, K, 2)
    k = square.shape[1]
    drawn = sample_world(world, square)                                  # (P, K, 3)
    if not (_map_share(world, n, k) > 0).any():
        k = 0  # no pixel bright enough for the map's rays (a uniform sky): the uniform rays alone
    # Maximum heuristic (Veach 1997, 9.2.4): a pixel belongs to the technique that draws it
    # more densely — bright pixels (a sun) to the map's rays, dim ones to the uniform rays. The
    # balance heuristic left a uniform ray landing on the sun a few per cent of its light: a
    # spike as large as a shaded probe's whole light, there or not by the luck of the set.
    basis_u = sh_basis(d)                                                # (N, 9)
    by_map_u = _by_map(world, d, n, k)
    f_u = world_radiance(world, d) * (~by_map_u * 4.0 * math.pi / n)[:, None]  # (N, 3)
    hidden = (np.asarray(ray_triangles) >= 0).astype(np.float64)        # (P, N)
    out -= np.einsum("pn,nk,nc->pkc", hidden, basis_u, f_u)
    if k == 0:
        return out
    blocked = occluded(tris, np.repeat(p, k, axis=0), drawn.reshape(-1, 3), np.inf).reshape(count, k)
    # the map's rays that are blocked, each with its pixel's mean basis: the ray says whether
    # the pixel is hidden, and the basis's spread within one pixel of a sun 10⁴–10⁵ times the
    # sky would be noise the size of a shaded probe's whole light
    flat = drawn.reshape(-1, 3)
    pdf = world_pdf(world, flat)
    f_w = world_radiance(world, flat) * (_by_map(world, flat, n, k) / np.maximum(k * pdf, 1e-30))[:, None]
    f_w = f_w.reshape(count, k, 3)
    hidden_w = np.einsum("pjk,pjc->pkc", _pixel_mean_basis(world, flat).reshape(count, k, 9),
                         f_w * blocked[..., None])
    # ratio estimator: the map's rays carry a known share of the map's light (``_map_share``);
    # scaled to it, the count of rays that happen to land on a sun rather than the sky is no
    # noise any more (``world_light.world_direct``'s visible share does the same)
    drawn_share = f_w.sum(axis=1) * _C0                                   # (P, 3)
    known = _map_share(world, n, k)                                       # (3,)
    scale = np.divide(known, drawn_share, out=np.ones_like(drawn_share), where=drawn_share > 0)
    out -= hidden_w * scale[:, None, :]
    return out


def emissive_sides(tris, emission) -> tuple[np.ndarray, np.ndarray]:
    """((T, 3) radiance of every triangle's material emission, float32-rounded as
    ``EmitterLight`` holds it, (T,) its emitting side as ``EmitterLight.sides``: +1 the side
    its normal faces, −1 the other, 0 both; meaningful where the radiance is not 0)."""
    emission = np.maximum(np.nan_to_num(np.asarray(emission, np.float64)), 0.0)
    materials = np.asarray(tris.materials)
    last = len(emission) - 1
    materials = np.where((materials >= 0) & (materials < last), materials, last)
    radiance = emission[materials].astype(np.float32).astype(np.float64)
    sides = np.zeros(len(radiance), np.int8)
    keep = np.flatnonzero(radiance @ LUMINANCE > 0)
    if len(keep):
        corners = np.asarray(tris.positions, np.float64)
        sides[keep] = emitting_sides(corners[keep], np.asarray(tris.objects)[keep])
    return radiance, sides


def _total_power(light) -> float:
    return float(np.sum(light.area * (light.radiance @ LUMINANCE)))


def emitter_hit_pdf(light, radiance, distance, cos_light) -> np.ndarray:
    """Solid-angle pdf of ``sample_points`` for a point of radiance ``radiance`` (..., 3) at
    ``distance`` seen at |cos| ``cos_light`` of its triangle: p_area r² / |cos_l|."""
    pdf_area = (np.asarray(radiance, np.float64) @ LUMINANCE) / _total_power(light)
    r2 = np.asarray(distance, np.float64) ** 2
    return pdf_area * r2 / np.maximum(np.abs(cos_light), 1e-12)


def emitter_probe_sh(tris, light, positions, directions, rays, radiance, sides, ids,
                     samples: int = 64, seed: int = 0) -> np.ndarray:
    """(P, 9, 3) the emissive triangles' light arriving at each probe (module doc).
    rays : ``validity.ProbeRays`` of the uniform ``directions`` (P × N); radiance, sides :
    ``emissive_sides``; ids (P,) the probes' sample ids."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    count, n = len(p), len(d)
    out = np.zeros((count, 9, 3))
    if count == 0:
        return out
    square = hashed_square(np.asarray(ids), EMITTER_STREAM, samples, seed)
    k = square.shape[1]
    # the uniform rays landing on an emitter
    tri = np.asarray(rays.triangle)
    hit_p, hit_n = np.nonzero(tri >= 0)
    t_hit = tri[hit_p, hit_n]
    glow = radiance[t_hit]
    lit = np.flatnonzero(glow @ LUMINANCE > 0)
    if len(lit):
        hp, hn, ht = hit_p[lit], hit_n[lit], t_hit[lit]
        corners = np.asarray(tris.positions, np.float64)[ht]
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal /= np.maximum(norm3(normal)[:, None], 1e-30)
        cos_l = np.einsum("mc,mc->m", d[hn], normal)
        # the ray arrives on the side facing away from its direction: the side of -cos_l
        side = sides[ht]
        emitting = (side == 0) | (side * -np.sign(cos_l) > 0)
        pdf = np.where(emitting, emitter_hit_pdf(light, glow[lit], rays.t[hp, hn], cos_l), 0.0)
        f = glow[lit] * _balance(n, k, pdf)[:, None]
        np.add.at(out, hp, sh_basis(d[hn])[:, :, None] * f[:, None, :])
    # the emitters' own samples
    index, targets = sample_points(light, square)                       # (P, K), (P, K, 3)
    w = targets - p[:, None]
    r = np.sqrt(np.einsum("pkc,pkc->pk", w, w))
    dirs = w / np.maximum(r, 1e-30)[..., None]
    c = light.corners[index]
    normal = np.cross(c[..., 1, :] - c[..., 0, :], c[..., 2, :] - c[..., 0, :])
    normal /= np.maximum(norm3(normal)[..., None], 1e-30)
    cos_l = np.einsum("pkc,pkc->pk", dirs, normal)
    side = light.sides[index]
    useful = ((side == 0) | (side * -np.sign(cos_l) > 0)) & (np.abs(cos_l) > 1e-6) & (r > 1e-9)
    seen = np.zeros(useful.shape, bool)
    if useful.any():
        origins = np.broadcast_to(p[:, None], dirs.shape)
        seen[useful] = ~occluded(tris, origins[useful], dirs[useful], r[useful])
    pdf = emitter_hit_pdf(light, light.radiance[index], r, cos_l)
    f = light.radiance[index] * (_balance(n, k, pdf) * seen)[..., None]   # (P, K, 3)
    out += np.einsum("pjk,pjc->pkc", sh_basis(dirs.reshape(-1, 3)).reshape(count, k, 9), f)
    return out
