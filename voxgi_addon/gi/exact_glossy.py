"""Exact one-bounce glossy reflections: Cycles' Glossy Indirect pass with exact rays (numpy
reference of ``render/shaders/bvh_glossy.glsl``; both draw the same rays).

Per surface point p with unit normal n (facing the viewer), unit direction v to the viewer, its
Principled material and a sample id (the pixel index, row 0 on top):

* ``rays`` reflected directions l from GGX's distribution of visible normals (Heitz 2018,
  "Sampling the GGX distribution of visible normals") for α = roughness²: half vectors h drawn
  from the point's rotated Hammersley set (``sampling.hammersley``, stream ``GLOSSY_STREAM``),
  l = 2(v·h)h − v, in the frame ``sampling.perpendicular_basis(n)``;
* each ray weighted by the Principled glossy lobes' BSDF × cos (``principled.glossy_reflectance``,
  Cycles' ``eval``) over the sample's density pdf(l) = G1(v) D(h) / (4 n·v); reflections below
  the surface weigh 0;
* the radiance arriving along each ray as the diffuse gather sees it
  (``exact_indirect.ray_radiance``: the hit's exact direct light, diffuse and glossy, plus its
  emission);
* **Glossy Indirect** = mean(weight × radiance) / Glossy Color (``principled.glossy_color``),
  the light without the glossy colour, as Cycles' pass holds it. A mirror (α² at or below
  ``principled.ROUGHNESS_SQ_THRESHOLD``) reflects about n, one ray's radiance.

Importance sampling the visible normals keeps the weight to Fresnel × (1 + Λ(v)) /
(1 + Λ(v) + Λ(l)), at most about 1: no fireflies from the lobe itself.
"""
from __future__ import annotations

import numpy as np

from ..scene.snapshot import RAY_GLOSSY
from .exact_indirect import LUMINANCE, SURFACE_EPSILON, hit_emission, ray_radiance
from .principled import ROUGHNESS_SQ_THRESHOLD, diffuse_weight, glossy_color, glossy_reflectance
from .sampling import hammersley, perpendicular_basis, vndf_half_vectors

__all__ = ["DISC_SIDES", "GLOSSY_STREAM", "area_shine", "disc_shine", "round_lamp_disc",
           "WORLD_GLOSSY_STREAM", "EMITTER_GLOSSY_STREAM", "glossy_indirect", "glossy_pick_chance",
           "emitters_shine", "emitters_glossy_field", "glossy_world_direct"]

GLOSSY_STREAM = 0x6105  # hash stream of the glossy rays' rotation
WORLD_GLOSSY_STREAM = 0x6107  # hash stream of the map-importance rays of glossy_world_direct
# A metal's colour is all glossy: its Glossy Indirect carries what a dielectric's Diffuse
# Indirect does, so the glossy gather gives points of metallic ≥ 0.5 this many times the rays.
METAL_RAY_FACTOR = 4
# emitters_glossy: a direction toward a triangle's centre below this cosine over the horizon is
# lifted to it, so that the Fresnel ratio there stays defined (the LTC integral itself clips).
HORIZON_LIFT = 0.02
EMITTER_GLOSSY_STREAM = 0x6109  # hash stream of its rays drawn on the emitters


def _lambda(alpha2, cos):
    tan2 = np.maximum(1.0 / np.maximum(cos * cos, 1e-30) - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha2 * tan2) - 1.0)


class _Lobe:
    """The Principled glossy lobe of each point: its colour and its GGX visible-normal samples
    (the module doc)."""

    def __init__(self, normals, views, materials, principled, base=None):
        n = self.n = np.asarray(normals, np.float64).reshape(-1, 3)
        v = self.v = np.asarray(views, np.float64).reshape(-1, 3)
        base_table, param_table = (np.asarray(a, np.float64) for a in principled)
        last = len(base_table) - 1
        mat = np.asarray(materials).reshape(-1)
        mat = np.where((mat >= 0) & (mat < last), mat, last)
        base = base_table[mat] if base is None else np.asarray(base, np.float64).reshape(-1, 3)
        params = param_table[mat]
        metallic, level, rough = params[:, 0], params[:, 1], np.clip(params[:, 2], 0.0, 1.0)
        alpha = rough * rough
        self.alpha2 = (alpha * alpha)[:, None]
        self.mirror = alpha * alpha <= ROUGHNESS_SQ_THRESHOLD
        self.alpha = np.where(self.mirror, 1e-3, alpha)
        self.t, self.b = perpendicular_basis(n)
        self.cos_ni = np.einsum("ij,ij->i", n, v)
        self.shading = (base[:, None], metallic[:, None], level[:, None], rough[:, None])
        self.colour = glossy_color(base, metallic, level, rough, np.clip(self.cos_ni, 0.0, 1.0))

    def pdf(self, dirs):
        """(N, K) density of ``sample``'s directions (N, K, 3) (GGX visible normals; D of the
        half vector as ``glossy_reflectance`` evaluates it, so that it cancels in the weight;
        the GLSL port takes 1 − cos² as |n × h|², exact in float32 near a mirror's peak)."""
        n, v = self.n, self.v
        h_eval = v[:, None] + dirs
        h_eval /= np.maximum(np.linalg.norm(h_eval, axis=-1, keepdims=True), 1e-30)
        cos2 = np.minimum(np.einsum("nkc,nc->nk", h_eval, n) ** 2, 1.0)
        sin2 = np.minimum((np.cross(n[:, None], h_eval) ** 2).sum(-1), 1.0)
        den = sin2 + self.alpha2 * cos2
        d = self.alpha2 / (np.pi * np.maximum(den * den, 1e-30))
        cos_ni = self.cos_ni[:, None]
        return d / (4.0 * np.maximum(cos_ni, 1e-4) * (1.0 + _lambda(self.alpha2, cos_ni)))

    def glossy_chance(self, dirs):
        """(N, K) the chance that Cycles picked each direction by the glossy closure: its
        sample weight × density over both closures' (directional albedos as the weights, the
        cosine density for the diffuse one; 1 for a mirror). Cycles counts a bounce by the
        picked closure but files the path's light by the closures' values, so most of a
        dielectric's Glossy Indirect rides on paths picked diffuse, with one diffuse bounce
        fewer ahead (docs/gi_pipeline.md "Multi-bounce radiance cache", "Bounces counted by
        the picked closure")."""
        base, metallic, level, rough = (a[:, 0] for a in self.shading)
        diffuse = diffuse_weight(base, metallic, level, rough, np.clip(self.cos_ni, 0.0, 1.0))
        glossy = (self.colour @ LUMINANCE)[:, None] * self.pdf(dirs)
        cosine = (diffuse @ LUMINANCE)[:, None] * np.maximum(
            np.einsum("nkc,nc->nk", dirs, self.n), 0.0) / np.pi
        chance = glossy / np.maximum(glossy + cosine, 1e-30)
        return np.where(self.mirror[:, None], 1.0, chance)

    def reflectance(self, dirs):
        """(N, K, 3) BSDF × cos of the lobe toward the viewer for light from ``dirs``."""
        return glossy_reflectance(*self.shading, self.n[:, None], self.v[:, None], dirs)

    def sample(self, ids, rays: int, seed: int):
        """((N, K, 3) reflected directions, (N, K, 3) their weight BSDF × cos / density)."""
        n, v, t, b = self.n, self.v, self.t, self.b
        view_local = np.stack([np.einsum("ij,ij->i", t, v), np.einsum("ij,ij->i", b, v),
                               np.maximum(self.cos_ni, 1e-4)], axis=1)
        view_local /= np.linalg.norm(view_local, axis=1, keepdims=True)
        h_local = vndf_half_vectors(view_local, self.alpha, hammersley(ids, GLOSSY_STREAM, rays, seed))
        h = h_local[..., :1] * t[:, None] + h_local[..., 1:2] * b[:, None] + h_local[..., 2:] * n[:, None]
        h = np.where(self.mirror[:, None, None], n[:, None], h)
        cos_vh = np.einsum("nkc,nc->nk", h, v)
        dirs = 2.0 * cos_vh[..., None] * h - v[:, None]
        dirs /= np.maximum(np.linalg.norm(dirs, axis=-1, keepdims=True), 1e-30)
        cos_no = np.einsum("nkc,nc->nk", dirs, n)
        pdf = self.pdf(dirs)
        weight = np.where(((cos_no > 0.0) & (pdf > 0.0))[..., None],
                          self.reflectance(dirs) / np.maximum(pdf, 1e-30)[..., None], 0.0)
        return dirs, weight


def glossy_pick_chance(normals, views, materials, principled, dirs) -> np.ndarray:
    """(N, K) the chance Cycles picked each of the diffuse gather's directions ``dirs`` (N, K,
    3) by the receiver's glossy closure (``_Lobe.glossy_chance``), 0 on a mirror (a diffuse
    direction is never its reflection): such a path keeps every diffuse bounce to come."""
    lobe = _Lobe(normals, views, materials, principled)
    chance = lobe.glossy_chance(dirs)
    return np.where(lobe.mirror[:, None] | (lobe.cos_ni[:, None] <= 0.0), 0.0, chance)


def glossy_indirect(points, normals, views, materials, sample_ids, tris, lights, principled,
                    emission, rays: int = 16, seed: int = 0, world=(0.0, 0.0, 0.0),
                    hit_samples: int = 1, hit_glossy: bool = True, cache=None):
    """(Glossy Indirect (N, 3) float32, variance of its luminance mean (N,) float32) — see the
    module doc. ``rays`` per point, ``METAL_RAY_FACTOR`` × that at metallic ≥ 0.5. cache : the
    radiance cache the hits reflect too (``exact_indirect.ray_radiance``; None: one bounce),
    with one diffuse bounce more by the chance Cycles picked each ray's direction glossily
    (``_Lobe.glossy_chance``: a glossy bounce leaves every diffuse bounce to come).

    points, normals, views : (N, 3) surface points, unit normals facing the viewer and unit
    directions to the viewer; materials : (N,) material index per point (the last row of the
    tables for none); sample_ids : (N,) integer ids (pixel indices); principled : (base (M + 1,
    3), (metallic, Specular IOR Level, roughness) (M + 1, 3)) of
    ``preview.passes.principled_table``; emission : (M + 1, 3); the rest as
    ``exact_indirect.indirect_and_ao``.
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    ids = np.asarray(sample_ids).reshape(-1).astype(np.uint32)
    count = len(p)
    value, variance = np.zeros((count, 3), np.float32), np.zeros(count, np.float32)
    if count == 0 or rays < 1:
        return value, variance
    materials = np.asarray(materials).reshape(-1)
    metal = np.asarray(principled[1], np.float64)[materials, 0] >= 0.5
    views = np.asarray(views, np.float64).reshape(-1, 3)
    for group, group_rays in ((~metal, rays), (metal, rays * METAL_RAY_FACTOR)):
        if group.any():
            value[group], variance[group] = _glossy_indirect(
                p[group], n[group], views[group], materials[group], ids[group], tris, lights,
                principled, emission, group_rays, seed, world, hit_samples, hit_glossy, cache)
    return value, variance


def _glossy_indirect(p, n, views, materials, ids, tris, lights, principled, emission, rays,
                     seed, world, hit_samples, hit_glossy, cache=None):
    """``glossy_indirect`` with ``rays`` rays at every point."""
    count = len(p)
    lobe = _Lobe(n, views, materials, principled)
    dirs, weight = lobe.sample(ids, rays, seed)
    base_table, param_table = (np.asarray(a, np.float64) for a in principled)
    colour, mirror, cos_ni = lobe.colour, lobe.mirror, lobe.cos_ni

    origins = np.repeat(p + SURFACE_EPSILON * n, rays, axis=0)
    with np.errstate(over="ignore"):
        hit_ids = ids.repeat(rays) * np.uint32(rays) + np.tile(np.arange(rays, dtype=np.uint32), count)
    radiance, _ = ray_radiance(origins, dirs.reshape(-1, 3), hit_ids, tris, lights,
                               (base_table, param_table), emission, seed, world, hit_samples,
                               hit_glossy, ray=RAY_GLOSSY, cache=cache,
                               receiver=lobe.glossy_chance(dirs).reshape(-1))
    safe_colour = np.where(colour > 0.0, colour, 1.0)
    per_ray = np.where(colour[:, None] > 0.0,
                       weight * radiance.reshape(count, rays, 3) / safe_colour[:, None], 0.0)
    per_ray[mirror] = np.where(colour[mirror, None] > 0.0, radiance.reshape(count, rays, 3)[mirror], 0.0)
    per_ray[cos_ni <= 0.0] = 0.0
    value = per_ray.mean(axis=1)
    luminance = per_ray @ LUMINANCE
    variance = np.maximum((luminance ** 2).mean(axis=1) - (value @ LUMINANCE) ** 2, 0.0)
    return value.astype(np.float32), (variance / max(rays - 1, 1)).astype(np.float32)


def glossy_world_direct(points, normals, views, materials, sample_ids, tris, world, principled,
                        rays: int = 16, seed: int = 0, emission=None, emitters=None):
    """(Glossy Direct of the world and the emissive surfaces (N, 3) float32 without the glossy
    colour, variance of its luminance mean (N,) float32): what the glossy lobe sees of them
    (Cycles files it under Glossy Direct). The world by multiple importance sampling with the
    balance heuristic: ray j of the lobe's ``rays`` (``glossy_indirect``'s, same stream) and
    ray j drawn from the map's importance (``world_light.sample_world``, stream
    ``WORLD_GLOSSY_STREAM``) each add L f / (p_lobe + p_map) where they reach the sky
    unoccluded; a mirror takes its one reflected ray, and a uniform world the lobe's rays alone
    (its map's importance is uniform over the sphere). A map's sun (``world_light.Sun``) is
    left out of a lobe that is not a mirror's: each pixel takes it as a lamp
    (``passes.map_sun_shine``). With ``emission`` (M + 1, 3) per
    material, a lobe ray landing on an emissive triangle adds its emission × the ray's weight
    (``glossy_indirect`` then leaves it out); with ``emitters`` (``emitters.EmitterLight``, the
    same triangles) only a mirror's ray does: a glossy lobe gets them from ``emitters_shine``
    (the LTC integral of the lobe over each triangle, noise-free, times the visible share of
    rays drawn on them). world : ``world_light.WorldLight`` or None."""
    from ..scene.raycast import closest_hits
    from .world_light import sample_world, world_pdf, world_radiance

    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    ids = np.asarray(sample_ids).reshape(-1).astype(np.uint32)
    count = len(p)
    if count == 0 or rays < 1 or (world is None and emission is None):
        return np.zeros((count, 3), np.float32), np.zeros(count, np.float32)
    lobe = _Lobe(n, views, materials, principled)
    origins = np.repeat(p + SURFACE_EPSILON * n, rays, axis=0)

    def nearest(dirs, useful, uv=None):  # (N, K) the rays' nearest triangle (-1: none)
        out = np.full(useful.shape, -1)
        if useful.any():
            t, tri, u, v = closest_hits(tris, origins[useful.ravel()], dirs[useful], 0.0, np.inf,
                                        RAY_GLOSSY)
            out[useful] = np.where(np.isfinite(t), tri, -1)
            if uv is not None:
                uv[useful] = np.stack([u, v], axis=-1)
        return out

    dirs, weight = lobe.sample(ids, rays, seed)
    weight = np.where(lobe.mirror[:, None, None], 1.0, weight)
    useful = (weight.sum(-1) > 0) & (np.einsum("nkc,nc->nk", dirs, n) > 0)
    uv = np.zeros(useful.shape + (2,))
    hit = nearest(dirs, useful, uv)
    value = np.zeros(dirs.shape)
    if emission is not None:
        landed = useful & (hit >= 0)
        glow = hit_emission(tris, emission, hit[landed], uv[landed][:, 0], uv[landed][:, 1])
        # with the emitters as lights a glossy lobe gets them from emitters_shine
        # (noise-free); a mirror's one reflected ray still sees them
        share = 1.0 if emitters is None else lobe.mirror[:, None, None].astype(np.float64)
        seen = np.zeros(dirs.shape)
        seen[landed] = glow
        value += seen * weight * share
    if world is None:
        return _glossy_mean(lobe, value)
    lobe_pdf = lobe.pdf(dirs)
    # a uniform world: the lobe's rays alone (the map's importance is uniform over the sphere,
    # half of it below the horizon; GLSL bvh_glossy.glsl uniform_sky)
    map_pdf = np.zeros_like(lobe_pdf) if world.uniform else world_pdf(world, dirs)
    share = np.where(lobe.mirror[:, None], 1.0, lobe_pdf / np.maximum(lobe_pdf + map_pdf, 1e-30))
    sky = world_radiance(world, dirs)
    value += np.where((useful & (hit < 0) & ~_in_sun(world, sky, lobe))[..., None],
                      sky * weight * share[..., None], 0.0)
    if world.uniform:
        return _glossy_mean(lobe, value)

    def reaching(dirs, useful):  # (N, K) the rays that leave the scene
        return useful & (nearest(dirs, useful) < 0)

    dirs = sample_world(world, hammersley(ids, WORLD_GLOSSY_STREAM, rays, seed))
    lobe_pdf, map_pdf = lobe.pdf(dirs), world_pdf(world, dirs)
    useful = (~lobe.mirror[:, None]) & (np.einsum("nkc,nc->nk", dirs, n) > 0) & (map_pdf > 0)
    sky = world_radiance(world, dirs)
    useful &= ~_in_sun(world, sky, lobe)
    f = lobe.reflectance(dirs) / np.maximum(lobe_pdf + map_pdf, 1e-30)[..., None]
    value += np.where(reaching(dirs, useful)[..., None], sky * f, 0.0)
    return _glossy_mean(lobe, value)


def _in_sun(world, radiance, lobe) -> np.ndarray:
    """(N, K) the rays of a glossy lobe whose ``radiance`` (N, K, 3) is the map's sun's: a
    pixel's lobe takes the sun as a lamp (``world_light.sun_lamp``, ``passes.map_sun_shine``),
    so the world's gather leaves them out; a mirror's one ray keeps it."""
    if world.sun is None:
        return np.zeros(radiance.shape[:-1], bool)
    return (radiance @ LUMINANCE > world.sun.threshold) & ~lobe.mirror[:, None]


def _emitter_pdf(emitters, radiance, distance2, cos_l):
    """Solid-angle pdf of drawing a point of radiance ``radiance`` on the emitters (by power)
    seen at squared distance ``distance2`` under |cos_l|."""
    from .emitters import LUMINANCE as LUMA
    from .emitters import _total_power

    p_area = (radiance @ LUMA) / _total_power(emitters)
    return p_area * distance2 / np.maximum(np.abs(cos_l), 1e-30)


def emitters_shine(points, normals, views, materials, sample_ids, tris, principled, emitters,
                   rays: int = 16, seed: int = 0, base=None, field=None) -> np.ndarray:
    """(N, 3) the glossy light the emissive triangles send toward the viewer (Glossy Color ×
    their Glossy Direct) at surface points: ``emitters_glossy`` of the points' Principled lobes
    (``principled`` as ``glossy_indirect``'s; base : (N, 3) Base Color per texel, None: the
    table's), at the points lifted by SURFACE_EPSILON (off an emitter's own plane), as are its
    ``rays`` shadow rays. field : (N, 3) the unshadowed light over the Glossy Color
    (``emitters_glossy_field``, brought from the gather points by
    ``preview.upsample.EmitterField``) and (N,) its turn: where that is within
    ``emitters.NEAR_STEP`` of the lobe's width it stands for the unshadowed sum, which is
    evaluated only at the others (docs/gi_pipeline.md "Where a preview's time goes"); the
    visible share is every point's own. 0 for a mirror (its
    reflected ray in ``glossy_world_direct`` sees the emitters). The GLSL port is
    shaders/bvh_emitter_glossy.glsl."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3))
    if emitters is None or len(p) == 0 or rays < 1:
        return out
    ids = np.asarray(sample_ids).reshape(-1).astype(np.uint32)
    lobe = _Lobe(n, views, materials, principled, base)
    lifted = p + SURFACE_EPSILON * n  # off its own plane (an emitter's point sees none of it)
    origins = np.repeat(lifted, rays, axis=0).reshape(len(p), rays, 3)
    return emitters_glossy(lobe, emitters, tris, lifted, origins, ids, rays, seed, field)


def emitters_glossy_field(points, normals, views, materials, principled, emitters,
                          base=None) -> np.ndarray:
    """(N, 3) the emitters' unshadowed glossy light over the points' Glossy Color
    (``emitters_glossy``'s unshadowed sum, 0 where the colour is): the field the preview
    evaluates at its gather points only and brings to every pixel (``emitters_shine``'s
    ``field``; GLSL: bvh_emitter_glossy.glsl's mode 2). Arguments as ``emitters_shine``'s."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3))
    if emitters is None or len(p) == 0:
        return out
    lobe = _Lobe(n, views, materials, principled, base)
    glossy = np.flatnonzero(~lobe.mirror & (lobe.cos_ni > 0.0))
    light = _emitters_unshadowed(lobe, emitters, (p + SURFACE_EPSILON * n)[glossy], glossy)
    colour = lobe.colour[glossy]
    out[glossy] = np.divide(light, colour, out=np.zeros_like(light), where=colour > 0.0)
    return out


def emitters_glossy(lobe: _Lobe, emitters, tris, points, origins, ids, rays: int, seed: int,
                    field=None):
    """(N, 3) the glossy radiance the lobes reflect of the emissive triangles: the unshadowed
    integral, noise-free (``_emitters_unshadowed``; where ``field`` = (values, turn) holds —
    the turn within ``emitters.NEAR_STEP`` of the lobe's width min(1, 2α) — values × the
    lobe's colour instead), times the visible share of ``rays`` points drawn on the emitters
    by power (stream ``EMITTER_GLOSSY_STREAM``), each weighted by its luminance
    L f |cos_l| / (r² p_area) — a ratio estimator, as the diffuse light's; 1 where no drawn
    point reaches the lobe. 0 for a mirror (its reflected ray sees the emitters)."""
    out = np.zeros((len(points), 3))
    glossy = np.flatnonzero(~lobe.mirror & (lobe.cos_ni > 0.0))
    if len(glossy) == 0:
        return out
    unshadowed = np.zeros((len(glossy), 3))
    held = np.zeros(len(glossy), bool)
    if field is not None:  # within NEAR_STEP of the lobe's width
        from .emitters import NEAR_STEP

        values, turn = field
        turn = np.asarray(turn, np.float64).reshape(-1)[glossy]
        held = (turn >= 0.0) & (turn <= NEAR_STEP * np.minimum(1.0, 2.0 * lobe.alpha[glossy]))
        unshadowed[held] = np.asarray(values, np.float64).reshape(-1, 3)[glossy[held]] \
            * lobe.colour[glossy[held]]
    evaluated = glossy[~held]
    unshadowed[~held] = _emitters_unshadowed(lobe, emitters, points[evaluated], evaluated)
    seen, drawn = _emitter_weights(lobe, emitters, tris, origins, ids, rays, seed)
    total, lit = drawn[glossy].sum(axis=1), seen[glossy].sum(axis=1)
    visible = np.divide(lit, total, out=np.ones_like(lit), where=total > 0.0)
    out[glossy] = unshadowed * visible[:, None]
    return out


def _emitters_unshadowed(lobe: _Lobe, emitters, p, glossy) -> np.ndarray:
    """(G, 3) the unshadowed glossy light of the emissive triangles at points ``p`` (G, 3) of
    the lobes ``glossy`` (indices into ``lobe``'s, not mirrors, v above the horizon).

    The unshadowed integral of triangle t (facing the point) is L_t × the LTC integral of the
    GGX lobe over it (``ltc.ltc_polygon_integral``, fitted with F = 1) × the Fresnel the
    Principled lobe has where the lobe meets the triangle (the clipped triangle's mean
    direction under the LTC, ``ltc_polygon_integral``'s directions) relative to F = 1 (the
    lobe's reflectance there over a white metal's) × a white metal's glossy colour: the LTC
    shape holds no Fresnel, which a dielectric's lobe at a grazing view is mostly made of
    (without it: up to 5× off at 75°; with it 2.5% median error against brute force). The
    triangle's centre was the direction before: for a large emitter a few centimetres away
    (a ceiling panel over the ceiling) that is straight up, 45–65% dark at grazing views
    (tests/engine/test_exact_glossy.py); a Fresnel that varies across a lobe the triangle
    fills is still read 16–21% low at 60–80°."""
    from .emitters import _facing
    from .ltc import ltc_lobe_density, ltc_polygon_integral

    if len(glossy) == 0:
        return np.zeros((0, 3))
    emitters = getattr(emitters, "sums", None) or emitters  # a proxy where they are many
    n, v = lobe.n[glossy], lobe.v[glossy]
    base, metallic, level, rough = (a[glossy] for a in lobe.shading)  # (G, 1, 3), (G, 1) …
    shape, towards = ltc_polygon_integral(p, n, v, rough[:, 0], emitters.corners,
                                          directions=True)                 # (G, T), (G, T, 3)
    if emitters.corners.ndim == 3:  # shared triangles (per-point ones face their point)
        shape = np.where(_facing(emitters, p), shape, 0.0)
    lift = np.maximum(HORIZON_LIFT - np.einsum("gtc,gc->gt", towards, n), 0.0)
    towards = towards + lift[..., None] * n[:, None]
    towards /= np.linalg.norm(towards, axis=-1, keepdims=True)
    white = np.ones((len(glossy), 1, 3))
    actual = glossy_reflectance(base, metallic, level, rough, n[:, None], v[:, None], towards)
    plain = glossy_reflectance(white, 1.0, level, rough, n[:, None], v[:, None], towards)
    white_colour = glossy_color(white[:, 0], 1.0, level[:, 0], rough[:, 0],
                                np.clip(lobe.cos_ni[glossy], 0.0, 1.0))
    # the lobe itself where the LTC's density strays from it (toward the horizon): the full
    # lobe over the fitted one at that direction, for triangles small in the lobe (cover → 0,
    # where shape × it is the exact f L Ω), fading out for triangles that fill it (where the
    # LTC's integral is right and one direction does not stand for it)
    model = ltc_lobe_density(n, v, rough[:, 0], towards)[..., None] * white_colour[:, None]
    ratio = np.divide(actual, model, out=np.zeros_like(actual), where=model > 0.0)
    fresnel = np.divide(actual, plain, out=np.zeros_like(actual), where=plain > 0.0)
    trust = (1.0 - np.clip(shape, 0.0, 1.0)) * _narrow(emitters.corners, p)
    trust = trust[..., None]
    fresnel = np.where(model > 0.0, ratio ** trust * fresnel ** (1.0 - trust), fresnel)
    return np.einsum("gt,gtc->gc", shape, fresnel * emitters.radiance[None]) * white_colour


class _Polygon:
    """An area lamp as ``_emitters_unshadowed`` reads emitters: its outline's fan of
    triangles (T, 3, 3), each of the lamp's radiance (T, 3), lighting the side it emits to."""

    def __init__(self, outline, radiance, emit):
        k = np.arange(1, len(outline) - 1)
        self.corners = np.stack([np.broadcast_to(outline[0], (len(k), 3)), outline[k],
                                 outline[k + 1]], axis=1)
        self.radiance = np.broadcast_to(radiance, (len(k), 3))
        normal = np.cross(self.corners[:, 1] - self.corners[:, 0],
                          self.corners[:, 2] - self.corners[:, 0])
        self.sides = np.where(normal @ emit > 0.0, 1, -1).astype(np.int8)


def area_glossy(light, points, normals, views, materials, principled, base=None) -> np.ndarray:
    """(N, 3) the unshadowed glossy light an area lamp ``light`` sends toward ``views`` off
    surfaces at ``points`` with unit ``normals`` facing the views (``materials`` indices into
    the Principled table ``principled``; ``base`` per point, or the table's): its radiance ×
    the LTC integral of each point's GGX lobe over the lamp's outline, with the Fresnel where
    the lobe meets it — as the emissive triangles' (``_emitters_unshadowed``). A bounce hit's
    glossy lobe reflected a lamp by one direction (its lit part's middle): for a lobe narrower
    than the lamp that read 0.6 of the integral (docs/gi_pipeline.md "A hit's glossy lobe over
    an area light")."""
    from .direct_light import area_outline, light_frame

    points = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.zeros((len(points), 3))
    outline, area = area_outline(light)
    if area <= 0 or not len(points):
        return out
    emit = light_frame(light)[3]
    radiance = np.asarray(light.color, np.float64)[:3] * (light.power / (np.pi * area))
    lobe = _Lobe(normals, views, materials, principled, base)
    glossy = np.flatnonzero(~lobe.mirror & (lobe.cos_ni > 0.0))
    out[glossy] = _emitters_unshadowed(lobe, _Polygon(outline, radiance, emit), points[glossy],
                                       glossy)
    return out


def area_shine(light, direct, points, normals, views, materials, principled, base):
    """(N, 3) what glossy lobes at ``points`` (unit ``normals``, unit ``views`` toward the
    viewer; ``materials`` indices into the Principled table ``principled``, ``base`` (N, 3) per
    point, None: the table's) reflect toward the viewer of an area lamp whose shadowed Diffuse
    Direct there is ``direct`` (N, 3): its unshadowed glossy light (``area_glossy``, the lobe
    integrated over the lamp by LTC, without noise) × the visible share ``direct`` holds (its luminance over the
    unshadowed one, ``direct_light.area_unshadowed``), the lamp's shadowing taken as uniform
    over it. A bounce hit's lobe and a pixel's Glossy Direct both take it: the lobe toward one
    direction, the lamp's lit part's middle, read 0.6 of the integral for a lobe of roughness
    0.3 under a 1 m lamp (docs/gi_pipeline.md "A hit's glossy lobe over an area light"), and
    16 strata of the lamp left a smooth metal's reflection of it grainy ("An area lamp's
    glossy light by LTC")."""
    from .direct_light import area_unshadowed

    out = np.zeros((len(points), 3))
    colour = np.asarray(light.color, np.float64)[:3] @ LUMINANCE
    unshadowed = area_unshadowed(light, points, normals) * colour
    lit = np.flatnonzero((unshadowed > 0.0) & (np.asarray(direct, np.float64) @ LUMINANCE > 0.0))
    if len(lit):
        share = np.clip(np.asarray(direct, np.float64)[lit] @ LUMINANCE / unshadowed[lit], 0.0, 1.0)
        out[lit] = share[:, None] * area_glossy(light, points[lit], normals[lit], views[lit],
                                                materials[lit], principled,
                                                None if base is None else base[lit])
    return out


DISC_SIDES = 12  # a round lamp's visible disc as a regular polygon of this many corners
DISC_WIDEST = 1.2  # radians: the most a pixel's footprint widens a disc to (its clamp's)


def round_lamp_disc(light, points, grow=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a round lamp shows each of ``points`` (N, 3): ((N, DISC_SIDES, 3) its outline as a
    regular polygon, (N,) its angular radius, (N,) bool where it shows one). A point or spot
    light of radius r is a sphere: its silhouette, the disc (d² − r²)/d from the point along
    the way to its centre, of radius r √(d² − r²)/d (none from inside it); a sun is the disc
    of its angle one metre away toward it. grow : (N,) radians² added to the angular radius²
    (``lobe_footprint.disc_growth``: the pixel's footprint, as the disc's reflection spreads
    over it), None: none. The polygon's corners come from the axis's
    ``sampling.perpendicular_basis``, as the GPU's (glossy_direct.glsl)."""
    import math

    from .direct_light import light_frame

    points = np.asarray(points, np.float64).reshape(-1, 3)
    centre, _, _, emit = light_frame(light)
    if light.type == "SUN":
        half = math.tan(0.5 * float(light.angle))
        axis = np.broadcast_to(-np.asarray(emit, np.float64), points.shape)
        middle = points + axis
        radius = np.full(len(points), half)
        valid = np.full(len(points), half > 0.0)
    else:
        r = float(light.radius)
        offset = np.asarray(centre, np.float64) - points
        d = np.maximum(np.linalg.norm(offset, axis=1), 1e-30)
        axis = offset / d[:, None]
        valid = (r > 0.0) & (d > r * (1.0 + 1e-6))
        inside = np.maximum(d * d - r * r, 0.0)
        middle = points + axis * (inside / d)[:, None]
        radius = r * np.sqrt(inside) / d
    distance = np.linalg.norm(middle - points, axis=1)
    angular = np.arctan2(radius, np.maximum(distance, 1e-30))
    if grow is not None:
        grow = np.asarray(grow, np.float64).reshape(-1)
        if light.type == "SUN":
            valid = (angular > 0.0) | (grow > 0.0)
        else:
            valid = (d > r * (1.0 + 1e-6)) & ((r > 0.0) | (grow > 0.0))
        angular = np.minimum(np.sqrt(angular * angular + grow), DISC_WIDEST)
        radius = np.maximum(distance, 1e-30) * np.tan(angular)
    t, b = perpendicular_basis(np.ascontiguousarray(axis))
    turn = 2.0 * np.pi * np.arange(DISC_SIDES) / DISC_SIDES
    outline = middle[:, None] + radius[:, None, None] * (
        np.cos(turn)[None, :, None] * t[:, None] + np.sin(turn)[None, :, None] * b[:, None])
    return outline, angular, valid


class _Fan:
    """A polygon per point as ``_emitters_unshadowed`` reads emitters: each point's outline
    (G, K, 3) as a fan of triangles (G, K − 2, 3, 3), of radiance 1, facing its point."""

    def __init__(self, outline):
        k = np.arange(1, outline.shape[1] - 1)
        self.corners = np.stack([np.broadcast_to(outline[:, :1], (len(outline), len(k), 3)),
                                 outline[:, k], outline[:, k + 1]], axis=2)
        self.radiance = np.ones((len(k), 3))


def disc_shine(light, direct, points, normals, views, materials, principled, base,
               grow=None) -> np.ndarray:
    """(N, 3) what glossy lobes at ``points`` reflect toward ``views`` of a round lamp (a sphere
    light, a sun's disc: ``round_lamp_disc``) whose shadowed Diffuse Direct there is ``direct``
    (N, 3): direct × π × the lobe's mean over the disc, ∫ f cos dω / ∫ cos dω — the numerator
    the LTC integral of the lobe over the disc with its Fresnel (``_emitters_unshadowed``),
    the denominator Lambert's formula over it, both clipped to the horizon. 0 where the lamp
    shows no disc, for a mirror and for a view below the horizon (the lamp's one direction
    takes those: ``passes.glossy_direct_radiance``). grow : ``round_lamp_disc``'s."""
    from .ltc import _clamped_cosine_integral, local_frame

    points = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.zeros((len(points), 3))
    outline, _, valid = round_lamp_disc(light, points, grow)
    lobe = _Lobe(normals, views, materials, principled, base)
    local = np.einsum("nij,nkj->nki", local_frame(lobe.n, lobe.v), outline - points[:, None])
    flat = _clamped_cosine_integral(local)  # ∫ cos θ / π dω
    glossy = np.flatnonzero(valid & ~lobe.mirror & (lobe.cos_ni > 0.0) & (flat > 0.0))
    if len(glossy):
        integral = _emitters_unshadowed(lobe, _Fan(outline[glossy]), points[glossy], glossy)
        out[glossy] = np.asarray(direct, np.float64)[glossy] * integral / flat[glossy, None]
    return out


def _narrow(corners, points) -> np.ndarray:
    """(G, T) how narrow each triangle ``corners`` (T, 3, 3), or each point's (G, T, 3, 3),
    looks from each point (G, 3):
    1 − its spread / (π/2), clipped to [0, 1], where the spread is the largest angle between
    the directions to its corners. ``emitters_glossy`` lets the lobe over the LTC's density at
    one direction stand for a triangle only as far as the triangle is narrow: that ratio swings
    across a lobe (toward the horizon above all), and over a triangle whose corners lie a
    quarter turn apart or more — a ceiling panel 5 cm under a grazingly seen ceiling, spanning
    150° of it — one direction's ratio was 2–3× off brute force
    (tests/engine/test_exact_glossy.py)."""
    d = (corners if corners.ndim == 4 else corners[None]) - points[:, None, None]  # (G, T, 3, 3)
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-30)
    cosines = np.minimum(np.minimum(np.einsum("gtc,gtc->gt", d[:, :, 0], d[:, :, 1]),
                                    np.einsum("gtc,gtc->gt", d[:, :, 1], d[:, :, 2])),
                         np.einsum("gtc,gtc->gt", d[:, :, 0], d[:, :, 2]))
    spread = np.arccos(np.clip(cosines, -1.0, 1.0))
    return np.clip(1.0 - spread / (0.5 * np.pi), 0.0, 1.0)


def _emitter_weights(lobe: _Lobe, emitters, tris, origins, ids, rays: int, seed: int):
    """((N, K) luminance weight L f |cos_l| / (r² p_area) of ray j drawn on the emitters where
    it reaches its point unoccluded, the same weights drawn) — 0 for a mirror."""
    from ..scene.raycast import occluded
    from .emitters import _facing, sample_points

    k, targets = sample_points(emitters, hammersley(ids, EMITTER_GLOSSY_STREAM, rays, seed))
    start = origins.reshape(targets.shape)
    w = targets - start
    r2 = np.einsum("nkc,nkc->nk", w, w)
    r = np.sqrt(r2)
    d = w / np.maximum(r, 1e-30)[..., None]
    corners = emitters.corners[k]
    normal = np.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-30)
    cos_l = np.einsum("nkc,nkc->nk", d, normal)
    radiance = emitters.radiance[k]
    emit_pdf = _emitter_pdf(emitters, radiance, r2, cos_l)
    useful = (~lobe.mirror[:, None]) & (np.einsum("nkc,nc->nk", d, lobe.n) > 0) & \
        (np.abs(cos_l) > 0) & _facing(emitters, start[:, 0], k)
    seen = np.zeros(useful.shape, bool)
    if useful.any():
        seen[useful] = ~occluded(tris, start[useful], d[useful], r[useful])
    drawn = np.where(useful, (radiance * lobe.reflectance(d)) @ LUMINANCE
                     / np.maximum(emit_pdf, 1e-30), 0.0)
    return np.where(seen, drawn, 0.0), drawn


def _glossy_mean(lobe: _Lobe, value):
    """(mean over the rays of value (N, K, 3) without the glossy colour, its luminance
    variance), as ``glossy_indirect`` gives them (a mirror's value is the pass itself)."""
    colour, mirror, rays = lobe.colour, lobe.mirror, value.shape[1]
    safe_colour = np.where(colour > 0.0, colour, 1.0)
    per_ray = np.where(colour[:, None] > 0.0, value / safe_colour[:, None], 0.0)
    per_ray[mirror] = np.where(colour[mirror, None] > 0.0, value[mirror], 0.0)
    per_ray[lobe.cos_ni <= 0.0] = 0.0
    mean = per_ray.mean(axis=1)
    luminance = per_ray @ LUMINANCE
    variance = np.maximum((luminance ** 2).mean(axis=1) - (mean @ LUMINANCE) ** 2, 0.0)
    return mean.astype(np.float32), (variance / max(rays - 1, 1)).astype(np.float32)
