"""The Accurate integrator's final gather (numpy reference of ``render/gpu_gather.py``).

Diffuse Indirect and AO of the preview with exact geometry, at a cost that does not grow with
the image: one gather point per stride × stride block (``upsample.sample_pixels``), ``rays``
cosine-distributed exact rays from each (``gi.exact_indirect.indirect_and_ao``: the hit lit by
the exact direct light, i.e. one-bounce path tracing with next-event estimation), then the
noise is removed by the edge-aware à-trous filter (``denoise.atrous_filter``, driven by the
per-point variances) and the result brought to full resolution by the joint-bilateral
``upsample``. Deterministic for a seed: every ray comes from the point's hashed sequence, keyed
by its full-resolution pixel index.

Why this estimator (docs/gi_pipeline.md "The Accurate integrator"): dense reduced-resolution
rays with an edge-aware filter give every visible surface its own exact near field (contact
shading, thin walls) without the interpolation rules an irradiance cache needs, and the GPU
cost is one dispatch per pass.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..gi.emitters import emitter_light
from ..gi.exact_glossy import glossy_indirect, glossy_world_direct
from ..gi.exact_indirect import indirect_and_ao
from ..gi.surface_lookup import geometric_normals
from ..scene.snapshot import RAY_DIFFUSE
from .denoise import GLOSSY_SIGMA_LUMINANCE, atrous_filter, spread_spikes
from .sparse_gather import gather_lists, glossy_cells, sparse_glossy_settings, sparse_plan, sparse_settings
from .upsample import sample_pixels, upsample


@dataclass(frozen=True)
class GatherSettings:
    """rays : exact rays per gather point; glossy_rays : exact rays per point of the glossy
    gather (``gather_glossy``); ao_distance : metres (Cycles' AO distance);
    hit_glossy : a bounce hit's glossy lobe reflects the lights toward the receiver (the light
    path diffuse → glossy; Cycles keeps it even with no glossy bounce: its light sampling at a
    hit evaluates every closure, docs/gi_pipeline.md "What one bounce means in Cycles");
    hit_samples : shadow rays per light at each bounce hit; denoise_iterations : à-trous passes
    (taps 1, 2, 4, … cells apart); seed : the sequences' seed; world : RGB radiance of a miss
    (0 gives Cycles' pass split, where the world seen from a receiver is direct light).
    bounces : diffuse bounces of the Diffuse Indirect gather (Cycles' Light Paths): 1 is the
    exact one-bounce gather and builds no cache; N > 1 adds at each bounce hit the light of
    bounces 2 … N from a radiance cache of N − 1 iterations (``gi.radiance_cache``, with
    ``cache_rays`` rays per voxel face on a ``cache_resolution``³ grid; 0: Auto,
    ``radiance_cache.build_cache``). cache_focus : the camera's or the emitters' position on
    the cache's lattice (``focused``; None: none), around which Auto nests finer grids, their
    faces' rays within ``cache_nest_rays`` (0: ``radiance_cache.BASE_RAYS``). sparse : the
    diffuse gather traces one cell in four where the light is smooth and the cells where it
    is not (``sparse_gather``, each with ``SPARSE_RAYS`` × rays), the others filled from them.
    glossy_chains : at ``bounces`` 1, a glossy scatter still goes on where Cycles' Glossy
    bounces go past its Diffuse 1 (its Total above 1): the bounce hits' glossy lobes reflect
    the light of one more diffuse bounce, as the receiver's glossy closure does in the glossy
    gather — a cache of no iteration of its own and its first one ahead
    (``uses_cache``; docs/gi_pipeline.md "One bounce and Cycles' glossy bounces")."""

    rays: int = 64
    glossy_rays: int = 8
    ao_distance: float = 1.0
    hit_glossy: bool = True
    hit_samples: int = 1
    denoise_iterations: int = 4
    seed: int = 0
    world: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bounces: int = 1
    cache_rays: int = 8
    cache_resolution: int = 0
    cache_focus: tuple | None = None
    cache_nest_rays: int = 0
    sparse: bool = False
    glossy_chains: bool = False


def uses_cache(settings: GatherSettings) -> bool:
    """Whether the gathers read a radiance cache: Bounces above 1, or 1 with the glossy
    bounces going on (``GatherSettings.glossy_chains``)."""
    return settings.bounces > 1 or (settings.bounces == 1 and settings.glossy_chains)


def focused(settings: GatherSettings, camera, tris, emission=None) -> GatherSettings:
    """``settings`` with the radiance cache's focus (snapped: ``radiance_cache.snap_focus``),
    where there is a cache whose grids Auto lays out: the ``camera``'s position where it stands
    among the geometry, else the emitters' power-weighted centre (``radiance_cache
    .emitters_centre``; emission : per material as ``light_injection.material_emission``,
    None: not asked), where the light changes fastest; else none."""
    if not uses_cache(settings) or settings.cache_resolution or \
            len(getattr(tris, "positions", ())) == 0:
        return settings
    from ..gi.radiance_cache import RAYS_PER_ITERATION, emitters_centre, snap_focus
    focus = None if camera is None else \
        snap_focus(tris, np.asarray(camera.world_matrix, np.float64)[:3, 3])
    if focus is None and emission is not None:
        focus = snap_focus(tris, emitters_centre(tris, emission))
        if focus is not None:  # its nested grids may take up to half a gather's rays
            return replace(settings, cache_focus=focus, cache_nest_rays=RAYS_PER_ITERATION)
    return replace(settings, cache_focus=focus, cache_nest_rays=0)


def cache_settings(settings: GatherSettings) -> tuple:
    """What the radiance cache depends on among ``settings`` (its key beside the scene's)."""
    return (settings.bounces, settings.cache_rays, settings.cache_resolution,
            tuple(float(w) for w in settings.world), settings.hit_samples, settings.hit_glossy,
            settings.cache_focus, settings.cache_nest_rays, uses_cache(settings))


def radiance_cache(tris, lights, albedo, emission, settings: GatherSettings):
    """The radiance cache the gathers read at their bounce hits for ``settings.bounces``
    (None where they read none, ``uses_cache``; ``gi.radiance_cache.cached_cache``, kept
    between calls)."""
    if not uses_cache(settings):
        return None
    from ..gi.radiance_cache import cached_cache
    return cached_cache(tris, lights, albedo, emission, settings.bounces, settings.cache_rays,
                        settings.cache_resolution, settings.world, settings.hit_samples,
                        settings.hit_glossy, settings.cache_focus, settings.cache_nest_rays)


VIEW_BACKOFF = 2e-4  # metres: gather points step back along the camera ray (see gather_gi)


def gather_gi(tris, lights, albedo, emission, hit, position, normal, settings: GatherSettings,
              stride: int, direction=None, low: bool = False, shown=None,
              material=None) -> np.ndarray:
    """(H, W, 4) float32: Diffuse Indirect (RGB, Cycles' units) and AO per pixel, 0 where the
    pixel sees no surface. low : return (the filtered gather points' values (Hl, Wl, 4), their
    valid (Hl, Wl) bool) instead, before the upsample (``upsample.upsample`` of them is the
    image; ``upsample.upsample_at`` reads them at other points).

    hit : (H, W) bool; position, normal : (H, W, 3) the G-buffer (row 0 = top; normals facing
    the viewer). albedo, emission : (M + 1, 3) per material (``passes.material_table``).
    direction : (H, W, 3) the camera rays' unit directions: each gather point steps back along
    its ray by VIEW_BACKOFF, so a point seen on a crease (a ceiling within a hair of a wall, or
    just behind it after float32 rasterization) starts its rays inside the room, not in the wall.
    shown : (H, W) bool the pixels whose surface shows diffuse light (``passes.shows_diffuse``;
    None: all): with ``settings.sparse``, the others' points draw ``sparse_gather.AO_RAYS``.
    material : (H, W) material index per pixel (the tables' last row for none): with
    ``direction`` and the Principled pair as ``albedo``, a ray's hit reflects one more bounce
    of the cache by the chance Cycles picked it glossily (``exact_indirect.indirect_and_ao``
    receivers); None: never.
    """
    height, width = hit.shape
    rows, cols = sample_pixels(height, width, stride)
    valid = hit[rows][:, cols]
    cell_p = position[rows][:, cols]
    cell_n = normal[rows][:, cols]
    cell_g = None  # the cells' geometric normals (the rays below their triangle carry none)
    receivers = None  # the cells' (views, materials): the receivers' glossy picks
    if direction is not None:
        cell_d = direction[rows][:, cols]
        cell_g = np.array(cell_n, np.float64)
        cell_g[valid] = geometric_normals(tris, cell_p[valid], cell_d[valid], cell_n[valid],
                                          RAY_DIFFUSE)
        cell_p = cell_p - VIEW_BACKOFF * cell_d
        if material is not None:
            receivers = (-cell_d, np.asarray(material)[rows][:, cols])
    # the cells gathered: all, or with ``settings.sparse`` one in four where the light is
    # smooth (sparse_gather), the others filled by the filter's first pass
    traced = sparse_plan(valid, cell_p, cell_n) if settings.sparse else valid
    rays = sparse_settings(settings, np.count_nonzero(valid), np.count_nonzero(traced)).rays \
        if settings.sparse else settings.rays
    values = np.zeros(valid.shape + (4,), np.float32)
    variance = np.zeros(valid.shape + (3,), np.float32)  # (…, the points' reach)
    cache = radiance_cache(tris, lights, albedo, emission, settings)
    ids = rows[:, None] * width + cols[None, :]

    def trace(cells, at: GatherSettings):
        indirect, ao, var = indirect_and_ao(
            cell_p[cells], cell_n[cells], ids[cells], tris, lights, albedo, emission,
            rays=at.rays, ao_distance=at.ao_distance, seed=at.seed, world=at.world,
            hit_samples=at.hit_samples, statistics=True, hit_glossy=at.hit_glossy,
            cache=cache, geometric=None if cell_g is None else cell_g[cells],
            receivers=None if receivers is None else (receivers[0][cells], receivers[1][cells]))
        return np.concatenate([indirect, ao[:, None]], axis=1), var

    if not settings.sparse:
        values[traced], variance[traced] = trace(traced, replace(settings, rays=rays))
    else:  # metals' points trace AO only; then the second list (noisy_holes)
        diffuse = valid if shown is None else np.asarray(shown, bool)[rows][:, cols]
        traced = gather_lists(traced, valid, diffuse, values, variance,
                              replace(settings, rays=rays), trace)
    unseen = valid & ~diffuse if settings.sparse else None
    values, _ = atrous_filter(values, variance[..., :2], valid, cell_p, cell_n,
                              iterations=settings.denoise_iterations, holes=valid & ~traced,
                              unseen=unseen, reach=variance[..., 2])
    if low:
        return values, valid
    return upsample(values, valid, hit, position, normal, stride)


def gather_glossy(tris, lights, principled, emission, hit, position, normal, direction, material,
                  settings: GatherSettings, stride: int, low: bool = False,
                  shown=None) -> np.ndarray:
    """(H, W, 3) float32: Glossy Indirect (Cycles' units, without the glossy colour) per pixel,
    0 where the pixel sees no surface — ``settings.glossy_rays`` exact rays from the GGX visible
    normals of each gather point (``gi.exact_glossy``), the à-trous filter and the upsample of
    ``gather_gi`` (the glossy light is filtered in the AO slot's place, which stays 0); low :
    ``gather_gi``'s (values (Hl, Wl, 4), valid) instead.

    direction : (H, W, 3) the camera rays' unit directions; material : (H, W) material index
    per pixel (the tables' last row for none); principled : ``passes.principled_table``.
    shown : (H, W) bool the pixels whose surface shows diffuse light (``gather_gi``'s; None:
    all): with ``settings.sparse`` the others' points are all traced
    (``sparse_gather.glossy_cells``).
    """
    return _glossy_cells(glossy_indirect, (tris, lights, principled, emission), {
        "world": settings.world, "hit_samples": settings.hit_samples,
        "hit_glossy": settings.hit_glossy,
        "cache": radiance_cache(tris, lights, principled, emission, settings)},
        hit, position, normal, direction, material, settings, stride, low, sparse=True,
        shown=shown)


def gather_glossy_world(tris, world, principled, hit, position, normal, direction, material,
                        settings: GatherSettings, stride: int, emission=None,
                        low: bool = False) -> np.ndarray:
    """(H, W, 3) float32: the Glossy Direct of the world and, given their ``emission`` table,
    the emissive surfaces (Cycles' units, without the glossy colour) per pixel —
    ``gi.exact_glossy.glossy_world_direct`` with ``settings.glossy_rays`` rays of each
    technique at the gather points of ``gather_glossy``, the same filter and upsample.
    world : ``gi.world_light.WorldLight`` (None with no emission: zeros); low : as
    ``gather_glossy``'s."""
    if world is None and emission is None:
        if low:
            rows, cols = sample_pixels(*hit.shape, stride)
            valid = hit[rows][:, cols]
            return np.zeros(valid.shape + (4,), np.float32), valid
        return np.zeros(hit.shape + (3,), np.float32)
    emitters = None if emission is None else emitter_light(tris, emission)
    return _glossy_cells(glossy_world_direct, (tris, world, principled),
                         {"emission": emission, "emitters": emitters},
                         hit, position, normal, direction, material, settings, stride, low)


def _glossy_cells(estimator, scene, options, hit, position, normal, direction, material,
                  settings: GatherSettings, stride: int, low: bool = False,
                  sparse: bool = False, shown=None) -> np.ndarray:
    """``estimator(points, normals, views, materials, ids, *scene, rays, seed, **options)`` →
    (rgb, variance) at the glossy gather points (stepped back along the camera rays), filtered
    and upsampled to (H, W, 3). sparse : with ``settings.sparse``, the cells of
    ``sparse_gather.glossy_cells`` (``shown``: ``gather_glossy``'s), the others holes the
    filter fills."""
    height, width = hit.shape
    rows, cols = sample_pixels(height, width, stride)
    valid = hit[rows][:, cols]
    cell_p = position[rows][:, cols] - VIEW_BACKOFF * direction[rows][:, cols]
    cell_n = normal[rows][:, cols]
    traced = glossy_cells(valid, cell_p, cell_n, stride, sparse and settings.sparse,
                          None if shown is None else np.asarray(shown, bool)[rows][:, cols])
    holes = valid & ~traced
    if holes.any():
        settings = sparse_glossy_settings(settings, np.count_nonzero(valid),
                                          np.count_nonzero(traced))
    ids = (rows[:, None] * width + cols[None, :])[traced]
    values = np.zeros(valid.shape + (4,), np.float32)
    variance = np.zeros(valid.shape + (2,), np.float32)
    glossy, var = estimator(cell_p[traced], cell_n[traced], -direction[rows][:, cols][traced],
                            material[rows][:, cols][traced], ids, *scene,
                            rays=settings.glossy_rays, seed=settings.seed, **options)
    values[traced, :3] = glossy
    variance[traced, 0] = var
    if not holes.any():
        # (a ray that found a lamp's highlight: its light spread over its surface first; with
        # holes the fill compares each tap with the hole's traced neighbours instead)
        values, variance = spread_spikes(values, variance, valid, cell_p, cell_n)
    values, _ = atrous_filter(values, variance, valid, cell_p, cell_n,
                              iterations=settings.denoise_iterations, fit=False,
                              sigma_luminance=GLOSSY_SIGMA_LUMINANCE,
                              holes=holes if holes.any() else None)
    if low:
        return values, valid
    return upsample(values, valid, hit, position, normal, stride)[..., :3]
