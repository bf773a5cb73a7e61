"""A glossy lobe widened by what a pixel's sample stands for (specular anti-aliasing).

Cycles' pixel is its filter's average over the pixel (``scene.camera.blackman_harris``); where a
curved surface turns under the pixel, its reflection of a small bright light (a sun, a lamp, an
HDRI's sun) is the lobe averaged over the normals the pixel covers. The preview evaluates the
lamps' glossy light once at the pixel centre (``passes.glossy_direct_radiance``, GLSL
``glossy_direct.glsl``), so a sharp lobe on a ball drew the sun's reflection as the lobe at one
normal: a pin-point most pixels miss, the sum of the highlight lost or doubled by where the
centres fell (a chrome ball under a sun: Glossy Direct 0.12 off Cycles).

The normal's spread over the sample's footprint widens the lobe instead, as geometric specular
anti-aliasing does (Kaplanyan et al. 2016, "Filtering distributions of normals for shading
antialiasing"; Tokuyoshi & Kaplanyan 2019): the normal turns by ∂n/∂x and ∂n/∂y a pixel, so over
a footprint of standard deviation σ pixels its slopes spread with variance σ²|∂n/∂x|² and
σ²|∂n/∂y|². Convolving a Beckmann-like lobe of α with that adds twice the per-axis variance to
α²; isotropic, the two axes' mean: α'² = α² + σ² (|∂n/∂x|² + |∂n/∂y|²), at most
``FOOTPRINT_LIMIT`` (where a pixel straddles a silhouette the difference means nothing).

σ is half the texture footprint (``textures.filter_footprint``: 2σ of Cycles' filter over the
pixel's own square, 0.265 px at Filter Size 1.5; the filter's tails are the neighbours' share,
``passes.filter_passes``), over ``share`` for a sub-pixel pass (one of AA_SIDE² samples of its
pixel, as its textures' footprint). ∂n is the interpolated shading normal's (before a normal
map) change to the next pixel's camera ray through the same triangle's plane: the GPU's
``dFdx``/``dFdy`` in ``gbuffer_frag.glsl``, which writes the widened roughness into the
G-buffer's normal.w. Only lobes evaluated per pixel take it (the lamps' glossy light and Fast's
glossy cones); the gathers' lobes are traced at fewer points and filtered over wider windows
than a pixel, and take the material's roughness.
"""
from __future__ import annotations

import numpy as np

from ..scene.camera import DEFAULT_FILTER_WIDTH, camera_rays
from ..scene.textures import filter_footprint

__all__ = ["FOOTPRINT_LIMIT", "footprint_variance", "normal_spread", "lobe_roughness",
           "disc_growth"]

FOOTPRINT_LIMIT = 0.18  # the most α² the footprint adds (Kaplanyan et al.'s clamp)


def footprint_variance(filter_width: float = DEFAULT_FILTER_WIDTH, share: int = 1) -> float:
    """σ² (pixels²) of the footprint a sample stands for: half of ``filter_footprint`` over
    ``share`` (a sub-pixel pass's samples each stand for 1 / share of the pixel's width)."""
    sigma = 0.5 * filter_footprint(filter_width) / max(int(share), 1)
    return float(sigma * sigma)


def lobe_roughness(roughness, spread, variance: float) -> np.ndarray:
    """Roughness (α = roughness²) of the lobe widened by the footprint: α'² = α² +
    min(variance × spread, FOOTPRINT_LIMIT). roughness : the material's; spread : |∂n/∂x|² +
    |∂n/∂y|² per pixel (``normal_spread``); variance : ``footprint_variance``. The GLSL twin is
    gbuffer_frag.glsl's."""
    r = np.clip(np.asarray(roughness, np.float64), 0.0, 1.0)
    add = np.minimum(variance * np.asarray(spread, np.float64), FOOTPRINT_LIMIT)
    return np.sqrt(np.sqrt(r ** 4 + add))


def disc_growth(lobe, roughness) -> np.ndarray:
    """(N,) radians² a round lamp's disc (``exact_glossy.round_lamp_disc``) grows by in its
    angular radius² at a pixel whose lobe roughness (``lobe_roughness``) is ``lobe`` and its
    material's ``roughness``: the reflected direction turns by twice the normal, so over the
    footprint it spreads with variance 4 σ² |∂n|² / 2 per axis (the two axes' mean), and a
    uniform disc of radius ρ has variance ρ² / 4 per axis: ρ'² = ρ² + 8 σ² |∂n|², the α² the
    footprint adds × 8. The lamp's light stays the same; only the solid angle it comes from
    grows, as Cycles' pixel averages a small highlight over the normals it covers — without
    the long tails a GGX lobe widened as far would add around it."""
    added = np.clip(np.asarray(lobe, np.float64), 0.0, 1.0) ** 4 - \
        np.clip(np.asarray(roughness, np.float64), 0.0, 1.0) ** 4
    return 8.0 * np.maximum(added, 0.0)


def normal_spread(tris, camera, hits, width: int, height: int, offset=(0.0, 0.0)) -> np.ndarray:
    """(H, W) |∂n/∂x|² + |∂n/∂y|² of the interpolated shading normal (unit, before a normal
    map) at each pixel of ``hits`` (``raycast.primary_visibility`` of the same camera, size
    and ``offset``): the normal where the next pixel's camera ray (x right, y down) meets the
    hit triangle's plane, less the pixel's own. 0 on flat-shaded triangles and the
    background; inf where a neighbour's ray runs along the plane."""
    spread = np.zeros(height * width)
    corners_all = getattr(tris, "corner_normals", None)
    seen = np.flatnonzero(np.asarray(hits.hit).reshape(-1))
    if corners_all is None or len(seen) == 0:
        return spread.reshape(height, width)
    tri = np.asarray(hits.triangle).reshape(-1)[seen]
    corners = np.asarray(corners_all, np.float64)[tri]
    vertices = np.asarray(tris.positions, np.float64)[tri]
    face = np.asarray(tris.normals, np.float64)[tri]

    def normal_at(points):
        e1, e2 = vertices[:, 1] - vertices[:, 0], vertices[:, 2] - vertices[:, 0]
        w = points - vertices[:, 0]
        d11, d12, d22 = (np.einsum("ij,ij->i", a, b) for a, b in ((e1, e1), (e1, e2), (e2, e2)))
        w1, w2 = np.einsum("ij,ij->i", w, e1), np.einsum("ij,ij->i", w, e2)
        det = d11 * d22 - d12 * d12
        safe = np.where(np.abs(det) > 0.0, det, 1.0)
        u = (d22 * w1 - d12 * w2) / safe
        v = (d11 * w2 - d12 * w1) / safe
        n = (1.0 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1] + \
            v[:, None] * corners[:, 2]
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.where(length > 1e-12, n / np.maximum(length, 1e-12), face)

    bary = np.asarray(hits.barycentric).reshape(-1, 2)[seen]
    own = (1.0 - bary.sum(axis=1))[:, None] * corners[:, 0] + bary[:, :1] * corners[:, 1] + \
        bary[:, 1:] * corners[:, 2]
    length = np.linalg.norm(own, axis=1, keepdims=True)
    own = np.where(length > 1e-12, own / np.maximum(length, 1e-12), face)
    total = np.zeros(len(seen))
    for step in ((1.0, 0.0), (0.0, 1.0)):
        origins, directions = camera_rays(camera, width, height,
                                          (offset[0] + step[0], offset[1] + step[1]))
        o, d = origins[seen], directions[seen]
        across = np.einsum("ij,ij->i", d, face)
        grazing = np.abs(across) <= 1e-9
        t = np.einsum("ij,ij->i", vertices[:, 0] - o, face) / np.where(grazing, 1.0, across)
        change = normal_at(o + d * t[:, None]) - own
        total += np.where(grazing, np.inf, np.einsum("ij,ij->i", change, change))
    spread[seen] = total
    return spread.reshape(height, width)
