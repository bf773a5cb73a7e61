"""Multi-bounce light for Fast quality's cones: the radiance cache in the voxels they read
(docs/gi_pipeline.md "Multi-bounce radiance cache", issue 20 point 2).

A cone sees the voxels' outgoing radiance; injection gives them albedo × their direct light
(+ emission), so a cone from a pixel carries one bounce. With *Bounces* N > 1 the voxels also
reflect the indirect light the radiance cache of N − 1 iterations holds at them
(``radiance_cache.lookup`` half a voxel in front of the voxel's centre along its normal,
× its albedo) — the same cache
the Accurate gathers read at their bounce hits: the voxel then sends bounces 1 … N − 1 of
light arriving at it, and the cone's pixel gets bounces 1 … N. The sum is made in the voxels
before the octree, so every cone that samples them (diffuse, glossy, at any level) reads it,
and numpy and the GPU trace the same octree. Shadow cones read occlusion only: their octree
is left as it is.

``cone_octrees`` gives the octree of each kind of cone (``ray_views``) for one update and one
cache, built once and kept while both are the same objects (one render's passes, and the next
render of an unchanged scene).
"""
from __future__ import annotations

import numpy as np

from .light_injection import InjectedRadiance, voxel_centres
from .radiance_cache import lookup
from .ray_views import KINDS, view_octree
from .svo import build_octree

__all__ = ["LOOKUP_OFFSET", "bounced_radiance", "cone_octrees"]

# The cache is read this many voxels in front of a voxel's centre, along its normal: at the
# cell's lit face. At the centre half the Cornell box's wall voxels found no cache voxel
# holding their face among their eight neighbours (and read 0); half a voxel out, 3%.
LOOKUP_OFFSET = 0.5


def bounced_radiance(cascades, radiance, cache) -> InjectedRadiance:
    """Per cascade (N_i, 3) float32 the voxels' ``radiance`` plus albedo × the ``cache``'s
    indirect light for their normals, ``LOOKUP_OFFSET`` voxels in front of their centres
    (``radiance_cache.lookup``); the emission part
    (``InjectedRadiance.emission``) is kept as it was."""
    out = InjectedRadiance()
    for cv, light in zip(cascades, radiance):
        light = np.asarray(light, np.float64)
        if cv.voxel_count:
            normals = np.asarray(cv.normal, np.float64)
            at = voxel_centres(cv) + normals * (LOOKUP_OFFSET * cv.grid.span)
            indirect = lookup(cache, at, normals)
            light = light + np.asarray(cv.albedo, np.float64) * indirect
        out.append(light.astype(np.float32))
    out.emission = getattr(radiance, "emission", None)
    return out


_HELD: dict = {}


def cone_octrees(state, cache) -> dict:
    """{kind: octree} of ``ray_views.KINDS`` for the update ``state`` (``update.GIState``): the
    update's own octrees when ``cache`` is None (one bounce), else the diffuse and glossy ones
    rebuilt from ``bounced_radiance`` with the update's octree settings (kinds that share an
    octree share the rebuilt one). The last result is kept for the same state and cache."""
    own = {kind: view_octree(state, kind) for kind in KINDS}
    if cache is None:
        return own
    held = _HELD.get("entry")
    if held is not None and held[0] is state and held[1] is cache:
        return held[2]
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
    _HELD["entry"] = (state, cache, out)
    return out
