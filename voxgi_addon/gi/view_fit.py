"""View-fitted cascades: the voxel span and the cascades' centre from what the camera sees.

The thesis anchors the cascades on the camera with a fixed base span (``place_cascades``). A
camera standing far from the geometry then looks at nothing but its coarsest cascade. Here
(docs/gi_pipeline.md "View-fitted cascades"):

1. ``probe_view`` casts a coarse grid of exact primary rays (``PROBE_WIDTH`` columns, the
   camera's aspect) and keeps the hit points, one per pixel: near geometry, which fills more
   of the image, gets more points. Without a camera (or hits) the triangles' centres, weighted
   by area, stand in.
2. ``fit_view`` picks the resolution (the largest that the memory budget allows for the
   cascade count, ``voxel_memory_bytes``), then the finest base span ``SPAN_UNIT``·2^k for
   which cascade 0 holds ``finest_share`` of the probe points and cascades 0–1 hold
   ``two_finest_share`` of them, each at least ``margin_cells`` cells inside its faces. The
   coarser cascades double outward from there over the surroundings that bounce light into
   view. The common centre sits on the visible points (per axis the middle of their 2–98%
   range, or of the densest window one finest cascade wide when they spread wider), snapped
   to whole coarsest voxels like the camera-anchored centre.
3. The span never drops below what the voxel caches allow: every mesh must fit the cache's
   1024 cells per axis in the coarsest cascade, and the caches' estimated size
   (``cache_memory_bytes``) must stay within the budget.

Spans are powers of two of ``SPAN_UNIT``, so a small camera move keeps the span (and the
session's voxel caches of that span); ``fit_view(previous=...)`` adds hysteresis: the previous
span and centre stay while they still hold ``HYSTERESIS`` less than the targets. Everything is
deterministic.
"""
from __future__ import annotations

import dataclasses
import hashlib
import math
import weakref
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGIError
from ..scene.geometry import world_triangles
from ..scene.raycast import camera_first_hits, few_rays_grid, primary_visibility
from ..voxelize.packing import MAX_CELLS_PER_AXIS
from .cascades import MAX_CASCADES, CascadeGrid, place_cascades

__all__ = ["SPAN_UNIT", "PROBE_WIDTH", "FitSettings", "ViewProbe", "ViewFit", "probe_view",
           "cascade_shares", "fit_view", "voxel_memory_bytes", "cache_memory_bytes",
           "RESOLUTIONS"]

SPAN_UNIT = 1.0          # metres: fitted spans are SPAN_UNIT · 2^k (exact in binary)
PROBE_WIDTH = 64         # probe rays per image row (rows follow the camera's aspect)
RESOLUTIONS = (32, 64, 128, 256)
HYSTERESIS = 0.05        # shares the previous fit may lose before it is replaced
_SPAN_RANGE = (-14, 12)  # k of the finest / coarsest base span considered (0.06 mm .. 4 km)
_QUANTILES = (0.02, 0.98)

# Memory model of the cascades (calibrated on the octree's own stats, ``VoxelOctree.stats``
# and ``preview/volume_textures.volume_atlas``): the GPU atlas holds every octree level as a
# dense block of 7 RGBA16F tables; the CPU octree keeps 73 bytes per dense node, a sparse
# level an int32 index map over its window plus about 175 bytes per present node, of which a
# cascade has about 3·res² (a surface crossing its cube).
_ATLAS_BYTES_PER_TEXEL = 8 * 7
_DENSE_NODE_BYTES = 73
_SPARSE_NODE_BYTES = 175
_SPARSE_NODES_PER_RES2 = 3
_INDEX_MAP_LIMIT = 128 ** 3
# Voxel caches: 12 bytes per voxel (20 when skinned); a surface of area A touches about
# 1.5·A/span² cells of a conservative voxelization.
_CACHE_VOXEL_BYTES = 12
_CELLS_PER_AREA = 1.5


@dataclass(frozen=True)
class FitSettings:
    """How ``fit_view`` fits the cascades.

    budget_bytes : memory for the cascades' volume (GPU atlas + CPU octree, estimated by
        ``voxel_memory_bytes``); the voxel caches must fit it too (``cache_memory_bytes``).
    cascade_count : cascades (1..8). dense_depth : octree levels stored dense (as GISettings).
    finest_share, two_finest_share : shares of the visible points that cascade 0, and
        cascades 0–1, must hold. margin_cells : a point counts for a cascade only this many
        cells inside its faces (cones need some room around a surface).
    resolutions : grid resolutions to choose from (powers of two), largest that fits wins.
    probe_width : probe rays per image row.
    """

    budget_bytes: int = 256 * 1_000_000
    cascade_count: int = 3
    dense_depth: int = 6
    finest_share: float = 0.9
    two_finest_share: float = 0.99
    margin_cells: int = 2
    resolutions: tuple[int, ...] = RESOLUTIONS
    probe_width: int = PROBE_WIDTH


@dataclass(frozen=True, eq=False)
class ViewProbe:
    """What the fit looks at. points : (N, 3) float64 world metres; weights : (N,) float64
    summing to 1 (one probe pixel each, or triangle area); source : 'camera' (probe rays hit
    something) or 'triangles' (no camera or nothing in view: the triangles' centres)."""

    points: np.ndarray
    weights: np.ndarray
    source: str
    width: int = 0
    height: int = 0
    # digest of what it was cast from (``view_key``): a fit of an unchanged view reuses it
    key: bytes = b""
    # what the objects other than the skinned ones showed the rays (``_StillView``): the next
    # probe of a pose traces only the skinned ones (docs/gi_pipeline.md "Posed updates")
    still: object = None


@dataclass(frozen=True, eq=False)
class _StillView:
    """The probe rays' first hits on a snapshot's objects other than its skinned ones: the
    camera and width, those objects' placements, meshes and materials they were cast
    against (``same_as``), and per ray the hit distance, point and whether it shows a point
    (not the background or a holdout)."""

    camera: tuple
    objects: tuple
    meshes: tuple
    materials: object
    textures: object
    depth: np.ndarray
    position: np.ndarray
    hit: np.ndarray

    @staticmethod
    def inputs(snapshot, width, still):
        camera = tuple(_value_bytes(getattr(snapshot.camera, f.name))
                       for f in dataclasses.fields(snapshot.camera)) + (int(width),)
        objects = tuple((o.name, o.mesh, o.kind, _value_bytes(o.world_matrix), o.visibility,
                         o.holdout) for o in still)
        return camera, objects, tuple(snapshot.meshes.get(o.mesh) for o in still)

    def same_as(self, snapshot, width, still) -> bool:
        camera, objects, meshes = self.inputs(snapshot, width, still)
        return (camera == self.camera and objects == self.objects
                and all(a is b for a, b in zip(meshes, self.meshes, strict=True))
                and snapshot.materials is self.materials and snapshot.textures is self.textures)


@dataclass(frozen=True, eq=False)
class ViewFit:
    """The fitted cascades.

    base_span : cascade 0 voxel edge (metres, SPAN_UNIT·2^k); resolution; cascade_count;
    centre : (3,) float64 common centre, a multiple of the coarsest span.
    shares : (count + 1,) share of the probe's points whose finest cascade is i (no margin);
        the last entry is outside every cascade.
    memory_bytes : estimated cascade volume (``voxel_memory_bytes``); cache_bytes : estimated
    voxel caches; budget_bytes; probe : the ViewProbe; warnings : what kept the fit from its
    targets.
    """

    base_span: float
    resolution: int
    cascade_count: int
    centre: np.ndarray
    shares: np.ndarray
    memory_bytes: int
    cache_bytes: int
    budget_bytes: int
    probe: ViewProbe = field(repr=False)
    warnings: tuple[str, ...] = ()

    def grids(self) -> list[CascadeGrid]:
        return place_cascades(self.centre, self.base_span, self.resolution, self.cascade_count)


# ------------------------------------------------------------------------------ probe

def _feed(digest, value) -> None:
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        digest.update(f"{a.dtype.str}{a.shape}".encode())
        digest.update(a.tobytes())
    else:
        digest.update(repr(value).encode())


def view_key(snapshot, width: int) -> bytes:
    """Digest of everything the probe and the mesh sizes read: the camera, every object's
    matrix, kind and mesh (positions, triangles), the armatures' matrices, and ``width``.
    Hashing is ~1000× cheaper than casting the probe, so an unchanged view costs nearly
    nothing to fit again."""
    digest = hashlib.blake2b(digest_size=16)
    _feed(digest, int(width))
    camera = snapshot.camera
    if camera is not None:
        for f in dataclasses.fields(camera):
            _feed(digest, getattr(camera, f.name))
    for obj in snapshot.objects:
        for value in (obj.name, obj.mesh, obj.kind, obj.armature, obj.world_matrix):
            _feed(digest, value)
    for name in sorted(snapshot.meshes):
        mesh = snapshot.meshes[name]
        for value in (name, mesh.positions, mesh.triangles):
            _feed(digest, value)
        skin = mesh.skin
        if skin is not None:
            for value in (skin.armature, skin.weights, skin.bone_indices):
                _feed(digest, value)
    for name in sorted(snapshot.armatures):
        arm = snapshot.armatures[name]
        for value in (name, arm.rest_matrices, arm.pose_matrices, arm.world_matrix):
            _feed(digest, value)
    return digest.digest()


def _value_bytes(value):
    return np.asarray(value).tobytes() if isinstance(value, np.ndarray) else value


def _first_hits(snapshot, objects, camera, width, height):
    """(depth (N,), point (N, 3), shows a point (N,)) of the probe rays on ``objects`` only."""
    tris = world_triangles(dataclasses.replace(snapshot, objects=objects), shading=False)
    return camera_first_hits(tris, camera, width, height)


def _split_hits(snapshot, width, height, previous: ViewProbe | None):
    """The probe rays' hit points and a ``_StillView``, tracing the skinned objects and the
    others apart: the others' hits are taken from ``previous`` when it was cast against the
    same of them from the same camera. The nearer of the two hits along a ray is the one a
    single trace of every triangle finds (same distances, same point), so the probe is the
    same either way."""
    moving = [o for o in snapshot.objects if o.kind == "skinned"]
    still = [o for o in snapshot.objects if o.kind != "skinned"]
    camera = snapshot.camera
    kept = None if previous is None else previous.still
    if kept is None or not kept.same_as(snapshot, width, still):
        depth, position, hit = _first_hits(snapshot, still, camera, width, height)
        kept = _StillView(*_StillView.inputs(snapshot, width, still), snapshot.materials,
                          snapshot.textures, depth, position, hit)
    depth, position, hit = _first_hits(snapshot, moving, camera, width, height)
    nearer = depth < kept.depth
    hit = np.where(nearer, hit, kept.hit)
    position = np.where(nearer[:, None], position, kept.position)
    return position[hit], kept


def probe_view(snapshot, width: int = PROBE_WIDTH, triangles=None,
               previous: ViewProbe | None = None, key: bytes | None = None) -> ViewProbe:
    """Hit points of a ``width``-column grid of exact primary rays of the snapshot's camera (the
    rows follow its aspect), or, without a camera or hits, the area-weighted triangle centres.
    previous : an earlier probe: what its rays showed of the objects that are not skinned is
    reused when they, the camera and the materials are the same (a pose traces only the
    skinned objects; ``_split_hits``).
    key : the snapshot's ``view_key`` when the caller has it.
    Raises VoxGIError when the snapshot has no triangles at all."""
    if key is None:
        key = view_key(snapshot, width) if triangles is None else b""
    camera = snapshot.camera
    seen = camera is not None and camera.type in ("PERSP", "ORTHO")
    if seen and triangles is None and any(o.kind == "skinned" for o in snapshot.objects) and \
            any(o.kind != "skinned" for o in snapshot.objects):
        w0, h0 = camera.resolution
        height = max(1, int(round(width * h0 / max(w0, 1))))
        points, still = _split_hits(snapshot, width, height, previous)
        if len(points):
            return ViewProbe(points, np.full(len(points), 1.0 / len(points)), "camera",
                             width, height, key, still)
    tris = world_triangles(snapshot, shading=False) if triangles is None else triangles
    if len(tris) == 0:
        raise VoxGIError("the scene has no triangles to fit the cascades to")
    if triangles is None:
        few_rays_grid(tris)
    if seen:
        w0, h0 = camera.resolution
        height = max(1, int(round(width * h0 / max(w0, 1))))
        hits = primary_visibility(tris, camera, width, height)
        points = hits.position[hits.hit]
        if len(points):
            return ViewProbe(points, np.full(len(points), 1.0 / len(points)), "camera",
                             width, height, key)
    corners = np.asarray(tris.positions, np.float64)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1)
    keep = np.isfinite(area) & (area > 0)
    if not keep.any():
        raise VoxGIError("the scene has no triangles with an area to fit the cascades to")
    return ViewProbe(corners[keep].mean(axis=1), area[keep] / area[keep].sum(), "triangles",
                     key=key)


def cascade_shares(probe: ViewProbe, grids: list[CascadeGrid], margin_cells: int = 0) -> np.ndarray:
    """(len(grids) + 1,) share of the probe's weight whose finest cascade is i (a point counts
    for a cascade ``margin_cells`` or more cells inside its faces); the last entry: in none."""
    shares = np.zeros(len(grids) + 1)
    left = np.ones(len(probe.points), bool)
    for i, grid in enumerate(grids):
        cells = grid.cells_of(probe.points)
        inside = left & ((cells >= margin_cells) & (cells < grid.resolution - margin_cells)).all(axis=1)
        shares[i] = probe.weights[inside].sum()
        left &= ~inside
    shares[-1] = probe.weights[left].sum()
    return shares


# ------------------------------------------------------------------------------ memory

def voxel_memory_bytes(resolution: int, cascade_count: int, dense_depth: int = 6) -> int:
    """Estimated bytes of the cascades' volume: the GPU atlas (every octree level as a
    zero-bordered block of 7 RGBA16F tables, ``volume_textures``) plus the CPU octree."""
    res_level = int(math.log2(resolution))
    depth = res_level + cascade_count - 1
    # Dense levels hold all 2^ℓ nodes per axis, sparse ones a window of at most one cascade.
    windows = [2 ** level if level <= dense_depth else 2 ** min(level, res_level)
               for level in range(depth + 1)]
    pad = max(windows) + 2
    atlas = _ATLAS_BYTES_PER_TEXEL * pad * pad * sum(w + 2 for w in windows)
    cpu = 0
    for level, w in enumerate(windows):
        if level <= dense_depth:
            cpu += _DENSE_NODE_BYTES * w ** 3
        else:
            cpu += (4 * w ** 3 if w ** 3 <= _INDEX_MAP_LIMIT else 0)
            cpu += _SPARSE_NODE_BYTES * _SPARSE_NODES_PER_RES2 * w * w
    return int(atlas + cpu)


def _mesh_sizes(snapshot) -> tuple[float, float]:
    """(largest object extent in metres (an upper bound: object AABB × largest axis scale),
    total surface area in m² of every object)."""
    largest, area = 0.0, 0.0
    for obj in snapshot.objects:
        mesh = snapshot.meshes.get(obj.mesh)
        if mesh is None or len(mesh.triangles) == 0:
            continue
        scale = float(np.linalg.norm(np.asarray(obj.world_matrix, np.float64)[:3, :3], axis=0).max())
        sizes = _local_sizes(mesh)
        if not np.isfinite(scale) or sizes is None:
            continue
        largest = max(largest, sizes[0] * scale)
        area += sizes[1] * scale * scale
    return largest, area


_SIZES: dict[int, tuple] = {}


def _local_sizes(mesh) -> tuple[float, float] | None:
    """(largest extent, surface area) of ``mesh`` in its own space (None: no finite vertex),
    kept per mesh while it lives: a pose or a move fits again with the same meshes
    (docs/gi_pipeline.md "Posed updates"), 2 ms a fit on the imported rig."""
    kept = _SIZES.get(id(mesh))
    if kept is not None and kept[0]() is mesh and kept[1] is mesh.positions \
            and kept[2] is mesh.triangles:
        return kept[3]
    positions = np.asarray(mesh.positions, np.float64)
    finite = positions[np.isfinite(positions).all(axis=1)]  # NaN vertices are dropped
    sizes = None
    if len(finite):
        tri = positions[np.asarray(mesh.triangles, np.int64)]
        a = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        sizes = (float((finite.max(axis=0) - finite.min(axis=0)).max()), float(np.nansum(a)))
    try:
        ref = weakref.ref(mesh, lambda _, key=id(mesh): _SIZES.pop(key, None))
    except TypeError:  # not weakly referable: not kept
        return sizes
    _SIZES[id(mesh)] = (ref, mesh.positions, mesh.triangles, sizes)
    return sizes


def cache_memory_bytes(area: float, base_span: float, cascade_count: int) -> int:
    """Estimated bytes of voxel caches of ``area`` m² of surface at ``cascade_count`` spans."""
    cells = sum(_CELLS_PER_AREA * area / (base_span * 2.0 ** i) ** 2 for i in range(cascade_count))
    return int(cells * _CACHE_VOXEL_BYTES)


# ------------------------------------------------------------------------------ fit

def _weighted_quantiles(values: np.ndarray, weights: np.ndarray, qs) -> np.ndarray:
    order = np.argsort(values, kind="stable")
    v, cw = values[order], np.cumsum(weights[order])
    idx = np.searchsorted(cw, np.asarray(qs) * cw[-1], side="left")
    return v[np.clip(idx, 0, len(v) - 1)]


def _axis_centre(values: np.ndarray, weights: np.ndarray, length: float) -> float:
    """Middle of the 2–98% range of ``values`` when it is at most ``length`` long, else the
    middle of the heaviest window ``length`` long (first one on ties)."""
    lo, hi = _weighted_quantiles(values, weights, _QUANTILES)
    if hi - lo <= length:
        return 0.5 * (lo + hi)
    order = np.argsort(values, kind="stable")
    v, w = values[order], weights[order]
    cw = np.concatenate([[0.0], np.cumsum(w)])
    end = np.searchsorted(v, v + length, side="right")
    best = int(np.argmax(cw[end] - cw[np.arange(len(v))]))
    return 0.5 * (v[best] + v[end[best] - 1])


def _centre(probe: ViewProbe, base_span: float, resolution: int, count: int,
            margin_cells: int) -> np.ndarray:
    inner = (resolution - 2 * margin_cells) * base_span
    c = np.array([_axis_centre(probe.points[:, a], probe.weights, inner) for a in range(3)])
    coarsest = base_span * 2.0 ** (count - 1)
    return np.floor(c / coarsest + 0.5) * coarsest


def _meets(shares: np.ndarray, count: int, settings: FitSettings, slack: float = 0.0) -> bool:
    if count == 1:
        return shares[0] >= settings.two_finest_share - slack
    return (shares[0] >= settings.finest_share - slack
            and shares[0] + shares[1] >= settings.two_finest_share - slack)


def _pick_resolution(settings: FitSettings, warnings: list) -> tuple[int, int]:
    options = sorted(int(r) for r in settings.resolutions)
    fitting = [r for r in options
               if voxel_memory_bytes(r, settings.cascade_count, settings.dense_depth)
               <= settings.budget_bytes]
    if not fitting:
        warnings.append(f"the voxel memory budget ({settings.budget_bytes / 1e6:.0f} MB) is "
                        f"below the smallest grid's need; using {options[0]}³")
    res = fitting[-1] if fitting else options[0]
    return res, voxel_memory_bytes(res, settings.cascade_count, settings.dense_depth)


def fit_view(snapshot, settings: FitSettings = FitSettings(), previous: ViewFit | None = None,
             probe: ViewProbe | None = None) -> ViewFit:
    """The view-fitted cascades of ``snapshot`` (see the module docstring).

    previous : the last fit of this scene; it is kept (span, centre and all) while its shares
        stay within ``HYSTERESIS`` of the targets and the resolution and count are unchanged,
        and its span is kept while a finer one does not meet the targets.
    probe : a ViewProbe to use instead of casting the probe rays again. Without one, the
        previous fit's probe is reused when its ``view_key`` is this snapshot's (nothing in
        view moved), else the probe rays are cast.
    Raises VoxGIError for a scene without triangles or bad settings.
    """
    count = int(settings.cascade_count)
    if not 1 <= count <= MAX_CASCADES:
        raise VoxGIError(f"cascade count must be between 1 and {MAX_CASCADES}, got {count!r}")
    warnings: list[str] = []
    if probe is None:
        key = view_key(snapshot, settings.probe_width)
        if previous is not None and previous.probe.key and previous.probe.key == key:
            probe = previous.probe
        else:
            probe = probe_view(snapshot, settings.probe_width, key=key,
                               previous=None if previous is None else previous.probe)
    res, memory = _pick_resolution(settings, warnings)
    margin = int(settings.margin_cells)
    largest, area = _mesh_sizes(snapshot)

    # The finest span the caches allow: every mesh inside 1024 cells in the coarsest cascade,
    # the caches' estimated size within the budget.
    k_floor = _SPAN_RANGE[0]
    if largest > 0:
        need = largest / (MAX_CELLS_PER_AXIS - 1) / 2.0 ** (count - 1)
        k_floor = max(k_floor, math.ceil(math.log2(need / SPAN_UNIT)))
    while k_floor < _SPAN_RANGE[1] and \
            cache_memory_bytes(area, SPAN_UNIT * 2.0 ** k_floor, count) > settings.budget_bytes:
        k_floor += 1

    def placed(k):
        span = SPAN_UNIT * 2.0 ** k
        centre = _centre(probe, span, res, count, margin)
        grids = place_cascades(centre, span, res, count)
        return span, centre, cascade_shares(probe, grids, margin)

    def result(span, centre):
        grids = place_cascades(centre, span, res, count)
        return ViewFit(span, res, count, centre, cascade_shares(probe, grids), memory,
                       cache_memory_bytes(area, span, count), int(settings.budget_bytes), probe,
                       tuple(warnings))

    same_shape = previous is not None and previous.resolution == res and \
        previous.cascade_count == count
    if same_shape and previous.base_span >= SPAN_UNIT * 2.0 ** k_floor * (1 - 1e-12):
        kept = cascade_shares(probe, previous.grids(), margin)
        if _meets(kept, count, settings, HYSTERESIS):
            finer_k = round(math.log2(previous.base_span / SPAN_UNIT)) - 1
            if finer_k < k_floor or not _meets(placed(finer_k)[2], count, settings):
                return result(previous.base_span, np.asarray(previous.centre, np.float64))

    # A cube holding a share f > ½ of the weight covers the (1 − f)–f range on every axis, so
    # nothing finer than that range's width over the resolution can meet the targets.
    f = float(settings.finest_share)
    spread = 0.0 if f <= 0.5 else max(
        float(np.ptp(_weighted_quantiles(probe.points[:, a], probe.weights, (1 - f, f))))
        for a in range(3))
    k_start = max(k_floor, math.floor(math.log2(max(spread, 1e-9) / res / SPAN_UNIT)) - 1)
    best = None
    for k in range(k_start, _SPAN_RANGE[1] + 1):
        span, centre, shares = placed(k)
        if _meets(shares, count, settings):
            best = (span, centre)
            break
    if best is None:  # nothing meets the targets (points spread beyond 4 km?): the coarsest
        warnings.append("no voxel span fits the view; using the coarsest considered")
        span, centre, _ = placed(_SPAN_RANGE[1])
        best = (span, centre)
    elif k == k_floor and k_floor > _SPAN_RANGE[0]:
        _, _, finer = placed(k_floor - 1)
        if _meets(finer, count, settings):
            warnings.append(
                f"the voxel span is held at {best[0]:g} m by the voxel caches (largest mesh "
                f"{largest:.3g} m must fit {MAX_CELLS_PER_AXIS} voxels in the coarsest cascade; "
                f"caches within the memory budget); the view would allow {best[0] / 2:g} m")
    return result(*best)
