"""Emissive surfaces as a light: every triangle whose material emits, sampled by next-event
estimation like a lamp, so that their light is Diffuse Direct as in Cycles (a surface that sees
an emitter, straight or through its shadow rays, is lit directly; the gathers' bounce hits are
lit by the emitters the same way and no longer count the emission they land on).

Each emissive triangle t (world corners, radiance L_t = Emission Color × Strength in Cycles'
units, both sides emitting, as Cycles' mesh lights do) is evaluated as the area lights are
(``direct_light``):

* **Unshadowed**, exact: ``Σ_t L_t ∫_t max(n·ω, 0)/π dω`` — Lambert's formula over each
  triangle clipped to the point's horizon (``clipped_form_factors``). No noise.
* **Visible share**, per colour channel: a ratio estimator ``Σ f V / Σ f`` over m × m strata of
  the point's hashed stream (``sampling.hashed_square``, stream = the emitters' index in the
  lights list): stratum k picks a triangle by power (area × luminance, an inclusive CDF) with
  its first coordinate and a uniform point on it with the remainder and the second
  (``sample_points``); f = L cos_x cos_l / r² / p_area. Where every shadow ray is unoccluded
  the share is exactly 1.
* **At a bounce hit** (``EmitterLight.exact`` False: the full sum over every triangle at every
  hit cost the emissive room 3.7 × its preview's time) each stratum's picked triangle gives its
  own exact light, L_t FF_t / P_t (P_t its pick's chance), less its sample's f / π where the
  shadow ray is hidden: unbiased, and exact where nothing hides the emitters. The plain
  estimate f / π it replaces drew 1/r² at hits beside an emitter, rare bright rays that the
  sparse gather's spike retrace then took out of the image's light (docs/gi_pipeline.md
  "Emitters at bounce hits").

``EmitterLight`` stands in the lights list (``world_light.scene_lights``) with
``type == "EMITTERS"``; ``emitter_table`` packs it for ``render/shaders/bvh_lights.glsl``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..scene.short_axis import any_along, max_along, norm3
from ..scene.textures import sample_texture
from .world_light import hidden_less

__all__ = ["EmitterLight", "emitter_light", "emitters_direct", "unshadowed_sum", "proxy_triangles",
           "clipped_form_factors", "sample_points", "emitter_table", "EMITTER_TEXELS",
           "MAX_EMITTER_TRIANGLES"]

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
EMITTER_TEXELS = 4
# Beyond this many emissive triangles the exact per-point sum costs too much (and a GPU
# invocation's loops would pass llvmpipe's limit, docs/blender_facts.md): more are summed over
# a proxy (``proxy_triangles``: each emissive object its share of PROXY_PER_OBJECT triangles an
# object, at least PROXY_TRIANGLES and at most MAX_EMITTER_TRIANGLES in all, its vertices
# clustered, its power kept), and scenes of more than MAX_EMISSIVE_TRIANGLES keep the
# emission seen by the gathers' rays instead (emitter_light returns None).
MAX_EMITTER_TRIANGLES = 1024
PROXY_TRIANGLES = 256
PROXY_PER_OBJECT = 64  # a proxy's budget is at least this many triangles an emissive object
# (the GPU's table holds a row per triangle and per proxy triangle: 16,384 rows at most)
MAX_EMISSIVE_TRIANGLES = 16384 - MAX_EMITTER_TRIANGLES - 1
# Triangles with an emission texture are split into at most this many pieces in all (each
# emitting the texture's mean over it), at most 4^MAX_SPLIT_LEVEL per triangle.
TEXTURED_EMITTER_TRIANGLES = 512
MAX_SPLIT_LEVEL = 5
_CHUNK = 8  # emissive triangles per step of the exact sum (memory: points × 8 × 6 corners)


@dataclass(frozen=True, eq=False)
class EmitterLight:
    """corners (E, 3, 3) float64 world corners; radiance (E, 3); area (E,); cdf (E,)
    inclusive CDF of power (area × luminance); sides (E,): +1 the triangle lights the side its
    normal faces, −1 the other side, 0 both (``emitting_sides``).
    exact : the unshadowed light is the exact sum over the triangles (primary surfaces); False
    at the gathers' bounce hits, where the shadow rays' plain estimate (unbiased, noisier) is
    enough and the sum would cost most of the gather.
    margin : None, or (E,) where the triangles are a proxy of the emissive surface
    (``proxy_triangles``): how far from each triangle's plane the surface it stands in for
    lies. It lights only points further than this from its plane, so that the surface is not
    lit by its own proxy (``_facing``).
    sums : None, or the proxy (an ``EmitterLight`` with a margin) the exact sums run over, where
    the triangles are more than MAX_EMITTER_TRIANGLES (``unshadowed_sum``, ``emitter_distances``,
    the glossy light's unshadowed part); the shadow rays draw their points on the triangles
    themselves either way, so the visible share is the surface's own."""

    corners: np.ndarray
    radiance: np.ndarray
    area: np.ndarray
    cdf: np.ndarray
    sides: np.ndarray
    exact: bool = True
    type: str = "EMITTERS"
    name: str = "Emissive surfaces"
    margin: np.ndarray | None = None
    sums: EmitterLight | None = None


def emitting_sides(corners, objects) -> np.ndarray:
    """(E,) which side of each emissive triangle can light anything: an object whose emissive
    triangles close up (every edge shared by two of them) only lights its outside (+1 with
    outward normals, −1 with inward ones, by the sign of its enclosed volume) — its inside
    emission never leaves it, and counting it would double the exact sum that the shadow rays
    must then halve, noisily; an open surface (a panel) lights both sides, as Cycles' mesh
    lights do."""
    sides = np.zeros(len(corners), np.int8)
    for obj in np.unique(objects):
        members = np.flatnonzero(objects == obj)
        c = corners[members]
        keys = [tuple(sorted((tuple(c[t, i]), tuple(c[t, (i + 1) % 3])))) for t in range(len(c))
                for i in range(3)]
        _, counts = np.unique(np.array([np.concatenate(k) for k in keys]), axis=0,
                              return_counts=True)
        if len(c) < 4 or not np.all(counts == 2):
            continue
        volume = np.einsum("ij,ij->i", c[:, 0], np.cross(c[:, 1], c[:, 2])).sum()
        sides[members] = 1 if volume > 0 else -1
    return sides


def subdivision(level: int) -> np.ndarray:
    """(4^level, 3, 3) barycentric weights of the corners of a triangle's regular subdivision
    into n² = 4^level triangles (n = 2^level; row k, corner i: the weights of the triangle's
    corners 0, 1, 2)."""
    n = 1 << level
    out = []
    for i in range(n):
        for j in range(n - i):
            out.append([(i, j), (i + 1, j), (i, j + 1)])
            if i + j < n - 1:
                out.append([(i + 1, j), (i + 1, j + 1), (i, j + 1)])
    ij = np.array(out, np.float64) / n                           # (n², 3 corners, (b1, b2))
    return np.concatenate([1.0 - ij.sum(axis=-1, keepdims=True), ij], axis=-1)


def _textured_split(tris, keep, corners, radiance):
    """The kept emissive triangles with their emission per texel (``SurfaceTextures
    .emission_slots``): each textured one split into 4^L pieces (``subdivision``, one level L
    for all: the most within TEXTURED_EMITTER_TRIANGLES in all, and no finer than its texels),
    each piece emitting the texture's mean over its UV footprint (16 points at the level of
    their share of it) × the strength. Returns (corners (E', 3, 3), radiance (E', 3), index
    (E',) of the triangle among ``keep``'s each piece comes from); the untextured ones as they
    are, one piece each."""
    surface = getattr(tris, "textures", None)
    kept = np.flatnonzero(keep)
    same = (corners[kept], radiance[kept], np.arange(len(kept)))
    if surface is None or getattr(surface, "emission_slots", None) is None:
        return same
    materials = np.asarray(tris.materials)[kept]
    row = surface.row_of(materials)
    slot = surface.emission_slots[row]
    textured = slot >= 0
    if not textured.any():
        return same
    area = 0.5 * norm3(np.cross(corners[kept, 1] - corners[kept, 0],
                                corners[kept, 2] - corners[kept, 0]))
    texels = float(np.max((surface.emission_density[kept] ** 2 * area)[textured], initial=0.0))
    level = 0
    while (level < MAX_SPLIT_LEVEL and (~textured).sum() + textured.sum() * 4 ** (level + 1)
           <= TEXTURED_EMITTER_TRIANGLES and 4 ** (level + 1) <= max(texels, 1.0)):
        level += 1
    pieces = subdivision(level)                                  # (P, 3, 3)
    probes = subdivision(2)                                      # 16 points per piece
    points = probes.mean(axis=1)                                 # (16, 3) barycentrics
    out_corners, out_radiance, out_index = [same[0][~textured]], [same[1][~textured]], \
        [np.flatnonzero(~textured)]
    at = np.flatnonzero(textured)
    tri = kept[at]
    piece_corners = np.einsum("pik,tkc->tpic", pieces, corners[tri])       # (T, P, 3, 3)
    # the probes' barycentrics in the whole triangle: piece corners weighted by the probe's
    weights = np.einsum("qi,pik->pqk", points, pieces)                     # (P, 16, 3)
    uv = np.einsum("pqk,tkc->tpqc", weights, np.asarray(surface.uvs, np.float64)[tri])
    share = area[at] * surface.emission_density[tri] ** 2 / (len(pieces) * len(points))
    lod = np.repeat(0.5 * np.log2(np.maximum(share, 1.0)), len(pieces) * len(points))
    glow = np.zeros((len(at), len(pieces), 3))
    flat_uv = uv.reshape(-1, 2)
    owner = np.repeat(np.arange(len(at)), len(pieces) * len(points))
    for s in np.unique(slot[at]):
        mine = np.flatnonzero(slot[at] == s)
        rows = np.isin(owner, mine)
        value = np.maximum(sample_texture(surface.textures[s], flat_uv[rows], lod[rows]), 0.0)
        glow[mine] = value.reshape(len(mine), len(pieces), len(points), 3).mean(axis=2)
    glow *= surface.emission_strength[row[at]][:, None, None]
    out_corners.append(piece_corners.reshape(-1, 3, 3))
    out_radiance.append(glow.reshape(-1, 3))
    out_index.append(np.repeat(at, len(pieces)))
    return (np.concatenate(out_corners), np.concatenate(out_radiance),
            np.concatenate(out_index))


def emitter_light(tris, emission) -> EmitterLight | None:
    """The emissive triangles of ``tris`` (``SceneTriangles``) with ``emission`` (M + 1, 3) per
    material (``preview.passes.material_table``, the last row for none); None when nothing
    emits or more than ``MAX_EMITTER_TRIANGLES`` do. Triangles whose material has an emission
    texture are split and emit the texture per piece (``_textured_split``). float32-rounded as
    the GPU table holds them."""
    emission = np.maximum(np.nan_to_num(np.asarray(emission, np.float64)), 0.0)
    materials = np.asarray(tris.materials)
    last = len(emission) - 1
    materials = np.where((materials >= 0) & (materials < last), materials, last)
    radiance = emission[materials]
    corners = np.asarray(tris.positions, np.float64)
    area = 0.5 * norm3(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    keep = (radiance @ LUMINANCE > 0) & (area > 0) & np.isfinite(area)
    if not keep.any() or keep.sum() > MAX_EMISSIVE_TRIANGLES:
        return None
    sides = emitting_sides(corners[keep], np.asarray(tris.objects)[keep])
    corners, radiance, index = _textured_split(tris, keep, corners, radiance)
    sides = sides[index]
    lit = radiance @ LUMINANCE > 0  # pieces of a texture's black parts light nothing
    if not lit.any():
        return None
    corners, radiance, sides = corners[lit], radiance[lit], sides[lit]
    sums = None
    if len(corners) > MAX_EMITTER_TRIANGLES:
        objects = np.asarray(tris.objects)[np.flatnonzero(keep)][index][lit]
        budget = min(MAX_EMITTER_TRIANGLES,
                     max(PROXY_TRIANGLES, PROXY_PER_OBJECT * len(np.unique(objects))))
        proxy = proxy_triangles(corners, radiance, sides, budget, objects)
        if proxy is None:
            return None
        sums = _ordered(*proxy)
    light = _ordered(corners, radiance, sides)
    return light if sums is None else dataclasses.replace(light, sums=sums)


def _ordered(corners, radiance, sides, margin=None) -> EmitterLight:
    """An ``EmitterLight`` of these triangles in a canonical order, float32-rounded as the GPU
    table holds them."""
    # a canonical order (by centroid), so that the samples do not depend on the order in which
    # the meshes list their triangles
    centroid = corners.mean(axis=1)
    order = np.lexsort((centroid[:, 2], centroid[:, 1], centroid[:, 0]))
    sides = sides[order]
    margin = None if margin is None else np.asarray(margin, np.float64)[order]
    corners = corners[order].astype(np.float32).astype(np.float64)
    radiance = radiance[order].astype(np.float32).astype(np.float64)
    area = 0.5 * norm3(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    power = area * (radiance @ LUMINANCE)
    cdf = np.cumsum(power) / power.sum()
    cdf[-1] = 1.0
    return EmitterLight(corners, radiance, area.astype(np.float32).astype(np.float64),
                        cdf.astype(np.float32).astype(np.float64), sides, margin=margin)


def proxy_triangles(corners, radiance, sides, budget: int, objects=None):
    """(corners, radiance, sides, margin) of about ``budget`` triangles standing in for the
    emissive triangles ``corners`` (E, 3, 3) with ``radiance`` (E, 3), ``sides`` (E,) and
    ``objects`` (E,) (None: one object), or None where none fits. Object by object, each
    its share of the budget by its triangles (at least 4): an object within its share keeps its
    triangles, a larger one is clustered (``_clustered``). ``margin`` (P,): 1.5 × the farthest
    a source corner lies from its proxy triangle's plane (0 for a triangle kept)."""
    corners = np.asarray(corners, np.float64)
    radiance = np.asarray(radiance, np.float64)
    sides = np.asarray(sides, np.int8)
    objects = np.zeros(len(corners), np.int64) if objects is None else np.asarray(objects)
    names, objects = np.unique(objects, return_inverse=True)
    objects = objects.ravel()
    counts = np.bincount(objects, minlength=len(names))
    parts = []
    for index in range(len(names)):
        mine = np.flatnonzero(objects == index)
        share = max(4, int(budget * counts[index] / len(corners)))
        if len(mine) <= share:
            parts.append((corners[mine], radiance[mine], sides[mine], np.zeros(len(mine))))
            continue
        made = _clustered(corners[mine], radiance[mine], sides[mine], share)
        if made is None:
            return None
        parts.append(made)
    return tuple(np.concatenate(column) for column in zip(*parts))


def _clustered(corners, radiance, sides, budget: int):
    """``proxy_triangles`` of one object: vertex clustering, the corners snapped to a grid of
    the object's extent × a factor grown by a fifth until the triangles left (those whose
    corners fall in three distinct cells, one for each (cell triple, side), wound as its first
    source) fit the budget; each cluster's corners move to their mean. A proxy triangle emits
    the area-weighted mean of its sources' radiance, scaled per side and channel so that the
    proxy sends the sources' power; a side the clustering leaves no triangle keeps its
    largest. Triangles flipped by the clustering, or of no area, are dropped."""
    points = corners.reshape(-1, 3)
    low = points.min(axis=0)
    extent = max(float((points.max(axis=0) - low).max()), 1e-12)
    area = 0.5 * norm3(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]))
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    group = np.asarray(sides, np.int64) + 1
    cell = extent / 64.0
    for _ in range(80):
        q = np.floor((points - low) / cell).astype(np.int64)
        cells, vertex = np.unique(q, axis=0, return_inverse=True)
        vertex = vertex.reshape(-1, 3)
        keep = (vertex[:, 0] != vertex[:, 1]) & (vertex[:, 1] != vertex[:, 2]) & \
            (vertex[:, 0] != vertex[:, 2])
        key = np.concatenate([np.sort(vertex, axis=1), group[:, None]], axis=1)
        unique, first, owner = np.unique(key[keep], axis=0, return_index=True,
                                         return_inverse=True)
        if len(unique) + len(np.setdiff1d(group, group[keep])) <= budget:
            break
        cell *= 1.2
    else:
        return None
    owner = owner.ravel()
    mean = np.zeros((len(cells), 3))
    np.add.at(mean, vertex.ravel(), points)
    mean /= np.bincount(vertex.ravel(), minlength=len(cells))[:, None]
    source = np.flatnonzero(keep)
    proxy = mean[vertex[source[first]]]                                   # (P, 3, 3)
    weight = np.zeros(len(unique))
    glow = np.zeros((len(unique), 3))
    np.add.at(weight, owner, area[source])
    np.add.at(glow, owner, area[source, None] * radiance[source])
    glow /= np.maximum(weight, 1e-30)[:, None]
    facing = np.zeros((len(unique), 3))
    np.add.at(facing, owner, normal[source])
    made = np.cross(proxy[:, 1] - proxy[:, 0], proxy[:, 2] - proxy[:, 0])
    proxy_area = 0.5 * norm3(made)
    good = (proxy_area > 0.0) & (np.einsum("pc,pc->p", made, facing) > 0.0)
    unit = made / np.maximum(2.0 * proxy_area, 1e-300)[:, None]
    apart = np.abs(np.einsum("sic,sc->si", corners[source] - proxy[owner, 0][:, None],
                             unit[owner])).max(axis=1)
    margin = np.zeros(len(unique))
    np.maximum.at(margin, owner, apart)
    proxy, glow, proxy_area, margin = proxy[good], glow[good], proxy_area[good], 1.5 * margin[good]
    proxy_group = unique[good, 3]
    lost = np.setdiff1d(group, proxy_group)  # a side left without a triangle keeps its largest
    if len(lost):
        order = np.lexsort((-area, group))
        largest = order[np.searchsorted(group[order], lost)]
        proxy = np.concatenate([proxy, corners[largest]])
        glow = np.concatenate([glow, radiance[largest]])
        proxy_area = np.concatenate([proxy_area, area[largest]])
        margin = np.concatenate([margin, np.zeros(len(lost))])
        proxy_group = np.concatenate([proxy_group, lost])
    sent = np.zeros((3, 3))  # the sources' power, per side and channel
    np.add.at(sent, group, area[:, None] * radiance)
    made_power = np.zeros((3, 3))
    np.add.at(made_power, proxy_group, proxy_area[:, None] * glow)
    scale = np.where(made_power > 0.0, sent / np.maximum(made_power, 1e-300), 0.0)
    return proxy, glow * scale[proxy_group], (proxy_group - 1).astype(np.int8), margin


# The emitters' light as a field (``preview.upsample.EmitterField``; docs/gi_pipeline.md
# "Where a preview's time goes"): a point reads it from the gather points around it only where
# the light's direction turns by at most NEAR_STEP × its lobe's width across them (1 rad for
# the diffuse cosine lobe, 2α for a GGX lobe of α = roughness²); elsewhere — near the emitters,
# on a lobe narrow against the gather points' spacing — the per-triangle sums are evaluated at
# the point itself. The upsample's quadratic B-spline reproduces linear functions, so its error
# is second order: half the field's curvature times the taps' second moment, the root mean
# square turn τ² in units of the lobe's width. 1/r² curves by 6/d² along the ray, so a point
# emitter at distance d errs by 1.5 τ² at most; NEAR_STEP = ¼ keeps that under 10%, and on the
# emissive room (640 × 480, a gather point per 4 × 4 px) the points served are within 1% of the
# exact sums.
NEAR_STEP = 0.25


def _facing(light: EmitterLight, p, index=None) -> np.ndarray:
    """(N, E) or, with ``index`` (N, K) triangle indices, (N, K): does the triangle light the
    side of it where p is (``EmitterLight.sides``)?"""
    corners = light.corners if index is None else light.corners[index]
    sides = light.sides if index is None else light.sides[index]
    normal = np.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    if index is None:
        height = np.einsum("nc,ec->ne", p, normal) - np.einsum("ec,ec->e", corners[:, 0], normal)
    else:
        height = np.einsum("nkc,nkc->nk", p[:, None] - corners[..., 0, :], normal)
    margin = getattr(light, "margin", None)  # (the area lights' polygons have none)
    if margin is None:
        return (sides == 0) | (sides * height > 0)
    # a proxy's triangle lights only points beyond its margin from its plane (height is × |normal|)
    band = (margin if index is None else margin[index]) * norm3(normal)
    return np.where(sides == 0, np.abs(height) > band, sides * height > band)


def triangle_distances(p, corners) -> np.ndarray:
    """(N, E) distance from points p (N, 3) to the nearest point of each triangle (E, 3, 3)
    (Ericson's closest point on a triangle; GLSL: bvh_lights.glsl emitter_distance)."""
    a, b, c = (corners[None, :, i] for i in range(3))          # (1, E, 3)
    q = np.asarray(p, np.float64)[:, None]                       # (N, 1, 3)
    ab, ac, ap, bp, cp = b - a, c - a, q - a, q - b, q - c

    def dot(x, y):
        return np.einsum("...c,...c->...", x, y)

    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), dot(ab, cp), \
        dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    denom = 1.0 / np.maximum(va + vb + vc, 1e-30)
    closest = ap - ab * (vb * denom)[..., None] - ac * (vc * denom)[..., None]  # the face
    cases = [  # the first that holds, as the GLSL tests them
        ((d1 <= 0) & (d2 <= 0), ap),
        ((d3 >= 0) & (d4 <= d3), bp),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0),
         ap - np.divide(d1, d1 - d3, out=np.zeros_like(d1), where=(d1 - d3) != 0)[..., None] * ab),
        ((d6 >= 0) & (d5 <= d6), cp),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0),
         ap - np.divide(d2, d2 - d6, out=np.zeros_like(d2), where=(d2 - d6) != 0)[..., None] * ac),
        ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
         bp - np.divide(d4 - d3, (d4 - d3) + (d5 - d6), out=np.zeros_like(d4),
                        where=((d4 - d3) + (d5 - d6)) != 0)[..., None] * (c - b)),
    ]
    for holds, offset in reversed(cases):
        closest = np.where(holds[..., None], offset, closest)
    return norm3(closest)


def emitter_distances(light: EmitterLight, p, n, chunk: int = 4096) -> np.ndarray:
    """(N,) distance from points p (N, 3) with unit normals n to the nearest emissive triangle
    that can light them: one lighting their side (``_facing``) with a corner above their
    tangent plane — an emitter's own points are not near it (GLSL: bvh_lights.glsl
    emitters_distance). The preview brings the emitters' light from its gather points to a
    pixel only where they lie well inside this distance (``preview.upsample.EmitterField``)."""
    light = light.sums or light
    p = np.asarray(p, np.float64).reshape(-1, 3)
    n = np.asarray(n, np.float64).reshape(-1, 3)
    out = np.full(len(p), 1e30)
    for start in range(0, len(p), chunk):
        q, m = p[start:start + chunk], n[start:start + chunk]
        above = max_along(np.einsum("nevc,nc->nev", light.corners[None] - q[:, None, None], m))
        near = np.where((above > 0) & _facing(light, q), triangle_distances(q, light.corners),
                        1e30)
        out[start:start + chunk] = near.min(axis=1) if near.shape[1] else 1e30
    return out


def clipped_form_factors(p, n, corners) -> np.ndarray:
    """(N, E) ``∫ max(n·ω, 0)/π dω`` over each triangle (E, 3, 3) seen from points p (N, 3)
    with unit normals n (N, 3), either side: the triangle clipped to the part above the point's
    tangent plane (up to 4 corners), then Lambert's formula |Σ_edges θ_k γ_k·n| / 2π."""
    return _form_factors(corners[None] - p[:, None, None], np.asarray(n, np.float64)[:, None])


def _form_factors(rel, n) -> np.ndarray:
    """``clipped_form_factors`` of the triangles whose corners lie at ``rel`` (..., 3, 3) from
    their points, of unit normals ``n`` (broadcast against rel's (..., 3) rows)."""
    h = np.einsum("...vc,...c->...v", rel, n)                   # heights above the plane
    slots = []
    for i in range(3):  # Sutherland–Hodgman against h >= 0: v_i if above, then the crossing
        j = (i + 1) % 3
        hi, hj = h[..., i], h[..., j]
        slots.append((rel[..., i, :], hi >= 0))
        t = np.divide(hi, hi - hj, out=np.zeros_like(hi), where=(hi - hj) != 0)
        slots.append((rel[..., i, :] + t[..., None] * (rel[..., j, :] - rel[..., i, :]),
                      (hi >= 0) != (hj >= 0)))
    points = np.stack([s[0] for s in slots], axis=-2)           # (N, E, 6, 3)
    valid = np.stack([s[1] for s in slots], axis=-1)            # (N, E, 6)
    # Unused slots repeat the previous valid corner: their edges have zero length and add 0.
    index = np.where(valid, np.arange(6), -1)
    last_valid = max_along(index)[..., None]
    index = np.maximum.accumulate(index, axis=-1)
    index = np.where(index < 0, last_valid, index)
    index = np.maximum(index, 0)
    points = np.take_along_axis(points, index[..., None], axis=-2)
    length = norm3(points)[..., None]
    a = np.divide(points, length, out=np.zeros_like(points), where=length > 0)
    b = np.roll(a, -1, axis=-2)
    cross = np.cross(a, b)
    sin = norm3(cross)
    angle = np.arctan2(sin, np.einsum("...c,...c->...", a, b))
    gamma = np.divide(cross, sin[..., None], out=np.zeros_like(cross), where=sin[..., None] > 1e-12)
    total = (angle * np.einsum("...kc,...c->...k", gamma, n)).sum(axis=-1)
    out = np.abs(total) / (2.0 * math.pi)
    return np.where(any_along(valid), out, 0.0)


def sample_points(light: EmitterLight, square) -> tuple[np.ndarray, np.ndarray]:
    """(triangle index (...,), uniform point on it (..., 3)) from ``square`` (..., 2) in
    [0, 1)²: the triangle by power from the first coordinate (inverse CDF), the point from its
    remainder and the second (√-warped barycentrics)."""
    u = np.asarray(square, np.float64)
    u0, u1 = u[..., 0], u[..., 1]
    k = np.minimum(np.searchsorted(light.cdf, u0, side="right"), len(light.cdf) - 1)
    low = np.where(k > 0, light.cdf[np.maximum(k - 1, 0)], 0.0)
    r = np.clip((u0 - low) / np.maximum(light.cdf[k] - low, 1e-30), 0.0, 1.0)
    s = np.sqrt(r)
    c = light.corners[k]
    point = (1.0 - s)[..., None] * c[..., 0, :] + (s * (1.0 - u1))[..., None] * c[..., 1, :] \
        + (s * u1)[..., None] * c[..., 2, :]
    return k, point


def unshadowed_sum(light: EmitterLight, p, n) -> np.ndarray:
    """(N, 3) the exact unshadowed Diffuse Direct of the emissive triangles at points p (N, 3)
    with unit normals n: Σ_t L_t × ``clipped_form_factors`` over the triangles lighting p's
    side, O(N × triangles). The anti-aliased preview evaluates it once per pixel centre and
    again only where a sub-pixel pass sees another surface (``emitters_direct``'s
    ``unshadowed``). GLSL: emitters_unshadowed in render/shaders/bvh_lights.glsl."""
    light = light.sums or light  # a proxy where the triangles are many (``EmitterLight.sums``)
    p = np.asarray(p, np.float64).reshape(-1, 3)
    n = np.asarray(n, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3))
    facing = _facing(light, p)
    for a in range(0, len(light.corners), _CHUNK):
        factors = clipped_form_factors(p, n, light.corners[a:a + _CHUNK])
        out += (factors * facing[:, a:a + _CHUNK]) @ light.radiance[a:a + _CHUNK]
    return out


def emitters_direct(light: EmitterLight, p, n, occluded, strata, reflect=None,
                    unshadowed=None):
    """(N, 3) Diffuse Direct of the emissive triangles at points p with unit normals n (facing
    the viewer). occluded : callable(origins (M, 3), unit directions (M, 3), lengths (M,)) ->
    (M,) bool, the shadow test (None: no shadows); strata : callable(point indices) -> (N, K, 2)
    the points' hashed strata.
    unshadowed : (N, 3) the exact unshadowed sum to take for the points' (an exact light's;
    ``unshadowed_sum``, in a sub-pixel pass its pixel centre's where it sees the centre's
    surface); None: evaluated here. The visible share is the points' own either way.
    reflect : callable(point indices (M,), unit directions (M, K, 3)) -> (M, K, 3), a BSDF ×
    cos toward the light (a bounce hit's glossy lobe, ``world_light.world_direct``'s): then
    also returns the (N, 3) radiance it reflects of the emitters, the same shadow rays' plain
    estimate (mean of L V reflect |cos_l| / (r² p_area))."""
    p = np.asarray(p, np.float64)
    n = np.asarray(n, np.float64)
    if light.exact or occluded is None:
        value = unshadowed_sum(light, p, n) if unshadowed is None else \
            np.array(unshadowed, np.float64).reshape(len(p), 3)
        lit = np.flatnonzero(any_along(value > 0))
    else:  # the shadow rays' own estimate, mean of f V
        value, lit = np.ones((len(p), 3)), np.arange(len(p))
    glossy = np.zeros_like(value)
    if len(lit) == 0 or occluded is None:
        return value if reflect is None else (value, glossy)
    k, targets = sample_points(light, strata(lit))              # (M, K), (M, K, 3)
    w = targets - p[lit, None]
    r2 = np.einsum("mkc,mkc->mk", w, w)
    r = np.sqrt(r2)
    d = w / np.maximum(r, 1e-30)[..., None]
    corners = light.corners[k]
    normal = np.cross(corners[..., 1, :] - corners[..., 0, :], corners[..., 2, :] - corners[..., 0, :])
    normal /= np.maximum(norm3(normal)[..., None], 1e-30)
    cos_x = np.einsum("mkc,mc->mk", d, n[lit])
    cos_l = np.abs(np.einsum("mkc,mkc->mk", d, normal))
    pdf_area = (light.radiance[k] @ LUMINANCE) / _total_power(light)
    g = np.maximum(cos_x, 0.0) * cos_l / np.maximum(r2, 1e-30) / np.maximum(pdf_area, 1e-30)
    facing = _facing(light, p[lit], k)
    g = np.where(facing, g, 0.0)
    f = light.radiance[k] * g[..., None]
    useful = g > 0
    blocked = np.zeros(useful.shape, bool)
    if useful.any():
        origins = np.repeat(p[lit], k.shape[1], axis=0).reshape(k.shape + (3,))
        blocked[useful] = occluded(origins[useful], d[useful], r[useful])
    if reflect is not None:
        towards = np.where(facing, cos_l / np.maximum(r2, 1e-30)
                           / np.maximum(pdf_area, 1e-30), 0.0)
        shine = light.radiance[k] * towards[..., None] * reflect(lit, d)
        glossy[lit] = np.where((useful & ~blocked)[..., None], shine, 0.0).sum(axis=1) / k.shape[1]
    if not light.exact:
        # each picked triangle's exact unshadowed light (L_t FF_t over its pick's chance P_t)
        # less its sample's estimate where that is hidden (f / π): unbiased, and a point
        # beside an emitter gets the bounded FF_t instead of its samples' 1/r² (a bounce hit's
        # light; docs/gi_pipeline.md "Emitters at bounce hits")
        pick = light.area[k] * (light.radiance[k] @ LUMINANCE) / _total_power(light)
        form = _form_factors(corners - p[lit, None, None], n[lit, None])   # (M, K)
        form = np.where(facing, form, 0.0)
        exact = light.radiance[k] * (form / np.maximum(pick, 1e-30))[..., None]
        value = (exact - f * blocked[..., None] / math.pi).sum(axis=1) / k.shape[1]
        return value if reflect is None else (value, glossy)
    # a pixel's light: the difference held at 0 whatever its strata (``hidden_less``)
    value[lit] = hidden_less(value[lit], f, blocked, k.shape[1], held=True)
    return value if reflect is None else (value, glossy)


def _total_power(light: EmitterLight) -> float:
    """Σ area × luminance (p_area of a point on triangle t = luminance_t / this)."""
    return float(np.sum(light.area * (light.radiance @ LUMINANCE)))


def emitter_table(light: EmitterLight | None, stream: int = 0) -> np.ndarray:
    """(E + P + 1, EMITTER_TEXELS, 4) float32 for ``bvh_lights.glsl``: row t = (corner 0,
    radiance r), (corner 1, radiance g), (corner 2, radiance b), (inclusive power CDF, side,
    margin, 0), the E triangles, then the P of their proxy (``EmitterLight.sums``; none
    without); the last row = (E, Σ area × luminance, stream, 1 = emitters), (the first row and
    the count of the triangles the sums run over, 0, 0) — a lone header row of zeros when
    nothing emits."""
    if light is None:
        return np.zeros((1, EMITTER_TEXELS, 4), np.float32)
    count = len(light.corners)
    sums = light.sums or light
    extra = 0 if light.sums is None else len(sums.corners)
    table = np.zeros((count + extra + 1, EMITTER_TEXELS, 4))
    for first, part in ((0, light), (count, light.sums)):
        if part is None:
            continue
        rows = slice(first, first + len(part.corners))
        table[rows, :3, :3] = part.corners
        table[rows, :3, 3] = part.radiance
        table[rows, 3, 0] = part.cdf
        table[rows, 3, 1] = part.sides
        if part.margin is not None:
            table[rows, 3, 2] = part.margin
    table[-1, 0] = (count, _total_power(light), stream, 1.0)
    table[-1, 1] = (count if extra else 0, extra or count, 0.0, 0.0)
    return table.astype(np.float32)
