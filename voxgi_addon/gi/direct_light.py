"""Direct diffuse light at surface points, in Cycles' units, with ray-traced shadows.

``diffuse_direct`` returns what Cycles' ``Diffuse Direct`` pass holds for a white Lambertian
surface: irradiance / π (no albedo), summed over lights, × light colour. The light models were
checked against Cycles 5.0 renders of a white plane (agreement 0.1–0.3 %; docs/blender_facts.md
"Cycles' radiometry" has the basic cases):

* SUN, strength S (W/m²): S/π · cosθ. A sun with an angle casts soft shadows: shadow rays
  sample the cone of directions of its disc.
* POINT, power P (W), radius r: P/(4π) · cosθ / (d² + r²) / π. The r² term is Cycles' default
  "Soft Falloff" (with it off Cycles gives the plain P/(4π d²); the snapshot does not record the
  option); shadow rays sample the disc of radius r that faces the shading point.
* SPOT: the point light times smoothstep(x), x = (cos φ − cos(size/2)) / ((1 − cos(size/2))·blend)
  clamped to [0, 1] (a hard edge for blend = 0); no cosine falloff inside the cone.
* AREA (SQUARE, RECTANGLE, DISK, ELLIPSE; ``size`` × ``size_y`` in the light's X/Y, diameters for
  the round shapes), power P: a one-sided Lambertian emitter of radiance P / (π · area) facing
  the light's −Z. The unshadowed irradiance is exact (Lambert's polygon formula; round shapes as
  a 64-gon of the same area), the light clipped by the point's horizon where it straddles it;
  the shadowed fraction is estimated from ``samples`` stratified points
  on the light, weighted by their share of the irradiance (a ratio estimator: no noise where
  the light is fully visible).

At 3 × 3 strata and more, a light's four corner strata are traced first; where those that
count (above the horizon) agree, the point sees all of the light or none of it and the other
strata are not traced (``_visible_share``): the preview's pixel centres trace 4 shadow rays a
light outside penumbrae instead of 16.

Normals should face the viewer (Cycles flips back-facing normals before shading).
"""
from __future__ import annotations

import math

import numpy as np

from ..scene import raycast
from ..scene.short_axis import any_along, norm3
from ..scene.snapshot import LightData
from .sampling import hashed_square, spherical_rectangle

__all__ = ["diffuse_direct", "emitters_unshadowed", "light_aims", "light_directions",
           "light_frame", "spot_factor",
           "stratified_square", "concentric_disk"]

_NORMAL_OFFSET = 1e-5  # metres: shadow rays start this far off the surface, towards the light
_POINT_CHUNK = 16384
_ROUND_SIDES = 64
ADAPTIVE_FROM = 3  # strata sides from which the corners' agreement settles a light's share


def stratified_square(count: int, samples: int, rng: np.random.Generator) -> np.ndarray:
    """(count, K, 2) jittered samples in [0, 1)², K = ceil(√samples)² strata per point."""
    m = max(1, math.ceil(math.sqrt(samples)))
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    cells = np.stack([i.ravel(), j.ravel()], axis=1).astype(np.float64)
    return (cells[None] + rng.random((count, m * m, 2))) / m


def concentric_disk(square: np.ndarray) -> np.ndarray:
    """Shirley–Chiu map of [0, 1)² samples (..., 2) to the unit disc (area preserving)."""
    a = 2.0 * square[..., 0] - 1.0
    b = 2.0 * square[..., 1] - 1.0
    first = np.abs(a) > np.abs(b)
    r = np.where(first, a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(first, (np.pi / 4) * b / a, np.pi / 2 - (np.pi / 4) * a / b)
    phi = np.where((a == 0) & (b == 0), 0.0, phi)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=-1)


def light_frame(light: LightData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, x axis, y axis, emission direction) in world space; axes keep the object's scale,
    the emission direction (local −Z) is a unit vector."""
    m = np.asarray(light.world_matrix, dtype=np.float64)
    z = m[:3, 2]
    return m[:3, 3].copy(), m[:3, 0].copy(), m[:3, 1].copy(), -z / max(np.linalg.norm(z), 1e-30)


def _perpendicular_basis(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (N, 3) orthogonal to unit vectors w (N, 3) and to each other."""
    helper = np.where(np.abs(w[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(w, helper)
    t /= norm3(t)[:, None]
    return t, np.cross(w, t)


def _occluded(occluder, origins, directions, max_t) -> np.ndarray:
    """Shadow test against triangles (``raycast.occluded``) or any occluder with that method."""
    if hasattr(occluder, "occluded"):
        return np.asarray(occluder.occluded(origins, directions, max_t), dtype=bool)
    return raycast.occluded(occluder, origins, directions, max_t)


def _visible_share(occluder, origins, directions, lengths, weights=None) -> np.ndarray:
    """(N,) unoccluded share of K shadow rays per point.

    origins : (N, 3); directions : (N, K, 3) unit; lengths : (N, K) (inf towards a sun);
    weights : (N, K) importance of each ray, or None for equal weights.
    """
    n, k, _ = directions.shape
    w = np.ones((n, k)) if weights is None else np.asarray(weights, np.float64)
    side = int(round(math.sqrt(k)))
    if side >= ADAPTIVE_FROM and side * side == k:
        # the four corners of the side × side strata first: where those that count agree,
        # the light is all seen or all hidden and the other rays are not traced
        # (bvh_lights.glsl stratum_order; docs/gi_pipeline.md "Where a preview's time goes")
        corners = np.array([0, side - 1, side * (side - 1), k - 1])
        rest = np.setdiff1d(np.arange(k), corners)
        blocked = np.zeros((n, k), bool)
        blocked[:, corners] = _trace(occluder, origins, directions[:, corners],
                                     lengths[:, corners])
        counted = w[:, corners] > 0.0
        seen = any_along(counted & ~blocked[:, corners])
        hidden = any_along(counted & blocked[:, corners])
        settled = any_along(counted) & (seen != hidden)
        open_rows = np.flatnonzero(~settled)
        if len(open_rows):
            blocked[np.ix_(open_rows, rest)] = _trace(
                occluder, origins[open_rows], directions[open_rows][:, rest],
                lengths[open_rows][:, rest])
        w = np.where(settled[:, None], np.where(np.isin(np.arange(k), corners), w, 0.0), w)
    else:
        blocked = _trace(occluder, origins, directions, lengths)
    total = w.sum(axis=1)
    lit = (w * ~blocked).sum(axis=1)
    return np.divide(lit, total, out=np.zeros(n), where=total > 0)


def _trace(occluder, origins, directions, lengths) -> np.ndarray:
    """(N, K) bool: the rays (N, K, 3) from origins (N, 3) blocked within lengths (N, K)."""
    n, k, _ = directions.shape
    if n * k == 0:
        return np.zeros((n, k), bool)
    return _occluded(occluder, np.repeat(origins, k, axis=0), directions.reshape(-1, 3),
                     lengths.reshape(-1)).reshape(n, k)


def _visible_share_of_points(occluder, origins, targets, weights=None) -> np.ndarray:
    """``_visible_share`` of rays from origins (N, 3) to target points (N, K, 3)."""
    ray = targets - origins[:, None]
    length = norm3(ray)
    return _visible_share(occluder, origins, ray / np.maximum(length, 1e-30)[..., None], length, weights)


def _sun(light, p, n, tris, strata):
    _, _, _, emit = light_frame(light)
    to_light = -emit
    cos = n @ to_light
    value = np.maximum(cos, 0.0) * light.power / math.pi
    lit = np.flatnonzero(value > 0)
    if len(lit) and tris is not None:
        half = 0.5 * float(light.angle)
        if half > 0:
            disk = concentric_disk(strata(lit)) * math.tan(half)
            t, b = _perpendicular_basis(to_light[None])
            dirs = to_light + disk[..., :1] * t[0] + disk[..., 1:] * b[0]  # (N, K, 3) in the cone
        else:
            dirs = np.tile(to_light, (len(lit), 1, 1))
        dirs = dirs / norm3(dirs)[..., None]
        origins = p[lit] + _NORMAL_OFFSET * n[lit]
        value[lit] *= _visible_share(tris, origins, dirs, np.full(dirs.shape[:2], np.inf))
    return value


def spot_factor(light: LightData, emit: np.ndarray, from_light: np.ndarray) -> np.ndarray:
    """(N,) a spot's cone at unit directions ``from_light`` (N, 3) away from it, its emission
    direction ``emit``: the smoothstep of its edge over Spot Blend, no falloff inside."""
    cos_half = math.cos(0.5 * float(light.spot_size))
    cos_phi = from_light @ emit
    if light.spot_blend <= 0.0:
        return (cos_phi > cos_half).astype(np.float64)
    x = np.clip((cos_phi - cos_half) / ((1.0 - cos_half) * float(light.spot_blend)), 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _point(light, p, n, tris, strata):
    centre, _, _, emit = light_frame(light)
    delta = centre - p
    d2 = np.einsum("ij,ij->i", delta, delta)
    dist = np.sqrt(d2)
    w = delta / np.maximum(dist, 1e-30)[:, None]
    radius = float(light.radius)
    value = light.power / (4.0 * math.pi) * np.maximum(np.einsum("ij,ij->i", n, w), 0.0)
    value /= (d2 + radius * radius) * math.pi
    if light.type == "SPOT":
        value *= spot_factor(light, emit, -w)
    lit = np.flatnonzero(value > 0)
    if len(lit) and tris is not None:
        if radius > 0:
            t, b = _perpendicular_basis(w[lit])
            disk = concentric_disk(strata(lit)) * radius
            targets = centre + disk[..., :1] * t[:, None] + disk[..., 1:] * b[:, None]
        else:
            targets = np.broadcast_to(centre, (len(lit), 1, 3))
        origins = p[lit] + _NORMAL_OFFSET * n[lit]
        value[lit] *= _visible_share_of_points(tris, origins, targets)
    return value


def area_outline(light: LightData) -> tuple[np.ndarray, float]:
    """(K, 3) world-space corners of the emitter (counter-clockwise about local +Z) and its area."""
    centre, x, y, _ = light_frame(light)
    sx = float(light.size)
    sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
    ex, ey = 0.5 * sx * x, 0.5 * sy * y
    if light.shape in ("DISK", "ELLIPSE"):
        angles = 2.0 * math.pi * np.arange(_ROUND_SIDES) / _ROUND_SIDES
        # A regular polygon of the ellipse's area stands in for it in the exact formula.
        grow = math.sqrt(2.0 * math.pi / (_ROUND_SIDES * math.sin(2.0 * math.pi / _ROUND_SIDES)))
        outline = centre + grow * (np.cos(angles)[:, None] * ex + np.sin(angles)[:, None] * ey)
        area = math.pi * 0.25 * sx * sy * np.linalg.norm(np.cross(x, y))
    else:
        outline = centre + np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) @ np.stack([ex, ey])
        area = sx * sy * np.linalg.norm(np.cross(x, y))
    return outline, float(area)


def _edge_terms(a: np.ndarray, b: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Lambert's formula's term of the edges a → b (…, 3) of a polygon seen from a point
    (directions from it, any length) for its unit normal n (broadcast): the angle the edge
    spans times the cosine of its great circle's pole with n."""
    a = a / np.maximum(norm3(a)[..., None], 1e-30)
    b = b / np.maximum(norm3(b)[..., None], 1e-30)
    cross = np.cross(a, b)
    sin = norm3(cross)
    angle = np.arctan2(sin, np.einsum("...c,...c->...", a, b))
    return angle * np.einsum("...c,...c->...", cross, n) / np.maximum(sin, 1e-30)


def _polygon_irradiance(p: np.ndarray, n: np.ndarray, outline: np.ndarray,
                        centroid: bool = False):
    """Lambert's formula: ∫ cosθ / π dω over the part of a convex polygon above each point's
    horizon (N,): the polygon clipped by the point's tangent plane, whose cut runs along the
    horizon from where the outline leaves it to where it comes back (0 where none of it is
    above). Exact, so a light that straddles a surface's horizon (a box's side under a ceiling
    light) is as smooth as one above it, as Cycles' converged render. centroid : also return
    the mean (N, 3) of the clipped polygon's corners (world space), where ``_area`` aims a
    shadow ray when none of its light samples fell above the horizon."""
    a = outline[None] - p[:, None]  # (N, K, 3)
    b = np.roll(a, -1, axis=1)
    ha = np.einsum("nkc,nc->nk", a, n)
    hb = np.roll(ha, -1, axis=1)
    above_a, above_b = ha > 0.0, hb > 0.0
    # where each edge crosses the horizon (used only on the edges that do)
    t = np.divide(ha, ha - hb, out=np.zeros_like(ha), where=above_a != above_b)
    cut = a + t[..., None] * (b - a)
    start = np.where(above_a[..., None], a, cut)
    end = np.where(above_b[..., None], b, cut)
    terms = np.where(above_a | above_b, _edge_terms(start, end, n[:, None]), 0.0)
    total = terms.sum(axis=1)
    leaves, enters = above_a & ~above_b, ~above_a & above_b
    crossed = leaves.any(axis=1) & enters.any(axis=1)
    if crossed.any():  # the horizon's stretch of the clipped outline: leave → enter
        rows = np.flatnonzero(crossed)
        exit_at = cut[rows, leaves[rows].argmax(axis=1)]
        entry_at = cut[rows, enters[rows].argmax(axis=1)]
        total[rows] += _edge_terms(exit_at, entry_at, n[rows])
    irradiance = np.abs(total) / (2.0 * math.pi)
    if not centroid:
        return irradiance
    corners = (above_a[..., None] * a + (above_a != above_b)[..., None] * cut).sum(axis=1)
    count = (above_a.astype(int) + (above_a != above_b)).sum(axis=1)
    return irradiance, p + corners / np.maximum(count, 1)[:, None]


def area_unshadowed(light, points, normals) -> np.ndarray:
    """(N,) ∫ cos θ / π dω over the part of area lamp ``light`` above each point's horizon,
    0 behind its emitting side: its unshadowed Diffuse Direct over its radiance (``_area``'s
    exact term), of which its shadowed one is the visible share."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.zeros(len(points))
    outline, area = area_outline(light)
    centre, _, _, emit = light_frame(light)
    front = np.flatnonzero((points - centre) @ emit > 0) if area > 0 else np.zeros(0, int)
    if len(front):
        out[front] = _polygon_irradiance(points[front],
                                         np.asarray(normals, np.float64).reshape(-1, 3)[front],
                                         outline)
    return out


def _area(light, p, n, tris, strata):
    """An area light's Diffuse Direct: its exact unshadowed light times the visible share of
    its shadow rays, each weighted by its share of the irradiance (a ratio estimator). A
    rectangle is drawn by solid angle, as Cycles draws it, so a sample's share is its cosine
    at the point alone (docs/gi_pipeline.md "Rectangular lights drawn by solid angle")."""
    centre, x, y, emit = light_frame(light)
    outline, area = area_outline(light)
    if area <= 0:
        return np.zeros(len(p))
    radiance = light.power / (math.pi * area)
    value = np.zeros(len(p))
    in_front = np.flatnonzero((p - centre) @ emit > 0)  # one-sided emitter
    if len(in_front) == 0:
        return value
    p, n = p[in_front], n[in_front]
    # Unshadowed Diffuse Direct (= irradiance / π): exact, the light clipped by the horizon.
    unshadowed, aim = _polygon_irradiance(p, n, outline, centroid=True)
    # Light samples, for the shadow rays.
    sampled = np.arange(len(p)) if tris is not None else np.zeros(0, int)
    if len(sampled):
        square = strata(in_front[sampled])
        unit = square * 2.0 - 1.0
        if light.shape in ("DISK", "ELLIPSE"):
            unit = concentric_disk(0.5 * (unit + 1.0))
        sx = float(light.size)
        sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
        ex, ey = 0.5 * sx * x, 0.5 * sy * y
        # a rectangle (its edges perpendicular) drawn by solid angle, as Cycles draws it: a
        # sample's share of the irradiance is then its cosine at the point alone; a disk or
        # an ellipse by area, its share cos·cos / r² (bvh_lights.glsl area_light)
        by_angle = light.shape not in ("DISK", "ELLIPSE") and \
            abs(float(ex @ ey)) <= 1e-6 * float(np.linalg.norm(ex) * np.linalg.norm(ey))
        if by_angle:
            targets, _ = spherical_rectangle(p[sampled], centre - ex - ey, 2.0 * ex, 2.0 * ey,
                                             square)
        else:
            targets = centre + unit[..., :1] * ex + unit[..., 1:] * ey
        w = targets - p[sampled, None]
        r2 = np.einsum("nkc,nkc->nk", w, w)
        cos_x = np.einsum("nkc,nc->nk", w, n[sampled])
        if by_angle:
            f = np.maximum(cos_x, 0.0) / np.sqrt(np.maximum(r2, 1e-30))
        else:
            cos_l = -(w @ emit)
            f = np.maximum(cos_x, 0.0) * np.maximum(cos_l, 0.0) / np.maximum(r2, 1e-30) ** 2
    lit = np.flatnonzero(unshadowed > 0)
    if len(lit) and tris is not None:  # here sampled = every point, so rows line up
        origins = p[lit] + _NORMAL_OFFSET * n[lit]
        # the samples above the horizon, each by its share of the irradiance; where none is
        # (a light mostly below it, one sample at a bounce hit), one ray to the middle of its
        # part above, so the share is never taken as 0 for want of a sample
        none = f[lit].sum(axis=1) <= 0.0
        share = _visible_share_of_points(tris, origins, targets[lit], f[lit])
        if none.any():
            share[none] = _visible_share_of_points(tris, origins[none],
                                                   aim[lit][none][:, None])
        unshadowed[lit] *= share
    value[in_front] = radiance * unshadowed
    return value


def _world(world, p, n, tris, strata, reflect=None, unlifted=None, variance=None,
           single=False, held=None, rest=None, fewer=None):
    """The world's Diffuse Direct (``world_light.world_direct``): its map-sampled rays through
    ``tris`` (lifted by the shadow terminator offset where diffuse_direct was given it), its
    cosine rays through ``unlifted`` (``tris`` when None); single: one ray a stratum; held :
    ``world_light.hidden_less``'s; rest, fewer : ``world_direct``'s."""
    from .world_light import world_direct

    origins_offset = _NORMAL_OFFSET * n
    unlifted = tris if unlifted is None else unlifted

    def through(occluder):
        return None if occluder is None else (
            lambda origins, dirs: _occluded(occluder, origins, dirs, np.full(len(dirs), np.inf)))

    return world_direct(world, p + origins_offset, n, through(unlifted), strata, reflect,
                        sampled=None if unlifted is tris else through(tris), variance=variance,
                        single=single, held=held, rest=rest, fewer=fewer)


def _emitters(emitters, p, n, tris, strata, reflect=None, unshadowed=None):
    from .emitters import emitters_direct

    occluded = None if tris is None else (
        lambda origins, dirs, lengths: _occluded(tris, origins, dirs, lengths))
    return emitters_direct(emitters, p + _NORMAL_OFFSET * n, n, occluded, strata, reflect,
                           unshadowed)


def emitters_unshadowed(emitters, points, normals) -> np.ndarray:
    """(N, 3) the exact unshadowed Diffuse Direct of ``emitters`` (``emitters.EmitterLight``)
    at surface points (N, 3) with unit normals (N, 3), at the points ``diffuse_direct`` lifts
    them to (``emitters.unshadowed_sum``): what its ``unshadowed`` takes."""
    from .emitters import unshadowed_sum

    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    return unshadowed_sum(emitters, p + _NORMAL_OFFSET * n, n)


_BY_TYPE = {"SUN": _sun, "POINT": _point, "SPOT": _point, "AREA": _area, "WORLD": _world,
            "EMITTERS": _emitters}


def world_block(block):
    """The strata block of the world's and the emitters' shadow rays in a sub-pixel pass that
    draws ``block`` = (M, row, column, m) of the lamps' M × M strata: the same share of a set
    twice as fine, (2M, 2 row, 2 column, 2m), four strata a sample where the lamps draw one;
    the lamps' own block where it already has four or more (m ≥ 2: the passes' strata at the
    default 16 Light Samples, ``passes.EDGE_STRATA``), so a sample's world and emitter rays
    stay four.
    A sample's one stratum of a sky or a sun in an HDRI is grain the world filter does not
    reach (it filters the pixel centres), seen as dark dots along silhouettes and shadow
    edges (docs/gi_pipeline.md "The world's strata at the sub-pixel samples"). A sample's
    world light is not held at 0 (``world_light.hidden_less``): its pixel's mean over the
    samples is the estimate, and held per sample it read bright inside shadows. A pass over
    all the strata (m = M: the centre pass, the viewport's samples) and None: as given."""
    if block is None:
        return None
    side, row, column, m = block
    if m >= side or m >= 2:
        return block
    return (2 * side, 2 * row, 2 * column, 2 * m)


def diffuse_direct(points, normals, lights, tris, samples: int = 16, seed: int = 0,
                   sample_ids=None, per_light: bool = False, strata_block=None, reflect=None,
                   unshadowed=None, terminator=None, world_variance=None,
                   one_technique: bool = False, world_strata: int | None = None,
                   world_fewer=None, first_stream: int = 0):
    """Cycles' ``Diffuse Direct`` (irradiance / π, no albedo) at surface points.

    Parameters
    ----------
    points : (N, 3) float world-space surface positions.
    normals : (N, 3) float unit normals facing the viewer.
    lights : list of ``LightData`` (types SUN, POINT, SPOT, AREA; others are ignored),
        ``world_light.WorldLight`` (the world) and ``emitters.EmitterLight`` (emissive
        triangles), the last two RGB lights of their own.
    tris : ``SceneTriangles`` (or a ``raycast.TriangleGrid``) that casts shadows, or any object with
        an ``occluded(origins, dirs, max_t)`` method (voxel occupancy); None = no shadows.
    samples : shadow rays per point for lights with an extent (area, point/spot radius, sun
        angle), rounded up to a square number for stratification; hard lights use one ray.
    seed : seed of the sampling pattern (the result is deterministic).
    sample_ids : optional (N,) integer id per point (e.g. its pixel index): the strata's jitter
        is then hashed from (id, light index, seed) (``sampling.hashed_square``), the pattern
        the GPU kernel ``render/shaders/bvh_direct.glsl`` draws, instead of drawn from numpy's
        generator in point order.

    per_light : return each light's share separately (the same samples as the sum).
    strata_block : (M, row, column, m), with ``sample_ids`` only: draw just the m × m block at
        (row, column) of each light's M × M hashed strata (``samples`` is then ignored) — one
        sub-pixel pass of the anti-aliased preview, whose passes share one stratified set
        (GLSL: ``STRATA_BLOCK`` in ``render/shaders/sampling.glsl``); the world and the
        emitters draw ``world_block`` of it. None: all strata.
    reflect : callable(point indices (M,), unit directions (M, K, 3)) -> (M, K, 3), a glossy
        BSDF × cos at the points (``world_light.world_direct``): then also returns, for the
        world and the emitters, the radiance it reflects from the same shadow rays — a bounce
        hit's glossy lobe lit by them (the lamps' is the caller's, at their centre direction).
    unshadowed : (N, 3) the emissive triangles' exact unshadowed light at the points
        (``emitters_unshadowed``; the anti-aliased preview's sub-pixel passes take their pixel
        centre's where they see its surface); None: evaluated here.
    terminator : ((N, 3) lifts, (N, 3) geometric normals) of the points
        (``terminator.find_lifts``): every shadow ray starts from its point lifted as Cycles'
        shadow terminator offset lifts it (``terminator.ShadowStarts``); None: from the point.
    world_variance : an (N,) float array that gets the variance of the luminance of the
        world's estimate (``world_light.hidden_variance``; the GPU's bvh_direct.glsl alpha).
    one_technique : the world's strata draw one ray each, by the map or by the cosine
        (``world_light.one_technique``), not one of each: a bounce hit's (bvh_shade.glsl
        ray_paths).
    world_strata : with ``sample_ids`` and all the strata (no ``strata_block``, or one of them
        all): the world's map and cosine rays over world_strata² strata of their own (the
        map's sun keeps the lamps'; ``passes.world_strata_side``, GLSL bvh_direct.glsl
        WORLD_STRATA). None: the lamps' strata.
    world_fewer : (N,) bool, with world_strata: the points that take them (the others the
        lamps' strata; ``passes.world_fewer_pixels``, GLSL bvh_direct's world_fewer). None: all.
    first_stream : the hash stream of ``lights[0]`` (light i's is first_stream + i: its index
        in the scene's lights list; ``light_table``'s).

    Returns
    -------
    (N, 3) float32 linear RGB; with ``per_light`` (L, N, 3), light by light; with ``reflect``
    a pair (that, the reflected radiance in the same shape).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    out = np.zeros((len(lights), len(p), 3), dtype=np.float64)
    shine = np.zeros_like(out)
    rng = np.random.default_rng(seed)
    ids = None if sample_ids is None else np.asarray(sample_ids).reshape(-1)
    unlifted = tris  # the world's rays Cycles finds by the BSDF's sampling: not lifted
    if terminator is not None and tris is not None and np.any(terminator[0]):
        from .terminator import ShadowStarts

        tris = ShadowStarts(tris, p + _NORMAL_OFFSET * n, n, *terminator)
    for row, light in enumerate(lights):
        index = first_stream + row  # its samples' stream
        shade = _BY_TYPE.get(light.type)
        if shade is None or getattr(light, "power", 1.0) == 0:
            continue
        color = np.asarray(getattr(light, "color", np.ones(3)), dtype=np.float64)
        for a in range(0, len(p), _POINT_CHUNK):
            b = min(len(p), a + _POINT_CHUNK)
            if ids is None:
                def strata(points_of_chunk):  # (count, K, 2) from the generator, in order
                    return stratified_square(len(points_of_chunk), samples, rng)
            elif strata_block is None:
                def strata(points_of_chunk, chunk_ids=ids[a:b], stream=index):
                    return hashed_square(chunk_ids[points_of_chunk], stream, samples, seed)
            else:
                def strata(points_of_chunk, chunk_ids=ids[a:b], stream=index,
                           block=world_block(strata_block) if light.type in ("WORLD", "EMITTERS")
                           else strata_block):
                    side, row, column, m = block
                    square = hashed_square(chunk_ids[points_of_chunk], stream, side * side, seed)
                    i, j = np.divmod(np.arange(m * m), m)
                    return square[:, (row + i) * side + column + j]
            given = {} if unshadowed is None or light.type != "EMITTERS" else {
                "unshadowed": np.asarray(unshadowed, np.float64).reshape(-1, 3)[a:b]}
            if light.type == "WORLD":
                given["unlifted"] = unlifted
                given["single"] = one_technique
                if world_strata is not None and ids is not None and \
                        (strata_block is None or strata_block[3] >= strata_block[0]):
                    given["rest"] = lambda points_of_chunk, chunk_ids=ids[a:b], stream=index: \
                        hashed_square(chunk_ids[points_of_chunk], stream,
                                      world_strata * world_strata, seed)
                    if world_fewer is not None:
                        given["fewer"] = np.asarray(world_fewer, bool).reshape(-1)[a:b]
                if strata_block is not None and strata_block[3] < strata_block[0]:
                    given["held"] = False  # a sample's share of its pixel's strata
                if world_variance is not None:
                    given["variance"] = part = np.zeros(b - a)
            if reflect is not None and light.type in ("WORLD", "EMITTERS"):
                value, glossy = shade(light, p[a:b], n[a:b], tris, strata,
                                      lambda lit, dirs, a=a: reflect(a + lit, dirs), **given)
                shine[row, a:b] += glossy * color
            else:  # a lamp with Cast Shadow off: nothing occludes it
                value = shade(light, p[a:b], n[a:b], tris if getattr(light, "cast_shadow", True)
                              else None, strata, **given)
            out[row, a:b] += (value[:, None] if value.ndim == 1 else value) * color
            if "variance" in given:  # (the colour is the world's strength: 1)
                world_variance[a:b] += part
    result = (out if per_light else out.sum(axis=0)).astype(np.float32)
    if reflect is None:
        return result
    return result, (shine if per_light else shine.sum(axis=0)).astype(np.float32)


def light_aims(lights, points, normals) -> list[np.ndarray]:
    """``light_directions``, except toward an area light: the direction to the middle of its
    part above each point's horizon (the clipped outline's corners' mean,
    ``_polygon_irradiance``), where it has one. A bounce hit's glossy lobe reflects a lamp
    toward one direction (``exact_indirect.ray_paths``); an area light whose centre lies below
    a face's horizon while part of it lights the face (a block's side under a ceiling light)
    was reflected by none (docs/gi_pipeline.md "The Accurate integrator", "A hit's glossy
    lobe toward the lit part of an area light")."""
    points = np.asarray(points, np.float64)
    normals = np.asarray(normals, np.float64)
    lamps = [light for light in lights if light.type not in ("WORLD", "EMITTERS")]
    out = []
    for light, towards in zip(lamps, light_directions(lamps, points)):
        if light.type == "AREA" and len(points):
            outline, area = area_outline(light)
            if area > 0:
                lit, aim = _polygon_irradiance(points, normals, outline, centroid=True)
                d = aim - points
                d /= np.maximum(norm3(d)[..., None], 1e-12)
                towards = np.where((lit > 0.0)[:, None], d, towards)
        out.append(towards)
    return out


def light_directions(lights, points) -> list[np.ndarray]:
    """Per lamp, (N, 3) unit directions from ``points`` towards it (a sun: against its
    direction of travel; others: towards its position). The world, which comes after the
    lamps (``world_light.scene_lights``), has no direction and is left out."""
    out = []
    for light in lights:
        if light.type in ("WORLD", "EMITTERS"):
            continue
        m = np.asarray(light.world_matrix, np.float64)
        if light.type == "SUN":
            d = np.broadcast_to(m[:3, 2] / np.linalg.norm(m[:3, 2]), points.shape)
        else:
            d = m[:3, 3] - points
        out.append(d / np.maximum(norm3(d)[..., None], 1e-12))
    return out
