"""Deterministic per-point sample patterns that numpy and GLSL compute bit for bit.

The GPU kernels (``render/shaders/bvh_common.glsl``) cannot share numpy's random generator, so
wherever the numpy reference and a kernel must draw *the same* samples (area-light strata,
the diffuse rays of ``indirect``) both derive them from a 32-bit integer hash of a per-point id
(the pixel index, row 0 on top), a stream number (the light index, or a ray purpose) and the
sample index. Everything is uint32 arithmetic with wrap-around, and a hash becomes a float as
``(h >> 8) · 2⁻²⁴`` — exact in float32 — so both sides get identical values in [0, 1).

* ``pcg_hash`` — the PCG-RXS-M-XS permutation of Jarzynski & Olano (JCGT 2020).
* ``hashed_square`` — the jittered strata of ``direct_light.stratified_square`` with hashed
  jitter: (N, K, 2) in [0, 1)², K = ceil(√samples)², stratum k = (k // m, k % m).
* ``hammersley`` — the N-point Hammersley set ((j + ½)/N, radical inverse of j) shifted per
  point by a hashed Cranley–Patterson rotation: stratified in x, low discrepancy in 2D, and
  independent between pixels.
* ``spherical_rectangle`` — points of a rectangular light uniform in the solid angle it subtends
  (Ureña et al. 2013), as Cycles draws them.
* ``perpendicular_basis`` — the tangent frame ``direct_light`` builds around a direction (the
  GLSL port makes the same choice of helper axis).
"""
from __future__ import annotations

import math

import numpy as np

from ..scene.short_axis import all_along, norm3

__all__ = [
    "hammersley",
    "hashed_square",
    "pcg_hash",
    "perpendicular_basis",
    "point_streams",
    "spherical_rectangle",
    "radical_inverse",
    "unit_float",
    "vndf_half_vectors",
]

_GOLDEN = np.uint32(0x9E3779B9)


def pcg_hash(v: np.ndarray) -> np.ndarray:
    """PCG-RXS-M-XS 32-bit permutation of uint32 values (any shape), uint32."""
    v = np.asarray(v, dtype=np.uint32)
    with np.errstate(over="ignore"):
        state = v * np.uint32(747796405) + np.uint32(2891336453)
        word = ((state >> ((state >> np.uint32(28)) + np.uint32(4))) ^ state) * np.uint32(277803737)
    return (word >> np.uint32(22)) ^ word


def unit_float(h: np.ndarray) -> np.ndarray:
    """uint32 hashes → float64 in [0, 1) with 24 bits (exact in float32)."""
    return (np.asarray(h, np.uint32) >> np.uint32(8)).astype(np.float64) * (1.0 / (1 << 24))


def point_streams(ids: np.ndarray, stream: int, seed: int = 0) -> np.ndarray:
    """(N,) uint32 per-point hash state of ``stream``: pcg(pcg(id + seed·φ) + stream)."""
    ids = np.asarray(ids).astype(np.uint32)
    with np.errstate(over="ignore"):
        h = pcg_hash(ids + np.uint32(seed) * _GOLDEN)
        return pcg_hash(h + np.uint32(stream))


def _values(state: np.ndarray, count: int) -> np.ndarray:
    """(N, count) floats in [0, 1): value i of a point is unit(pcg(state + i))."""
    with np.errstate(over="ignore"):
        return unit_float(pcg_hash(state[:, None] + np.arange(count, dtype=np.uint32)[None]))


def hashed_square(ids, stream: int, samples: int, seed: int = 0) -> np.ndarray:
    """(N, K, 2) jittered strata in [0, 1)², K = m², m = ceil(√samples); the jitter of stratum
    k's coordinate c is value 2k + c of the point's stream (``point_streams``)."""
    m = max(1, math.ceil(math.sqrt(samples)))
    k = np.arange(m * m)
    cells = np.stack([k // m, k % m], axis=1).astype(np.float64)
    jitter = _values(point_streams(ids, stream, seed), 2 * m * m).reshape(-1, m * m, 2)
    return (cells[None] + jitter) / m


def radical_inverse(j: np.ndarray) -> np.ndarray:
    """Van der Corput radical inverse in base 2 of uint32 j, as float64 in [0, 1) (32 bits)."""
    b = np.asarray(j, dtype=np.uint32)
    b = ((b << np.uint32(16)) | (b >> np.uint32(16))).astype(np.uint32)
    b = (((b & np.uint32(0x55555555)) << np.uint32(1)) | ((b & np.uint32(0xAAAAAAAA)) >> np.uint32(1)))
    b = (((b & np.uint32(0x33333333)) << np.uint32(2)) | ((b & np.uint32(0xCCCCCCCC)) >> np.uint32(2)))
    b = (((b & np.uint32(0x0F0F0F0F)) << np.uint32(4)) | ((b & np.uint32(0xF0F0F0F0)) >> np.uint32(4)))
    b = (((b & np.uint32(0x00FF00FF)) << np.uint32(8)) | ((b & np.uint32(0xFF00FF00)) >> np.uint32(8)))
    return (b >> np.uint32(8)).astype(np.float64) * (1.0 / (1 << 24))


def hammersley(ids, stream: int, count: int, seed: int = 0) -> np.ndarray:
    """(N, count, 2) rotated Hammersley points in [0, 1)²: point j of a pixel is
    ``frac(((j + ½)/count, φ₂(j)) + (r0, r1))`` with (r0, r1) values 0, 1 of its stream."""
    rotation = _values(point_streams(ids, stream, seed), 2)  # (N, 2)
    j = np.arange(count)
    base = np.stack([(j + 0.5) / count, radical_inverse(j)], axis=1)  # (count, 2)
    u = base[None] + rotation[:, None]
    return u - np.floor(u)


def perpendicular_basis(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (N, 3) orthogonal to unit vectors w (N, 3) and to each other (the helper
    axis is x unless |w.x| ≥ 0.9, then y — the GLSL port makes the same choice)."""
    helper = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(w, helper)
    t /= norm3(t)[:, None]
    return t, np.cross(w, t)


def spherical_rectangle(origins, corner, edge_x, edge_y, uv):
    """Points of a rectangle drawn uniformly in the solid angle it subtends from each origin
    (Ureña, Fajardo & King 2013, "An area-preserving parametrization for spherical
    rectangles"; Cycles samples its rectangular lights so): ((N, K, 3) points, (N,) solid
    angles in sr). origins (N, 3); the rectangle ``corner`` + s·``edge_x`` + t·``edge_y``,
    s, t in [0, 1] (the edges perpendicular); uv (N, K, 2) in [0, 1)², stratified as given.
    An origin in the rectangle's plane subtends nothing: its points are the rectangle's
    centre and its solid angle 0. ``render/shaders/bvh_lights.glsl`` ports it."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    corner = np.asarray(corner, np.float64)
    exl, eyl = float(np.linalg.norm(edge_x)), float(np.linalg.norm(edge_y))
    x, y = np.asarray(edge_x, np.float64) / exl, np.asarray(edge_y, np.float64) / eyl
    z = np.cross(x, y)
    d = corner - o
    z0 = d @ z
    flip = z0 > 0.0  # the rectangle's plane behind −z of the local frame
    zs = np.where(flip[:, None], -z, z)
    z0 = -np.abs(z0)
    x0, y0 = d @ x, d @ y
    x1, y1 = x0 + exl, y0 + eyl

    def unit(v):
        return v / np.maximum(norm3(v)[..., None], 1e-300)

    v00 = np.stack([x0, y0, z0], -1)
    v01 = np.stack([x0, y1, z0], -1)
    v10 = np.stack([x1, y0, z0], -1)
    v11 = np.stack([x1, y1, z0], -1)
    n0, n1 = unit(np.cross(v00, v10)), unit(np.cross(v10, v11))
    n2, n3 = unit(np.cross(v11, v01)), unit(np.cross(v01, v00))

    def angle(a, b):
        return np.arccos(np.clip(-np.einsum("ij,ij->i", a, b), -1.0, 1.0))

    g0, g1, g2, g3 = angle(n0, n1), angle(n1, n2), angle(n2, n3), angle(n3, n0)
    b0, b1 = n0[:, 2], n2[:, 2]
    k = 2.0 * math.pi - g2 - g3
    solid = np.maximum(g0 + g1 - k, 0.0)
    u, v = uv[..., 0], uv[..., 1]
    au = u * solid[:, None] + k[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        fu = (np.cos(au) * b0[:, None] - b1[:, None]) / np.sin(au)
        cu = np.clip(np.sign(fu) / np.sqrt(fu * fu + (b0 * b0)[:, None]), -1.0, 1.0)
        xu = np.clip(-(cu * z0[:, None]) / np.sqrt(np.maximum(1.0 - cu * cu, 1e-300)),
                     x0[:, None], x1[:, None])
        dd = np.sqrt(xu * xu + (z0 * z0)[:, None])
        h0 = y0[:, None] / np.sqrt(dd * dd + (y0 * y0)[:, None])
        h1 = y1[:, None] / np.sqrt(dd * dd + (y1 * y1)[:, None])
        hv = h0 + v * (h1 - h0)
        hv2 = hv * hv
        yv = np.where(hv2 < 1.0 - 1e-6, hv * dd / np.sqrt(np.maximum(1.0 - hv2, 1e-300)),
                      y1[:, None])
    points = o[:, None] + xu[..., None] * x + yv[..., None] * y + z0[:, None, None] * zs[:, None]
    bad = ~all_along(np.isfinite(points)) | (solid[:, None] <= 1e-12)
    centre = corner + 0.5 * (np.asarray(edge_x, np.float64) + np.asarray(edge_y, np.float64))
    points = np.where(bad[..., None], centre, points)
    return points, np.where(solid > 1e-12, solid, 0.0)


def vndf_half_vectors(view_local: np.ndarray, alpha: np.ndarray, square: np.ndarray) -> np.ndarray:
    """(N, K, 3) unit half vectors in the local frame (z = normal) drawn from GGX's visible
    normals for views ``view_local`` (N, 3) (z > 0) and roughness α (N,), from ``square``
    (N, K, 2) in [0, 1)² (Heitz 2018, listing 1)."""
    a = np.asarray(alpha, np.float64)[:, None]
    vh = np.stack([a[:, 0] * view_local[:, 0], a[:, 0] * view_local[:, 1], view_local[:, 2]], axis=1)
    vh /= norm3(vh)[:, None]
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    safe = np.sqrt(np.maximum(lensq, 1e-30))
    t1 = np.where((lensq > 1e-7)[:, None],
                  np.stack([-vh[:, 1] / safe, vh[:, 0] / safe, np.zeros_like(safe)], axis=1),
                  [[1.0, 0.0, 0.0]])
    t2 = np.cross(vh, t1)
    r = np.sqrt(square[..., 0])
    phi = 2.0 * np.pi * square[..., 1]
    p1, p2 = r * np.cos(phi), r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2:3])
    p2 = (1.0 - s) * np.sqrt(np.maximum(1.0 - p1 * p1, 0.0)) + s * p2
    p3 = np.sqrt(np.maximum(1.0 - p1 * p1 - p2 * p2, 0.0))
    nh = p1[..., None] * t1[:, None] + p2[..., None] * t2[:, None] + p3[..., None] * vh[:, None]
    h = np.stack([a * nh[..., 0], a * nh[..., 1], np.maximum(nh[..., 2], 0.0)], axis=-1)
    return h / np.maximum(norm3(h)[..., None], 1e-30)
