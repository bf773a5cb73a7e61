"""The GI preview of the scene camera as Cycles-named passes.

Primary visibility is exact (ray casting the scene's triangles); direct diffuse light is
computed per pixel with shadow rays; the indirect terms are cone-traced through the octree.
Pass meanings follow Cycles: ``Diffuse Direct`` / ``Diffuse Indirect`` are light without
albedo, ``Diffuse Color`` is the albedo, ``Combined`` = albedo × (direct + indirect) + emission
+ glossy indirect × specular colour. Background pixels are 0 in every pass.
"""
from __future__ import annotations

import dataclasses
import math
import time
import weakref
from typing import NamedTuple

import numpy as np

from ..errors import VoxGIError
from ..gi.cone_bounces import cone_octrees, fast_cache_settings
from ..gi.cone_shadows import cone_shadowed_direct
from ..gi.conetrace import (
    ConeSettings,
    trace_diffuse_and_ao,
    trace_glossy,
    trace_world_visibility,
    world_mips,
)
from ..gi.direct_light import (
    concentric_disk,
    diffuse_direct,
    emitters_unshadowed,
    light_directions,
    light_frame,
)
from ..gi.emitters import NEAR_STEP, emitter_distances
from ..gi.exact_glossy import area_shine, disc_shine, emitters_glossy_field, emitters_shine, round_lamp_disc
from ..gi.exact_indirect import LUMINANCE
from ..gi.light_injection import material_emission
from ..gi.principled import ROUGHNESS_SQ_THRESHOLD, diffuse_weight, glossy_color, glossy_reflectance
from ..gi.terminator import find_lifts
from ..gi.world_light import scene_lights, sun_lamp, sun_shadow, world_light
from ..scene.camera import DEFAULT_FILTER_WIDTH, blackman_harris, camera_frame, filter_samples
from ..scene.geometry import world_triangles
from ..scene.raycast import primary_visibility
from ..scene.short_axis import any_along, norm3
from ..scene.textures import TEXTURE_TAPS, primary_base, texel_emission
from . import transmission
from .denoise import atrous_filter
from .gather import (
    GatherSettings,
    focused,
    gather_gi,
    gather_glossy,
    gather_glossy_world,
    radiance_cache,
)
from .lobe_footprint import disc_growth, footprint_variance, lobe_roughness, normal_spread
from .resolve import combined_light, over, recoverable, resolve_samples
from .upsample import (
    STRIDES,
    EmitterField,
    field_stride,
    same_surface,
    sample_pixels,
    upsample,
    upsample_at,
)

PASS_NAMES = ("Combined", "Diffuse Direct", "Diffuse Indirect", "Diffuse Color",
              "Glossy Direct", "Glossy Indirect", "Glossy Color", "Ambient Occlusion")
SURFACE_EPSILON = 1e-4  # metres off the surface for shadow rays


def material_table(snapshot):
    """Per material index (+1 slot for 'none'): albedo (M+1, 3), roughness, specular colour,
    emission (M+1, 3)."""
    mats = snapshot.materials
    albedo = np.full((len(mats) + 1, 3), 0.8)
    rough = np.full(len(mats) + 1, 0.5)
    spec = np.full((len(mats) + 1, 3), 0.04)
    emission = np.zeros((len(mats) + 1, 3))
    for i, m in enumerate(mats):
        base = np.clip(np.nan_to_num(np.asarray(m.base_color[:3], np.float64)), 0, 1)
        albedo[i] = base * (1.0 - m.metallic)
        rough[i] = m.roughness
        spec[i] = 0.08 * m.specular * (1 - m.metallic) + base * m.metallic
        emission[i] = m.emission
    return albedo, rough, spec, emission


QUALITIES = ("ACCURATE", "FAST")


def principled_table(snapshot):
    """Per material index (+1 slot for 'none'): base colour (M+1, 3) and (metallic, Specular
    IOR Level, roughness) (M+1, 3) — the Principled BSDF parameters of ``gi.principled``."""
    mats = snapshot.materials
    base = np.full((len(mats) + 1, 3), 0.8)
    params = np.tile([0.0, 0.5, 0.5], (len(mats) + 1, 1))
    for i, m in enumerate(mats):
        base[i] = np.clip(np.nan_to_num(np.asarray(m.base_color[:3], np.float64)), 0, 1)
        given = np.array([m.metallic, m.specular, m.roughness], np.float64)
        params[i] = np.clip(np.where(np.isfinite(given), given, params[i]), 0, 1)  # NaN: default
    return base, params


AREA_GLOSSY_GRID = 4  # an area light's glossy reflection: 4 × 4 strata of it


# ``ltc_share``'s ramp, in strata that hold the lamp's reflection (the effective count of its
# AREA_GLOSSY_GRID² terms): the strata centres alone from LTC_FROM up, the LTC integral alone
# from LTC_FULL down
LTC_FROM, LTC_FULL = 15.0, 10.0


def ltc_share(terms, weights):
    """How much of an area light's glossy reflection is its LTC integral (the rest the
    AREA_GLOSSY_GRID² strata centres' sum), from the centres' terms (K, N) (each one's share of
    the irradiance × the lobe toward it, luminance) and those shares ``weights`` (K, N): by how
    many strata the reflection spreads over — the terms' effective count (Σ t)² / Σ t², over
    the shares' own (what a lobe flat over the lamp would give), × K. 0 while it spreads over
    LTC_FROM or more — a lobe wide against the strata, or the lamp in its smooth tail: the
    centres are then a quadrature without noise (a metal floor of roughness 0.8 under a 1.5 m
    lamp: 0.0021 off Cycles' Combined, the integral 0.0075, its fit's own error; the room of
    metals' floor seen near the camera, far from its highlight, 4 × closer than the integral)
    — rising to 1 (the integral alone) at LTC_FULL or fewer, where the centres' sum shows the
    lamp as dots (roughness 0.3: 0.0077 against the centres' 0.032; 0.15: 0.0062 against 0.53;
    docs/gi_pipeline.md "An area lamp's glossy light by LTC"). A point that sees no term takes
    the centres (0)."""
    def effective(values):
        values = np.asarray(values, np.float64)
        first, second = values.sum(axis=0), (values * values).sum(axis=0)
        return first * first / np.maximum(second, 1e-300), second > 0.0

    counted, seen = effective(terms)
    flat, lit = effective(weights)
    count = np.where(seen & lit, len(terms) * counted / np.maximum(flat, 1e-300), LTC_FROM)
    return np.clip((LTC_FROM - count) / (LTC_FROM - LTC_FULL), 0.0, 1.0)


# ``disc_share``'s ramp, in a round lamp's angular radius over the lobe's width (2α): its one
# direction alone up to DISC_FROM, the lobe's mean over its disc alone from DISC_FULL
DISC_FROM, DISC_FULL = 0.03, 0.1


def disc_share(alpha, angular):
    """How much of a round lamp's glossy reflection is the lobe's mean over its visible disc
    (``exact_glossy.disc_shine``; the rest its one direction's), by the disc's angular radius
    ``angular`` over the lobe's width (about 2α). On a metal floor 2.8 m from a point light
    (Combined off Cycles 1,024 spp, one direction / the disc): at a ratio of 0.03 (roughness
    0.8, a 0.1 m radius) 0.0006 / 0.0014 — the LTC's fit is the larger error; at 0.07 both
    near (0.0019 / 0.0028 at roughness 0.8, 0.0027 / 0.0016 at 0.5); from 0.1 the disc wins
    (0.0054 / 0.0024 at 0.104, 0.017 / 0.0029 at 0.19, 1.27 / 0.034 at roughness 0.1, where
    one direction draws the sphere's reflection as a pin-point; docs/gi_pipeline.md "A round
    lamp's glossy light over its disc")."""
    ratio = np.asarray(angular, np.float64) / np.maximum(2.0 * np.asarray(alpha, np.float64), 1e-6)
    return np.clip((ratio - DISC_FROM) / (DISC_FULL - DISC_FROM), 0.0, 1.0)


def _strata_centres(light, points, normals):
    """(K, N, 3) unit directions from ``points`` to the AREA_GLOSSY_GRID² strata centres of area
    light ``light``'s rectangle or ellipse (mapped as its shadow rays map theirs), (K, N) their
    weights summing to 1 (each centre's share of the unshadowed irradiance)."""
    position, x_axis, y_axis, emits = light_frame(light)
    size_y = light.size_y if light.shape in ("RECTANGLE", "ELLIPSE") else light.size
    half_x, half_y = 0.5 * light.size * x_axis, 0.5 * size_y * y_axis
    m = AREA_GLOSSY_GRID
    k = np.arange(m * m)
    square = (np.stack([k // m, k % m], axis=1) + 0.5) / m
    unit = concentric_disk(square) if light.shape in ("DISK", "ELLIPSE") else 2.0 * square - 1.0
    on_light = position + unit[:, :1] * half_x + unit[:, 1:] * half_y  # (K, 3)
    offset = on_light[:, None] - points[None]  # (K, N, 3)
    distance = np.maximum(norm3(offset), 1e-9)
    towards = offset / distance[..., None]
    receiver = np.maximum(np.einsum("knj,nj->kn", towards, normals), 0.0)
    weight = np.maximum(-(towards @ emits), 0.0) * receiver / distance ** 2  # irradiance share
    return towards, weight / np.maximum(weight.sum(axis=0, keepdims=True), 1e-30)


def glossy_direct_radiance(snapshot, points, normals, views, mat, per_light_direct, base=None,
                           rough=None, lights=None):
    """(N, 3) the glossy light the lights send to the viewer (Glossy Color × Glossy Direct),
    without noise.

    Each light's shadowed Diffuse Direct is turned back into the irradiance it brings (× π) and
    reflected toward the viewer by the Principled glossy lobe (``principled.glossy_reflectance``
    / cos): from a sun's or a point light's direction and, as far as ``disc_share`` says (a
    lobe narrow against the lamp), by the lobe's mean over the disc a sphere light or a sun
    shows (``exact_glossy.disc_shine``); from an area light's strata centres (weighted by their
    share of its irradiance) and, as far as ``ltc_share`` says (a reflection that few strata
    hold), by the lobe integrated over the lamp by LTC × the visible share of its light
    (``exact_glossy.area_shine``, as a bounce hit's metal lobe takes it). The light's
    shadowing is taken as uniform over it. views : (N, 3) unit directions from the points to
    the viewer; per_light_direct : (L, N, 3) Diffuse Direct light by light; base : (N, 3) the
    points' Base Color per texel (``scene.textures.primary_base``), None: the table's;
    rough : (N,) the pixels' lobe roughness (``lobe_footprint.lobe_roughness``: the material's
    widened by the pixel's footprint), None: the materials'. The footprint widens an area
    light's lobe, and a round lamp's disc instead (``lobe_footprint.disc_growth``: the same
    spread without a widened GGX lobe's long tails). lights : the lamps of
    ``per_light_direct`` (None: the snapshot's).
    """
    principled = principled_table(snapshot)
    own = (principled, mat)  # an area light's lobe: each point's own, widened
    grow = None
    if rough is not None:
        own = per_point_table(principled, mat, rough)
        grow = disc_growth(rough, principled[1][np.asarray(mat), 2])
    total = np.zeros((len(points), 3))
    for light, direct in zip(snapshot.lights if lights is None else lights, per_light_direct):
        (table, params), rows = own if light.type == "AREA" else (principled, mat)
        shading = (table[rows] if base is None else base, params[rows, 0], params[rows, 1],
                   params[rows, 2])
        if light.type == "AREA":
            towards, weights = _strata_centres(light, points, normals)
        else:
            towards, weights = np.stack(light_directions([light], points)), np.ones((1, len(points)))
        terms = np.zeros((len(towards), len(points), 3))
        for term, direction, weight in zip(terms, towards, weights):
            cos = np.einsum("ij,ij->i", normals, direction)
            reflect = glossy_reflectance(*shading, normals, views, direction)
            term[:] = np.where(cos[:, None] > 1e-4,
                               weight[:, None] * reflect / np.maximum(cos, 1e-4)[:, None], 0.0)
        # E·f summed over the light, with E = π × Diffuse Direct / (share-weighted cos) ≈ the
        # light's irradiance on the receiver's plane.
        shine = direct * np.pi * terms.sum(axis=0)
        if light.type == "AREA":  # the lobe over the lamp where few strata hold it
            share = ltc_share(terms @ LUMINANCE, weights)
            k = np.flatnonzero(share > 0.0)
            if len(k):
                integral = area_shine(light, direct[k], points[k], normals[k], views[k], rows[k],
                                      (table, params), None if base is None else base[k])
                shine[k] += share[k, None] * (integral - shine[k])
        elif light.type in ("POINT", "SPOT", "SUN"):  # the lobe's mean over the lamp's disc
            _, angular, valid = round_lamp_disc(light, points, grow)
            share = np.where(valid, disc_share(np.clip(params[rows, 2], 0.0, 1.0) ** 2, angular),
                             0.0)
            k = np.flatnonzero(share > 0.0)
            if len(k):
                mean = disc_shine(light, direct[k], points[k], normals[k], views[k], rows[k],
                                  (table, params), None if base is None else base[k],
                                  None if grow is None else grow[k])
                # a mirror or a view below the horizon keeps its one direction
                kept = np.all(mean == 0.0, axis=1)
                shine[k] += np.where(kept[:, None], 0.0, share[k, None] * (mean - shine[k]))
        total += shine
    return total


def map_sun_shine(snapshot, sun, points, normals, views, mat, direct, base=None, rough=None):
    """(N, 3) the glossy light the map's sun sends to the viewer (Glossy Color × its Glossy
    Direct): ``glossy_direct_radiance`` of ``sun`` (``world_light.sun_lamp``) from its own
    shadowed Diffuse Direct ``direct`` (N, 3) (traced as that lamp, stream after the scene's
    lights), 0 on a mirror, whose one reflected ray in the world's glossy gather sees the sun
    (``exact_glossy.glossy_world_direct``, which leaves it out of every other lobe). The
    pixel's lobe (``rough``) is widened by its footprint, so that a sun's reflection a fraction
    of a pixel wide on a curved surface is its pixel's average (``lobe_footprint``)."""
    shine = glossy_direct_radiance(snapshot, points, normals, views, mat, [direct], base, rough,
                                   [sun])
    material_rough = principled_table(snapshot)[1][np.asarray(mat), 2]
    return np.where((material_rough ** 4 <= ROUGHNESS_SQ_THRESHOLD)[:, None], 0.0, shine)


def per_point_table(principled, mat, rough):
    """(``principled_table`` of N rows + the last ('none'), indices (N,)): point i's material
    row with roughness ``rough[i]``, so that a function reading a lobe from (materials,
    table) reads each point's own lobe."""
    table, params = (np.asarray(a) for a in principled)
    mat = np.asarray(mat).reshape(-1)
    last = len(table) - 1
    rows = np.where((mat >= 0) & (mat < last), mat, last)
    own = params[rows].astype(np.float64)
    own[:, 2] = np.asarray(rough, np.float64).reshape(-1)
    return ((np.concatenate([table[rows], table[-1:]]), np.concatenate([own, params[-1:]])),
            np.arange(len(mat)))


def check_request(snapshot, width: int, height: int, gi_stride: int = 1,
                  quality: str = "ACCURATE") -> None:
    """Raise ``VoxGIError`` for a preview that cannot be rendered."""
    if quality not in QUALITIES:
        raise VoxGIError(f"quality must be one of {QUALITIES}, got {quality!r}")
    if gi_stride not in STRIDES:
        raise VoxGIError(f"GI resolution stride must be one of {STRIDES}, got {gi_stride}")
    if snapshot.camera is None:
        raise VoxGIError("the scene has no camera to render the preview from")
    if width < 1 or height < 1 or width * height > 16_000_000:
        raise VoxGIError(f"preview resolution {width}×{height} is out of range")


def material_indices(snapshot, material: np.ndarray) -> np.ndarray:
    """Per-pixel material indices with 'none' / out-of-range mapped to the table's last slot."""
    m = len(snapshot.materials)
    return np.where((material >= 0) & (material < m), material, m)


def shows_diffuse(snapshot) -> np.ndarray:
    """(M + 1,) bool per material index (the last: none): whether its surface shows diffuse
    light — a Diffuse Color above 0, as Cycles' Principled BSDF gives it (not a full metal,
    not black; per texel, the mean of its textures). A gather point on one that does not
    feeds the AO pass alone (``sparse_gather.ray_counts``)."""
    every = np.arange(len(snapshot.materials) + 1)
    return principled_colours(snapshot, every, np.ones(len(every)))[0].max(axis=1) > 0.0


COLOUR_BINS = 2049  # cos(view) samples of principled_colours' tables (0, 1/2048, …, 1)


def principled_colours(snapshot, mat, cos_view, base=None):
    """(Diffuse Color, Glossy Color) (N, 3) of Cycles' Principled BSDF for materials ``mat``
    (N,) seen at ``cos_view`` (N,) in [0, 1] (``gi.principled.diffuse_weight``,
    ``glossy_color``). The colours depend on the view through cos_view alone, so for more
    pixels than table entries each material is evaluated at ``COLOUR_BINS`` cosines and the
    pixels interpolate linearly: within 1e-4 of the direct evaluation, 8× faster at 640 × 480.
    base : (N, 3) the points' Base Color per texel (``scene.textures.primary_base``): points
    whose colour is not their material's are evaluated directly.
    """
    if base is not None:
        table = principled_table(snapshot)[0]
        own = np.flatnonzero(any_along(np.asarray(base) != table[np.asarray(mat)]))
        diffuse, glossy = principled_colours(snapshot, mat, cos_view)
        if len(own):
            params = principled_table(snapshot)[1][np.asarray(mat)[own]]
            args = (np.asarray(base)[own], params[:, 0], params[:, 1], params[:, 2],
                    np.asarray(cos_view, np.float64)[own])
            diffuse, glossy = np.array(diffuse, copy=True), np.array(glossy, copy=True)
            diffuse[own], glossy[own] = diffuse_weight(*args), glossy_color(*args)
        return diffuse, glossy
    base, params = principled_table(snapshot)
    mat = np.asarray(mat)
    cos_view = np.asarray(cos_view, np.float64)
    if len(mat) <= len(base) * COLOUR_BINS:
        args = (base[mat], params[mat, 0], params[mat, 1], params[mat, 2], cos_view)
        return diffuse_weight(*args), glossy_color(*args)
    grid = np.linspace(0.0, 1.0, COLOUR_BINS)
    rows = np.repeat(np.arange(len(base)), COLOUR_BINS)
    args = (base[rows], params[rows, 0], params[rows, 1], params[rows, 2],
            np.tile(grid, len(base)))
    x = cos_view * (COLOUR_BINS - 1)
    i0 = np.clip(x.astype(np.int64), 0, COLOUR_BINS - 2)
    f = (x - i0)[:, None]
    out = []
    for table in (diffuse_weight(*args), glossy_color(*args)):
        table = table.reshape(len(base), COLOUR_BINS, 3)
        out.append(table[mat, i0] * (1.0 - f) + table[mat, i0 + 1] * f)
    return tuple(out)


def compose_passes(snapshot, width, height, hit, mat, direct, indirect, ao, glossy,
                   normals=None, views=None, glossy_direct=None, glossy_world=None, base=None,
                   holdout=None):
    """The PASS_NAMES images (H, W, 3) float32 (row 0 = top) from the per-hit-pixel terms.

    hit : (H·W,) indices of the pixels that see a surface; mat : their material indices;
    direct, indirect, glossy : (N, 3) light without albedo; ao : (N,).
    normals, views : (N, 3) shading normals and unit directions to the viewer: with them
    ``Diffuse Color`` and the glossy colour are Cycles' Principled ones for that view
    (``gi.principled``), else the base colour × (1 − metallic) and a constant specular colour.
    glossy_direct : (N, 3) glossy light from the lights (already × the glossy colour), added to
    Combined as Cycles' Glossy Color × Glossy Direct.
    glossy_world : (N, 3) the world's glossy light without the glossy colour (part of Glossy
    Direct, ``gather.gather_glossy_world``).
    base : (N, 3) Base Color per texel (``scene.textures.primary_base``) or None.
    holdout : (H·W,) bool, the pixels whose camera ray met a holdout (the film's ``_holdout``),
    or None. ``Alpha`` (H, W) is 1 at the hit pixels.
    """
    albedo, _, spec, emission = material_table(snapshot)
    diffuse_colour, glossy_colour = albedo[mat], spec[mat]
    if normals is not None:
        cos_view = np.clip(np.einsum("ij,ij->i", normals, views), 0.0, 1.0)
        diffuse_colour, glossy_colour = principled_colours(snapshot, mat, cos_view, base)
    # Cycles stores a pass of light as the light over its colour, and 0 where the colour is 0
    # (per channel): a pure metal has no Diffuse Direct or Indirect.
    has_diffuse = np.asarray(diffuse_colour) > 0.0
    glossy_colour = np.broadcast_to(np.asarray(glossy_colour, np.float64), np.shape(direct))
    has_glossy = glossy_colour > 0.0
    shine = np.zeros(np.shape(direct)) if glossy_direct is None else glossy_direct
    if glossy_world is not None:
        shine = shine + glossy_colour * glossy_world
    values = {
        "Diffuse Direct": np.where(has_diffuse, direct, 0.0),
        "Diffuse Indirect": np.where(has_diffuse, indirect, 0.0),
        "Diffuse Color": diffuse_colour,
        "Glossy Direct": np.where(has_glossy, shine / np.where(has_glossy, glossy_colour, 1.0), 0.0),
        "Glossy Indirect": np.where(has_glossy, glossy, 0.0),
        "Glossy Color": glossy_colour,
        "Ambient Occlusion": np.repeat(np.asarray(ao)[:, None], 3, axis=1),
    }
    values["Combined"] = (diffuse_colour * (direct + indirect) + texel_emission(base, emission[mat])
                          + glossy_colour * glossy + shine)
    passes = {}
    for name in PASS_NAMES:
        image = np.zeros((height * width, 3), np.float32)
        image[hit] = values[name]
        passes[name] = image.reshape(height, width, 3)
    alpha = np.zeros(height * width, np.float32)
    alpha[hit] = 1.0  # the pixel centre's ray met a surface (see ``filter_coverage``)
    passes["Alpha"] = alpha.reshape(height, width)
    if holdout is not None and np.any(holdout):
        passes["_holdout"] = np.asarray(holdout, np.float32).reshape(height, width)
    return passes


AA_SIDE = 4  # the anti-aliased preview renders AA_SIDE² sub-pixel passes


# The sub-pixel passes' strata side over the pixel centres': an edge pixel's 16 passes trace 4×
# its centre's shadow rays (the hall at 640 × 480: Combined 0.10121 → 0.10003, below Cycles 16
# spp + OIDN's 0.10047, for the unresolved samples' rays; docs/gi_pipeline.md "More shadow rays
# at the edge pixels")
EDGE_STRATA = 2


def subpixel_passes(filter_width: float, light_samples: int):
    """The anti-aliased preview's passes: [(offset (x, y) in pixels, strata_block)], one per
    ``camera.filter_samples`` entry (AA_SIDE² of them, weighted by ``pass_weights``: a grid
    that one raster AA_SIDE times finer than the image draws together), each drawing a block
    of the shadow
    rays' M × M strata (``direct_light.diffuse_direct``'s strata_block) so that the passes
    together trace every stratum equally often. M = EDGE_STRATA × ⌈√light_samples⌉ (the
    pixel centres' side times EDGE_STRATA: an edge pixel's passes trace EDGE_STRATA² times a
    centre's shadow rays, where its light changes and no filter smooths it; docs/gi_pipeline.md
    "More shadow rays at the edge pixels") when it tiles the AA_SIDE × AA_SIDE passes (1, 2 or
    a multiple of AA_SIDE), else the nearest that does (6 → 8, 10 → 12, …). Pass (a, b) draws
    block (a, b) of side M / AA_SIDE, or for M < AA_SIDE stratum (a mod M, b mod M).
    filter_width ≤ 0: one pass through the pixel centres with all ⌈√light_samples⌉² strata
    (point sampling; ``centre_pass``)."""
    side = max(1, math.ceil(math.sqrt(light_samples)))
    if filter_width <= 0.0:
        return [((0.0, 0.0), (side, 0, 0, side))]
    side *= EDGE_STRATA
    if side > 2 and side % AA_SIDE:
        side = max(AA_SIDE, AA_SIDE * int(math.floor(side / AA_SIDE + 0.5)))
    out = []
    for k, offset in enumerate(filter_samples(filter_width, AA_SIDE)[0]):
        a, b = divmod(k, AA_SIDE)
        if side % AA_SIDE == 0:
            m = side // AA_SIDE
            out.append((tuple(offset), (side, a * m, b * m, m)))
        else:
            out.append((tuple(offset), (side, a % side, b % side, 1)))
    return out


def pass_weights(plan, filter_width: float) -> np.ndarray:
    """(P,) the weight of each pass of ``plan`` (``subpixel_passes``) in its pixel's sums, mean
    1: the filter's mass over the pass's cell of the grid (``camera.filter_samples``); ones for
    point sampling. A pixel's sums over the passes are Σ weight × sample, so dividing them by
    the pass count (``finish_passes``) is the filter's weighted mean. Pass (a, b) draws block
    (a, b) of the lights' strata, and the weights are symmetric in a and in b, so a light whose
    shadowed share varies linearly across its strata keeps its mean."""
    if len(plan) <= 1:
        return np.ones(len(plan))
    return filter_samples(filter_width, AA_SIDE)[1]


def subpixel_reach(plan) -> int:
    """How many pixels around a pixel's centre the sub-pixel ``plan``'s camera rays reach:
    ⌈largest |offset|⌉ (1 at any Filter Size: the offsets stay in the pixel's square; 0 for pixel
    centres alone). A ray of a pass lands between the centres of the pixels within that reach,
    so where they all see one surface, the pass's rays see it too (``edge_pixels``)."""
    largest = max((max(abs(x), abs(y)) for (x, y), _ in plan), default=0.0)
    return int(math.ceil(largest - 1e-12)) if largest > 0.0 else 0


def edge_pixels(hit, material, position, normal, reach: int) -> np.ndarray:
    """(H, W) bool: the pixels that need sub-pixel passes, from the pixel-centre G-buffer
    (hit (H, W) bool, material (H, W) int, position, normal (H, W, 3); row 0 on top). A pixel is
    an edge pixel when a pixel within ``reach`` (``subpixel_reach``; a square window) differs
    from it in coverage or material, or does not lie on the same surface: either point is off
    the other's tangent plane by more than ``upsample.PLANE_TOLERANCE`` × their distance
    (``same_surface``; depth steps and creases). Pixels within
    ``reach`` of the image border are edge pixels too (their passes' rays leave the G-buffer).
    Everything else is one smooth surface under every camera ray of the pixel: it keeps the
    pixel-centre pass with all strata. reach 0: no edge pixels. The numpy and GPU tracers both
    call this (the GPU on its read-back centre G-buffer), so they split the pixels alike."""
    hit = np.asarray(hit, bool)
    height, width = hit.shape
    edge = np.zeros((height, width), bool)
    if reach <= 0:
        return edge
    edge[:reach] = edge[-reach:] = True
    edge[:, :reach] = edge[:, -reach:] = True
    material = np.asarray(material)
    p = np.asarray(position, np.float64)
    n = np.asarray(normal, np.float64)
    for dy in range(reach + 1):
        for dx in range(-reach, reach + 1):
            if dy == 0 and dx <= 0:
                continue  # every unordered pair once
            a = (slice(0, height - dy), slice(max(0, -dx), width - max(0, dx)))
            b = (slice(dy, height), slice(max(0, dx), width - max(0, -dx)))
            differ = ~same_surface(hit[a], material[a], p[a], n[a], hit[b], material[b], p[b],
                                   n[b])
            edge[a] |= differ
            edge[b] |= differ
    return edge


def centre_pass(light_samples: int):
    """(offset, strata_block) of the edge-adaptive preview's first pass: the pixel centres
    with all strata (``subpixel_passes(0, light_samples)``), rendered at the pixels off the
    edges, which thus get exactly the point-sampled preview."""
    return subpixel_passes(0.0, light_samples)[0]


def lamp_light(diffuse_light, diffuse_colour, glossy_light, glossy_colour) -> np.ndarray:
    """(N,) the light of the lamps at N pixels for ``light_edge_pixels``, from their sums (N, 3)
    of Diffuse Color × Diffuse Direct, Diffuse Color, glossy light and Glossy Color: Diffuse
    Direct + Glossy Direct summed over the channels — the light without the surface's colours,
    so that a texture's edges under an even light are not taken for shadow edges (with the
    colours in, a tiled floor made 19% of a room's pixels light edges instead of 4%)."""
    def ratio(light, colour):
        light, colour = np.asarray(light, np.float64), np.asarray(colour, np.float64)
        return np.divide(light, colour, out=np.zeros_like(light), where=colour > 0.0)

    return (ratio(diffuse_light, diffuse_colour) + ratio(glossy_light, glossy_colour)).sum(axis=-1)


def light_edge_pixels(light, computed, reach: int, passes: int) -> np.ndarray:
    """(H, W) bool: the pixels of the edge-adaptive preview's shadow and light edges, from the
    centre pass's light of the lamps (H, W) (``lamp_light``: Diffuse Direct + Glossy Direct,
    summed over the channels; the world's and emitters' light, soft and noisier, is left out)
    at the ``computed`` pixels (H, W) bool. Cycles' pixel filter is symmetric, so
    the sub-pixel passes average a light that varies linearly across a pixel to its centre
    value; they change it where it bends. A pixel is a light edge pixel when it belongs to a
    line of three computed pixels (across, along, either diagonal) whose second difference
    exceeds 1 / ``passes`` of their largest light — more than one pass's share, what a
    shadow's edge through the window brings — or of the computed pixels' mean light, where
    that is larger: the filter over the centres (``filter_passes``) already follows a bend
    that spans pixels, and one far below the image's light (the dim tail of a glossy
    highlight, over the whole of a metal ball) moves its pixels by less than the passes'
    share of a typical pixel (docs/gi_pipeline.md "Sub-pixel passes where they
    show") — and, for reach > 1, the pixels within reach − 1 of those. reach 0: none."""
    light = np.asarray(light, np.float64)
    height, width = light.shape
    out = np.zeros((height, width), bool)
    if reach <= 0:
        return out
    # the image's mean light: a bend far below it (a glossy highlight's dim tail, a faint
    # penumbra) moves its pixels by less than a pass's share of a typical pixel's light
    mean = float(light[computed].mean()) if computed.any() else 0.0
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        ay, ax = abs(dy), abs(dx)
        middle = (slice(ay, height - ay), slice(ax, width - ax))
        before = (slice(ay - dy, height - ay - dy), slice(ax - dx, width - ax - dx))
        after = (slice(ay + dy, height - ay + dy), slice(ax + dx, width - ax + dx))
        valid = computed[before] & computed[middle] & computed[after]
        bend = np.abs(light[before] + light[after] - 2.0 * light[middle])
        top = np.maximum(np.maximum(np.maximum(light[before], light[middle]), light[after]), mean)
        bent = valid & (bend * passes > top)
        for part in (before, middle, after):
            out[part] |= bent
    grown = out.copy()
    for dy in range(-(reach - 1), reach):
        for dx in range(-(reach - 1), reach):
            grown[max(0, dy):height + min(0, dy), max(0, dx):width + min(0, dx)] |= \
                out[max(0, -dy):height + min(0, -dy), max(0, -dx):width + min(0, -dx)]
    return grown


# Accumulated sums of the sub-pixel passes (accumulate_pass, finish_passes): light passes are
# sums of light × colour, divided by the summed colour at the end, as Cycles divides its
# Diffuse/Glossy Direct/Indirect passes by Diffuse/Glossy Color (measured: a surface's edge
# pixels keep its full Diffuse Direct while their Diffuse Color falls with the coverage).
SUMS = ("emission", "coverage", "diffuse_color", "ao", "glossy_color", "diffuse_direct",
        "diffuse_indirect", "glossy_direct", "glossy_indirect", "holdout")
_SCALAR_SUMS = ("coverage", "ao", "holdout")  # (H·W,); "holdout": the rays that met a holdout


def accumulate_pass(sums, snapshot, hit, mat, normals, views, direct, indirect, ao, glossy,
                    shine, glossy_world=None, base=None):
    """Add one sub-pixel pass to ``sums`` (name of SUMS → (H·W, 3) float64, ``coverage`` and
    ``ao`` (H·W,)): hit, mat, normals, views, direct, shine as ``compose_passes`` takes them
    for this pass's camera rays; indirect, ao, glossy, glossy_world : the gathered terms at
    this pass's samples (``render_passes``: their centre's, or the gathers at their own points
    where they see another surface); base : (N, 3) Base Color per texel
    (``scene.textures.primary_base``) or None."""
    _, _, _, emission = material_table(snapshot)
    cos_view = np.clip(np.einsum("ij,ij->i", normals, views), 0.0, 1.0)
    diffuse_colour, glossy_colour = principled_colours(snapshot, mat, cos_view, base)
    light = np.asarray(shine, np.float64)
    if glossy_world is not None:
        light = light + glossy_colour * glossy_world
    for name, value in (("emission", texel_emission(base, emission[mat])), ("coverage", 1.0),
                        ("diffuse_color", diffuse_colour), ("ao", ao),
                        ("glossy_color", glossy_colour),
                        ("diffuse_direct", diffuse_colour * direct),
                        ("diffuse_indirect", diffuse_colour * indirect),
                        ("glossy_direct", light), ("glossy_indirect", glossy_colour * glossy)):
        sums[name][hit] += value


def new_sums(pixels: int):
    """Zero ``SUMS`` for ``pixels`` pixels (see ``accumulate_pass``)."""
    return {name: np.zeros(pixels if name in _SCALAR_SUMS else (pixels, 3))
            for name in SUMS}


def neighbour_weights(filter_width: float) -> np.ndarray:
    """(3, 3) share of Cycles' pixel filter (``blackman_harris`` over ± ``filter_width``,
    separable) that falls in each pixel of the 3 × 3 around a pixel's centre, relative to the
    centre pixel's share: 1 : 0.155 : 0.024 at Filter Size 1.5; zeros off the centre when
    the filter does not reach the neighbours (width ≤ 0.5)."""
    out = np.zeros((3, 3))
    out[1, 1] = 1.0
    if filter_width <= 0.5:
        return out
    x = np.linspace(-filter_width, filter_width, 4001)
    f = blackman_harris(x, filter_width)
    centre, side = f[np.abs(x) <= 0.5].sum(), f[x > 0.5].sum()
    along = np.array([side, centre, side]) / centre
    return np.outer(along, along)


def pass_tail_weights(plan, filter_width: float) -> np.ndarray:
    """(P, 3, 3) per sub-pixel pass of ``plan`` (``subpixel_passes``): the weight with which
    the pass's sample in a pixel q counts in the pixel q − e, at [ey + 1, ex + 1] for e = (ex,
    ey) (x right, y down), relative to its weight in q. Cycles samples each pixel's filter over
    its whole window, so a sample near q's border counts across it by the filter there: the
    sample at offset o lies o + e from the centre of q − e, and the offsets are drawn with
    density ∝ f inside q's square, so its weight there is f(o + e) / f(o) — scaled per e so
    that the passes' mean is ``neighbour_weights`` (a flat image stays flat). At ≤ 0.5 (the
    filter inside the pixel): the own pixel alone."""
    return tail_weights([offset for offset, _ in plan], filter_width,
                        pass_weights(plan, filter_width))


def tail_weights(offsets, filter_width: float, weights=None) -> np.ndarray:
    """(P, 3, 3) ``pass_tail_weights`` of the sub-pixel ``offsets`` (P, 2) (x right, y down)
    drawn as ``camera.filter_offsets`` draws them (weights None) or weighted as
    ``camera.filter_samples`` weighs them (weights (P,), their own pixel's); normalised over
    these offsets (the weighted mean of each neighbour's is its ``neighbour_weights``)."""
    base = neighbour_weights(filter_width)
    out = np.zeros((len(offsets), 3, 3))
    if base.sum() <= 1.0:
        out[:, 1, 1] = 1.0
        return out
    steps = np.array([-1.0, 0.0, 1.0])
    for k, (ox, oy) in enumerate(offsets):
        gx = blackman_harris(ox + steps, filter_width) / blackman_harris(ox, filter_width)
        gy = blackman_harris(oy + steps, filter_width) / blackman_harris(oy, filter_width)
        out[k] = np.outer(gy, gx)
    share = np.ones(len(out)) if weights is None else np.asarray(weights, np.float64)
    mean = np.tensordot(share, out, 1) / share.sum()
    return out * np.divide(base, mean, out=np.zeros_like(base), where=mean > 0.0)


def add_tails(tails, values, pixels, weights: np.ndarray, width: int, height: int) -> None:
    """Add one pass's samples at the flat ``pixels`` (values: name of SUMS → (N, C) or (N,)
    there) to the neighbours' ``tails`` (name → (H·W, C) or (H·W,)), by ``weights`` (3, 3)
    (``pass_tail_weights``' row for this pass): pixel p takes weights[e] × the sample of the
    pixel p + e, as ``_neighbour_sum`` does with pixel means. The readable reference of
    ``stacked_tails``, which the previews use: all passes at once."""
    y, x = np.divmod(np.asarray(pixels), width)
    for ey in (-1, 0, 1):
        for ex in (-1, 0, 1):
            w = weights[ey + 1, ex + 1]
            if (ey, ex) == (0, 0) or w == 0.0:
                continue
            ty, tx = y - ey, x - ex
            ok = (ty >= 0) & (ty < height) & (tx >= 0) & (tx < width)
            for name, value in values.items():
                tails[name][ty[ok] * width + tx[ok]] += w * np.asarray(value, np.float64)[ok]


def _resolve_view(seen, tris, height: int, width: int) -> dict:
    """A ray-cast G-buffer (``primary_visibility``'s, of ``tris``) as
    ``resolve.resolve_samples`` reads one: hit, material, position, normal, holdout, textured
    (its material has a Base Color or emission texture) as (H, W[, 3]) arrays."""
    holdout = np.zeros((height, width), bool) if seen.holdout is None else seen.holdout
    textured = np.zeros((height, width), bool)
    tex = getattr(tris, "textures", None)
    if tex is not None:
        hit = np.flatnonzero(seen.hit.ravel())
        materials = np.asarray(tris.materials)[seen.triangle.ravel()[hit]]
        row = tex.row_of(materials)
        emissive = tex.emission_slots[row] >= 0 if tex.emission_slots is not None else False
        textured.ravel()[hit] = (tex.slots[row] >= 0) | emissive
    return {"hit": seen.hit, "material": np.where(seen.hit, seen.material, -1),
            "position": seen.position, "normal": seen.normal, "holdout": holdout,
            "textured": textured}


def light_over_colours(sums):
    """(table (H·W, 24), own light (H·W,), colours_ok (H·W,) bool) of the centres' ``sums``
    for the textured samples that resolve from them (``resolve.resolve_samples``' by_light): the
    sums packed with the light passes over their colours and no colours nor emission (the
    sample's own go in, ``coloured``); the light passes over colours summed (what their spread
    test compares); whether the colours give their light back (``resolve.recoverable``)."""
    diffuse, glossy = sums["diffuse_color"], sums["glossy_color"]
    light = dict(sums)
    light["diffuse_direct"] = over(sums["diffuse_direct"], diffuse)
    light["diffuse_indirect"] = over(sums["diffuse_indirect"], diffuse)
    light["glossy_direct"] = over(sums["glossy_direct"], glossy)
    light["glossy_indirect"] = over(sums["glossy_indirect"], glossy)
    for name in ("emission", "diffuse_color", "glossy_color"):
        light[name] = np.zeros_like(sums[name])
    own = over(np.asarray(sums["diffuse_indirect"]) + sums["diffuse_direct"], diffuse) + \
        over(np.asarray(sums["glossy_indirect"]) + sums["glossy_direct"], glossy)
    return pack_sums(light), own.sum(axis=-1, dtype=np.float64), \
        recoverable(diffuse) & recoverable(glossy)


def coloured(packed, diffuse, glossy, emission) -> np.ndarray:
    """(N, 24) resolved light (``light_over_colours``' packing) coloured by the samples' own
    Diffuse and Glossy Color and emission (N, 3): the sums a shaded sample would carry."""
    out = np.array(packed, np.float64)
    values = unpack_sums(out)
    values["emission"][:] = emission
    values["diffuse_color"][:] = diffuse
    values["glossy_color"][:] = glossy
    for name, colour in (("diffuse_direct", diffuse), ("diffuse_indirect", diffuse),
                         ("glossy_direct", glossy), ("glossy_indirect", glossy)):
        values[name] *= colour
    return out


def pack_sums(values) -> np.ndarray:
    """(N, 24) float64: the SUMS (name → (N, 3) or (N,)) side by side in SUMS'
    order (``unpack_sums`` takes them apart)."""
    columns = [np.asarray(values[name], np.float64) for name in SUMS]
    return np.concatenate([c[:, None] if c.ndim == 1 else c for c in columns], axis=1)


def unpack_sums(packed: np.ndarray) -> dict:
    """name of SUMS → (N, 3) or (N,) views of a ``pack_sums`` array."""
    out, at = {}, 0
    for name in SUMS:
        if name in _SCALAR_SUMS:
            out[name], at = packed[:, at], at + 1
        else:
            out[name], at = packed[:, at:at + 3], at + 3
    return out


class Tails(NamedTuple):
    """The sub-pixel samples' filter tails in the pixels they reach (``stacked_tails``): ``at``
    (M,) the flat pixels, ascending; ``values`` name of SUMS → (M, C) or (M,) there. Only the
    listed pixels' neighbours get any: a dense image of them took 0.1–0.2 s of a 640 × 480
    preview in allocation and copies alone."""
    at: np.ndarray
    values: dict


NO_TAILS = Tails(np.zeros(0, np.int64), {})


def dense_tails(tails: dict) -> Tails:
    """The ``Tails`` of ``new_sums``-shaped tails (``add_tails``' readable form): the pixels
    where any sum is not 0."""
    rows = [np.asarray(value).reshape(len(value), -1) for value in tails.values()]
    at = np.flatnonzero(np.any(np.concatenate(rows, axis=1) != 0.0, axis=1))
    return Tails(at, {name: np.asarray(value)[at] for name, value in tails.items()})


def stacked_tails(samples: np.ndarray, weights: np.ndarray, pixels, width: int,
                  height: int) -> tuple[np.ndarray, np.ndarray]:
    """(at (M,), values (M, C) of ``samples``' dtype): the neighbours' tails of P sub-pixel
    passes' samples ``samples`` (P, N, C) — or (P, B, N, c) in B blocks of c channels, the
    values then (M, B·c), block after block — at the flat ``pixels`` (N,), pass k weighted by
    ``weights[k]`` (3, 3) (``pass_tail_weights``), at the M pixels they reach (ascending): pixel
    p takes Σ_k weights[k][e] × the pass k sample of the pixel p + e — ``add_tails`` pass by
    pass. The tails are linear in the samples, so each neighbour's weighted sum over the
    passes is one matrix product and is scattered once (docs/gi_pipeline.md "Anti-aliasing":
    8 scatters per name per pass took 2.9 of a 640 × 480 preview's 7.6 s, summing them name by
    name pass by pass another 0.2)."""
    samples = np.asarray(samples)
    if samples.ndim == 3:
        samples = samples[:, None]
    passes, blocks, count, channels = samples.shape
    weights = np.asarray(weights, np.float64).reshape(passes, 9)
    used = [k for k in range(9) if k != 4 and np.any(weights[:, k] != 0.0)]
    if not count or not used:
        return np.zeros(0, np.int64), np.zeros((0, blocks * channels), samples.dtype)
    summed = np.tensordot(weights[:, used].T.astype(samples.dtype),
                          samples.reshape(passes, -1), 1)
    summed = summed.reshape(len(used), blocks, count, channels)
    y, x = np.divmod(np.asarray(pixels), width)
    reached = []  # per neighbour: the samples whose target lies inside, and the targets
    for k in used:
        ty, tx = y - (k // 3 - 1), x - (k % 3 - 1)
        inside = np.flatnonzero((ty >= 0) & (ty < height) & (tx >= 0) & (tx < width))
        reached.append((inside, (ty * width + tx)[inside]))
    slot = np.full(width * height, -1, np.int64)  # each reached pixel's row in values
    for _, targets in reached:
        slot[targets] = 0
    at = np.flatnonzero(slot == 0)
    slot[at] = np.arange(len(at))
    values = np.zeros((len(at), blocks, channels), samples.dtype)
    for row, (inside, targets) in enumerate(reached):  # one target per sample: no collisions
        values[slot[targets]] += summed[row][:, inside].transpose(1, 0, 2)
    return at, values.reshape(len(at), blocks * channels)


def _neighbour_sum(image: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(H, W, C): Σ weights[dy + 1, dx + 1] × image[y + dy, x + dx] over the 8 neighbours
    (the centre left out; outside the image counts as 0). ``neighbour_weights`` are separable
    and symmetric (the filter's share along x times along y, 1 at the centre):
    ``_filtered_3x3`` less the centre."""
    return _filtered_3x3(image, weights[1, 0]) - image


def _window_max(image: np.ndarray) -> np.ndarray:
    """(H, W): the largest value of the (H, W) ``image`` in each pixel's 3 × 3 window."""
    padded = np.pad(image, 1)
    height, width = image.shape
    return np.max([padded[dy:dy + height, dx:dx + width] for dy in range(3) for dx in range(3)],
                  axis=0)


_LIGHTS = {"Diffuse Direct": "Diffuse Color", "Diffuse Indirect": "Diffuse Color",
           "Glossy Direct": "Glossy Color", "Glossy Indirect": "Glossy Color"}


def filter_passes(passes, filter_width: float):
    """Cycles' pixel filter over the neighbours (PASS_NAMES images (H, W, 3) → the same): each
    pixel's own passes are its square's share of the filter (the sub-pixel passes sample the
    filter inside it, ``camera.filter_samples``); the filter's tails reach the 8 neighbours'
    squares, which add their images weighted by the filter's share of each
    (``neighbour_weights``: 1 : 0.155 : 0.024 at Filter Size 1.5; nothing at ≤ 0.5). Colours,
    AO and Combined are the weighted means (a background neighbour adds 0, as to Cycles'
    film); light passes are Σ light × colour over Σ colour, as Cycles' film divides them — a
    pixel with no colour of its own (a metal beside a diffuse wall, the background beside an
    object) takes the light of the neighbours at least half covered by a coloured surface
    (their colour at least half the largest around them: that surface is at their border with
    the pixel, inside its filter; a sliver may lie beyond its reach). The film's (H, W)
    ``Alpha`` and ``_holdout`` shares, when given, are weighted means as Combined."""
    weights = neighbour_weights(filter_width)
    if weights.sum() <= 1.0:
        return passes
    height, width = passes["Combined"].shape[:2]
    norm = weights[1, 1] + _neighbour_sum(np.ones((height, width, 1)), weights)
    out = {}
    for name in ("Combined", "Diffuse Color", "Glossy Color", "Ambient Occlusion"):
        image = np.asarray(passes[name], np.float64)
        out[name] = (image + _neighbour_sum(image, weights)) / norm
    for name, colour_name in _LIGHTS.items():
        colour = np.asarray(passes[colour_name], np.float64)
        light = np.asarray(passes[name], np.float64) * colour
        amount = colour.sum(axis=-1)
        solid = (amount >= 0.5 * _window_max(amount))[..., None]
        own = colour > 0.0
        # pixels with colour: every neighbour; without: the solid ones
        top = light + np.where(own, _neighbour_sum(light, weights),
                               _neighbour_sum(np.where(solid, light, 0.0), weights))
        bottom = colour + np.where(own, _neighbour_sum(colour, weights),
                                   _neighbour_sum(np.where(solid, colour, 0.0), weights))
        out[name] = np.divide(top, bottom, out=np.zeros_like(top), where=bottom > 0.0)
    out = {name: out[name].astype(np.float32) for name in PASS_NAMES}
    for name in ("Alpha", "_holdout"):  # the film's (H, W) shares, filtered like Combined
        if name in passes:
            out[name] = filter_coverage(passes[name], filter_width)
    return out


def finish_passes(sums, count, width: int, height: int,
                  filter_width: float = DEFAULT_FILTER_WIDTH, tails=None):
    """The PASS_NAMES images (H, W, 3) float32 of ``count`` accumulated passes (an int, or
    (H·W,) per pixel: 1 off the edges, the pass count on them): per pixel, colours, AO and
    Combined are means over the passes (0 where a pass saw the background, as Cycles' film),
    light passes the light × colour over the colour (0 where that is 0); then Cycles' pixel
    filter over the neighbours — with ``tails`` (a ``Tails``, ``stacked_tails``' of the
    sub-pixel passes' samples of the pixels whose count is above 1, each pass weighted by
    its ``pass_tail_weights``), a pixel takes those pixels' samples by the filter at each
    sample's own place and the other pixels' means by their share (``filtered_sums``); without,
    every neighbour's mean by its share (``filter_passes``)."""
    count = np.broadcast_to(np.asarray(count, np.float64), (width * height,))
    per_pixel = count[:, None]
    if tails is not None:
        return filtered_sums(sums, count, tails, width, height, filter_width)

    def ratio(light, colour):
        return np.divide(light, colour, out=np.zeros_like(light), where=colour > 0.0)

    values = {
        "Combined": (sums["emission"] + sums["diffuse_direct"] + sums["diffuse_indirect"]
                     + sums["glossy_direct"] + sums["glossy_indirect"]) / per_pixel,
        "Diffuse Direct": ratio(sums["diffuse_direct"], sums["diffuse_color"]),
        "Diffuse Indirect": ratio(sums["diffuse_indirect"], sums["diffuse_color"]),
        "Diffuse Color": sums["diffuse_color"] / per_pixel,
        "Glossy Direct": ratio(sums["glossy_direct"], sums["glossy_color"]),
        "Glossy Indirect": ratio(sums["glossy_indirect"], sums["glossy_color"]),
        "Glossy Color": sums["glossy_color"] / per_pixel,
        "Ambient Occlusion": np.repeat((sums["ao"] / count)[:, None], 3, axis=1),
    }
    images = {name: values[name].reshape(height, width, 3) for name in PASS_NAMES}
    images["Alpha"] = (sums["coverage"] / count).reshape(height, width)
    if np.any(sums["holdout"]):  # the share of rays that met a holdout (preview.film)
        images["_holdout"] = (sums["holdout"] / count).reshape(height, width)
    return filter_passes(images, filter_width)


def filter_coverage(coverage: np.ndarray, filter_width: float) -> np.ndarray:
    """(H, W) or (H, W, C) float32: per-pixel means over the sub-pixel passes (the share of
    camera samples that met a surface; the world seen along them) through Cycles' pixel
    filter as ``filter_passes`` takes Combined — the film's alpha and background
    (``preview.film``)."""
    weights = neighbour_weights(filter_width)
    image = np.asarray(coverage, np.float64)
    flat = image.ndim == 2
    image = image[..., None] if flat else image
    if weights.sum() > 1.0:
        norm = weights[1, 1] + _neighbour_sum(np.ones(image.shape[:2] + (1,)), weights)
        image = (image + _neighbour_sum(image, weights)) / norm
    return (image[..., 0] if flat else image).astype(np.float32)


def _filtered_3x3(image: np.ndarray, side) -> np.ndarray:
    """(H, W, C): ``image`` + ``_neighbour_sum`` of it for separable weights 1 : side along
    each axis (``neighbour_weights``), in the image's dtype: a row pass and a column pass, the
    scaled image shifted onto the sum (no temporary per tap)."""
    side = image.dtype.type(side)
    scaled = image * side
    rows = image.copy()
    rows[:, 1:] += scaled[:, :-1]
    rows[:, :-1] += scaled[:, 1:]
    np.multiply(rows, side, out=scaled)
    out = rows
    out[1:] += scaled[:-1]
    out[:-1] += scaled[1:]
    return out


def filtered_sums(sums, count, tails: Tails, width: int, height: int, filter_width: float):
    """``finish_passes`` with the sub-pixel samples' own filter weights (``tails``): every
    sum S of a pixel p becomes S(p) / count(p) + tails(p) + Σ share(e) × S(p + e) over the
    neighbours p + e with count 1 (one pass through the centre, a smooth surface: its mean
    stands for its square); colours, AO and Combined are that over the summed weights, light
    passes Σ light × colour over Σ colour as Cycles' film divides them. A 1-pixel gap between
    two surfaces takes from each neighbour the part of its square next to the gap, not its
    mean (the mean was 3.7% off Diffuse Direct at the slot beside an emissive panel). In
    float32, as the images are (the float64 copies took 0.2 s of a 640 × 480 preview), name
    by name (each image small enough for the caches: all side by side took twice as long)."""
    weights = neighbour_weights(filter_width)
    side = np.float32(weights[1, 0])
    pixels = width * height
    count = np.asarray(count, np.float32).reshape(-1, 1)
    edge = np.flatnonzero(count > 1.0)  # their own mean, not their share of a neighbour's
    full = {}
    for name in SUMS:
        mean = np.asarray(sums[name], np.float32).reshape(pixels, -1) / count
        own = mean[edge]
        mean[edge] = 0.0
        total = _filtered_3x3(mean.reshape(height, width, -1), side).reshape(pixels, -1)
        total[edge] += own
        if len(tails.at):
            total[tails.at] += np.asarray(tails.values[name], np.float32).reshape(
                len(tails.at), -1)
        full[name] = total
    norm = _filtered_3x3(np.ones((height, width, 1), np.float32), side).reshape(-1, 1)

    def ratio(light, colour):
        return np.divide(light, colour, out=np.zeros_like(light), where=colour > 0.0)

    values = {
        "Combined": (full["emission"] + full["diffuse_direct"] + full["diffuse_indirect"]
                     + full["glossy_direct"] + full["glossy_indirect"]) / norm,
        "Diffuse Direct": ratio(full["diffuse_direct"], full["diffuse_color"]),
        "Diffuse Indirect": ratio(full["diffuse_indirect"], full["diffuse_color"]),
        "Diffuse Color": full["diffuse_color"] / norm,
        "Glossy Direct": ratio(full["glossy_direct"], full["glossy_color"]),
        "Glossy Indirect": ratio(full["glossy_indirect"], full["glossy_color"]),
        "Glossy Color": full["glossy_color"] / norm,
        "Ambient Occlusion": np.repeat(full["ao"] / norm, 3, axis=1),
    }
    passes = {name: values[name].reshape(height, width, 3).astype(np.float32, copy=False)
              for name in PASS_NAMES}
    passes["Alpha"] = (full["coverage"] / norm).reshape(height, width)
    if np.any(full["holdout"]):  # the share of rays that met a holdout (preview.film)
        passes["_holdout"] = (full["holdout"] / norm).reshape(height, width)
    return passes


def direct_light(octree, points, normals, lights, tris, cones, samples, shadows,
                 visibility=None, sample_ids=None, per_light=False, seed=0, strata_block=None,
                 unshadowed=None, views=None, world_variance=None, world_strata=None,
                 world_fewer=None, first_stream: int = 0):
    """(N, 3) Diffuse Direct at surface points: exact shadow rays against ``tris`` (shadows
    "RAYS") or one soft-shadow cone per light through ``octree`` ("CONES"; ``visibility``
    as in ``cone_shadows.cone_shadowed_direct``, the GPU tracer passes its own).
    sample_ids : the points' pixel indices: shadow rays then use the hashed strata that the
    GPU kernel ``render/shaders/bvh_direct.glsl`` draws (``direct_light.diffuse_direct``);
    seed : the strata's seed (the scene's Seed, ``GatherSettings.seed``); strata_block : one
    sub-pixel pass's block of them (``subpixel_passes``); unshadowed : the emitters' exact
    unshadowed light at the points ("RAYS"; ``emitters_unshadowed_at``), None: evaluated.
    views : (N, 3) the camera rays' unit directions to the points ("RAYS"): the shadow rays
    then leave smooth-shaded triangles as Cycles' shadow terminator offset lifts them
    (``terminator.find_lifts``, GLSL bvh_direct.glsl ``terminator_set``). world_variance :
    ("RAYS") gets the variance of the world's part (``direct_light.diffuse_direct``'s);
    world_strata, world_fewer, first_stream : ("RAYS") ``diffuse_direct``'s."""
    if shadows == "CONES":
        return cone_shadowed_direct(octree, points, normals, lights, cones, samples, visibility)
    terminator = None
    if views is not None and tris is not None and hasattr(tris, "positions"):
        terminator = find_lifts(tris, points, views, normals)
    return diffuse_direct(points + normals * SURFACE_EPSILON, normals, lights, tris,
                          samples=samples, sample_ids=sample_ids, per_light=per_light, seed=seed,
                          strata_block=strata_block, unshadowed=unshadowed,
                          terminator=terminator, world_variance=world_variance,
                          world_strata=world_strata, world_fewer=world_fewer,
                          first_stream=first_stream)


# The world light's filter spans about this share of the image's longer side: at 160 × 120 two
# passes (taps 1 and 2 pixels apart, a 13 × 13 window), at 640 × 480 four (61 × 61), the
# same part of the scene. A wider window at 160 × 120 smoothed the city's small shadows
# (docs/gi_pipeline.md "The world's light filtered", "... at every pixel")
WORLD_FILTER_SHARE = 0.08
# ... over every pixel whose estimate has any variance: no pixel is settled by the gathers'
# NOISE_TARGET. Their 2% is of indirect light, a share of a pixel's; the world's light is most
# of an open scene's pixels, and 2% grain left on the courtyards' sunlit ground was a tenth of
# their error (docs/gi_pipeline.md "The world's light filtered at every pixel")
WORLD_NOISE_TARGET = 0.0


# From this many passes (a window 4.7 times as wide as two passes' and 22 times the pixels) the
# filter averages enough pixels that a pixel centre's world rays go over a quarter fewer
# strata a side (16 -> 9 at the default 16 Light Samples): at 640 x 480 the sky courtyard's
# error stayed under Cycles 16 spp + OIDN's, where at 160 x 120 it reached it
# (docs/gi_pipeline.md "Fewer world rays where the filter is wide")
WORLD_FEWER_FROM = 4
# ... and only at the pixels that lie farther than this from the geometry's edges: the half
# width of the narrowest window the world's filter has (two passes, 13 x 13 pixels, the one
# that at 160 x 120 averages all the strata), so a pixel whose fewer rays the filter must
# average has that window on its own surface. Nearer an edge the filter, which stops at edges,
# averages fewer pixels: with the cut there the city's streets at 640 x 480 read 3% more error
# (docs/gi_pipeline.md "Fewer world rays where the filter is wide")
WORLD_FEWER_REACH = (4 * (1 << 2) - 3) // 2
# ... decided for whole blocks of this many pixels a side, the GPU kernels' work groups
# (render/gpu_shaders.py LOCAL_SIZE): llvmpipe runs a group's lanes in lock step, so a group
# whose pixels drew over both strata counts paid for both
WORLD_FEWER_BLOCK = 8
# ... and where a map's sun is traced apart, the rest of the map's rays go over fewer strata
# still, by the rest's share of the power, never below 2 × 2 (the least side at which a pixel's
# estimate of the hidden part is held at 0 or above: world_light.DIFFERENCE_STRATA). The
# rest's grain is its share of a sunlit pixel's light; the HDRI courtyard (a sun of 95% of the
# power) and the real HDRI's (57%) went from 3 × 3 to 2 × 2 strata, 5-10% of their 640 x 480
# preview, their error within 1% (docs/gi_pipeline.md "The rest of a sunny map over fewer strata")
REST_LEAST_SIDE = 2


def world_strata_side(samples: int, width: int, height: int, rest_share: float = 1.0) -> int:
    """The side of the strata of the world's map and cosine rays at a ``width`` × ``height``
    image's pixel centres, for ``samples`` Light Samples (the lamps' side ⌈√samples⌉): a
    quarter fewer (rounded down) where the world's filter has WORLD_FEWER_FROM passes or more
    (``world_filter_passes``). The map's sun keeps the lamps' strata; there the rest of the
    map, ``rest_share`` of its power (``WorldLight.rest_share``), goes over that side times its
    share (rounded up), at least REST_LEAST_SIDE: its grain over a sunlit pixel's light is then
    no more than a map without a sun has at the quarter fewer."""
    side = max(1, math.ceil(math.sqrt(samples)))
    if world_filter_passes(width, height) < WORLD_FEWER_FROM:
        return side
    fewer = side - side // 4
    return min(fewer, max(REST_LEAST_SIDE, math.ceil(fewer * rest_share - 1e-9)))


def hidden_variances(points, rays, spread: float = 0.0) -> np.ndarray:
    """(N, 2) the à-trous filter's variances (of the light's luminance, of its guide) of N gather
    points' (hidden rgb, hidden share) (N, 4) (the diffuse gather's ``bvh_gather.glsl``
    out_hidden over ``rays`` cosine rays, a count or (N,) counts): the hidden share as the
    gathers' AO is (pulled half a ray towards ½: a point whose rays all agree still admits
    neighbours within a ray's worth), the hidden light's luminance by the same binomial's
    relative variance plus the ``spread`` of the radiance the hidden rays carry
    (``rest_spread``: a hidden ray's light varies with where on the map it points, Var(L B)
    = s E[L]² (1 + c²) − s² E[L]² for a hidden share s and c² = Var(L) / E[L]², L taken
    independent of what hides it)."""
    points = np.asarray(points, np.float64)
    rays = np.maximum(np.asarray(rays, np.float64), 1.0)
    share = (points[:, 3] * rays + 0.5) / (rays + 1.0)
    luminance = points[:, :3] @ LUMINANCE
    return np.stack([luminance ** 2 * (1.0 - share + spread) / (share * rays),
                     share * (1.0 - share) / rays], axis=1)


# c² of each world's map, kept while its WorldLight lives (a key can be reused: world_light)
_SPREADS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def rest_spread(lights, sun_apart: bool) -> float:
    """c² = Var(L) / E[L]² of the luminance of the world's map over the sphere (by solid
    angle), its sun's pixels left out where ``sun_apart`` (the gathers' hidden rays leave it to
    the pixels' own, ``bvh_lights.glsl`` world_rest_radiance): how much a hidden ray's light
    varies with its direction, for ``hidden_variances``. 0 without a world or for a uniform
    one."""
    world = next((light for light in lights if light.type == "WORLD"), None)
    if world is None or world.uniform:
        return 0.0
    apart = sun_apart and world.sun is not None
    held = _SPREADS.setdefault(world, {})
    if apart not in held:
        luminance = np.asarray(world.radiance, np.float64) @ LUMINANCE
        if apart:
            luminance = np.where(luminance > world.sun.threshold, 0.0, luminance)
        rows = luminance.shape[0]
        weight = np.sin((np.arange(rows) + 0.5) * np.pi / rows)[:, None]
        total = weight.sum() * luminance.shape[1]
        mean = float((weight * luminance).sum() / total)
        square = float((weight * luminance * luminance).sum() / total)
        held[apart] = max(square / (mean * mean) - 1.0, 0.0) if mean > 0.0 else 0.0
    return held[apart]


def world_rest_share(lights) -> float:
    """``WorldLight.rest_share`` of the world among ``lights`` (1 without a world)."""
    return min((light.rest_share for light in lights if light.type == "WORLD"), default=1.0)


def world_fewer_pixels(edge, samples: int) -> np.ndarray | None:
    """(H, W) bool: the pixels whose world rays go over ``world_strata_side``'s fewer strata,
    from the image's geometric edge pixels ``edge`` (H, W) (``edge_pixels``; none when
    point-sampled): those with no edge pixel within WORLD_FEWER_REACH (a square window). None
    where no pixel's rays are cut (the filter's window is narrow, or so few Light Samples that
    a quarter fewer strata a side is as many)."""
    edge = np.asarray(edge, bool)
    height, width = edge.shape
    side = max(1, math.ceil(math.sqrt(samples)))
    if world_strata_side(samples, width, height) == side:
        return None
    reach = WORLD_FEWER_REACH
    counts = np.pad(edge.astype(np.int32), reach).cumsum(axis=0).cumsum(axis=1)
    counts = np.pad(counts, ((1, 0), (1, 0)))  # the edge pixels in each (2 reach + 1)² window
    span = 2 * reach + 1
    near = counts[span:, span:] - counts[:-span, span:] - counts[span:, :-span] + \
        counts[:-span, :-span]
    # whole blocks of the GPU's work groups, counted from the bottom row as its texels are
    block = WORLD_FEWER_BLOCK
    rows, columns = -(-height // block), -(-width // block)
    cut = np.ones((rows * block, columns * block), bool)
    cut[:height, :width] = near[::-1] == 0
    cut = cut.reshape(rows, block, columns, block).all(axis=(1, 3))
    return np.repeat(np.repeat(cut, block, axis=0), block, axis=1)[:height, :width][::-1]


def world_filter_passes(width: int, height: int) -> int:
    """The world light's filter passes for a ``width`` × ``height`` image: the fewest (at least
    two) whose window, 4 · 2^passes − 3 pixels wide, spans WORLD_FILTER_SHARE of its longer
    side."""
    passes = 2
    while 4 * (1 << passes) - 3 < WORLD_FILTER_SHARE * max(width, height):
        passes += 1
    return passes


def world_filtered(per_light, variance, lights, hit, seen) -> np.ndarray:
    """``per_light`` (L, N, 3) of a whole image's pixels ``hit`` (N,) with the world's and
    emitters' light (their sum) filtered over the image by the diffuse gather's à-trous filter
    (``denoise.atrous_filter`` on the G-buffer ``seen``, stride 1), ``variance`` (N,) the
    world's estimate's (``direct_light.diffuse_direct``'s world_variance): the world's row gets
    the filtered sum, the emitters' row 0 (GLSL: the world's and emitters' dispatch filtered,
    ``render/gpu_preview.py`` ``_world_smooth``; docs/gi_pipeline.md "The world's light
    filtered")."""
    rows = [k for k, light in enumerate(lights) if light.type in ("WORLD", "EMITTERS")]
    height, width = seen.hit.shape
    values = np.zeros((height * width, 4), np.float64)
    spread = np.zeros((height * width, 2), np.float64)
    values[hit, :3] = per_light[rows].sum(axis=0)
    spread[hit, 0] = variance
    filtered, _ = atrous_filter(values.reshape(height, width, 4), spread.reshape(height, width, 2),
                                seen.hit, seen.position, seen.normal,
                                iterations=world_filter_passes(width, height),
                                noise_target=WORLD_NOISE_TARGET)
    out = np.array(per_light, copy=True)
    out[rows] = 0.0
    out[[k for k in rows if lights[k].type == "WORLD"][0]] = filtered.reshape(-1, 4)[hit, :3]
    return out


def emitters_unshadowed_at(emitters, points, normals) -> np.ndarray:
    """(N, 3) the emitters' exact unshadowed Diffuse Direct at surface points as
    ``direct_light`` evaluates it (``direct_light.emitters_unshadowed`` at the points lifted
    by SURFACE_EPSILON; the GPU's ``gpu_bvh.emitters_unshadowed_texture``)."""
    return emitters_unshadowed(emitters, points + normals * SURFACE_EPSILON, normals)


def emitter_field(snapshot, tris, seen, materials, emitters, stride: int,
                  filter_width: float) -> EmitterField:
    """The emitters' unshadowed glossy light (``exact_glossy.emitters_glossy_field``) and
    Diffuse Direct (``emitters_unshadowed_at``) with their distance to the emitters
    (``emitters.emitter_distances``) at the gather points of ``seen`` (one per stride × stride
    block, ``upsample.sample_pixels``): the only points where their per-triangle sums are
    evaluated everywhere (docs/gi_pipeline.md "Where a preview's time goes"; the GPU's
    ``gpu_preview.emitter_fields``). materials : (H·W,) the pixels' material indices."""
    height, width = seen.hit.shape
    rows, cols = sample_pixels(height, width, stride)
    valid = seen.hit[rows][:, cols]
    cells = (rows[:, None] * width + cols[None, :])[valid]
    p = seen.position.reshape(-1, 3)[cells]
    n = seen.normal.reshape(-1, 3)[cells]
    mat = materials[cells]
    principled = principled_table(snapshot)
    base = primary_base(tris, seen, cells, principled[0][mat], snapshot.camera, width, height,
                        filter_width, TEXTURE_TAPS)  # None: untextured (the centres' G-buffer)
    glossy = np.zeros(valid.shape + (3,))
    diffuse = np.zeros(valid.shape + (3,))
    distance = np.zeros(valid.shape)
    glossy[valid] = emitters_glossy_field(p, n, -seen.direction.reshape(-1, 3)[cells], mat,
                                          principled, emitters, base)
    diffuse[valid] = emitters_unshadowed_at(emitters, p, n)
    distance[valid] = emitter_distances(emitters, p + n * SURFACE_EPSILON, n)
    eye = None if snapshot.camera.type == "ORTHO" else camera_frame(snapshot.camera)[1]
    return EmitterField(glossy, diffuse, distance, valid, seen.position, seen.normal, stride,
                        eye)


def emitters_unshadowed_held(emitters, points, normals, values, turn) -> np.ndarray:
    """(N, 3) the emitters' unshadowed Diffuse Direct at surface points: the field's
    ``values`` where its ``turn`` is within NEAR_STEP (``upsample.EmitterField``), else
    ``emitters_unshadowed_at`` the point (GLSL: bvh_direct.glsl)."""
    out = np.array(values, np.float64).reshape(-1, 3)
    turn = np.asarray(turn).reshape(-1)
    own = np.flatnonzero(~((turn >= 0.0) & (turn <= NEAR_STEP)))
    if len(own):
        out[own] = emitters_unshadowed_at(emitters, np.asarray(points)[own],
                                          np.asarray(normals)[own])
    return out


def fast_direct(octree, seen, stride, hit, lights, tris, cones, samples, shadows, lamps=0):
    """Fast quality's Diffuse Direct at the ``hit`` pixels of ``seen`` from every light
    (``world_light.scene_lights``: lamps, world, emissive triangles): (N, 3) in all and
    (lamps, N, 3) of each of the first ``lamps`` lights (the lamps, for their glossy light).
    With shadows "RAYS" as Accurate's centre pass (``direct_light``, the pixels' hashed
    strata); with "CONES" by ``cone_shadows`` — the world's visible share from the diffuse cone
    set, traced at the cones' ``stride`` and upsampled as they are (``render/gpu_fast.py`` does
    the same)."""
    p = seen.position.reshape(-1, 3)[hit]
    n = seen.normal.reshape(-1, 3)[hit]
    if shadows != "CONES":
        each = direct_light(octree, p, n, lights, tris, cones, samples, shadows, sample_ids=hit,
                            per_light=True, views=seen.direction.reshape(-1, 3)[hit])
        return each.sum(axis=0), each[:lamps]
    world = next((light for light in lights if light.type == "WORLD"), None)
    positions, normals = seen.position.reshape(-1, 3), seen.normal.reshape(-1, 3)
    seen_world = None
    if world is not None:
        sky = world_mips(world.radiance)
        seen_world = _traced(seen, stride, hit, lambda pixels: trace_world_visibility(
            octree, positions[pixels], normals[pixels], cones, sky), 4)
    each = np.zeros((lamps, len(p), 3), np.float32)
    for index in range(lamps):
        each[index] = cone_shadowed_direct(octree, p, n, lights[index:index + 1], cones, samples)
    rest = cone_shadowed_direct(octree, p, n, lights[lamps:], cones, samples,
                                world_seen=None if seen_world is None else seen_world.__getitem__)
    return each.sum(axis=0) + rest, each


def _traced(seen, stride, hit, trace, channels):
    """(N, channels) of ``trace(pixels)`` at the ``hit`` pixels (flat indices), tracing every
    pixel (stride 1) or one per stride × stride block and upsampling (``gi_upsample``)."""
    if stride == 1:
        return trace(hit)
    height, width = seen.hit.shape
    rows, cols = sample_pixels(height, width, stride)
    valid = seen.hit[rows][:, cols]
    low = np.zeros(valid.shape + (channels,), np.float32)
    low[valid] = trace((rows[:, None] * width + cols[None, :])[valid])
    full = upsample(low, valid, seen.hit, seen.position, seen.normal, stride)
    return full.reshape(-1, channels)[hit]


def render_passes(snapshot, gi_state, width: int, height: int, cones: ConeSettings,
                  light_samples: int = 16, shadows: str = "RAYS", gi_stride: int = 1,
                  quality: str = "ACCURATE", gather_settings: GatherSettings | None = None,
                  glossy_indirect: bool = True, filter_width: float = DEFAULT_FILTER_WIDTH):
    """Render the passes at ``width`` × ``height`` with the numpy tracer. ``gi_state`` (the
    voxel octree) is used by Fast quality only; Accurate may pass None.

    glossy_indirect : trace glossy reflections (exact rays in Accurate quality,
    ``gather.gather_glossy``; cones in Fast); False leaves Glossy Indirect 0, as Cycles does
    with no glossy bounces.

    quality : "ACCURATE" — exact direct light and the exact-ray final gather for Diffuse Indirect
    and AO (``gather``; ``gather_settings``, default: 64 rays, the cones' AO distance);
    "FAST" — the thesis' cone tracing through the octree for both.

    gi_stride : trace the cones (diffuse indirect light, AO, glossy) at one pixel of every
    gi_stride × gi_stride block and upsample (``gi_upsample``); 1 = every pixel.

    shadows : "RAYS" (exact shadow rays against the triangles) or "CONES" (one cone per light
    through the octree, ``cone_shadows``).

    filter_width : Cycles' pixel Filter Size (Blackman-Harris, pixels). Accurate quality
    anti-aliases with it: ``subpixel_passes`` camera passes, each with its own visibility,
    direct light, glossy light of the lamps and colours, averaged (``accumulate_pass``); the
    gathered terms (Diffuse Indirect, AO, Glossy Indirect, the world's glossy light: the
    gathers upsampled to the pixel centres) come from the pixel centres, and so do the
    emitters' glossy light and the unshadowed sum of their Diffuse Direct — read there from
    their field, evaluated at the gather points (``emitter_field``) — except in the passes that
    see another surface than their pixel's centre (``same_surface``), which read the gathers
    (``upsample.upsample_at``) and the field at their own points (the shadow rays are each
    pass's own). ≤ 0, or Fast quality: pixel centres only.

    Returns (passes, timings): passes maps each name of PASS_NAMES to an (H, W, 3) float32
    image (row 0 = top); timings maps stage names to seconds.
    """
    check_request(snapshot, width, height, gi_stride, quality)
    t0 = time.perf_counter()
    tris = world_triangles(snapshot)
    if len(tris) == 0:
        raise VoxGIError("the scene has no triangles to render")
    layer = (gi_state, width, height, cones, light_samples, shadows, gi_stride, quality,
             gather_settings, glossy_indirect, filter_width)
    front, timings = _render_layer(snapshot, tris, tris, *layer)
    timings["visibility"] += time.perf_counter() - t0
    glass = transmission.glass_materials(snapshot, tris)
    if glass is None:
        return front, timings
    # glass in view: what is behind it, seen through it (preview.transmission)
    t0 = time.perf_counter()

    def hits_at(offset):
        seen = primary_visibility(tris, snapshot.camera, width, height, offset)
        return seen.material, np.einsum("hwi,hwi->hw", seen.normal, seen.direction)

    from .film import background
    sampled = filter_width if quality == "ACCURATE" else 0.0  # Fast: pixel centres
    weight = transmission.glass_weight(snapshot.materials, hits_at, width, height, sampled)
    behind, _ = _render_layer(snapshot, tris, transmission.behind_glass(tris, glass), *layer,
                              only=transmission.behind_pixels(weight))
    world = background(snapshot.world, snapshot.camera, width, height, sampled)
    timings["behind glass"] = time.perf_counter() - t0
    return transmission.composite(front, behind, weight, world), timings


def _render_layer(snapshot, tris, camera_tris, gi_state, width, height, cones, light_samples,
                  shadows, gi_stride, quality, gather_settings, glossy_indirect, filter_width,
                  only=None):
    """``render_passes`` of one layer: camera rays see ``camera_tris`` (``tris``, or them with
    glass hidden from the camera: ``transmission.behind_glass``), every other ray ``tris``;
    only : (H, W) bool the pixels to shade (None: all; the others as background)."""
    if quality == "ACCURATE":
        shadows = "RAYS"
    gather_settings = gather_settings or GatherSettings(ao_distance=cones.ao_distance)
    if quality == "ACCURATE":  # the radiance cache nests finer grids around the camera
        gather_settings = focused(gather_settings, snapshot.camera, tris,
                                  material_emission(snapshot))
    timings = {}
    t0 = time.perf_counter()
    seen = primary_visibility(camera_tris, snapshot.camera, width, height)
    if only is not None:
        seen = dataclasses.replace(seen, hit=seen.hit & only)
    hit = np.flatnonzero(seen.hit.ravel())
    dirs = seen.direction.reshape(-1, 3)
    timings["visibility"] = time.perf_counter() - t0

    _, rough, _, _ = material_table(snapshot)
    materials = material_indices(snapshot, seen.material.ravel())
    mat = materials[hit]
    # the lobes evaluated per pixel (the lamps' glossy light, Fast's glossy cones) widened by
    # the pixel's footprint (lobe_footprint; GPU: the G-buffer's normal.w)
    lobe = lobe_roughness(principled_table(snapshot)[1][materials, 2], normal_spread(camera_tris, snapshot.camera, seen,
                                                          width, height).ravel(),
                          footprint_variance(filter_width if quality == "ACCURATE"
                                             else DEFAULT_FILTER_WIDTH))

    # the lamps, then the world and the emissive triangles
    lights = scene_lights(snapshot, tris, material_table(snapshot)[3])
    if quality != "ACCURATE":  # Accurate: per sub-pixel pass, below
        # the octree each kind of cone reads (Cycles' ray visibility), with Bounces > 1 the
        # voxels also reflecting the radiance cache's light (gi/cone_bounces.py)
        t0 = time.perf_counter()
        octrees = cone_octrees(gi_state, radiance_cache(tris, lights, principled_table(snapshot),
                                                        material_table(snapshot)[3],
                                                        fast_cache_settings(gather_settings,
                                                                            tris)))
        timings["radiance cache"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        direct, per_lamp = fast_direct(octrees["shadow"], seen, gi_stride, hit,
                                       lights, tris, cones, light_samples, shadows,
                                       len(snapshot.lights))
        timings["direct"] = time.perf_counter() - t0
    positions, normals = seen.position.reshape(-1, 3), seen.normal.reshape(-1, 3)

    def diffuse_and_ao(pixels):
        indirect, ao = trace_diffuse_and_ao(octrees["diffuse"], positions[pixels],
                                            normals[pixels], cones)
        return np.concatenate([indirect, ao[:, None]], axis=1)

    def glossy_cones(pixels):  # Fast: the cones see the world where they leave the voxels
        return trace_glossy(octrees["glossy"], positions[pixels], normals[pixels],
                            dirs[pixels], lobe[pixels], cones,
                            world_mips(getattr(snapshot.world, "radiance", None)))

    t0 = time.perf_counter()
    low = {}  # Accurate: the gather points' filtered values (upsample_at reads them)

    def upsampled(values_valid, channels):  # the gather points' values at every centre
        return upsample(*values_valid, seen.hit, seen.position, seen.normal,
                        gi_stride)[..., :channels].reshape(-1, channels)[hit]

    if quality == "ACCURATE":
        _, _, _, emission = material_table(snapshot)
        shown = shows_diffuse(snapshot)[material_indices(snapshot, seen.material)] & seen.hit
        low["diffuse"] = gather_gi(tris, lights, principled_table(snapshot), emission, seen.hit,
                                   seen.position, seen.normal, gather_settings, gi_stride,
                                   seen.direction, low=True, shown=shown,
                                   material=materials.reshape(height, width))
        traced = upsampled(low["diffuse"], 4)
        timings["diffuse+ao gather"] = time.perf_counter() - t0
    else:
        traced = _traced(seen, gi_stride, hit, diffuse_and_ao, 4)
        timings["diffuse+ao cones"] = time.perf_counter() - t0
    indirect, ao = traced[:, :3], traced[:, 3]
    t0 = time.perf_counter()
    if glossy_indirect and quality == "ACCURATE":
        low["glossy"] = gather_glossy(tris, lights, principled_table(snapshot), emission,
                                      seen.hit, seen.position, seen.normal, seen.direction,
                                      materials.reshape(height, width), gather_settings,
                                      gi_stride, low=True, shown=shown)
        glossy = upsampled(low["glossy"], 3)
        timings["glossy gather"] = time.perf_counter() - t0
    elif glossy_indirect:
        glossy = _traced(seen, gi_stride, hit, glossy_cones, 3)
        timings["glossy cones"] = time.perf_counter() - t0
    else:
        glossy = np.zeros((len(hit), 3))
    if quality != "ACCURATE":  # the lamps' glossy light (the cones see the rest), colours
        p, n, views = positions[hit], normals[hit], -dirs[hit]  # for the view as Cycles'
        base = primary_base(tris, seen, hit, principled_table(snapshot)[0][mat],
                            snapshot.camera, width, height)  # None: untextured
        shine = glossy_direct_radiance(snapshot, p, n, views, mat, per_lamp, base, lobe[hit])
        return compose_passes(snapshot, width, height, hit, mat, direct, indirect, ao,
                              glossy, n, views, shine, base=base,
                              holdout=None if seen.holdout is None else seen.holdout.ravel()), \
            timings
    t0 = time.perf_counter()
    emitting = any(light.type == "EMITTERS" for light in lights)
    emitters = next((light for light in lights if light.type == "EMITTERS"), None)
    sun = sun_lamp(world_light(snapshot.world))  # the map's sun: each pixel's lobe takes it
    low["world"] = gather_glossy_world(tris, world_light(snapshot.world),
                                       principled_table(snapshot), seen.hit, seen.position,
                                       seen.normal, seen.direction,
                                       materials.reshape(height, width), gather_settings,
                                       gi_stride, emission if emitting else None, low=True)
    glossy_world = np.zeros((height * width, 3))
    glossy_world[hit] = upsampled(low["world"], 3)
    valid = low["diffuse"][1]
    # the gather points' (Diffuse Indirect, AO), Glossy Indirect and world glossy light, for
    # the sub-pixel samples that see another surface than their centre (upsample_at)
    gathered = [low["diffuse"][0], low.get("glossy", (np.zeros_like(low["diffuse"][0]),))[0],
                low["world"][0]]
    timings["world glossy gather"] = time.perf_counter() - t0
    centre_glow = np.zeros((height * width, 3))
    centre_unshadowed = np.zeros((height * width, 3))
    if emitters is not None:
        # the emitters' unshadowed glossy light and Diffuse Direct at the field's points, read
        # at the centres (evaluated where the field does not hold: near the emitters), the
        # glossy light with each centre's own visible share
        t0 = time.perf_counter()
        field = emitter_field(snapshot, tris, seen, materials, emitters,
                              field_stride(gi_stride), filter_width)
        glossy_field, glossy_turn, diffuse_field, diffuse_turn = field.at_centres(hit)
        timings["emitters' light field"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        centre_glow[hit] = emitters_shine(
            positions[hit], normals[hit], -dirs[hit], mat, hit, tris, principled_table(snapshot),
            emitters, gather_settings.glossy_rays, gather_settings.seed,
            primary_base(tris, seen, hit, principled_table(snapshot)[0][mat], snapshot.camera,
                         width, height, filter_width, TEXTURE_TAPS),
            field=(glossy_field, glossy_turn))
        timings["emitters' glossy light"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        centre_unshadowed[hit] = emitters_unshadowed_held(emitters, positions[hit], normals[hit],
                                                          diffuse_field, diffuse_turn)
        timings["emitters' unshadowed light"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    def centre(values, channels):  # the gathered terms over every pixel (0 off the centre hits)
        out = np.zeros((height * width, channels))
        out[hit] = np.asarray(values).reshape(len(hit), channels)
        return out

    indirect, ao, glossy = centre(indirect, 3), centre(ao, 1)[:, 0], centre(glossy, 3)
    sums = new_sums(height * width)
    plan = subpixel_passes(filter_width, light_samples)
    reach = subpixel_reach(plan)
    edge = edge_pixels(seen.hit, materials.reshape(height, width), seen.position, seen.normal,
                       reach).ravel()
    centre_seen = seen

    def shade(seen, pixels, block, lamps=None, into=None, offset=(0.0, 0.0), taps=1, share=1):
        """Add one pass at ``pixels`` (H·W,) bool to ``into`` (the sums if None); lamps : gets
        the lamps' light there; offset : the pass's (``subpixel_passes``); taps, share :
        ``primary_base``'s (the centre pass's taps stand for the whole pixel; a sub-pixel pass
        is one of AA_SIDE² samples)."""
        hit = np.flatnonzero(seen.hit.ravel() & pixels)
        p = seen.position.reshape(-1, 3)[hit]
        n = seen.normal.reshape(-1, 3)[hit]
        mat = material_indices(snapshot, seen.material.ravel())[hit]
        views = -seen.direction.reshape(-1, 3)[hit]
        base = primary_base(tris, seen, hit, principled_table(snapshot)[0][mat],
                            snapshot.camera, width, height, filter_width,
                            taps, share)  # None: untextured
        # The gathered terms and the emitters' glossy light and unshadowed Diffuse Direct:
        # the centre's where this pass sees the surface its pixel's centre sees, else the
        # gathers and the field at the pass's own points (a silhouette's samples that see the
        # wall behind; a 1-pixel slot between a ceiling and a panel under it), the centre's
        # terms where no gather point fits (docs/gi_pipeline.md "Anti-aliasing")
        terms = [indirect[hit], ao[hit], glossy[hit], glossy_world[hit]]
        other = np.zeros(0, np.int64)
        if seen is not centre_seen:  # (materials, positions, normals: the centre's)
            other = np.flatnonzero(~same_surface(
                True, mat, p, n, centre_seen.hit.ravel()[hit], materials[hit],
                positions[hit], normals[hit]))
        rows, cols = np.divmod(hit[other], width)
        if len(other):
            (di_ao, gl, world), fits = upsample_at(
                gathered, valid, centre_seen.position, centre_seen.normal, gi_stride, rows,
                cols, p[other], n[other], offset)
            own = other[fits]
            for k, value in enumerate((di_ao[fits, :3], di_ao[fits, 3], gl[fits, :3],
                                       world[fits, :3])):
                terms[k] = terms[k].copy()
                terms[k][own] = value
        glow, unshadowed = centre_glow[hit], None
        if emitters is not None:
            glossy_at, glossy_turn, diffuse_at, diffuse_turn = field.at(
                rows, cols, p[other], n[other], offset)
            glow[other] = emitters_shine(
                p[other], n[other], views[other], mat[other], hit[other], tris,
                principled_table(snapshot), emitters, gather_settings.glossy_rays,
                gather_settings.seed, None if base is None else base[other],
                field=(glossy_at, glossy_turn))
            unshadowed = centre_unshadowed[hit]
            unshadowed[other] = emitters_unshadowed_held(emitters, p[other], n[other],
                                                         diffuse_at, diffuse_turn)
        # (the shadow rays are the pass's own: its block of the strata)
        # the centre pass's world light is filtered over the image (F12's; the GPU's
        # _world_smooth), from the variance of its estimate
        variance = np.zeros(len(hit)) if seen is centre_seen and shadows == "RAYS" and \
            any(light.type == "WORLD" for light in lights) else None
        # (and its rays go over world_strata_side's strata where the filter's window is wide
        # and on one surface: world_fewer_pixels)
        fewer = None if variance is None else world_fewer_pixels(edge.reshape(height, width),
                                                                 light_samples)
        per_light = direct_light(None, p, n, lights, tris, cones, light_samples, shadows,
                                 sample_ids=hit, per_light=True, seed=gather_settings.seed,
                                 strata_block=block, unshadowed=unshadowed, views=-views,
                                 world_variance=variance,
                                 world_strata=None if fewer is None else world_strata_side(
                                     light_samples, width, height, world_rest_share(lights)),
                                 world_fewer=None if fewer is None else fewer.ravel()[hit])
        if variance is not None:
            per_light = world_filtered(per_light, variance, lights, hit, seen)
        own_lobe = lobe[hit] if seen is centre_seen else lobe_roughness(
            principled_table(snapshot)[1][mat, 2],
            normal_spread(camera_tris, snapshot.camera, seen, width, height, offset).ravel()[hit],
            footprint_variance(filter_width, share))
        shine = glossy_direct_radiance(snapshot, p, n, views, mat,
                                       per_light[:len(snapshot.lights)], base, own_lobe)
        if sun is not None:  # the map's sun in the pixel's lobe, traced as a lamp
            sun_direct = direct_light(None, p, n, [sun_shadow(sun)], tris, cones, light_samples,
                                      shadows, sample_ids=hit, per_light=True, seed=gather_settings.seed,
                                      strata_block=block, views=-views,
                                      first_stream=len(lights))[0]
            glow = glow + map_sun_shine(snapshot, sun, p, n, views, mat, sun_direct, base,
                                        own_lobe)
        accumulate_pass(sums if into is None else into, snapshot, hit, mat, n, views,
                        per_light.sum(axis=0), terms[0], terms[1], terms[2], shine + glow,
                        terms[3], base)
        if seen.holdout is not None:  # the film's alpha: these rays show nothing, not the world
            (sums if into is None else into)["holdout"][seen.holdout.ravel() & pixels] += 1.0
        if lamps is not None:  # the lamps' light as the GPU's sums hold it after the lamps
            only = new_sums(height * width)
            accumulate_pass(only, snapshot, hit, mat, n, views,
                            per_light[:len(snapshot.lights)].sum(axis=0), terms[0], terms[1],
                            terms[2], shine, terms[3], base)
            lamps["light"] = lamp_light(only["diffuse_direct"], only["diffuse_color"],
                                        only["glossy_direct"], only["glossy_color"])

    def own_colours(seen, pixels):
        """(Diffuse Color, Glossy Color, emission) (N, 3) of a sub-pixel pass's samples at the
        flat ``pixels`` (each a hit), by their own texels (``accumulate_pass``'s)."""
        mat = material_indices(snapshot, seen.material.ravel())[pixels]
        n = seen.normal.reshape(-1, 3)[pixels]
        views = -seen.direction.reshape(-1, 3)[pixels]
        base = primary_base(tris, seen, pixels, principled_table(snapshot)[0][mat],
                            snapshot.camera, width, height, filter_width, 1, AA_SIDE)
        cos_view = np.clip(np.einsum("ij,ij->i", n, views), 0.0, 1.0)
        diffuse, glossy = principled_colours(snapshot, mat, cos_view, base)
        return diffuse, glossy, texel_emission(base, material_table(snapshot)[3][mat])

    # The centre pass over every pixel, then its shadow and light edges join the geometry's
    # and the sub-pixel passes render all edges: each sample takes the centres' sums around
    # it where they see its surface and their light is smooth (resolve.resolve_samples), the
    # others are shaded. The edge pixels' centre sums are what the samples resolve from.
    lamps = {}
    shade(centre_seen, np.ones(height * width, bool), centre_pass(light_samples)[1], lamps,
          taps=TEXTURE_TAPS)
    lit = light_edge_pixels(lamps["light"].reshape(height, width),
                            centre_seen.hit & ~edge.reshape(height, width), reach,
                            len(plan)).ravel()
    edge |= lit
    # Each sub-pixel pass's samples count in the neighbours by the filter at their own place.
    tails = NO_TAILS
    listed = np.flatnonzero(edge)
    if len(listed):
        table, light = pack_sums(sums), combined_light(sums)
        # what a textured sample resolves from: the centres' light over their colours
        light_table, own_light, colours_ok = light_over_colours(sums)
        for values in sums.values():
            values[edge] = 0.0
        centres = _resolve_view(centre_seen, tris, height, width)
        samples = []
        for (offset, block), weight in zip(plan, pass_weights(plan, filter_width)):
            one = new_sums(height * width)
            seen_pass = primary_visibility(camera_tris, snapshot.camera, width, height, offset)
            at = _resolve_view(seen_pass, tris, height, width)
            resolved, packed = resolve_samples(
                centres, light, table, listed, width, height, offset,
                {key: value.reshape(height * width, -1)[listed].squeeze(-1)
                 if value.ndim == 2 else value.reshape(height * width, 3)[listed]
                 for key, value in at.items()},
                light_values=light_table, own_light=own_light, colours_ok=colours_ok)
            # a textured sample's light, coloured by its own colours and emission
            mine = np.flatnonzero(resolved & at["textured"].ravel()[listed] &
                                  seen_pass.hit.ravel()[listed])
            if len(mine):
                packed[mine] = coloured(packed[mine], *own_colours(seen_pass, listed[mine]))
            left = np.zeros(height * width, bool)
            left[listed[~resolved]] = True
            shade(seen_pass, left, block, into=one, offset=offset, share=AA_SIDE)
            packed[~resolved] = pack_sums({name: one[name][listed[~resolved]] for name in SUMS})
            for name, value in unpack_sums(packed).items():
                sums[name][listed] += weight * value
            samples.append(packed * (weight / len(plan)))
        at, packed = stacked_tails(np.stack(samples), pass_tail_weights(plan, filter_width),
                                   listed, width, height)
        tails = Tails(at, unpack_sums(packed))
    count = np.where(edge, len(plan), 1)
    timings["sub-pixel passes" if len(plan) > 1 else "direct + compose"] = \
        time.perf_counter() - t0
    return finish_passes(sums, count, width, height, filter_width, tails), timings
