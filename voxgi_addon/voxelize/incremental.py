"""Rebuild only the voxel caches that changed (the viewport's voxelization job).

Every cache key (``scene_caches.cache_sources``: a mesh, or a mesh with its scale baked in)
gets a **fingerprint**: a hash of what its voxels are made of — object-space positions,
triangles, each triangle's albedo and specular, skin weights, the spans. ``refresh_caches``
voxelizes a key only when no stored caches carry its fingerprint, and reuses the rest:

* moving objects, posing bones or moving lights changes no fingerprint: nothing is voxelized;
* editing one mesh changes its key's fingerprint only: that mesh is voxelized, the others kept;
* editing a material changes the albedo of the triangles using it: those keys are rebuilt
  (geometry and attributes; the voxels' colours are averages over the triangles touching
  each voxel, so the surface pass is redone with them);
* undo / redo: the ``CacheStore`` keeps the last ``keep`` versions of every key, so a mesh
  restored by undo finds its earlier caches by fingerprint (reused, not re-voxelized), and a
  key restored to something never voxelized is voxelized — a cache can never be stale,
  whatever the names say.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGICancelled
from ..scene.snapshot import SceneSnapshot
from .scene_caches import (
    CacheBuildResult,
    StageTimer,
    add_cascade_stats,
    build_mesh_caches,
    cache_sources,
    check_build_request,
    triangle_materials,
)

__all__ = ["CacheStore", "RefreshResult", "mesh_fingerprint", "refresh_caches"]


def _feed(digest, array) -> None:
    if array is None:
        digest.update(b"none")
        return
    a = np.ascontiguousarray(array)
    digest.update(f"{a.dtype.str}{a.shape}".encode())
    digest.update(a.tobytes())


def mesh_fingerprint(key: str, positions, mesh, snapshot: SceneSnapshot, base_span: float,
                     cascade_count: int) -> str:
    """Hex digest of everything a key's caches are made of (see the module doc)."""
    digest = hashlib.blake2b(digest_size=16)
    digest.update(f"{key}|{float(base_span)!r}|{int(cascade_count)}".encode())
    albedo, spec = triangle_materials(snapshot, mesh)
    for array in (positions, mesh.triangles, albedo, spec):
        _feed(digest, array)
    # textured materials: their UVs and the textures' content and sampling (per texel albedo)
    textures = tuple(getattr(snapshot, "textures", ()) or ())
    slots = [int(getattr(m, "base_color_texture", -1)) for m in snapshot.materials]
    if any(0 <= s < len(textures) for s in slots):
        _feed(digest, mesh.uvs)
        digest.update(repr([(textures[s].key, textures[s].interpolation, textures[s].extension,
                             np.asarray(textures[s].uv_transform).tolist()) if
                            0 <= s < len(textures) else None for s in slots]).encode())
    # cut-outs: the Alpha per material and its textures (the voxels' coverage)
    alphas = [(float(getattr(m, "alpha", 1.0)), int(getattr(m, "alpha_texture", -1)))
              for m in snapshot.materials]
    if any(a < 1.0 or 0 <= s < len(textures) for a, s in alphas):
        _feed(digest, mesh.uvs)
        digest.update(repr([(a, (textures[s].key, textures[s].interpolation,
                                 textures[s].extension, np.asarray(textures[s].uv_transform).tolist())
                             if 0 <= s < len(textures) else None) for a, s in alphas]).encode())
    skin = mesh.skin
    _feed(digest, None if skin is None else skin.weights)
    _feed(digest, None if skin is None else skin.bone_indices)
    return digest.hexdigest()


@dataclass
class _KeyCaches:
    """One key's caches at one fingerprint, with what voxelizing it reported."""

    fingerprint: str
    caches: list
    skipped: list
    dropped: int
    warnings: list


@dataclass
class CacheStore:
    """Caches by key and fingerprint, the newest last; at most ``keep`` versions per key.
    Owned by one scene's viewport session; read and written by one job at a time."""

    keep: int = 2
    versions: dict[str, list[_KeyCaches]] = field(default_factory=dict)
    # key → (MeshData, positions, fingerprint): skip hashing a snapshot's unchanged mesh data
    _memo: dict[str, tuple] = field(default_factory=dict)

    def find(self, key: str, fingerprint: str) -> _KeyCaches | None:
        return next((v for v in self.versions.get(key, ()) if v.fingerprint == fingerprint), None)

    def put(self, key: str, entry: _KeyCaches) -> None:
        kept = [v for v in self.versions.get(key, ()) if v.fingerprint != entry.fingerprint]
        self.versions[key] = (kept + [entry])[-self.keep:]

    def forget_except(self, keys) -> None:
        """Drop keys no longer in the scene beyond one version (undo may bring them back)."""
        keys = set(keys)
        for key in list(self.versions):
            if key not in keys:
                self.versions[key] = self.versions[key][-1:]

    def fingerprint(self, key, positions, mesh, snapshot, base_span, cascade_count) -> str:
        memo = self._memo.get(key)
        if memo is not None and memo[0] is mesh and memo[1] is positions and \
                memo[2] is snapshot.materials and memo[3] == (base_span, cascade_count):
            return memo[4]
        value = mesh_fingerprint(key, positions, mesh, snapshot, base_span, cascade_count)
        self._memo[key] = (mesh, positions, snapshot.materials, (base_span, cascade_count), value)
        return value

    @property
    def nbytes(self) -> int:
        return sum(c.nbytes for vs in self.versions.values() for v in vs for c in v.caches
                   if c is not None)


@dataclass
class RefreshResult:
    """caches : the scene's caches now; voxelized : keys voxelized by this call (sorted);
    reused : keys whose stored caches were taken as they were."""

    caches: CacheBuildResult
    voxelized: list[str]
    reused: list[str]


def refresh_caches(store: CacheStore, snapshot: SceneSnapshot, base_span: float,
                   cascade_count: int, cancel=None, progress=None) -> RefreshResult:
    """The snapshot's caches, voxelizing only keys whose fingerprint has no stored caches.

    cancel : callable → True to stop (VoxGICancelled between meshes and cascades; the store
    keeps whatever finished). progress : callable(fraction 0..1, text) or None.
    """
    check_build_request(snapshot, base_span, cascade_count)
    result = CacheBuildResult(warnings=list(snapshot.warnings))
    timer = StageTimer(result.timings)
    sources = cache_sources(snapshot, result)
    t0 = time.perf_counter()
    prints = {key: store.fingerprint(key, src.positions, src.mesh, snapshot, base_span,
                                     cascade_count) for key, src in sources.items()}
    timer.add("fingerprint", t0)
    todo = [key for key in sources if store.find(key, prints[key]) is None]
    weights = {key: max(1, len(sources[key].mesh.triangles)) for key in todo}
    total, done = sum(weights.values()), 0
    for key in todo:
        if cancel is not None and cancel():
            raise VoxGICancelled("voxelization cancelled")
        if progress is not None:
            progress(done / max(total, 1), f"voxelizing '{key}'")
        src = sources[key]
        one = CacheBuildResult()
        build_mesh_caches(key, src.positions, src.mesh, snapshot, base_span, cascade_count, one,
                          timer, cancel, src.span_scale)
        store.put(key, _KeyCaches(prints[key], one.caches[key], one.skipped,
                                  one.dropped_triangles.get(key, 0), one.warnings))
        done += weights[key]
    for key in sources:
        entry = store.find(key, prints[key])
        result.caches[key] = entry.caches
        result.skipped.extend(entry.skipped)
        if entry.dropped:
            result.dropped_triangles[key] = entry.dropped
        result.warnings.extend(w for w in entry.warnings if w not in result.warnings)
    store.forget_except(sources)
    add_cascade_stats(result, base_span, cascade_count)
    return RefreshResult(result, sorted(todo), sorted(set(sources) - set(todo)))
