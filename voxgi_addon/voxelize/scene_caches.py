"""Build every mesh's voxel caches for a scene snapshot: the voxelization job.

One cache per (mesh key, cascade); cascade i uses ``base_span · 2**i``. Static and rigid
objects with a non-unit scale get a cache of their scaled mesh (key ``mesh|scale``), shared
by every object with that mesh and scale; the runtime then applies only their rigid part.
Skinned objects keep their cache in model space, since their bones carry the whole object
matrix: a uniform scale s (an armature at 0.01 over a mesh in centimetres) is voxelized at
``span / s`` (key ``mesh|span:s``), so the cache holds the voxels of the same character built
at scale 1 and the skinning matrices carry them to the world span (Yalçıner 2016, 4.7); a
non-uniform remainder is baked into the rest vertices (``object_scale.skin_bake``).
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGICancelled, VoxGIError
from ..scene.glass import ray_alpha
from ..scene.snapshot import MeshData, SceneSnapshot
from ..scene.textures import (
    cutout_random,
    sample_alpha,
    sample_texture,
    texel_density,
    texture_texels,
)
from . import object_scale
from .attributes import average_attributes
from .cache import VoxelCache, pack_cache
from .mesh_checks import filter_triangles
from .packing import MAX_CELLS_PER_AXIS
from .surface import lattice_bounds, voxelize_triangles

DEFAULT_ALBEDO = np.array([0.8, 0.8, 0.8], np.float32)


@dataclass(frozen=True)
class SkippedMesh:
    """A mesh too large for 1024 cells per axis at one span."""

    mesh: str
    cascade: int
    span: float
    dims: tuple[int, int, int]

    def __str__(self) -> str:
        d = "×".join(str(v) for v in self.dims)
        return (f"mesh '{self.mesh}' skipped at cascade {self.cascade} (span {self.span:g} m): "
                f"needs {d} voxels, more than {MAX_CELLS_PER_AXIS} per axis")


@dataclass(frozen=True)
class CascadeStats:
    cascade: int
    span: float
    voxel_count: int
    nbytes: int


@dataclass(frozen=True)
class ObjectBinding:
    """How an object uses a cache: ``world ≈ rigid_matrix @ cache object space``."""

    cache_key: str
    rigid_matrix: np.ndarray
    kind: str


@dataclass(frozen=True)
class CacheSource:
    """What one cache key is voxelized from: object-space ``positions`` (V, 3) (a scale or
    residual stretch baked in), the ``mesh`` (triangles, materials, skin) and ``span_scale``:
    the cache's spans are the cascade spans divided by it (the unit scale of a skinned mesh,
    1 for everything else)."""

    positions: np.ndarray
    mesh: MeshData
    span_scale: float = 1.0


@dataclass
class CacheBuildResult:
    caches: dict[str, list[VoxelCache | None]] = field(default_factory=dict)
    bindings: dict[str, ObjectBinding] = field(default_factory=dict)
    cascade_stats: list[CascadeStats] = field(default_factory=list)
    skipped: list[SkippedMesh] = field(default_factory=list)
    dropped_triangles: dict[str, int] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def total_voxels(self) -> int:
        return sum(s.voxel_count for s in self.cascade_stats)

    @property
    def total_bytes(self) -> int:
        return sum(s.nbytes for s in self.cascade_stats)


class StageTimer:
    """Adds the seconds since ``start`` to ``timings[stage]``."""

    def __init__(self, timings):
        self.timings = timings

    def add(self, stage, start):
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - start


def cache_sources(snapshot: SceneSnapshot, result: CacheBuildResult) -> dict[str, CacheSource]:
    """Which keys to voxelize from what (``CacheSource``), baking non-unit scales; fills
    bindings."""
    sources: dict[str, CacheSource] = {}
    for obj in snapshot.objects:
        mesh = snapshot.meshes.get(obj.mesh)
        if mesh is None:
            raise VoxGIError(f"object '{obj.name}' refers to unknown mesh '{obj.mesh}'")
        if not np.isfinite(obj.world_matrix).all():
            result.warnings.append(f"object '{obj.name}': its matrix has NaN/inf values; skipped")
            continue
        rigid, stretch = object_scale.split_rigid(obj.world_matrix)
        key, positions, span_scale = obj.mesh, mesh.positions, 1.0
        if obj.kind == "skinned":
            rigid = np.asarray(obj.world_matrix, np.float64)  # bones carry the deformation
            span_scale, residual = object_scale.skin_bake(rigid)
            if not (np.isfinite(span_scale) and span_scale > 1e-12):
                result.warnings.append(f"object '{obj.name}': its matrix has zero scale; skipped")
                continue
            key = object_scale.skin_key(obj.mesh, span_scale, residual)
            if key == obj.mesh:
                span_scale = 1.0
            if not object_scale.is_identity(residual):
                result.warnings.append(
                    f"object '{obj.name}' is skinned with non-uniform scale or shear: its "
                    "non-uniform part is baked into its rest shape and the uniform part "
                    f"({span_scale:.4g}) into its voxel span, so at rest its voxels are cubes "
                    "of the cascade's span")
                positions = np.asarray(mesh.positions, np.float64) @ residual.T
        elif not object_scale.is_identity(stretch):
            if not object_scale.is_uniform(stretch):
                result.warnings.append(
                    f"object '{obj.name}' has non-uniform scale or shear: voxels cannot be "
                    "transformed under it (Yalçıner 2016, 4.7), so the scale is baked into its "
                    "cache and only its rotation and location are applied at runtime")
            key = f"{obj.mesh}|scale:{object_scale.stretch_key(stretch)}"
            positions = np.asarray(mesh.positions, np.float64) @ stretch.T
        result.bindings[obj.name] = ObjectBinding(key, rigid, obj.kind)
        sources.setdefault(key, CacheSource(positions, mesh, span_scale))
    return sources


def triangle_materials(snapshot: SceneSnapshot, mesh: MeshData):
    """Per-triangle albedo (T, 3) and specular (T,) = 1 - roughness (1 = mirror-like)."""
    mats = snapshot.materials
    albedo = np.tile(DEFAULT_ALBEDO, (len(mats) + 1, 1))
    spec = np.full(len(mats) + 1, 0.5, np.float32)
    for i, m in enumerate(mats):
        albedo[i] = np.clip(np.nan_to_num(m.base_color[:3]), 0.0, 1.0)
        spec[i] = 1.0 - float(np.clip(m.roughness, 0.0, 1.0))
    idx = np.asarray(mesh.triangle_materials, np.int64)
    idx = np.where((idx >= 0) & (idx < len(mats)), idx, len(mats))
    return albedo[idx], spec[idx]


def texel_albedo(snapshot: SceneSnapshot, mesh: MeshData, positions, keep=None):
    """The voxelizer's ``texel_albedo`` callable for ``mesh`` (object-space ``positions``, its
    triangles ``keep`` (indices) as voxelized), or None when none of its materials has a
    texture or it has no UVs: a (triangle, voxel) contact's albedo is the Base Color texture at
    the piece's centroid UV, trilinear at the footprint of one voxel span (the mean over about
    the voxel's area); untextured triangles keep their material's colour."""
    if mesh.uvs is None:
        return None
    textures = tuple(getattr(snapshot, "textures", ()) or ())
    slots = np.full(len(snapshot.materials) + 1, -1, np.int64)
    for i, m in enumerate(snapshot.materials):
        index = int(getattr(m, "base_color_texture", -1))
        if 0 <= index < len(textures):
            slots[i] = index
    keep = np.arange(len(mesh.triangles)) if keep is None else np.asarray(keep)
    idx = np.asarray(mesh.triangle_materials, np.int64)[keep]
    slot = slots[np.where((idx >= 0) & (idx < len(snapshot.materials)), idx, len(snapshot.materials))]
    if not (slot >= 0).any():
        return None
    albedo, _ = triangle_materials(snapshot, mesh)
    albedo = albedo[keep]
    uvs = np.asarray(mesh.uvs, np.float32)[keep]
    corners = np.asarray(positions, np.float64)[np.asarray(mesh.triangles, np.int64)[keep]]
    density = texel_density(corners, uvs)
    texels = np.array([texture_texels(t) for t in textures] + [0.0])

    def sample(pair_tri, bary, span):
        out = np.asarray(albedo, np.float64)[pair_tri].copy()
        for s in np.unique(slot[pair_tri]):
            if s < 0:
                continue
            at = np.flatnonzero(slot[pair_tri] == s)
            tri = pair_tri[at]
            b = np.asarray(bary, np.float32)[at]
            c = uvs[tri]
            uv = (1.0 - b[:, :1] - b[:, 1:]) * c[:, 0] + b[:, :1] * c[:, 1] + b[:, 1:] * c[:, 2]
            lod = np.log2(np.maximum(span * density[tri] * texels[s], 1.0))
            out[at] = np.clip(sample_texture(textures[s], uv, lod), 0.0, 1.0)
        return out

    return sample


def texel_alpha(snapshot: SceneSnapshot, mesh: MeshData, positions, keep=None):
    """The voxelizer's ``texel_alpha`` callable for ``mesh`` (as ``texel_albedo``), or None
    when all its materials are opaque: a (triangle, voxel) contact's Alpha is the material's
    value, or its alpha texture at the piece's centroid UV at the footprint of one voxel span
    (the cut-out's coverage of about the voxel's area)."""
    textures = tuple(getattr(snapshot, "textures", ()) or ())
    count = len(snapshot.materials)
    values = np.ones(count + 1)
    slots = np.full(count + 1, -1, np.int64)
    for i, m in enumerate(snapshot.materials):
        # glass lets the cones through as other rays (scene.glass)
        values[i] = ray_alpha(m, bool(getattr(snapshot, "refractive_caustics", True)))
        index = int(getattr(m, "alpha_texture", -1))
        if 0 <= index < len(textures) and mesh.uvs is not None:
            slots[i] = index
    keep = np.arange(len(mesh.triangles)) if keep is None else np.asarray(keep)
    idx = np.asarray(mesh.triangle_materials, np.int64)[keep]
    row = np.where((idx >= 0) & (idx < count), idx, count)
    value, slot = values[row], slots[row]
    if not ((slot >= 0) | (value < 1.0)).any():
        return None
    uvs = None if mesh.uvs is None else np.asarray(mesh.uvs, np.float32)[keep]
    corners = np.asarray(positions, np.float64)[np.asarray(mesh.triangles, np.int64)[keep]]
    density = None if uvs is None else texel_density(corners, uvs)
    texels = np.array([texture_texels(t) for t in textures] + [0.0])

    def sample(pair_tri, bary, span):
        out = value[pair_tri].copy()
        for s in np.unique(slot[pair_tri]):
            if s < 0:
                continue
            at = np.flatnonzero(slot[pair_tri] == s)
            tri = pair_tri[at]
            b = np.asarray(bary, np.float32)[at]
            c = uvs[tri]
            uv = (1.0 - b[:, :1] - b[:, 1:]) * c[:, 0] + b[:, :1] * c[:, 1] + b[:, 1:] * c[:, 2]
            lod = np.log2(np.maximum(span * density[tri] * texels[s], 1.0))
            out[at] = sample_alpha(textures[s], uv, lod)
        return out

    return sample


def covered_voxels(cells: np.ndarray, coverage, cascade: int) -> np.ndarray | None:
    """(N,) bool voxels kept of a cut-out's voxels: each one where a hash of its cell and
    cascade (``textures.cutout_random``) is below its ``coverage`` — so cones and probes see
    through in proportion, as rays pass cut-outs; None when every voxel is opaque."""
    if coverage is None or (np.asarray(coverage) >= 1.0).all():
        return None
    cells = np.asarray(cells, np.float32).reshape(-1, 3)
    salt = np.full_like(cells, np.float32(cascade + 1))
    return cutout_random(cells, salt, np.zeros(len(cells), np.int64)) < np.asarray(coverage)


def _kept(attrs, keep):
    """``attrs`` (``VoxelAttributes``) of the voxels ``keep`` (bool)."""
    return dataclasses.replace(attrs, **{
        f.name: None if getattr(attrs, f.name) is None else np.asarray(getattr(attrs, f.name))[keep]
        for f in dataclasses.fields(attrs)})


def build_mesh_caches(key, positions, mesh, snapshot, base_span, cascade_count, result, timer,
                      cancel=None, span_scale: float = 1.0):
    """Voxelize one mesh at every cascade span into ``result.caches[key]``.

    cancel : optional callable returning True to stop; raises VoxGICancelled between cascades.
    span_scale : the object-space span is ``base_span · 2**i / span_scale`` (``CacheSource``).
    """
    t0 = time.perf_counter()
    check = filter_triangles(key, positions, mesh.triangles)
    if check.dropped:
        result.dropped_triangles[key] = check.dropped
        result.warnings.append(
            f"mesh '{key}': dropped {check.dropped} triangles "
            f"({check.degenerate} zero-area, {check.non_finite} with NaN/inf vertices)")
    tris = np.asarray(mesh.triangles, np.int64)[check.keep]
    texels = texel_albedo(snapshot, mesh, positions, np.flatnonzero(check.keep))
    alphas = texel_alpha(snapshot, mesh, positions, np.flatnonzero(check.keep))
    albedo, spec = triangle_materials(snapshot, mesh)
    albedo, spec = albedo[check.keep], spec[check.keep]
    used = np.unique(tris)
    timer.add("check", t0)
    caches: list[VoxelCache | None] = []
    if len(tris) == 0:
        result.warnings.append(f"mesh '{key}' has no usable faces; it gets no voxels")
        result.caches[key] = [None] * cascade_count
        return
    skin = mesh.skin
    finer = False
    for cascade in range(cascade_count):
        if cancel is not None and cancel():
            raise VoxGICancelled("voxelization cancelled; no caches were kept")
        span = base_span * 2**cascade / span_scale
        lo, dims = lattice_bounds(np.asarray(positions)[used], span)
        if (dims > MAX_CELLS_PER_AXIS).any():
            result.skipped.append(SkippedMesh(key, cascade, base_span * 2**cascade,
                                              tuple(int(d) for d in dims)))
            caches.append(None)
            continue
        t0 = time.perf_counter()
        surface = voxelize_triangles(positions, tris, span)
        timer.add("voxelize", t0)
        t0 = time.perf_counter()
        attrs = average_attributes(surface, positions, tris, albedo, spec,
                                   None if skin is None else skin.weights,
                                   None if skin is None else skin.bone_indices, texels, alphas)
        cells = surface.cells
        keep = covered_voxels(cells, attrs.coverage, cascade)
        if keep is not None:
            cells, attrs = np.asarray(cells)[keep], _kept(attrs, keep)
        timer.add("attributes", t0)
        t0 = time.perf_counter()
        caches.append(pack_cache(key, cascade, span, lo, dims, cells, attrs, finer))
        timer.add("pack", t0)
        finer = True
    result.caches[key] = caches


def check_build_request(snapshot, base_span: float, cascade_count: int) -> None:
    """Raise VoxGIError for settings or a snapshot that cannot be voxelized."""
    if not (np.isfinite(base_span) and base_span > 0):
        raise VoxGIError(f"base voxel span must be a positive number of metres, got {base_span!r}")
    if not 1 <= int(cascade_count) <= 8:
        raise VoxGIError(f"cascade count must be between 1 and 8, got {cascade_count!r}")
    if not snapshot.objects:
        raise VoxGIError("the scene has no visible mesh objects to voxelize")


def build_scene_caches(snapshot: SceneSnapshot, base_span: float, cascade_count: int,
                       cancel=None) -> CacheBuildResult:
    """Voxelize every mesh of a snapshot at ``cascade_count`` spans (``base_span · 2**i``).

    cancel : optional callable returning True to stop; raises VoxGICancelled between meshes
        and between the cascades of a mesh.
    Raises VoxGIError for unusable input (no mesh objects, bad settings).
    """
    check_build_request(snapshot, base_span, cascade_count)
    result = CacheBuildResult(warnings=list(snapshot.warnings))
    timer = StageTimer(result.timings)
    sources = cache_sources(snapshot, result)
    for key, source in sources.items():
        if cancel is not None and cancel():
            raise VoxGICancelled("voxelization cancelled; no caches were kept")
        build_mesh_caches(key, source.positions, source.mesh, snapshot, base_span, cascade_count,
                          result, timer, cancel, source.span_scale)
    add_cascade_stats(result, base_span, cascade_count)
    return result


def add_cascade_stats(result: CacheBuildResult, base_span: float, cascade_count: int) -> None:
    """Fill ``result.cascade_stats`` (voxels and bytes per cascade) from its caches."""
    result.cascade_stats = []
    for cascade in range(cascade_count):
        present = [c[cascade] for c in result.caches.values() if c[cascade] is not None]
        result.cascade_stats.append(CascadeStats(
            cascade, base_span * 2**cascade,
            sum(c.voxel_count for c in present), sum(c.nbytes for c in present)))
