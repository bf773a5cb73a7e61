"""Exact ambient occlusion and a raw one-bounce diffuse-indirect estimator (numpy reference).

The statement, in numpy on ``raycast``, of what ``render/shaders/bvh_gather.glsl`` computes
on the GPU through the BVH; both draw the same rays (``sampling``), so they agree up to float32
rounding. Per surface point p with unit normal n (facing the viewer) and sample id (its pixel
index, row 0 on top):

* ``rays`` directions, cosine-distributed about n: the point's rotated Hammersley set
  (``sampling.hammersley``, stream ``RAY_STREAM``) mapped to the disc (Shirley–Chiu) and lifted
  to the hemisphere, in ``sampling.perpendicular_basis(n)``; rays start at p + 10⁻⁴·n and count
  hits beyond ``SHADOW_EPSILON``.
* **Ambient Occlusion** (Cycles' AO pass): the share of those rays whose nearest hit is at least
  ``ao_distance`` away (cosine-weighted unoccluded fraction; white surfaces, no albedo).
* **Diffuse Indirect** (Cycles' units: light arriving after one bounce, without the receiver's
  albedo; with cosine-weighted rays the estimator of E/π is the mean radiance): a hit at x
  contributes albedo(x) · Diffuse Direct(x) + emission(x) — the exact direct light of
  ``direct_light.diffuse_direct`` at x with the hit's shading normal turned towards the ray,
  ``hit_samples`` shadow ray(s) per light with an extent, sample id ``id · rays + j`` and seed
  ``seed + 1`` — and a miss contributes ``world``. Albedo and emission come from
  ``preview.material_table`` (base colour × (1 − metallic)).

Cycles files the world seen straight from the receiver under Diffuse Direct, not Indirect, and
also lights the bounce point with the world; pass ``world = 0`` for Cycles' pass split (the test
scenes have black worlds, where both agree).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..scene.raycast import closest_hits
from ..scene.snapshot import RAY_DIFFUSE
from .direct_light import area_outline, concentric_disk, diffuse_direct, light_aims, light_frame, spot_factor
from .principled import diffuse_weight, glossy_color, glossy_reflectance
from .radiance_cache import cache_levels, cell_size, lookup
from .sampling import hammersley, pcg_hash, perpendicular_basis, point_streams, unit_float, vndf_half_vectors

__all__ = ["CONTINUE_STREAM", "LAMP_PICK_FLOOR", "LAMP_PICK_STREAM", "METAL_FOLLOWED", "RAY_STREAM",
           "SURFACE_EPSILON", "RayPaths",
           "cosine_directions", "follow_metal_hits", "gather_rays", "indirect_and_ao", "lamp_picks",
           "metal_lobe_rays", "ray_paths", "ray_radiance"]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights of R, G, B
RAY_STREAM = 0x5EED   # hash stream of the diffuse rays' rotation
# hash stream of a metal hit's reflection, followed one bounce further (``metal_lobe_rays``),
# and (xor'ed into the ray's light-sample id) of the light samples at that second hit
CONTINUE_STREAM = 0x6C0B
# Metallic from which a hit's glossy lobe is followed (``ray_radiance``) and reflects an area
# lamp by the lobe's integral over it (``_area_shine``; the others by the lobe toward one
# direction, the lamp's lit part's middle: 0.6-1 of the integral, a dielectric's glossy lobe a
# small part of what it reflects but at grazing views, and the integral at every hit cost the
# box and the textured room a fifth more time for no change: docs/gi_pipeline.md "A hit's
# glossy lobe over an area light")
METAL_FOLLOWED = 0.5
# hash stream of the draw that follows a dielectric hit's glossy lobe by its share
# (``lobe_follow_chance``)
LOBE_FOLLOW_STREAM = 0x6C1D
# The near field (cache cells): a diffuse gather ray hitting within this many cells of the
# finest cache grid holding the hit reads no cache there — the lookup's trilinear voxels reach
# back around the gather point itself — but is followed one diffuse bounce further
# (``near_bounce_rays``), as a final gather traces its short rays on past a photon map's
# footprint (docs/gi_pipeline.md "The near field followed"); MAX_FOLLOWS such bounces at most
# (a second one took a light cove's slot from 0.55-0.74 of path tracing to 0.91-0.99, but the
# images hardly moved and the 140k-triangle diorama's preview took 8% longer)
NEAR_FIELD = 1.0
MAX_FOLLOWS = 1
# ... and only a hit on a surface turned more than 60 degrees from the receiver's (the cosine
# of their normals under NEAR_FACING): two surfaces facing each other within a cell, a gap
# thinner than the cache's voxels, whose one face per axis and sign cannot hold both, and a
# crease (a wall's foot seen from the ground beside it), where the cache's light at the wall
# blends the voxels about the crease and reads its foot low (Diffuse Indirect 2-6% of Combined
# under Cycles' along a courtyard's walls). Not the hits in or near the receiver's own plane:
# followed everywhere near, the 140k-triangle diorama's preview took 14% longer for nothing
# (docs/gi_pipeline.md "The near field followed", "Creases followed too")
NEAR_FACING = 0.5
SURFACE_EPSILON = 1e-4  # metres off the surface, as preview.SURFACE_EPSILON
# A gather point's reach: the harmonic mean of its rays' hit distances (a miss counts as
# infinitely far), the scale over which its light changes (Ward's irradiance-cache radius),
# which bounds the filter's taps (preview.denoise REACH). A hit nearer than NEAREST_HIT
# metres counts as that near (no division by 0).
NEAREST_HIT = 1e-4
# A bounce hit traces the shadow rays of one lamp (sun, point, spot, area), picked by
# ``lamp_picks`` from this hash stream (of its light-sample id and seed + 1), its light divided
# by its chance: a hit's cost no longer grows with the lamps. LAMP_PICK_FLOOR of the chance is
# spread evenly over the lamps, the rest goes by each one's unshadowed light at the hit, so
# that a lamp the weights underrate (an area lamp whose centre is below the horizon) is still
# picked (docs/gi_pipeline.md "One lamp a bounce hit").
LAMP_PICK_STREAM = 0x6C2F
LAMP_PICK_FLOOR = 0.25


def cosine_directions(normals: np.ndarray, square: np.ndarray) -> np.ndarray:
    """(N, K, 3) unit directions, cosine-distributed about unit ``normals`` (N, 3), from
    ``square`` (N, K, 2) in [0, 1)²: the concentric disc point (x, y) lifted to √(1 − x² − y²)."""
    disk = concentric_disk(square)
    z = np.sqrt(np.maximum(0.0, 1.0 - (disk ** 2).sum(-1)))
    t, b = perpendicular_basis(normals)
    d = disk[..., :1] * t[:, None] + disk[..., 1:] * b[:, None] + z[..., None] * normals[:, None]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _hit_normals(tris, tri, u, v, d):
    """Shading normals (interpolated corner normals, else the face normal) of hits, turned
    against the rays d, as ``raycast.primary_visibility`` turns them."""
    face = np.asarray(tris.normals, dtype=np.float64)[tri]
    shading = face
    if tris.corner_normals is not None:
        c = np.asarray(tris.corner_normals, dtype=np.float64)[tri]
        smooth = (1.0 - u - v)[:, None] * c[:, 0] + u[:, None] * c[:, 1] + v[:, None] * c[:, 2]
        length = np.linalg.norm(smooth, axis=1, keepdims=True)
        shading = np.where(length > 1e-12, smooth / np.maximum(length, 1e-12), face)
    sign = np.where(np.einsum("ij,ij->i", face, d) > 0, -1.0, 1.0)[:, None]
    return shading * sign


def hit_emission(tris, emission, triangles, b1, b2) -> np.ndarray:
    """(N, 3) float64 the emission where rays hit ``triangles`` (N,) at barycentrics (b1, b2):
    per texel where the material has an emission texture (``SurfaceTextures.emission_at``,
    level 0, as the Base Color at bounce hits), else the material's ``emission`` (M + 1, 3)
    row."""
    table = np.asarray(emission, np.float64)
    last = len(table) - 1
    material = np.asarray(tris.materials)[np.asarray(triangles, np.int64)]
    material = np.where((material >= 0) & (material < last), material, last)
    out = table[material]
    surface = getattr(tris, "textures", None)
    if surface is not None and surface.emission_slots is not None and len(out):
        texel, textured = surface.emission_at(triangles, material, b1, b2)
        out = np.where(textured[:, None], texel, out)
    return out


@dataclass(frozen=True, eq=False)
class RayPaths:
    """What bounce rays see, apart from the radiance cache (``ray_paths``). radiance : (K, 3)
    ``world`` on a miss, else the hit's emission plus its exact direct light reflected toward
    the ray's origin; distance : (K,) of the nearest hit, inf on a miss; hit : (H,) the rays
    that hit; points, normals : (H, 3) their hit points and shading normals (turned toward the
    origin); weight : (H, 3) what each hit reflects toward the origin of light arriving
    uniformly: its diffuse weight plus, Principled, its glossy lobes' albedo (Cycles' Glossy
    Color), else its albedo; glossy : (H, 3) the glossy lobes' part of it. What a ray returns
    with a cache is linear in it (``with_cache``), so the radiance cache traces its rays once
    and iterates by lookups alone (``radiance_cache.relax``)."""

    radiance: np.ndarray
    distance: np.ndarray
    hit: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    weight: np.ndarray
    glossy: np.ndarray
    roughness: np.ndarray | None = None  # (H,) the hits' Principled roughness and metallic
    metallic: np.ndarray | None = None

    @property
    def glossy_share(self) -> np.ndarray:
        """(H,) the glossy lobes' share of each hit's ``weight`` (summed over rgb)."""
        total = self.weight.sum(axis=1)
        return np.where(total > 0, self.glossy.sum(axis=1) / np.maximum(total, 1e-30), 0.0)

    def with_cache(self, cache, receiver=None) -> np.ndarray:
        """(K, 3) float64: the radiance with the hits also reflecting the indirect light
        ``cache`` holds at them (None or an empty cache: ``radiance``). A glossy scatter at
        the hit does not count toward Cycles' diffuse bounces, so the glossy lobes reflect the
        light of one more diffuse bounce: the cache's ``lookup`` × (1 + its one-more-bounce
        ratio) (docs/gi_pipeline.md "Multi-bounce radiance cache", "Glossy scatters between
        diffuse bounces"). receiver : (K,) per ray the chance Cycles picked the receiver's
        glossy closure for it (``exact_glossy._Lobe.glossy_chance``; None: 0, the diffuse
        gather): the hit's diffuse share reflects that much of one more bounce too."""
        out = self.radiance.copy()
        if cache is not None and not cache.iterations and cache.ahead and len(self.hit):
            # one bounce, the glossy bounces going on: only what a glossy scatter carries —
            # the hits' glossy lobes, and the share of their diffuse one whose receiver's
            # path was picked glossy — reflects the first iteration, held ahead
            arriving = lookup(replace(cache, faces=cache.ahead, iterations=1, ahead=()),
                              self.points, self.normals)
            chance = 0.0 if receiver is None else \
                np.asarray(receiver, np.float64).reshape(-1)[self.hit][:, None]
            out[self.hit] += ((self.weight - self.glossy) * chance + self.glossy) * arriving
        elif cache is not None and cache.iterations and len(self.hit):
            arriving, more = lookup(cache, self.points, self.normals, more=True)
            if receiver is None:
                out[self.hit] += (self.weight + self.glossy * more[:, None]) * arriving
            else:
                chance = np.asarray(receiver, np.float64).reshape(-1)[self.hit][:, None]
                out[self.hit] += ((self.weight - self.glossy) * (1.0 + chance * more[:, None])
                                  + self.glossy * (1.0 + more[:, None])) * arriving
        return out


_LAMP_KINDS = ("SUN", "POINT", "SPOT", "AREA")


def _lamps(lights) -> list[int]:
    """The indices in ``lights`` of the lamps the GPU's light table holds
    (``preview.light_table``: a sun, point, spot or area light of non-zero power, an area
    light of non-zero area), in its order."""
    return [i for i, light in enumerate(lights) if light.type in _LAMP_KINDS and light.power != 0
            and (light.type != "AREA" or area_outline(light)[1] > 0)]


def _pick_weights(light, points, normals) -> np.ndarray:
    """(H,) ``lamp_picks``' weight of ``light`` at ``points`` with ``normals``: its Diffuse
    Direct there as if nothing hid it and an area lamp were a point at its centre (luminance).
    GLSL ``lamp_pick_weight`` (bvh_shade.glsl)."""
    centre, _, _, emit = light_frame(light)
    power = float(light.power) * float(np.asarray(light.color, np.float64)[:3] @ LUMINANCE)
    if light.type == "SUN":
        return power * np.maximum(normals @ -emit, 0.0) / np.pi
    delta = centre - points
    d2 = np.einsum("ij,ij->i", delta, delta)
    dist = np.sqrt(np.maximum(d2, 1e-30))
    c = np.maximum(np.einsum("ij,ij->i", normals, delta), 0.0) / dist
    if light.type == "AREA":  # Lambert's small-source form, the lamp's area keeping it finite
        facing = np.maximum(-delta @ emit, 0.0) / dist
        return power * c * facing / (np.pi * np.pi * (d2 + area_outline(light)[1]))
    cone = spot_factor(light, emit, -delta / dist[:, None]) if light.type == "SPOT" else 1.0
    return power * cone * c / (4.0 * np.pi * np.pi * (d2 + float(light.radius) ** 2))


def _metal_weights(lights, lamps, weights, points, normals, metal, diffuse, views, shading):
    """``weights`` (L, H) at the metal hits ``metal`` (H,) bool whose glossy lobe is taken:
    times what the hit sends toward ``views`` — its diffuse weight ``diffuse`` (H, 3) and its
    lobe (Principled ``shading``) toward the lamp (``light_aims``), as ``ray_paths`` reflects
    each lamp — since a metal's light is its lobe's. GLSL ``hit_lamp_weight``."""
    k = np.flatnonzero(metal)
    if not len(k):
        return weights
    weights = weights.copy()
    at = [i for i, light in enumerate(lights) if light.type not in ("WORLD", "EMITTERS")]
    aims = light_aims(lights, points[k], normals[k])  # (the lamps of ``at``, in its order)
    part = tuple(np.asarray(a)[k] for a in shading)
    for row, i in enumerate(lamps):
        towards = aims[at.index(i)]
        cos = np.einsum("ij,ij->i", normals[k], towards)
        reflected = glossy_reflectance(*part, normals[k], views[k], towards) @ LUMINANCE
        lobe = np.where(cos > 1e-4, np.pi / np.maximum(cos, 1e-4) * reflected, 0.0)
        weights[row, k] *= diffuse[k] @ LUMINANCE + lobe
    return weights


def lamp_picks(lights, points, normals, hit_ids, seed: int, metal=None):
    """The lamp each bounce hit traces (``LAMP_PICK_STREAM``): (the picked light's index in
    ``lights`` (H,), its chance (H,)), or None where the lights hold fewer than two lamps (the
    one there is always traced). points : (H, 3) where the hits' light is taken (lifted off the
    surface); seed : the hits' light samples' seed (``ray_paths``' seed + 1). metal : None, or
    (mask (H,), diffuse weight (H, 3), views (H, 3), Principled shading) of the metal hits whose
    lobe is taken, weighed by what they reflect (``_metal_weights``)."""
    lamps = _lamps(lights)
    if len(lamps) < 2:
        return None
    points = np.asarray(points, np.float64)
    normals = np.asarray(normals, np.float64)
    weights = np.stack([_pick_weights(lights[i], points, normals) for i in lamps])  # (L, H)
    if metal is not None:
        weights = _metal_weights(lights, lamps, weights, points, normals, *metal)
    total = weights.sum(axis=0)
    count = len(lamps)
    spread = (1.0 - LAMP_PICK_FLOOR) * weights / np.where(total > 0.0, total, 1.0) + \
        LAMP_PICK_FLOOR / count
    chances = np.where(total > 0.0, spread, 1.0 / count)
    u = unit_float(point_streams(hit_ids, LAMP_PICK_STREAM, seed))
    below = np.cumsum(chances, axis=0)
    first = np.argmax(u[None, :] < below, axis=0)  # the first lamp whose share holds u …
    k = np.where((u[None, :] < below).any(axis=0), first, count - 1)  # … else the last
    return np.asarray(lamps)[k], chances[k, np.arange(len(k))]


def ray_paths(origins, dirs, hit_ids, tris, lights, albedo, emission, seed: int = 0,
              world=(0.0, 0.0, 0.0), hit_samples: int = 1, hit_glossy: bool = False,
              emission_seen: bool | None = None, ray: int = RAY_DIFFUSE, hits=None,
              one_world_ray: bool = True) -> RayPaths:
    """The ``RayPaths`` of bounce rays (``ray_radiance`` without a cache, plus what a cache
    would add to: the hits, their normals and weights). hits : the rays' closest hits
    (t, triangle, u, v), (K,) each, traced already (``raycast.closest_hits``; None: traced
    here). one_world_ray : each of a hit's world strata draws one ray, by the map or by the
    cosine (``world_light.one_technique``), as the GPU's gathers and cache do; False: one of
    each (a probe's bake, whose few rays a probe are not filtered)."""
    t, tri, u, v = closest_hits(tris, origins, dirs, 0.0, np.inf, ray) if hits is None else \
        (np.asarray(a) for a in hits)
    radiance = np.tile(np.asarray(world, dtype=np.float64), (len(dirs), 1))
    # With the emissive triangles among the lights their light reaches the origin as direct
    # light (next-event estimation, gi/emitters.py): a ray landing on one adds no emission
    # (unless the caller says it sees it: the glossy gather, which has no such estimate yet).
    if emission_seen is None:
        emission_seen = not any(light.type == "EMITTERS" for light in lights)
    hit = np.flatnonzero(tri >= 0)
    x = ns = weight = glossy = np.zeros((0, 3))
    roughness = metallic = None
    if len(hit):
        x = origins[hit] + t[hit, None] * dirs[hit]
        ns = _hit_normals(tris, tri[hit], u[hit], v[hit], dirs[hit])
        material = np.asarray(tris.materials)[tri[hit]]
        last = len(emission) - 1
        material = np.where((material >= 0) & (material < last), material, last)
        if getattr(tris, "textures", None) is not None:  # Roughness / Metallic per texel
            material = tris.textures.variant_at(tri[hit], material, u[hit], v[hit])
        # emissive triangles by each picked triangle's exact light less its hidden sample's
        # here (emitters.EmitterLight.exact False)
        at_hits = [replace(light, exact=False) if light.type == "EMITTERS" else light
                   for light in lights]
        principled = isinstance(albedo, tuple)  # (base, (metallic, level, roughness))
        if principled:
            base, params = (np.asarray(a, np.float64)[material] for a in albedo)
            if getattr(tris, "textures", None) is not None:  # Base Color per texel, level 0
                base = tris.textures.base_at(tri[hit], np.asarray(tris.materials)[tri[hit]],
                                             u[hit], v[hit], base)
            shading = (base, params[:, 0], params[:, 1], params[:, 2])
            roughness, metallic = np.clip(params[:, 2], 0.0, 1.0), params[:, 0]
        reflect = None
        if principled and hit_glossy:
            def reflect(points, towards):  # the hit's glossy lobe toward the ray's origin
                k = towards.shape[1]
                return glossy_reflectance(
                    *(np.repeat(a[points], k, axis=0) for a in shading),
                    np.repeat(ns[points], k, axis=0), -np.repeat(dirs[hit][points], k, axis=0),
                    towards.reshape(-1, 3)).reshape(towards.shape)
        # the world's strata one ray each (world_light.one_technique): the hits' mean over a
        # gather point's rays is what counts, and the second ray a stratum cost the HDRI
        # courtyard's gathers a fifth of their time
        lit = diffuse_direct(x + ns * SURFACE_EPSILON, ns, at_hits, tris, samples=hit_samples,
                             seed=seed + 1, sample_ids=hit_ids[hit], per_light=True,
                             reflect=reflect, one_technique=one_world_ray)
        if reflect is not None:  # the world's and emitters' light off the hit's glossy lobe
            lit, reflected = lit
        # one lamp a hit (LAMP_PICK_STREAM), its light over its chance; every light's share is
        # computed here, the GPU traces the picked lamp's shadow rays alone. A metal hit whose
        # lobe is taken weighs the lamps by what its lobe reflects of them.
        metal = None
        if principled and hit_glossy:
            mu = np.clip(-np.einsum("ij,ij->i", ns, dirs[hit]), 0.0, 1.0)
            metal = (metallic >= METAL_FOLLOWED, diffuse_weight(*shading, mu), -dirs[hit],
                     shading)
        share = np.ones((len(lights), len(hit)))
        picks = lamp_picks(lights, x + ns * SURFACE_EPSILON, ns, hit_ids[hit], seed + 1, metal)
        if picks is not None:
            picked, chance = picks
            for i in _lamps(lights):
                share[i] = np.where(picked == i, 1.0 / chance, 0.0)
        # the emission per texel where the material has an emission texture (level 0)
        radiance[hit] = hit_emission(tris, emission, tri[hit], u[hit], v[hit]) \
            if emission_seen else 0.0
        arriving = (lit * share[:, :, None]).sum(axis=0)
        if principled:
            mu = np.clip(-np.einsum("ij,ij->i", ns, dirs[hit]), 0.0, 1.0)
            diffuse = diffuse_weight(*shading, mu)
            radiance[hit] += diffuse * arriving
            # uniform light (the cache's) is also reflected by the glossy lobe's albedo
            glossy = glossy_color(*shading, mu)
            weight = diffuse + glossy
            if reflect is not None:
                radiance[hit] += reflected.sum(axis=0)
            lit_at = x + ns * SURFACE_EPSILON
            lamps = [light for light in lights if light.type not in ("WORLD", "EMITTERS")]
            wide = metallic >= METAL_FOLLOWED  # metals reflect an area lamp by the integral
            for light, direct, towards, scale in zip(lamps, lit if hit_glossy else (),
                                                     light_aims(lights, lit_at, ns), share):
                cos = np.einsum("ij,ij->i", ns, towards)
                shine = direct * (np.pi / np.maximum(cos, 1e-4))[:, None] * \
                    glossy_reflectance(*shading, ns, -dirs[hit], towards)
                shine = np.where(cos[:, None] > 1e-4, shine, 0.0)
                if light.type == "AREA" and wide.any():  # the lobe over the lamp (LTC)
                    from .exact_glossy import area_shine

                    k = np.flatnonzero(wide)
                    shine[k] = area_shine(light, direct[k], lit_at[k], ns[k], -dirs[hit][k],
                                          material[k], albedo, base[k])
                radiance[hit] += shine * scale[:, None]
        else:
            weight = np.asarray(albedo, np.float64)[material]
            glossy = np.zeros_like(weight)
            radiance[hit] += weight * arriving
    return RayPaths(radiance, t, hit, x, ns, weight, glossy, roughness, metallic)


def metal_lobe_rays(normals, dirs, roughness, hit_ids, seed: int = 0) -> np.ndarray:
    """(N, 3) one direction per hit drawn from its GGX lobe (visible normals, Heitz 2018) of
    ``roughness`` about ``normals``, seen along ``dirs`` (the arriving rays), from the hash of
    each ray's light-sample id ``hit_ids`` (``CONTINUE_STREAM``): the reflection a metal hit's
    path is followed along (``ray_radiance``; bvh_shade.glsl ``metal_lobe_ray``)."""
    normals = np.asarray(normals, np.float64)
    dirs = np.asarray(dirs, np.float64)
    alpha = np.maximum(np.asarray(roughness, np.float64) ** 2, 1e-3)
    t, b = perpendicular_basis(normals)
    v = -dirs
    local = np.stack([np.einsum("ij,ij->i", t, v), np.einsum("ij,ij->i", b, v),
                      np.maximum(np.einsum("ij,ij->i", normals, v), 1e-4)], axis=1)
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    h = point_streams(hit_ids, CONTINUE_STREAM, seed)
    square = np.stack([unit_float(h), unit_float(pcg_hash(h))], axis=-1)[:, None, :]
    half = vndf_half_vectors(local, alpha, square)[:, 0]
    m = half[:, :1] * t + half[:, 1:2] * b + half[:, 2:3] * normals
    return dirs - 2.0 * np.einsum("ij,ij->i", dirs, m)[:, None] * m


def follow_metal_hits(paths: RayPaths, metal, dirs, hit_ids, tris, lights, albedo, emission,
                      seed: int = 0, ray: int = RAY_DIFFUSE):
    """The hits ``metal`` (indices into ``paths``' hits: the metals and the dielectrics whose
    glossy lobe ``ray_radiance`` follows, ``lobe_follow_chance``) followed one reflection further
    (``metal_lobe_rays``; bvh_shade.glsl ``metal_follow``): (up, second) — ``up`` the indices
    into ``metal`` whose reflection leaves above the surface, ``second`` the ``RayPaths`` of
    those reflections (no world, no emission: the metal's own light sampling holds them; one
    light sample a light, the glossy lobes lit; light-sample ids hashed with
    ``CONTINUE_STREAM``), None when there is none."""
    rays = paths.hit[metal]
    normals = paths.normals[metal]
    ids = np.asarray(hit_ids).astype(np.uint32)[rays]
    further = metal_lobe_rays(normals, np.asarray(dirs, np.float64)[rays],
                              paths.roughness[metal], ids, seed)
    up = np.flatnonzero(np.einsum("ij,ij->i", further, normals) > 0.0)
    if not len(up):
        return up, None
    start = paths.points[metal][up] + SURFACE_EPSILON * normals[up]
    return up, ray_paths(start, further[up], pcg_hash(ids[up] ^ np.uint32(CONTINUE_STREAM)),
                         tris, lights, albedo, emission, seed, (0.0, 0.0, 0.0), 1, True, False,
                         ray)


def near_bounce_rays(normals, hit_ids, seed: int = 0) -> np.ndarray:
    """(N, 3) the cosine-distributed direction about each of unit ``normals`` a near hit is
    followed along (``ray_radiance``'s near field; bvh_shade.glsl ``near_bounce_ray``): the
    concentric disc point of the hash of the ray's light-sample id (``CONTINUE_STREAM``, as a
    metal's reflection: a hit takes one or the other), lifted."""
    h = point_streams(np.asarray(hit_ids).astype(np.uint32), CONTINUE_STREAM, seed)
    square = np.stack([unit_float(h), unit_float(pcg_hash(h))], axis=-1)[:, None, :]
    return cosine_directions(np.asarray(normals, np.float64), square)[:, 0]


def _near(cache, paths: RayPaths, receivers) -> np.ndarray:
    """Indices into ``paths``' hits that lie within ``NEAR_FIELD`` cells of the cache, face
    their ray's receiver or meet it at a crease (``receivers``, (K, 3) its normal per ray: the
    cosine under ``NEAR_FACING``) and are no metals (their lobes are followed as such)."""
    facing = np.einsum("ij,ij->i", paths.normals, receivers[paths.hit]) < NEAR_FACING
    near = facing & (paths.distance[paths.hit] < NEAR_FIELD * cell_size(cache, paths.points))
    if paths.metallic is not None:
        near &= paths.metallic < METAL_FOLLOWED
    return np.flatnonzero(near)


def _follow_near(paths: RayPaths, out, hit_ids, tris, lights, albedo, emission, seed, ray,
                 cache, receivers) -> None:
    """``ray_radiance``'s near field, in ``out``: each non-metal hit within ``NEAR_FIELD``
    cells of the cache that faces its receiver (``_near``; ``receivers``: (K, 3) the
    receivers' normals) reflects, by its weight, one exact diffuse bounce further
    (``near_bounce_rays``) instead of the cache's light (its glossy lobes keep the cache's one
    more bounce); where that bounce lands near again, it is followed again, up to
    ``MAX_FOLLOWS`` bounces and the cache's iterations. A hit f bounces on reads the cache f
    iterations fewer (``radiance_cache.cache_levels``: bounces 2 … N in all), none once the
    path has them all. Nothing is followed where the cache keeps no earlier iterations.
    Returns the hits followed (indices into ``paths``' hits)."""
    levels = cache_levels(cache)
    if not levels:
        return np.zeros(0, np.int64)
    near = _near(cache, paths, receivers)
    if not len(near):
        return near
    index = paths.hit[near]  # the rays of ``out`` each followed path adds to
    normals = paths.normals[near]
    arriving, more = lookup(cache, paths.points[near], normals, more=True)
    out[index] = paths.radiance[index] + paths.glossy[near] * more[:, None] * arriving
    carried = paths.weight[near]
    points = paths.points[near]
    ids = np.asarray(hit_ids).astype(np.uint32)[index]
    for follow in range(1, min(MAX_FOLLOWS, cache.iterations) + 1):
        further = near_bounce_rays(normals, ids, seed)
        ids = pcg_hash(ids ^ np.uint32(CONTINUE_STREAM))  # the next hit's light-sample ids
        step = ray_paths(points + SURFACE_EPSILON * normals, further, ids, tris, lights, albedo,
                         emission, seed, (0.0, 0.0, 0.0), 1, True, None, ray)
        out[index] += carried * step.radiance
        if follow == cache.iterations or not len(step.hit):
            break  # the path holds every bounce (or left the scene)
        on = _near(cache, step, normals) if follow < MAX_FOLLOWS else np.zeros(0, np.int64)
        read = np.setdiff1d(np.arange(len(step.hit)), on)
        rays = step.hit[read]
        out[index[rays]] += carried[rays] * step.weight[read] * lookup(
            replace(cache, faces=levels[follow], ahead=()), step.points[read],
            step.normals[read])
        rays = step.hit[on]
        index, carried, ids = index[rays], carried[rays] * step.weight[on], ids[rays]
        points, normals = step.points[on], step.normals[on]
        if not len(index):
            break
    return near


def ray_radiance(origins, dirs, hit_ids, tris, lights, albedo, emission, seed: int = 0,
                 world=(0.0, 0.0, 0.0), hit_samples: int = 1, hit_glossy: bool = False,
                 emission_seen: bool | None = None, ray: int = RAY_DIFFUSE, cache=None,
                 receiver=None, near_field=None, hits=None, one_world_ray: bool = True):
    """((K, 3) radiance arriving back along each ray, (K,) distance of its nearest hit, inf on
    a miss): what a bounce ray of the gathers sees — ``world`` on a miss, else the hit's
    emission plus its exact direct light reflected toward the ray's origin (see
    ``indirect_and_ao``; ``hit_ids`` (K,) uint32 are the hits' light-sample ids). ray : the
    kind of ray (``snapshot.RAY_DIFFUSE`` / ``RAY_GLOSSY``: the triangles it sees).
    cache : a ``radiance_cache.RadianceCache`` (None: none): the hit also reflects the indirect
    light the cache holds at it (bounces beyond the first) by its diffuse weight and, taking
    that light as uniform over the hemisphere, its glossy lobes' albedo (Cycles' Glossy Color):
    the paths that bounce glossily in between (Cycles' default light paths allow 4 glossy
    bounces). A hit keeps the cache for its diffuse share; its glossy share is followed one
    reflection further instead (``metal_lobe_rays``), a metal's (Metallic ≥
    ``METAL_FOLLOWED``) always, a dielectric's by the chance ``lobe_follow_chance``: that
    hit's own light and its cache's, carried by the Glossy Color ÷ the chance
    (docs/gi_pipeline.md "Metals reflect where they point", "Where the box's regional bias comes from").
    near_field : (K, 3) the
    receivers' normals of the diffuse gather's rays (None: not it): a hit facing its receiver
    within ``NEAR_FIELD`` cells of the cache is followed one diffuse bounce further instead of
    reading the cache (``_follow_near``). hits : the rays' closest hits, traced already
    (``ray_paths``). one_world_ray : as ``ray_paths``' (the rays' own hits; the hits past
    them, a metal's reflection or the near field, draw one ray a stratum)."""
    paths = ray_paths(origins, dirs, hit_ids, tris, lights, albedo, emission, seed, world,
                      hit_samples, hit_glossy, emission_seen, ray, hits, one_world_ray)
    out = paths.with_cache(cache, receiver)
    if cache is None or not cache.iterations:
        return out, paths.distance
    near = np.zeros(0, np.int64)
    if near_field is not None and len(paths.hit):
        near = _follow_near(paths, out, hit_ids, tris, lights, albedo, emission, seed, ray,
                            cache, np.asarray(near_field, np.float64).reshape(-1, 3))
    if paths.metallic is None or not len(paths.hit):
        return out, paths.distance
    # A hit's glossy lobe does not take the cache's light as uniform: it is followed one
    # reflection further, a metal's always, a dielectric's by the chance of its glossy share
    # (docs/gi_pipeline.md "Metals reflect where they point", "Where the box's regional bias comes from")
    rest = np.setdiff1d(np.arange(len(paths.hit)), near)
    chance = lobe_follow_chance(paths)
    ids = np.asarray(hit_ids).astype(np.uint32)[paths.hit]
    followed = (chance > 0.0) & ((chance >= 1.0) | (
        unit_float(pcg_hash(ids ^ np.uint32(LOBE_FOLLOW_STREAM))) < chance))
    rays = paths.hit[rest]
    arriving, more = lookup(cache, paths.points[rest], paths.normals[rest], more=True)
    picked = 0.0 if receiver is None else \
        np.asarray(receiver, np.float64).reshape(-1)[rays][:, None]
    out[rays] = paths.radiance[rays] + (paths.weight[rest] - paths.glossy[rest]) * \
        (1.0 + picked * more[:, None]) * arriving
    lobes = rest[followed[rest]]
    if len(lobes):
        up, second = follow_metal_hits(paths, lobes, dirs, hit_ids, tris, lights, albedo,
                                       emission, seed, ray)
        if second is not None:
            carried = paths.glossy[lobes] / chance[lobes][:, None]
            out[paths.hit[lobes][up]] += carried[up] * second.with_cache(cache)
    return out, paths.distance


def lobe_follow_chance(paths: RayPaths) -> np.ndarray:
    """(H,) the chance each hit's glossy lobe is followed one reflection further
    (``ray_radiance``; bvh_shade.glsl): 1 for a metal (Metallic ≥ ``METAL_FOLLOWED``), else
    its glossy lobes' share of its weight (luminance), the followed ones carrying the lobes'
    light ÷ that chance — an estimate of what the lobe reflects where it points, without the
    uniform light the cache would give it (which read the box's back wall 2–4% bright:
    docs/gi_pipeline.md "Where the box's regional bias comes from: the hits' glossy lobes")."""
    share = (paths.glossy @ LUMINANCE) / np.maximum(paths.weight @ LUMINANCE, 1e-30)
    return np.where(paths.metallic >= METAL_FOLLOWED, 1.0, np.clip(share, 0.0, 1.0))


def gather_rays(points, normals, sample_ids, rays: int, seed: int = 0):
    """((N·rays, 3) origins, (N·rays, 3) unit directions, (N·rays,) uint32 hit sample ids) of
    the gathers' ``rays`` cosine rays per point (module doc), point by point."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    ids = np.asarray(sample_ids).reshape(-1).astype(np.uint32)
    dirs = cosine_directions(n, hammersley(ids, RAY_STREAM, rays, seed)).reshape(-1, 3)
    origins = np.repeat(p + SURFACE_EPSILON * n, rays, axis=0)
    with np.errstate(over="ignore"):
        hit_ids = ids.repeat(rays) * np.uint32(rays) + np.tile(np.arange(rays, dtype=np.uint32),
                                                              len(p))
    return origins, dirs, hit_ids


def indirect_and_ao(points, normals, sample_ids, tris, lights, albedo, emission, rays: int = 16,
                    ao_distance: float = 1.0, seed: int = 0, world=(0.0, 0.0, 0.0),
                    hit_samples: int = 1, statistics: bool = False, hit_glossy: bool = False,
                    cache=None, geometric=None, receivers=None):
    """(Diffuse Indirect (N, 3) float32, Ambient Occlusion (N,) float32) — see the module doc;
    with ``statistics`` also (N, 3) float32: the variance of the indirect light's luminance mean
    (unbiased sample variance / rays), that of the AO mean (from the share of unoccluded rays
    pulled half a ray towards ½, (k + ½)/(rays + 1), so agreeing rays still give a variance)
    and the point's reach (the harmonic mean of the rays' hit distances, a miss infinitely far,
    ``NEAREST_HIT``; 0 where no ray hits), the inputs of ``preview.denoise.atrous_filter``.

    points, normals : (N, 3) surface points and unit normals facing the viewer (metres).
    sample_ids : (N,) integer sample id per point (the pixel index, row 0 on top).
    tris : ``SceneTriangles``; lights : the snapshot's ``LightData`` list.
    albedo, emission : (M + 1, 3) per material index, the last row for triangles without one
        (``preview.material_table``). ``albedo`` may instead be the Principled pair (base
        (M + 1, 3), (metallic, Specular IOR Level, roughness) (M + 1, 3)) of
        ``preview.passes.principled_table``: a hit then reflects the diffuse weight Cycles gives
        it seen from the receiver (``principled.diffuse_weight``) and, with ``hit_glossy``, its
        glossy lobe's reflection of each light toward the receiver (the light at its centre
        direction): the path diffuse → glossy, which Cycles' light sampling at the hit keeps
        whatever the glossy bounce limit.
    cache : a ``radiance_cache.RadianceCache`` whose indirect light the hits reflect too (the
        bounces beyond the first); None: one bounce.
    geometric : (N, 3) the points' geometric normals (``surface_lookup.geometric_normals``):
        a ray below its triangle's plane carries no light — Cycles' diffuse BSDF drops such
        directions (``bsdf_diffuse_sample``) — though AO still counts it; None: every ray.
    receivers : (views (N, 3) unit directions to the viewer, materials (N,) indices) of the
        points, with ``albedo`` the Principled pair: a ray's hit reflects one more diffuse
        bounce of the cache by the chance Cycles picked its direction by the receiver's glossy
        closure (``exact_glossy.glossy_pick_chance``: a glossy pick leaves every diffuse bounce
        to come, as the glossy gather's rays); None: none.
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    ids = np.asarray(sample_ids).reshape(-1).astype(np.uint32)
    count = len(p)
    if count == 0:
        empty = (np.zeros((0, 3), np.float32), np.zeros(0, np.float32))
        return (*empty, np.zeros((0, 3), np.float32)) if statistics else empty
    origins, dirs, hit_ids = gather_rays(p, n, ids, rays, seed)
    chance = None
    if receivers is not None and cache is not None and isinstance(albedo, tuple):
        from .exact_glossy import glossy_pick_chance
        chance = glossy_pick_chance(n, receivers[0], receivers[1], albedo,
                                    dirs.reshape(count, rays, 3)).reshape(-1)
    radiance, t = ray_radiance(origins, dirs, hit_ids, tris, lights, albedo, emission, seed,
                               world, hit_samples, hit_glossy, cache=cache, receiver=chance,
                               near_field=np.repeat(n, rays, axis=0))
    if geometric is not None:
        ng = np.repeat(np.asarray(geometric, np.float64).reshape(-1, 3), rays, axis=0)
        radiance = np.where((np.einsum("ij,ij->i", dirs, ng) > 0.0)[:, None], radiance, 0.0)
    unoccluded = (t >= ao_distance).reshape(count, rays).mean(axis=1)
    per_ray = radiance.reshape(count, rays, 3)
    indirect = per_ray.mean(axis=1)
    if not statistics:
        return indirect.astype(np.float32), unoccluded.astype(np.float32)
    luminance = per_ray @ LUMINANCE
    lum_var = np.maximum((luminance ** 2).mean(axis=1) - (indirect @ LUMINANCE) ** 2, 0.0)
    share = (unoccluded * rays + 0.5) / (rays + 1.0)
    nearness = np.where(np.isfinite(t), 1.0 / np.maximum(t, NEAREST_HIT), 0.0)
    nearness = nearness.reshape(count, rays).sum(axis=1)
    reach = np.where(nearness > 0.0, rays / np.maximum(nearness, 1e-30), 0.0)
    variance = np.stack([lum_var / max(rays - 1, 1), share * (1.0 - share) / rays, reach],
                        axis=1)
    return indirect.astype(np.float32), unoccluded.astype(np.float32), variance.astype(np.float32)
