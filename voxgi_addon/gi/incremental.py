"""A GI update that redoes only the stages a change needs (the viewport's worker job).

``update_gi`` (``gi/update.py``) always runs every stage. ``update_gi_stages`` takes the
previous ``GIState`` and the stages of an ``UpdatePlan`` (``scene/changes.py``): when the
cascades need no transform (a light moved, the world changed) and the grids did not move,
the previous cascades and their occupancy are reused and only the direct light is injected
again and the octree rebuilt. Anything else runs ``update_gi``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import VoxGICancelled
from .cascades import place_cascades
from .light_injection import inject_direct_light
from .svo import build_octree
from .update import GISettings, GIState, anchor_position, light_key, update_gi
from .voxel_shadows import CascadeOccupancy

__all__ = ["StagedGI", "cascade_grids", "grids_equal", "same_caches", "update_gi_stages"]


@dataclass(eq=False)
class StagedGI:
    """A ``GIState`` with the caches its cascades were built from (so the next update knows
    whether they can be reused) and the stages that produced it."""

    state: GIState
    caches: object
    stages: tuple[str, ...] = ()


def cascade_grids(snapshot, caches, settings: GISettings):
    """The grids ``update_gi`` would place for this snapshot's camera (cheap: no voxels)."""
    base_span = caches.cascade_stats[0].span
    ahead = settings.view_ahead * 0.5 * settings.resolution * base_span
    position, _ = anchor_position(snapshot, ahead)
    return place_cascades(position, base_span, settings.resolution, len(caches.cascade_stats))


def grids_equal(a, b) -> bool:
    """Same cascades (count, spans, resolution, origins)."""
    return a is not None and b is not None and len(a) == len(b) and all(
        x.resolution == y.resolution and abs(x.span - y.span) <= 1e-12 * y.span
        and np.array_equal(x.origin, y.origin) for x, y in zip(a, b))


def same_caches(a, b) -> bool:
    """The same cache objects bound the same way (objects neither moved nor re-voxelized)."""
    if a is b:
        return True
    if a is None or b is None or a.caches.keys() != b.caches.keys() or \
            a.bindings.keys() != b.bindings.keys():
        return False
    return all(a.caches[k] is b.caches[k] for k in a.caches) and all(
        x.cache_key == y.cache_key and np.array_equal(x.rigid_matrix, y.rigid_matrix)
        for x, y in ((a.bindings[n], b.bindings[n]) for n in a.bindings))


def update_gi_stages(snapshot, caches, settings: GISettings, previous: StagedGI | None,
                     stages, cancel=None, progress=None) -> StagedGI:
    """The new state and the stages run. stages : the plan's stage names; "transform" absent
    means the cascades may be reused (they are, when ``previous`` was built from ``caches``
    on the same grids). progress : callable(fraction, text) or None."""
    grids = cascade_grids(snapshot, caches, settings)
    reuse = ("transform" not in stages and previous is not None
             and same_caches(previous.caches, caches) and grids_equal(previous.state.grids, grids))
    if not reuse:
        if progress is not None:
            progress(0.0, "transforming voxels into cascades")
        state = update_gi(snapshot, caches, settings, cancel=cancel,
                          previous=None if previous is None else previous.state)
        return StagedGI(state, caches, ("transform", "inject", "octree"))
    timings: dict[str, float] = {}

    def stage(name, fraction, fn, *args, **kw):
        if cancel is not None and cancel():
            raise VoxGICancelled("GI update cancelled")
        if progress is not None:
            progress(fraction, name)
        t0 = time.perf_counter()
        value = fn(*args, **kw)
        timings[name] = time.perf_counter() - t0
        return value

    previous = previous.state
    occupancy = stage("occupancy", 0.0, CascadeOccupancy, previous.cascades)
    radiance = stage("inject", 0.0, inject_direct_light, previous.cascades, snapshot, occupancy,
                     settings.light_samples, rays=getattr(previous.radiance, "rays", None),
                     keep_rays=True)
    depth = int(np.log2(settings.resolution)) + len(previous.grids) - 1
    octree = stage("svo", 0.6, build_octree, previous.cascades, radiance,
                   min(settings.dense_depth, depth), one_sided_leaves=settings.one_sided_leaves)
    state = GIState(previous.grids, previous.cascades, radiance, octree, timings,
                    list(previous.warnings), placement=previous.placement,
                    light_key=light_key(snapshot, settings))
    return StagedGI(state, caches, ("inject", "octree"))
