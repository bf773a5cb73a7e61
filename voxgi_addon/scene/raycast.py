"""Exact ray casting against the scene's world-space triangles (numpy only).

* ``closest_hits`` — nearest hit per ray (Möller–Trumbore, double-sided, float64).
* ``occluded`` — any hit closer than a per-ray distance (shadow rays).

Rays are traced through a uniform grid (``TriangleGrid``, built once per ``SceneTriangles`` and
cached): the grid is the project's exact conservative voxelization of the triangles, walked with
a 3D DDA that is vectorised over rays — every step, each live ray tests the triangles of its
current cell and stops once its best hit lies before the cell's exit. Results equal brute force.
"""
from __future__ import annotations

import dataclasses
import weakref
from dataclasses import dataclass

import numpy as np

from ..voxelize.surface import LATTICE_OFFSET, voxelize_triangles
from .camera import camera_ray_lengths, camera_rays, image_points
from .geometry import SceneTriangles
from .snapshot import RAY_CAMERA, RAY_DIFFUSE, RAY_SHADOW, CameraData
from .textures import cutout_hits

__all__ = [
    "TriangleGrid", "build_grid", "closest_hits", "occluded", "SHADOW_EPSILON", "PrimaryHits",
    "primary_visibility", "camera_first_hits",
]

SHADOW_EPSILON = 1e-4  # metres: shadow rays ignore hits this close to either end
_RAY_CHUNK = 1 << 13  # rays traced together: bounds the pair arrays, keeps them in cache
_CELLS_PER_TRIANGLE = 4.0
_MAX_CELLS_PER_AXIS = 128
_DET_EPSILON = 1e-12


# --------------------------------------------------------------------------- grid

@dataclass(frozen=True, eq=False)
class TriangleGrid:
    """Uniform grid over a set of triangles (cells listed in CSR form).

    origin : (3,) float64 world position of the lattice (cell c spans
        ``origin + (c - LATTICE_OFFSET + [0, 1]) · span``, as ``voxelize`` defines cells).
    span : cell edge in metres. dims : (3,) int64 cells per axis.
    cell_start : (X·Y·Z + 2,) int64, triangles of linear cell k are
        ``cell_triangles[cell_start[k]:cell_start[k + 1]]`` (k = x·Y·Z + y·Z + z; k = X·Y·Z is
        an always-empty sentinel cell).
    corners : (10, T) float64 rows: first corner xyz, edge 1 xyz, edge 2 xyz and |e1|·|e2| (the
        scale of the Möller–Trumbore determinant) of each triangle.
    cutout : (``textures.SurfaceTextures``, materials (T,)) of triangles some of whose
        materials are not opaque (a hit on them counts by ``textures.cutout_hits``), or None.
    """

    origin: np.ndarray
    span: float
    dims: np.ndarray
    cell_start: np.ndarray
    cell_triangles: np.ndarray
    corners: np.ndarray
    cutout: tuple | None = None


def cutouts_of(tris, camera: bool = False):
    """(``SurfaceTextures``, materials) of ``tris`` when some triangle is a cut-out, else None;
    ``camera``: as camera rays meet them (glass at its own Alpha, ``SurfaceTextures.for_camera``)."""
    surface = getattr(tris, "textures", None)
    if surface is not None and camera:
        surface = surface.for_camera()
    if surface is None or surface.cutout is None or not np.any(surface.cutout):
        return None
    return surface, np.asarray(tris.materials)


def counted_hits(cutout, good, tri, u, v, origins, directions) -> np.ndarray:
    """``good`` (P,) bool with the hits on cut-out triangles that the ray passes through
    (``textures.cutout_hits``) taken out; origins, directions (P, 3) per pair."""
    if cutout is None or not good.any():
        return good
    surface, materials = cutout
    at = np.flatnonzero(good)
    at = at[surface.cutout[tri[at]]]
    if len(at) == 0:
        return good
    kept = cutout_hits(surface, materials, tri[at], u[at], v[at], np.asarray(origins)[at],
                       np.asarray(directions)[at])
    good = good.copy()
    good[at[~kept]] = False
    return good


def _box_pairs(positions, origin, span, dims) -> tuple[np.ndarray, np.ndarray]:
    """(cell (P, 3), triangle (P,)) pairs of every triangle with each cell its bounding box
    overlaps: more cells than the triangle crosses, found without testing any. A triangle
    with a non-finite corner is in none (no ray hits it)."""
    a, b, c = positions[:, 0], positions[:, 1], positions[:, 2]
    smallest, largest = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    # (per column: numpy's reductions over a row of 3 are slow)
    finite = np.isfinite(smallest[:, 0] + smallest[:, 1] + smallest[:, 2]
                         + largest[:, 0] + largest[:, 1] + largest[:, 2])
    with np.errstate(invalid="ignore"):  # a grid of non-finite bounds lists nothing useful
        low = np.clip(np.floor((smallest - origin) / span + LATTICE_OFFSET)
                      .astype(np.int64), 0, dims - 1)
        high = np.clip(np.floor((largest - origin) / span + LATTICE_OFFSET)
                       .astype(np.int64), 0, dims - 1)
    size = high - low + 1
    count = np.where(finite, size[:, 0] * size[:, 1] * size[:, 2], 0)
    triangle = np.repeat(np.arange(len(positions)), count)
    k = np.arange(len(triangle)) - np.repeat(np.cumsum(count) - count, count)  # index in the box
    sx, sy = size[triangle, 0], size[triangle, 1]
    cell = low[triangle] + np.stack([k % sx, (k // sx) % sy, k // (sx * sy)], axis=1)
    return cell, triangle


def _corner_rows(positions: np.ndarray) -> np.ndarray:
    """(10, T) ``TriangleGrid.corners`` rows of triangles ``positions`` (T, 3, 3)."""
    e1 = positions[:, 1] - positions[:, 0]
    e2 = positions[:, 2] - positions[:, 0]
    scale = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    return np.ascontiguousarray(np.concatenate([positions[:, 0].T, e1.T, e2.T, scale[None]]))


def build_grid(tris: SceneTriangles, cells_per_triangle: float = _CELLS_PER_TRIANGLE,
               exact: bool = True) -> TriangleGrid:
    """A ``TriangleGrid`` with about ``cells_per_triangle`` cells per triangle: fewer cells
    are quicker to build (each triangle is tested against fewer of them) and slower to trace
    through (more triangles per cell), which pays for a few rays (``few_rays_grid``). exact :
    a triangle is listed in the cells it crosses (``voxelize_triangles``); False: in every
    cell its bounding box overlaps (no test; the hits are the same)."""
    positions = np.asarray(tris.positions, dtype=np.float64).reshape(-1, 3, 3)
    count = len(positions)
    lo, hi = tris.bounds
    extent = np.maximum(hi - lo, 1e-9)
    target = float(np.clip(cells_per_triangle * count, 1.0, _MAX_CELLS_PER_AXIS**3))
    span = float(np.cbrt(np.prod(extent) / target))
    span = max(span, float(extent.max()) / _MAX_CELLS_PER_AXIS, 1e-6)
    origin = lo - 0.5 * span
    dims = np.floor((hi - origin) / span + LATTICE_OFFSET).astype(np.int64) + 2
    corners = _corner_rows(positions)
    if count == 0:
        return TriangleGrid(origin, span, dims, np.zeros(int(dims.prod()) + 2, np.int64),
                            np.zeros(0, np.int32), corners, cutouts_of(tris))
    if exact:
        # triangles with a non-finite corner are in no cell (no ray can hit them)
        finite = np.flatnonzero(np.isfinite(positions).all(axis=(1, 2)))
        surface = voxelize_triangles(
            (positions[finite] - origin).reshape(-1, 3),
            np.arange(3 * len(finite)).reshape(-1, 3), span
        )
        cells = surface.cells.astype(np.int64)[surface.cell_of_pair]
        triangles = finite[surface.triangle_of_pair].astype(surface.triangle_of_pair.dtype)
    else:
        cells, triangles = _box_pairs(positions, origin, span, dims)
        triangles = triangles.astype(np.int32)
    keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]
    order = np.argsort(keys, kind="stable")
    counts = np.bincount(keys, minlength=int(dims.prod()) + 1)  # + the empty sentinel cell
    cell_start = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    return TriangleGrid(origin, span, dims, cell_start, triangles[order], corners,
                        cutouts_of(tris))


_GRIDS: "weakref.WeakKeyDictionary[SceneTriangles, TriangleGrid]" = weakref.WeakKeyDictionary()


FEW_RAYS_CELLS_PER_TRIANGLE = 0.1


def few_rays_grid(tris: SceneTriangles) -> None:
    """Build the grid ``tris`` will be traced through with ``FEW_RAYS_CELLS_PER_TRIANGLE``: for
    a few thousand rays (the view fit's probe) building the usual grid costs more than the
    tracing it saves. The hits are the same (every triangle a ray crosses is tested)."""
    if tris not in _GRIDS:
        _GRIDS[tris] = build_grid(tris, FEW_RAYS_CELLS_PER_TRIANGLE, exact=False)


def _grid_of(tris) -> TriangleGrid:
    if isinstance(tris, TriangleGrid):
        return tris
    grid = _GRIDS.get(tris)
    if grid is None:
        grid = _GRIDS[tris] = build_grid(tris)
    return grid


# --------------------------------------------------------------------------- tracing

def _intersect(corners: np.ndarray, o: np.ndarray, d: np.ndarray):
    """Möller–Trumbore on pairs, structure-of-arrays.

    corners : (10, P) rows v0 xyz, e1 xyz, e2 xyz, |e1|·|e2| of each pair's triangle.
    o, d : (3, P) ray origin and direction of each pair.
    Returns t, u, v (P,) float64; t is +inf where the ray misses the triangle.
    """
    v0x, v0y, v0z, e1x, e1y, e1z, e2x, e2y, e2z, scale = corners
    ox, oy, oz = o
    dx, dy, dz = d
    px, py, pz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    sx, sy, sz = ox - v0x, oy - v0y, oz - v0z
    qx, qy, qz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    ok = np.abs(det) > _DET_EPSILON * scale * np.sqrt(dx * dx + dy * dy + dz * dz)
    inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
    u = (sx * px + sy * py + sz * pz) * inv
    v = (dx * qx + dy * qy + dz * qz) * inv
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0)
    return np.where(hit, t, np.inf), u, v


def _pairs(grid: TriangleGrid, keys: np.ndarray):
    """(ray slot, triangle) pairs of the rays whose current cells are ``keys``."""
    start = grid.cell_start[keys]
    count = grid.cell_start[keys + 1] - start
    total = int(count.sum())
    if total == 0:
        return None, None
    slot = np.repeat(np.arange(len(keys)), count)
    first = np.cumsum(count) - count
    offset = np.arange(total) - np.repeat(first, count)
    return slot, grid.cell_triangles[np.repeat(start, count) + offset]


# Rows of the per-ray float state (structure of arrays, one column per live ray); the rows a
# (ray, triangle) pair needs come first so that one gather of ``_PAIR_ROWS`` rows serves them.
_O, _D, _LO, _HI, _FOUND, _NEXT, _DELTA = slice(0, 3), slice(3, 6), 6, 7, 8, 9, 12
_PAIR_ROWS = 9


def _start_state(grid: TriangleGrid, o, d, t_min, t_max):
    """Clip rays to the grid; returns (live ray indices, float state (15, L), cells (3, L), steps (3, L))."""
    span = grid.span
    base = grid.origin - LATTICE_OFFSET * span  # world position of the lattice corner
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        ta = (base - o) * inv
        tb = (base + grid.dims * span - o) * inv
    ta = np.where(np.isnan(ta), -np.inf, ta)
    tb = np.where(np.isnan(tb), np.inf, tb)
    t_enter = np.maximum(t_min, np.minimum(ta, tb).max(axis=1))
    t_leave = np.minimum(t_max, np.maximum(ta, tb).min(axis=1))
    ray = np.flatnonzero(t_enter <= t_leave)
    o, d, inv = o[ray], d[ray], inv[ray]
    g = (o + d * t_enter[ray, None] - base) / span
    cell = np.clip(np.floor(g).astype(np.int64), 0, grid.dims - 1)
    step = np.sign(d).astype(np.int64)
    state = np.empty((15, len(ray)))
    state[_O], state[_D] = o.T, d.T
    with np.errstate(divide="ignore", invalid="ignore"):
        boundary = base + (cell + (step > 0)) * span
        state[_NEXT:_NEXT + 3] = np.where(step != 0, (boundary - o) * inv, np.inf).T
        state[_DELTA:_DELTA + 3] = np.where(step != 0, span * np.abs(inv), np.inf).T
    state[_LO], state[_HI], state[_FOUND] = t_min[ray], t_leave[ray], np.inf
    return ray, state, np.ascontiguousarray(cell.T), np.ascontiguousarray(step.T)


def _trace_chunk(grid: TriangleGrid, o, d, t_min, t_max, any_hit: bool, accept=None):
    """Trace one chunk of rays; returns best t (inf = none), triangle (-1), u, v. accept :
    (T,) bool triangles the rays may hit (their ray visibility), None = all."""
    n = len(o)
    best_t, best_tri = np.full(n, np.inf), np.full(n, -1, dtype=np.int64)
    best_u, best_v = np.zeros(n), np.zeros(n)
    ray, state, cell, step = _start_state(grid, o, d, t_min, t_max)
    dims = grid.dims
    empty_cell = int(dims.prod())  # the sentinel cell of finished rays: no triangles
    finished = np.zeros(len(ray), dtype=bool)
    while len(ray):
        keys = np.where(finished, empty_cell, (cell[0] * dims[1] + cell[1]) * dims[2] + cell[2])
        slot, tri = _pairs(grid, keys)
        if slot is not None:
            pair_state = state[:_PAIR_ROWS, slot]
            t, u, v = _intersect(grid.corners[:, tri], pair_state[_O], pair_state[_D])
            good = (t > pair_state[_LO]) & (t < np.minimum(pair_state[_FOUND], pair_state[_HI]))
            if accept is not None:
                good &= accept[tri]
            good = counted_hits(grid.cutout, good, tri, u, v, pair_state[_O].T, pair_state[_D].T)
            if good.any():
                slot, tri, t, u, v = slot[good], tri[good], t[good], u[good], v[good]
                found = state[_FOUND]
                np.minimum.at(found, slot, t)
                win = t == found[slot]
                target = ray[slot[win]]
                best_t[target], best_tri[target] = t[win], tri[win]
                best_u[target], best_v[target] = u[win], v[win]
        # Step every ray into the neighbour across its nearest cell wall (3D DDA).
        n0, n1, n2 = state[_NEXT], state[_NEXT + 1], state[_NEXT + 2]
        axis = np.where(n0 <= n1, np.where(n0 <= n2, 0, 2), np.where(n1 <= n2, 1, 2))
        t_exit = np.minimum(np.minimum(n0, n1), n2)
        done = (state[_FOUND] <= t_exit) | (t_exit >= state[_HI])
        if any_hit:
            done |= np.isfinite(state[_FOUND])
        live = np.arange(len(ray))
        moved = cell[axis, live] + step[axis, live]
        cell[axis, live] = moved
        state[_NEXT + axis, live] = t_exit + state[_DELTA + axis, live]
        done |= (moved < 0) | (moved >= dims[axis])
        if done.sum() > len(ray) // 8:  # drop finished rays now and then, not at every step
            keep = np.flatnonzero(~done)
            ray, state, cell, step = ray[keep], state[:, keep], cell[:, keep], step[:, keep]
            finished = np.zeros(len(ray), dtype=bool)
        else:
            finished = done
            state[_HI, done] = -np.inf  # stays done
    return best_t, best_tri, best_u, best_v


def _trace(tris, origins, directions, t_min, t_max, any_hit, ray):
    grid = _grid_of(tris)
    surface = getattr(tris, "textures", None)
    if ray == RAY_CAMERA and getattr(surface, "camera_alpha_values", None) is not None:
        grid = dataclasses.replace(grid, cutout=cutouts_of(tris, camera=True))  # glass: opaque
    accept = tris.accepted(ray) if hasattr(tris, "accepted") else None
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    n = len(o)
    t_min = np.broadcast_to(np.asarray(t_min, dtype=np.float64), (n,))
    t_max = np.broadcast_to(np.asarray(t_max, dtype=np.float64), (n,))
    out_t = np.full(n, np.inf)
    out_tri = np.full(n, -1, dtype=np.int64)
    out_u, out_v = np.zeros(n), np.zeros(n)
    if grid.corners.shape[1] == 0:
        return out_t, out_tri, out_u, out_v
    for a in range(0, n, _RAY_CHUNK):
        b = min(n, a + _RAY_CHUNK)
        out_t[a:b], out_tri[a:b], out_u[a:b], out_v[a:b] = _trace_chunk(
            grid, o[a:b], d[a:b], t_min[a:b], t_max[a:b], any_hit, accept
        )
    return out_t, out_tri, out_u, out_v


def closest_hits(tris, origins, directions, t_min=0.0, t_max=np.inf, ray: int = RAY_DIFFUSE):
    """Nearest triangle hit along each ray.

    Parameters
    ----------
    tris : ``SceneTriangles`` (its grid is built on first use and cached) or a ``TriangleGrid``.
    origins, directions : (N, 3) float world space; directions need not be unit (t is then in
        units of their length).
    t_min, t_max : scalar or (N,) bounds; hits with ``t_min < t < t_max`` count.
    ray : the kind of ray (a ``snapshot.RAY_*`` bit): only triangles it sees count
        (``SceneTriangles.visibility``).

    Returns
    -------
    t : (N,) float64 hit distance, +inf for a miss.
    tri : (N,) int64 triangle index into ``tris``, -1 for a miss.
    u, v : (N,) float64 barycentrics of the hit (point = v0 + u·e1 + v·e2), 0 for a miss.
    """
    return _trace(tris, origins, directions, t_min, t_max, False, ray)


def occluded(tris, origins, directions, max_t, epsilon: float = SHADOW_EPSILON,
             ray: int = RAY_SHADOW) -> np.ndarray:
    """(N,) bool: does any triangle that ``ray`` rays see (shadow rays: the objects that cast
    shadows) cross the ray with ``epsilon < t < max_t - epsilon``?

    ``directions`` should be unit vectors so that ``epsilon`` is in metres; ``max_t`` is a scalar
    or (N,) (``inf`` for a directional light).
    """
    max_t = np.asarray(max_t, dtype=np.float64) - epsilon
    t, _, _, _ = _trace(tris, origins, directions, epsilon, max_t, True, ray)
    return np.isfinite(t)


# --------------------------------------------------------------------------- primary visibility

@dataclass(frozen=True)
class PrimaryHits:
    """What the camera sees at each pixel centre (row 0 = top); background pixels are zero/-1.

    hit : (H, W) bool geometry coverage.
    position : (H, W, 3) float64 world-space hit point.
    normal : (H, W, 3) float64 unit shading normal: interpolated ``corner_normals`` where the
        triangles carry them, else the face normal; turned to the camera side of the face (Cycles
        flips both normals of a back-facing hit).
    face_normal : (H, W, 3) float64 unit geometric normal, turned the same way.
    direction : (H, W, 3) float64 unit camera-ray direction (the view vector is its negative).
    depth : (H, W) float64 distance from the near plane along the ray (inf = background).
    triangle, material, object : (H, W) int32 indices into ``SceneTriangles``, the snapshot's
        materials and objects (-1 = background or no material); a material with Roughness /
        Metallic per texel gives its texel's variant (``textures.SurfaceTextures.variant_at``).
    barycentric : (H, W, 2) float64 weights of the hit triangle's corners 1 and 2 (corner 0
        has 1 − both; 0 on the background), or None.
    """

    hit: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    face_normal: np.ndarray
    direction: np.ndarray
    depth: np.ndarray
    triangle: np.ndarray
    material: np.ndarray
    object: np.ndarray
    barycentric: np.ndarray | None = None
    holdout: np.ndarray | None = None  # (H, W) bool: the ray met a holdout (the film's alpha 0)


def primary_visibility(tris: SceneTriangles, camera: CameraData, width: int | None = None,
                       height: int | None = None, offset=(0.0, 0.0)) -> PrimaryHits:
    """Exact primary visibility of a ``width`` × ``height`` image of ``camera`` (see ``camera_rays``;
    ``offset`` moves every ray off its pixel centre); rays stop at the far clipping plane.
    Camera rays see only what Cycles' camera rays see; one that meets a holdout sees nothing
    (``hit`` False there, as on the background)."""
    width = int(width or camera.resolution[0])
    height = int(height or camera.resolution[1])
    origins, directions = camera_rays(camera, width, height, offset)
    t, tri, u, v = closest_hits(tris, origins, directions, 0.0, camera_ray_lengths(camera, directions),
                                RAY_CAMERA)
    holdout = getattr(tris, "holdout", None)
    held = np.zeros(len(tri), bool)
    if holdout is not None:
        held = (tri >= 0) & np.asarray(holdout)[np.maximum(tri, 0)]
        tri = np.where(held, -1, tri)
    hit = tri >= 0
    index = np.where(hit, tri, 0)
    position = np.where(hit[:, None], origins + directions * np.where(hit, t, 0.0)[:, None], 0.0)
    face = np.asarray(tris.normals, dtype=np.float64)[index] if len(tris) else np.zeros((len(t), 3))
    shading = face
    if tris.corner_normals is not None and len(tris):
        corners = np.asarray(tris.corner_normals, dtype=np.float64)[index]
        smooth = ((1.0 - u - v)[:, None] * corners[:, 0] + u[:, None] * corners[:, 1]
                  + v[:, None] * corners[:, 2])
        length = np.linalg.norm(smooth, axis=1, keepdims=True)
        shading = np.where(length > 1e-12, smooth / np.maximum(length, 1e-12), face)
    surface = getattr(tris, "textures", None)
    if surface is not None and surface.normal_slots is not None and hit.any():
        # normal maps: the shading normal perturbed per texel (before it is turned)
        seen = np.flatnonzero(hit)
        shading = np.array(shading, copy=True)
        shading[seen] = surface.normal_at(index[seen], np.asarray(tris.materials)[index[seen]],
                                          u[seen], v[seen], shading[seen])
    sign = np.where(np.einsum("ij,ij->i", face, directions) > 0, -1.0, 1.0)[:, None] * hit[:, None]

    def per_pixel(values):
        out = np.where(hit, np.asarray(values)[index] if len(tris) else -1, -1)
        return out.astype(np.int32).reshape(height, width)

    material = per_pixel(tris.materials)
    if surface is not None and surface.param_slots is not None and hit.any():
        # Roughness / Metallic per texel: the material variant of the hit's texel
        seen = np.flatnonzero(hit)
        flat = material.reshape(-1)
        flat[seen] = surface.variant_at(index[seen], flat[seen], u[seen], v[seen])

    return PrimaryHits(
        hit=hit.reshape(height, width),
        position=position.reshape(height, width, 3),
        normal=(shading * sign).reshape(height, width, 3),
        face_normal=(face * sign).reshape(height, width, 3),
        direction=directions.reshape(height, width, 3),
        depth=t.reshape(height, width),
        triangle=per_pixel(np.arange(len(tris))),
        material=material,
        object=per_pixel(tris.objects),
        barycentric=np.where(hit[:, None], np.stack([u, v], axis=1), 0.0).reshape(height, width, 2),
        holdout=held.reshape(height, width),
    )


# --------------------------------------------------------------------------- a few camera rays

# (ray, triangle) pairs per ray up to which ``camera_first_hits`` tests the pairs directly
PROJECTED_PAIRS_PER_RAY = 16
_PIXEL_MARGIN = 1e-3  # pixels around a triangle's projected bounds (rounding of the projection)


def _projected_pairs(tris: SceneTriangles, camera: CameraData, width: int, height: int,
                     limit: int):
    """(ray, triangle) pairs of the pixel-centre rays of a ``width`` × ``height`` image and
    the triangles whose projected bounds hold that centre (every pair in which the ray can
    hit the triangle), or None when there would be more than ``limit``. A triangle reaching
    behind the camera's eye pairs with every ray, one wholly behind it with none, and one
    with a non-finite corner with none (no ray hits it)."""
    positions = np.asarray(tris.positions, np.float64).reshape(-1, 3, 3)
    x, y, front = image_points(camera, positions, width, height)
    x, y, front = x.reshape(-1, 3), y.reshape(-1, 3), front.reshape(-1, 3)
    # the pixels whose centres (i + ½, j + ½) lie in the bounds (a column at a time: numpy's
    # reductions over rows of 3 are slow)
    with np.errstate(invalid="ignore"):
        low_x = np.minimum(np.minimum(x[:, 0], x[:, 1]), x[:, 2])
        high_x = np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2])
        low_y = np.minimum(np.minimum(y[:, 0], y[:, 1]), y[:, 2])
        high_y = np.maximum(np.maximum(y[:, 0], y[:, 1]), y[:, 2])
        i0 = np.clip(np.ceil(low_x - 0.5 - _PIXEL_MARGIN), 0, width)
        i1 = np.clip(np.floor(high_x - 0.5 + _PIXEL_MARGIN), -1, width - 1)
        j0 = np.clip(np.ceil(low_y - 0.5 - _PIXEL_MARGIN), 0, height)
        j1 = np.clip(np.floor(high_y - 0.5 + _PIXEL_MARGIN), -1, height - 1)
    finite = np.isfinite(low_x + high_x + low_y + high_y)  # (NaN corners project to NaN)
    ahead = front[:, 0] & front[:, 1] & front[:, 2]
    across = (front[:, 0] | front[:, 1] | front[:, 2]) & ~ahead \
        & np.isfinite(positions.reshape(-1, 9)).all(axis=1)
    ahead &= finite
    i0, j0 = np.where(across, 0, i0), np.where(across, 0, j0)
    i1, j1 = np.where(across, width - 1, i1), np.where(across, height - 1, j1)
    columns = np.where(ahead | across, np.maximum(i1 - i0 + 1, 0), 0).astype(np.int64)
    rows = np.where(ahead | across, np.maximum(j1 - j0 + 1, 0), 0).astype(np.int64)
    count = columns * rows
    if int(count.sum()) > limit:
        return None
    triangle = np.repeat(np.arange(len(positions)), count)
    k = np.arange(len(triangle)) - np.repeat(np.cumsum(count) - count, count)
    wide = columns[triangle]
    ray = (j0[triangle].astype(np.int64) + k // wide) * width + i0[triangle].astype(np.int64) \
        + k % wide
    return ray, triangle


def camera_first_hits(tris: SceneTriangles, camera: CameraData, width: int, height: int):
    """(depth (N,), position (N, 3), shows (N,)) of the pixel-centre camera rays of a
    ``width`` × ``height`` image (ray j·W + i): ``primary_visibility``'s depth, position and
    hit, flattened. A few thousand rays against triangles that each cover few of them (the
    view fit's probe of a posed character) are tested against the triangles whose projected
    bounds hold them (``_projected_pairs``): no grid is built. Otherwise they are traced
    through a grid of few cells (``few_rays_grid``). Both test each ray against every
    triangle it can hit with the same arithmetic: the same distances, the same points."""
    width, height = int(width), int(height)
    pairs = None
    if len(tris):
        pairs = _projected_pairs(tris, camera, width, height,
                                 PROJECTED_PAIRS_PER_RAY * width * height)
    if pairs is None:
        few_rays_grid(tris)
        hits = primary_visibility(tris, camera, width, height)
        return hits.depth.reshape(-1), hits.position.reshape(-1, 3), hits.hit.reshape(-1)
    ray, tri = pairs
    origins, directions = camera_rays(camera, width, height)
    count = len(origins)
    best_t, best_tri = np.full(count, np.inf), np.full(count, -1, np.int64)
    if len(ray):
        positions = np.asarray(tris.positions, np.float64).reshape(-1, 3, 3)
        o, d = origins[ray].T, directions[ray].T
        t, u, v = _intersect(_corner_rows(positions[tri]), o, d)
        good = (t > 0.0) & (t < camera_ray_lengths(camera, directions)[ray])
        accept = tris.accepted(RAY_CAMERA) if hasattr(tris, "accepted") else None
        if accept is not None:
            good &= accept[tri]
        good = counted_hits(cutouts_of(tris, camera=True), good, tri, u, v, o.T, d.T)
        ray, tri, t = ray[good], tri[good], t[good]
        np.minimum.at(best_t, ray, t)
        win = t == best_t[ray]
        best_tri[ray[win]] = tri[win]
    shows = best_tri >= 0
    holdout = getattr(tris, "holdout", None)
    if holdout is not None:
        shows &= ~np.asarray(holdout)[np.maximum(best_tri, 0)]
    position = np.where(shows[:, None], origins + directions * np.where(shows, best_t, 0.0)[:, None],
                        0.0)
    return best_t, position, shows
