"""Between the engine's ``CacheBuildResult`` and a file's ``VoxelSet``."""
from __future__ import annotations

from ...voxelize.scene_caches import CacheBuildResult, CascadeStats
from .model import VoxelSet


def voxel_set_from_result(result: CacheBuildResult) -> VoxelSet:
    """The caches, bindings and skipped meshes of a voxelization result (reports are dropped)."""
    stats = result.cascade_stats
    cascade_count = len(stats) or max((len(c) for c in result.caches.values()), default=0)
    base_span = stats[0].span if stats else next(
        (c.span / 2**c.cascade for cs in result.caches.values() for c in cs if c is not None), 1.0)
    caches = [c for cs in result.caches.values() for c in cs if c is not None]
    return VoxelSet(float(base_span), int(cascade_count), list(result.caches), caches,
                    dict(result.bindings), list(result.skipped))


def voxel_set_to_result(voxels: VoxelSet) -> CacheBuildResult:
    """A ``CacheBuildResult`` holding the file's caches (per key, one entry per cascade)."""
    result = CacheBuildResult(bindings=dict(voxels.bindings), skipped=list(voxels.skipped))
    result.caches = {key: [None] * voxels.cascade_count for key in voxels.keys}
    for cache in voxels.caches:
        result.caches[cache.key][cache.cascade] = cache
    for cascade in range(voxels.cascade_count):
        present = [c[cascade] for c in result.caches.values() if c[cascade] is not None]
        result.cascade_stats.append(CascadeStats(
            cascade, voxels.base_span * 2**cascade,
            sum(c.voxel_count for c in present), sum(c.nbytes for c in present)))
    return result
