"""Camera-centred nested cascade grids and the world voxels of each (Yalçıner 2016, 4.3 & 4.7).

Every update, each object's cached voxels (object space, built once by ``mesh_caches``) are
transformed to world space — one matrix for static and rigid objects, per-voxel blended bone
matrices for skinned ones — placed on the cascade lattice, culled outside the grid, and dropped
where the finer cascade already holds that mesh. Voxels landing in one cell are merged. No mesh
is re-voxelized.

Placing a voxel (``transform_mode``):

* ``'patch'`` (default; the thesis' "voxel fractions" future work): every cache voxel stores its
  surface plane (normal + plane offset, ``voxel_packing``). The voxel becomes a small planar
  patch — its plane clipped to its own object-space cube, shrunk by ``PATCH_SHRINK`` voxel — which
  is transformed by the voxel's matrix and conservatively voxelized into the cascade lattice
  with the exact ``voxelize_triangles``. The patch can touch up to a few cells; each touched cell
  gets the voxel's attributes. Because the shrunk patch lies strictly inside its cube, a
  rotation by multiples of 90° or a whole-voxel move (cache lattice onto grid lattice) lands
  every patch inside exactly one cell: those transforms equal re-voxelization exactly, as in
  centre mode. At other angles the result follows the transformed surface, not its voxel
  centres (≥ 0.95 IoU against re-voxelizing at 45° in the tests, instead of ~0.6).
* ``'centre'``: the cell holding the transformed voxel centre (Yalçıner 2016, Fig. 4.15).

Grids follow ``docs/gi_pipeline.md``: cascade 0 is the finest, span_i = base_span·2^i, all
share one centre snapped to the coarsest span, so cascade i−1 covers exactly the cells
``[res/4, 3·res/4)`` of cascade i.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import VoxGIError
from ..scene.skinning import blend_matrices, skin_matrices, transform_normals, transform_points
from ..scene.snapshot import ObjectData, SceneSnapshot
from ..voxelize import object_scale
from ..voxelize.cache import VoxelCache
from ..voxelize.cube_clipping import MAX_PATCH_VERTICES, PATCH_SHRINK, voxel_patches
from ..voxelize.scene_caches import CacheBuildResult
from ..voxelize.surface import voxelize_triangles

__all__ = ["CascadeGrid", "CascadeVoxels", "place_cascades", "build_cascades", "merge_voxels",
           "cells_within", "place_objects", "merge_placement", "Placement", "ObjectPlacement", "grids_key",
           "transformed_cell_bounds", "voxel_patches", "TRANSFORM_MODES", "PATCH_SHRINK"]

MAX_CASCADES = 8
TRANSFORM_MODES = ("patch", "centre")
_SPAN_TOLERANCE = 1e-9



def cells_within(cells: np.ndarray, low, high) -> np.ndarray:
    """(…, 3) cells → (…,) bool: every coordinate in [low, high) (low, high: scalars or (3,)).
    A column at a time: numpy's ``all`` over rows of 3 is 20–30 times slower, and the posed
    update asks this of every voxel and shadow-ray point (docs/gi_pipeline.md "Posed
    updates")."""
    c = np.asarray(cells)
    x, y, z = c[..., 0], c[..., 1], c[..., 2]
    if np.ndim(low) == 0 and np.ndim(high) == 0:  # (no broadcast_to: 5 µs a call)
        return (x >= low) & (x < high) & (y >= low) & (y < high) & (z >= low) & (z < high)
    (lx, ly, lz), (hx, hy, hz) = np.broadcast_to(low, (3,)), np.broadcast_to(high, (3,))
    return (x >= lx) & (x < hx) & (y >= ly) & (y < hy) & (z >= lz) & (z < hz)

@dataclass(frozen=True, eq=False)
class CascadeGrid:
    """One cascade: cell (i, j, k) covers ``origin + [i, i+1)·span`` (world metres) per axis.

    index : 0 = finest. span : voxel edge in metres. resolution : cells per axis (power of two).
    origin : (3,) float64 world position of the grid's minimum corner (read-only).
    """

    index: int
    span: float
    resolution: int
    origin: np.ndarray

    def __post_init__(self):
        origin = np.array(self.origin, np.float64).reshape(3)
        origin.setflags(write=False)
        object.__setattr__(self, "origin", origin)

    @property
    def size(self) -> float:
        """Edge length of the grid cube in metres."""
        return self.resolution * self.span

    @property
    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """World AABB of the grid: (min (3,), max (3,)) float64 metres."""
        return self.origin, self.origin + self.size

    def cells_of(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N, 3) int64 cells holding them, ``floor((p − origin)/span)``.

        Not clipped: use ``contains`` to keep the ones inside the grid.
        """
        return np.floor((np.asarray(points, np.float64) - self.origin) / self.span).astype(np.int64)

    def contains(self, cells: np.ndarray) -> np.ndarray:
        """(N, 3) integer cells → (N,) bool, True where every coordinate is in [0, resolution)."""
        return cells_within(cells, 0, self.resolution)


@dataclass(frozen=True, eq=False)
class CascadeVoxels:
    """The merged world voxels of one cascade.

    grid : the cascade. cells : (N, 3) int32 unique cells, sorted by (x, y, z).
    albedo : (N, 3) float32 mean linear RGB. normal : (N, 3) float32 unit world normals.
    specular : (N,) float32 mean. count : (N,) int32 cache voxels merged into the cell (in
        patch mode: whose patch touches the cell).
    mesh_has_finer : (N,) bool, True when every voxel merged into the cell came from a mesh
        that also has a cache at cascade i−1 (inside the finer cascade's region such voxels
        are dropped, so there it is always False).
    """

    grid: CascadeGrid
    cells: np.ndarray
    albedo: np.ndarray
    normal: np.ndarray
    specular: np.ndarray
    count: np.ndarray
    mesh_has_finer: np.ndarray

    @property
    def voxel_count(self) -> int:
        return len(self.cells)


def _is_power_of_two(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def place_cascades(camera_position, base_span: float, resolution: int,
                   count: int) -> list[CascadeGrid]:
    """The ``count`` nested grids around a camera, finest first.

    camera_position : (3,) world metres. base_span : cascade 0 voxel edge in metres (> 0).
    resolution : cells per axis of every cascade, a power of two ≥ 8. count : 1..8.
    The shared centre is the camera rounded to the coarsest span S = base_span·2^(count−1),
    so the grids move in whole coarse voxels; ``origin_i = C − (resolution/2)·span_i``.
    Raises VoxGIError for a bad camera position or settings.
    """
    cam = np.asarray(camera_position, np.float64)
    if cam.shape != (3,) or not np.isfinite(cam).all():
        raise VoxGIError(f"camera position must be 3 finite numbers, got {camera_position!r}")
    if not (np.isfinite(base_span) and base_span > 0):
        raise VoxGIError(f"base voxel span must be a positive number of metres, got {base_span!r}")
    if int(resolution) != resolution or not _is_power_of_two(int(resolution)) or resolution < 8:
        raise VoxGIError(f"cascade resolution must be a power of two ≥ 8, got {resolution!r}")
    if int(count) != count or not 1 <= count <= MAX_CASCADES:
        raise VoxGIError(f"cascade count must be between 1 and {MAX_CASCADES}, got {count!r}")
    res, count = int(resolution), int(count)
    coarsest = float(base_span) * 2.0 ** (count - 1)
    centre = np.floor(cam / coarsest + 0.5) * coarsest
    grids = []
    for i in range(count):
        span = float(base_span) * 2.0**i
        grids.append(CascadeGrid(i, span, res, centre - (res // 2) * span))
    return grids


def _check_grids(grids) -> None:
    """Grids must be the nested family of ``place_cascades`` (finest first, in order)."""
    for pos, g in enumerate(grids):
        if g.index != pos:
            raise VoxGIError(f"cascade grids must be given finest first with indices 0..n−1; "
                             f"position {pos} holds cascade {g.index}")
        if pos and (g.resolution != grids[0].resolution
                    or abs(g.span - 2 * grids[pos - 1].span) > _SPAN_TOLERANCE * g.span):
            raise VoxGIError("cascade grids must share one resolution and double their span "
                             "outward (use place_cascades)")


class _ObjectTransform:
    """Object space → world for one object at this frame: one matrix, or blended bone matrices.

    span_scale : a cache voxel of object-space span ``c`` is a world voxel of ``c · span_scale``
    (the unit scale of a skinned mesh, ``object_scale.skin_bake``; 1 for the others, whose
    scale is baked into their cache).
    """

    def __init__(self, obj: ObjectData, binding_key: str, snapshot: SceneSnapshot,
                 warnings: list):
        world = np.asarray(obj.world_matrix, np.float64)
        self.bones = None
        self.span_scale = 1.0
        if obj.kind == "skinned":
            self._skinned(obj, world, binding_key, snapshot, warnings)
            return
        self.matrix, stretch = object_scale.split_rigid(world)  # the scale is baked in the cache
        baked = binding_key.partition("|scale:")[2]
        now = "" if object_scale.is_identity(stretch) else object_scale.stretch_key(stretch)
        if baked != now:
            warnings.append(f"object '{obj.name}' changed scale since it was voxelized; its voxels "
                            "keep the old scale until the scene is voxelized again")

    def _skinned(self, obj, world, binding_key, snapshot, warnings):
        """The bones carry the object matrix; the cache is in model space with the residual
        stretch N baked in and spans divided by s (``object_scale.skin_bake``), so every bone
        matrix is right-multiplied by N⁻¹."""
        s, residual = object_scale.skin_bake(world)
        if object_scale.skin_key(obj.mesh, s, residual) != binding_key:
            s, residual = object_scale.parse_skin_key(binding_key, obj.mesh)  # as voxelized
            warnings.append(f"object '{obj.name}' changed scale since it was voxelized; the "
                            "skinning resizes its voxels until the scene is voxelized again")
        self.span_scale = 1.0 if binding_key == obj.mesh else s
        unbake = np.eye(4)
        unbake[:3, :3] = np.linalg.inv(residual)
        self.matrix = world @ unbake
        armature = snapshot.armatures.get(obj.armature) if obj.armature else None
        if armature is not None:
            self.bones = skin_matrices(armature, world) @ unbake
        if self.bones is None or not np.isfinite(self.bones).all():
            self.bones = None
            warnings.append(f"object '{obj.name}': armature '{obj.armature}' is missing or "
                            "has NaN/inf matrices; its voxels stay in the rest pose")

    def all_matrices(self) -> np.ndarray:
        """(M, 4, 4) every matrix a voxel's blended matrix is a convex combination of."""
        if self.bones is None:
            return self.matrix[None]
        return np.concatenate([self.bones, self.matrix[None]])

    def per_voxel(self, cache: VoxelCache, attrs) -> np.ndarray:
        """(4, 4) or (N, 4, 4) matrices for the voxels of ``cache``."""
        if self.bones is None or attrs.weights is None:
            return self.matrix
        return blend_matrices(self.bones, attrs.weights, attrs.bone_indices, fallback=self.matrix)


def _box_corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(8, 3) corners of the box [lo, hi]."""
    pick = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], bool)
    return np.where(pick, hi, lo)


def transformed_cell_bounds(cache: VoxelCache, matrices: np.ndarray, grid: CascadeGrid):
    """Conservative range of grid cells the cache's voxel centres can land in.

    matrices : (M, 4, 4); every voxel's matrix is a convex combination of them (one matrix for
    rigid objects; bones plus the object matrix for skinned ones), so the AABB of the cache box
    transformed by each bounds every transformed centre. Returns lo, hi (3,) int64 inclusive.
    """
    corners = _box_corners(cache.origin_cell * cache.span,
                           (cache.origin_cell + cache.dims) * cache.span)
    world = np.einsum("mij,cj->mci", matrices[:, :3, :3], corners) + matrices[:, None, :3, 3]
    world = world.reshape(-1, 3)
    return grid.cells_of(world.min(axis=0)), grid.cells_of(world.max(axis=0))


def _finer_region(grid: CascadeGrid) -> tuple[int, int]:
    """Cells [lo, hi) per axis of cascade ``grid.index`` that cascade index−1 covers."""
    return grid.resolution // 4, 3 * grid.resolution // 4


def _object_voxels(cache: VoxelCache, transform: _ObjectTransform, grid: CascadeGrid,
                   drop_finer: bool):
    """World voxels of one object's cache in one grid, before merging (or None if none land).

    Returns cells (n, 3) int64, albedo (n, 3), normal (n, 3), specular (n,).
    """
    lo, hi = transformed_cell_bounds(cache, transform.all_matrices(), grid)
    if (hi < 0).any() or (lo >= grid.resolution).any():
        return None  # the whole object misses this cascade
    if drop_finer:
        f0, f1 = _finer_region(grid)
        if (lo >= f0).all() and (hi < f1).all():
            return None  # all inside the finer cascade, which holds this mesh
    attrs = cache.attributes()
    matrices = transform.per_voxel(cache, attrs)
    cells = grid.cells_of(transform_points(matrices, cache.centres()))
    keep = grid.contains(cells)
    if drop_finer:
        f0, f1 = _finer_region(grid)
        keep &= ~cells_within(cells, f0, f1)
    if not keep.any():
        return None
    m = matrices if matrices.ndim == 2 else matrices[keep]
    normal = transform_normals(m, attrs.normal[keep])
    return cells[keep], attrs.albedo[keep], normal, attrs.specular[keep]


def _patch_triangles(count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles of polygons with ``count`` vertices (slots of 6 per voxel).

    Returns triangles (T, 3) int64 vertex indices into the flattened (N·6) vertex array and
    voxel (T,) int64. A polygon with fewer than 3 vertices becomes the point (slot 0) thrice,
    so the caller must put the voxel centre there.
    """
    n = len(count)
    base = np.arange(n, dtype=np.int64) * MAX_PATCH_VERTICES
    k = np.arange(1, MAX_PATCH_VERTICES - 1)  # fan triangles (0, k, k+1)
    use = (k[None, :] + 1 < count[:, None]) | ((k[None, :] == 1) & (count[:, None] < 3))
    voxel, j = np.nonzero(use)
    point = count[voxel] < 3
    tri = np.stack([base[voxel], base[voxel] + np.where(point, 0, k[j]),
                    base[voxel] + np.where(point, 0, k[j] + 1)], axis=1)
    return tri, voxel


def _max_scale(matrices: np.ndarray) -> float:
    """Largest spectral norm of the linear parts of (M, 4, 4) matrices: bounds how far any
    convex combination of them stretches a patch."""
    return float(np.linalg.norm(matrices[:, :3, :3], ord=2, axis=(1, 2)).max())


def _object_patch_voxels(cache: VoxelCache, transform: _ObjectTransform, grid: CascadeGrid,
                         drop_finer: bool):
    """Like ``_object_voxels`` but every voxel is its surface patch, voxelized in the grid.

    Returns one row per (voxel, touched cell): cells (n, 3) int64, albedo, normal, specular.
    """
    res = grid.resolution
    all_m = transform.all_matrices()
    lo, hi = transformed_cell_bounds(cache, all_m, grid)
    if (hi < -1).any() or (lo > res).any():
        return None  # the whole object misses this cascade (patches reach ≤ 1 cell past a tie)
    if drop_finer:
        f0, f1 = _finer_region(grid)
        if (lo >= f0 + 1).all() and (hi < f1 - 1).all():
            return None
    attrs = cache.attributes()
    matrices = transform.per_voxel(cache, attrs)
    object_centres = cache.centres()
    centres = transform_points(matrices, object_centres)
    # a patch stays within (√3/2)·span·scale of its centre: cull by the centre's cell first
    margin = int(np.ceil(0.87 * _max_scale(all_m) * cache.span / grid.span)) + 1
    centre_cells = grid.cells_of(centres)
    keep = cells_within(centre_cells, -margin, res + margin)
    if drop_finer:
        keep &= ~cells_within(centre_cells, f0 + margin, f1 - margin)
    idx = np.flatnonzero(keep)
    if not len(idx):
        return None
    corners, count = cache.patches  # object space, relative to the centres; cached per cache
    count = count[idx].astype(np.int64)
    m = matrices if matrices.ndim == 2 else matrices[idx]
    if m.ndim == 2:  # rotate the corners, move the centres
        world = (corners[idx].reshape(-1, 3) @ m[:3, :3].T.astype(np.float32)).reshape(-1, 6, 3)
        world = world + centres[idx, None, :]
    else:
        poly = corners[idx].astype(np.float64) + object_centres[idx, None, :]
        world = np.einsum("nij,nkj->nki", m[:, :3, :3], poly) + m[:, None, :3, 3]
    tri, tri_voxel = _patch_triangles(count)
    surface = voxelize_triangles(world.reshape(-1, 3) - grid.origin, tri, grid.span)
    # unique (voxel, cell) contacts: a voxel counts once per cell it touches
    pair_voxel = tri_voxel[surface.triangle_of_pair]
    pair_key = np.unique(pair_voxel * len(surface.cells) + surface.cell_of_pair)
    pv, pc = np.divmod(pair_key, len(surface.cells))
    cells = surface.cells[pc].astype(np.int64)
    inside = grid.contains(cells)
    if drop_finer:
        inside &= ~cells_within(cells, f0, f1)
    if not inside.any():
        return None
    pv, cells = pv[inside], cells[inside]
    normal = transform_normals(m, attrs.normal[idx])[pv]
    return cells, attrs.albedo[idx[pv]], normal, attrs.specular[idx[pv]]


def merge_voxels(grid: CascadeGrid, cells, albedo, normal, specular, has_finer) -> CascadeVoxels:
    """Merge voxels sharing a cell: mean albedo/specular, renormalised mean normal, count.

    cells : (n, 3) int inside the grid; albedo (n, 3); normal (n, 3) unit; specular (n,);
    has_finer : (n,) bool. Where opposite normals cancel, the cell keeps its first voxel's normal.
    """
    res = grid.resolution
    c = np.asarray(cells, np.int64).reshape(-1, 3)
    if len(c) == 0:
        z3 = np.zeros((0, 3), np.float32)
        return CascadeVoxels(grid, np.zeros((0, 3), np.int32), z3, z3.copy(),
                             np.zeros(0, np.float32), np.zeros(0, np.int32), np.zeros(0, bool))
    keys = (c[:, 0] * res + c[:, 1]) * res + c[:, 2]
    order = np.argsort(keys, kind="stable")
    keys = keys[order]
    starts = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
    count = np.diff(np.r_[starts, len(keys)])

    def mean(values):
        v = np.asarray(values, np.float64)[order]
        return np.add.reduceat(v, starts, axis=0) / (count if v.ndim == 1 else count[:, None])

    n = mean(normal)
    length = np.linalg.norm(n, axis=1)
    flat = length < 1e-3
    if flat.any():
        n[flat] = np.asarray(normal, np.float64)[order[starts[flat]]]
        length = np.linalg.norm(n, axis=1)
    n /= np.maximum(length, 1e-30)[:, None]
    finer = np.logical_and.reduceat(np.asarray(has_finer, bool)[order], starts)
    return CascadeVoxels(grid, c[order[starts]].astype(np.int32), mean(albedo).astype(np.float32),
                         n.astype(np.float32), mean(specular).astype(np.float32),
                         count.astype(np.int32), finer)


def _cache_at(caches: CacheBuildResult, key: str, grid: CascadeGrid,
              span_scale: float = 1.0) -> tuple[VoxelCache | None, bool]:
    """The mesh's cache at the grid's cascade and whether it has one at the finer cascade.
    span_scale : world span of a cache voxel per object-space span (``_ObjectTransform``)."""
    per_cascade = caches.caches.get(key)
    if per_cascade is None:
        raise VoxGIError(f"no voxel cache for mesh '{key}'; voxelize the scene again")
    i = grid.index
    if i >= len(per_cascade):
        raise VoxGIError(f"the caches hold {len(per_cascade)} cascades but cascade {i} was "
                         "asked for; voxelize the scene again with this cascade count")
    cache = per_cascade[i]
    if cache is not None and abs(cache.span * span_scale - grid.span) > _SPAN_TOLERANCE * grid.span:
        raise VoxGIError(f"mesh '{key}' was voxelized with span {cache.span * span_scale:g} m at "
                         f"cascade {i} "
                         f"but the cascade's span is {grid.span:g} m; voxelize the scene again")
    return cache, i > 0 and per_cascade[i - 1] is not None


@dataclass(eq=False)
class ObjectPlacement:
    """One object's world voxels in every grid, before merging, and what they were made of.

    cache_list : the caches (per cascade) they were placed from (compared by identity);
    signature : the object's matrix, kind, cache key and armature matrices (bytes);
    per_grid : per grid a tuple (cells, albedo, normal, specular, has_finer) or None;
    warnings : what placing it reported (repeated when it is reused).
    """

    cache_list: object
    signature: tuple
    per_grid: list
    warnings: list


@dataclass(eq=False)
class Placement:
    """Every object's placed voxels for one set of grids (``place_objects``). ``placed`` names
    the objects transformed by the call that made it; the others were taken from the
    previous placement as they were."""

    grids_key: tuple
    mode: str
    objects: dict
    placed: tuple
    warnings: list


def grids_key(grids) -> tuple:
    """The identity of a grid family: (index, span, resolution, origin bytes) per grid."""
    return tuple((g.index, float(g.span), int(g.resolution), g.origin.tobytes()) for g in grids)


def _bytes(array) -> bytes:
    return np.ascontiguousarray(np.asarray(array, np.float64)).tobytes()


def object_signature(obj: ObjectData, binding_key: str, snapshot: SceneSnapshot) -> tuple:
    """What an object's placed voxels depend on besides its caches and the grids."""
    armature = snapshot.armatures.get(obj.armature) if obj.armature else None
    bones = () if obj.kind != "skinned" or armature is None else (
        _bytes(armature.rest_matrices), _bytes(armature.pose_matrices),
        _bytes(armature.world_matrix))
    return (binding_key, obj.kind, obj.armature, _bytes(obj.world_matrix), bones)


def place_objects(caches: CacheBuildResult, snapshot: SceneSnapshot, grids: list[CascadeGrid],
                  transform_mode: str = "patch", previous: Placement | None = None) -> Placement:
    """Every bound object's cache voxels placed in every grid (``build_cascades`` before
    merging). With ``previous`` (the placement of an earlier update), an object whose caches,
    matrix and armature pose are unchanged on the same grids is not transformed again: its
    voxels are taken from ``previous``, so an update costs in proportion to what moved.
    Raises VoxGIError when the caches do not fit the grids."""
    if transform_mode not in TRANSFORM_MODES:
        raise VoxGIError(f"transform mode must be one of {TRANSFORM_MODES}, got {transform_mode!r}")
    place = _object_patch_voxels if transform_mode == "patch" else _object_voxels
    _check_grids(grids)
    key = grids_key(grids)
    old = previous.objects if previous is not None and previous.grids_key == key and \
        previous.mode == transform_mode else {}
    objects = {o.name: o for o in snapshot.objects}
    warnings = [f"object '{o.name}' has no voxel cache yet; voxelize the scene to include it"
                for o in snapshot.objects
                if o.name not in caches.bindings and np.isfinite(o.world_matrix).all()]
    out, placed = {}, []
    for name, binding in caches.bindings.items():
        obj = objects.get(name)
        if obj is None:
            continue  # deleted or hidden since voxelization
        if not np.isfinite(obj.world_matrix).all():
            warnings.append(f"object '{name}': its matrix has NaN/inf values; left out")
            continue
        cache_list = caches.caches.get(binding.cache_key)
        signature = object_signature(obj, binding.cache_key, snapshot)
        before = old.get(name)
        if before is not None and before.cache_list is cache_list and \
                before.signature == signature:
            out[name] = before
            continue
        mine: list[str] = []
        transform = _ObjectTransform(obj, binding.cache_key, snapshot, mine)
        per_grid = []
        for grid in grids:
            cache, has_finer = _cache_at(caches, binding.cache_key, grid, transform.span_scale)
            voxels = None
            if cache is not None and cache.voxel_count:
                voxels = place(cache, transform, grid, drop_finer=has_finer)
            per_grid.append(None if voxels is None else
                            (*voxels, np.full(len(voxels[0]), has_finer)))
        out[name] = ObjectPlacement(cache_list, signature, per_grid, mine)
        placed.append(name)
    for item in out.values():
        warnings.extend(item.warnings)
    return Placement(key, transform_mode, out, tuple(placed), warnings)


def merge_placement(placement: Placement, grids: list[CascadeGrid]) -> list[CascadeVoxels]:
    """The merged ``CascadeVoxels`` of every grid from a ``place_objects`` result."""
    out = []
    for grid in grids:
        items = [p.per_grid[grid.index] for p in placement.objects.values()
                 if p.per_grid[grid.index] is not None]
        joined = [np.concatenate(a) for a in zip(*items)] if items else [np.zeros((0, 3))] * 5
        out.append(merge_voxels(grid, *joined))
    return out


def build_cascades(caches: CacheBuildResult, snapshot: SceneSnapshot, grids: list[CascadeGrid],
                   warnings: list[str] | None = None,
                   transform_mode: str = "patch") -> list[CascadeVoxels]:
    """World voxels of every cascade from the cached voxels (no re-voxelization).

    caches : the voxelization result (caches per mesh key and cascade, object bindings).
    snapshot : the current frame: object matrices, kinds and armature poses are read here,
        so moving objects, bones or the camera only needs a new snapshot.
    grids : from ``place_cascades`` (finest first); cache spans (times a skinned cache's unit
        scale) must match the grid spans.
    warnings : optional list that receives messages about objects that could not be placed.
    transform_mode : ``'patch'`` (default) voxelizes each voxel's transformed surface patch;
        ``'centre'`` snaps its transformed centre (see the module docstring). In patch mode
        ``count`` is the number of cache voxels whose patch touches the cell.
    Returns one ``CascadeVoxels`` per grid. Raises VoxGIError when the caches do not fit.
    """
    placement = place_objects(caches, snapshot, grids, transform_mode)
    if warnings is not None:
        warnings.extend(placement.warnings)
    return merge_placement(placement, grids)
