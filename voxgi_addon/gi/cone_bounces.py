"""Multi-bounce light for Fast quality's cones: the radiance cache in the voxels they read
(docs/gi_pipeline.md "Multi-bounce radiance cache", issue 20 point 2).

A cone sees the voxels' outgoing radiance; injection gives them albedo × their direct light
(+ emission), so a cone from a pixel carries one bounce. With *Bounces* N > 1 the voxels also
reflect the indirect light the radiance cache of N − 1 iterations holds at them
(``radiance_cache.lookup`` at the voxel's centre, or just in front of it: ``voxel_indirect``,
× its albedo) — the cache the Accurate gathers read at their bounce hits, at a coarser Auto
resolution (``fast_cache_settings``): the voxel then sends bounces 1 … N − 1 of the light
arriving at it, and the cone's pixel gets bounces 1 … N. The sum is made in the voxels
before the octree, so every cone that samples them (diffuse, glossy, at any level) reads it,
and numpy and the GPU trace the same octree. Shadow cones read occlusion only: their octree
is left as it is.

``cone_octrees`` gives the octree of each kind of cone (``ray_views``) for one update and one
cache, built once and kept while the update's octrees and the cache are the same objects (one
render's passes, and the next render of an unchanged scene).
"""
from __future__ import annotations

import dataclasses
import weakref

import numpy as np

from .light_injection import InjectedRadiance, voxel_centres
from .radiance_cache import BASE_RAYS, build_cache, lookup
from .ray_views import KINDS, view_octree
from .svo import build_octree

__all__ = ["FAST_CACHE_RESOLUTIONS", "LOOKUP_STEPS", "bounced_radiance", "cone_octrees",
           "fast_cache_settings", "voxel_indirect"]

# Where a voxel reads the cache: at its centre, else (no cache voxel holding the face among
# the eight around it: a 0) this many cache voxels in front of it along its normal, the first
# that finds one. The voxel's surface lies anywhere in its cell and the cache holds the cells
# its triangles touch, on their own lattice: a wall at the box's rim has its cascade centre
# outside the cache's grid, a floor on a cache cell boundary only the cells below it. One
# point misses: at the centre 50% of the Cornell box's voxels (32³ cache), 14% of the emissive
# room's (64³); half a cascade voxel out 3% and 61%; the first of these, 0.8% of the latter.
LOOKUP_STEPS = (0.0, 0.5, 1.0)


def bounced_radiance(cascades, radiance, cache) -> InjectedRadiance:
    """Per cascade (N_i, 3) float32 the voxels' ``radiance`` plus albedo × the ``cache``'s
    indirect light for them (``voxel_indirect``); the emission part
    (``InjectedRadiance.emission``) is kept as it was."""
    out = InjectedRadiance()
    for cv, light in zip(cascades, radiance):
        light = np.asarray(light, np.float64)
        if cv.voxel_count:
            light = light + np.asarray(cv.albedo, np.float64) * voxel_indirect(cv, cache)
        out.append(light.astype(np.float32))
    out.emission = getattr(radiance, "emission", None)
    return out


def voxel_indirect(cascade, cache) -> np.ndarray:
    """(N, 3) float64 the ``cache``'s indirect light (E/π) for the voxels of ``cascade``
    (``CascadeVoxels``) and their normals: ``radiance_cache.lookup`` at the first point of
    ``LOOKUP_STEPS`` (cache voxels along the normal from the centre) that finds the face."""
    normals = np.asarray(cascade.normal, np.float64)
    centres = voxel_centres(cascade)
    span = float(cache.grids[0].span)  # the finest grid's
    out = np.zeros((len(centres), 3))
    todo = np.arange(len(centres))
    for step in LOOKUP_STEPS:
        if len(todo) == 0:
            break
        value = lookup(cache, centres[todo] + normals[todo] * (step * span), normals[todo])
        found = value.sum(axis=1) > 0
        out[todo[found]] = value[found]
        todo = todo[~found]
    return out


# Fast's cache resolutions when the settings say Auto (``GatherSettings.cache_resolution`` 0):
# the finest of these whose iteration stays within Auto's ray budget
# (``radiance_cache.BASE_RAYS``), the coarsest otherwise — Accurate's Auto without its
# 64³. Fast's error is its cones' own: against Cycles' default light paths the four bounce
# scenes' Combined at 32³ is within −0.026 … +0.018 of Accurate's Auto (32³–64³ there) and
# −0.031 … +0.005 of 16³'s, the cache taking 1.4–3.7 s; 16³ let the thin-wall room's dark side
# reach 2.3% of the lit side's light (32³: 1.9%; the one-bounce cones 1.3%).
FAST_CACHE_RESOLUTIONS = (32, 16)


def fast_cache_settings(settings, tris):
    """``settings`` (``preview.gather.GatherSettings``) with Fast's cache resolution for the
    triangles ``tris`` where it is Auto (``FAST_CACHE_RESOLUTIONS``); a set resolution, or
    one bounce (no cache), keeps them as they are."""
    if getattr(settings, "cache_resolution", 0) or settings.bounces <= 1:
        return settings
    counts = _FACE_COUNTS.setdefault(tris, {})  # kept per triangles: the viewport asks per slice
    for resolution in FAST_CACHE_RESOLUTIONS:
        if resolution not in counts:
            counts[resolution] = sum(int(p.sum()) for p in build_cache(tris, resolution).present)
        if counts[resolution] * settings.cache_rays <= BASE_RAYS:
            break
    return dataclasses.replace(settings, cache_resolution=resolution)


_FACE_COUNTS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


_HELD: dict = {}


def cone_octrees(state, cache) -> dict:
    """{kind: octree} of ``ray_views.KINDS`` for the update ``state`` (``update.GIState``): the
    update's own octrees when ``cache`` is None (one bounce), else the diffuse and glossy ones
    rebuilt from ``bounced_radiance`` with the update's octree settings (kinds that share an
    octree share the rebuilt one). The last result is kept for the same octrees and cache."""
    own = {kind: view_octree(state, kind) for kind in KINDS}
    if cache is None:
        return own
    # an update that reused everything is a new state holding the same octrees
    key = (*own.values(), cache)
    held = _HELD.get("entry")
    if held is not None and len(held[0]) == len(key) and all(a is b for a, b in zip(held[0], key)):
        return held[1]
    one_sided = getattr(getattr(state, "settings", None), "one_sided_leaves", True)
    views = getattr(state, "ray_views", None) or {}
    rebuilt: dict = {}
    out = {}
    for kind, octree in own.items():
        if kind == "shadow":  # occlusion only: the same as the diffuse cones' where shared
            out[kind] = out["diffuse"] if octree is own["diffuse"] else octree
            continue
        if id(octree) not in rebuilt:
            view = views.get(kind)
            cascades, radiance = (state.cascades, state.radiance) if view is None else \
                (view.cascades, view.radiance)
            rebuilt[id(octree)] = build_octree(cascades, bounced_radiance(cascades, radiance, cache),
                                               octree.dense_depth, one_sided_leaves=one_sided)
        out[kind] = rebuilt[id(octree)]
    _HELD["entry"] = (key, out)
    return out
