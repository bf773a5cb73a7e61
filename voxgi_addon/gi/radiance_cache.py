"""A multi-bounce radiance cache in voxels: the light that reaches a surface after two or more
bounces, for the Accurate gathers' bounce hits (docs/gi_pipeline.md "Multi-bounce radiance
cache").

The Accurate gather shades each bounce hit with its exact direct light (one bounce). With
*Bounces* N > 1 it also adds, at the hit, the hit's diffuse weight × the **indirect** light
arriving there, looked up in this cache. The cache holds, per voxel of its grids (the cells the
scene's triangles touch, ``voxelize_triangles``), the indirect light (Cycles' units: E/π, what a
white Lambertian surface would reflect) arriving through each of the six axis faces of the voxel
(an "ambient cube": +x, −x, +y, −y, +z, −z; a voxel holds the axes its triangles face). A
surface point with unit normal n reads Σ_a n_a² · face(a, sign n_a), each face trilinear over
the eight nearest voxels of the finest grid holding the point that hold it (the others carry no
weight).

Iteration k (``iterate``) gathers face f of every voxel with ``rays`` cosine-distributed exact
rays about the face's axis, starting ``FACE_OFFSET`` voxels out of the voxel centre along it
(the diffuse gather itself, at those points: the GPU runs ``shaders/bvh_gather.glsl`` on them),
and shades each with ``exact_indirect.ray_radiance`` — the hit's exact direct light (every light:
lamps, world, emitters) reflected by its albedo — *plus* the hit's diffuse weight × iteration
k − 1's cache at the hit. So iteration 1 holds the two-bounce light, iteration k the light of
bounces 2 … k + 1, and the gather with a cache of N − 1 iterations returns bounces 1 … N: the
first bounce exact, the rest cached. Bounces = 1 builds no cache at all. A hit's glossy
scatter does not count toward Cycles' diffuse bounces: the glossy share of a hit's weight
reads iteration k itself (``relax``'s ``level``, a second pass), and the gathers' hits reflect
one more iteration by their glossy lobes (``one_more_bounce``; docs/gi_pipeline.md
"Multi-bounce radiance cache", "Glossy scatters between diffuse bounces").

Numpy only; the GPU reads the same values from ``cache_texels`` (``render/gpu_gather.py``,
``shaders/bvh_shade.glsl`` ``cache_indirect``) and looks them up as ``lookup`` does.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, replace

import numpy as np

from ..errors import VoxGIError
from ..scene.geometry import bulk_bounds
from ..scene.short_axis import any_along, max_along, min_along
from ..voxelize.surface import LATTICE_OFFSET, voxelize_triangles
from .cascades import CascadeGrid, cells_within
from .sampling import point_streams, unit_float

__all__ = ["FACE_OFFSET", "RadianceCache", "build_cache", "cache_grids", "cache_key",
           "cache_levels", "cache_texels", "cell_size", "cached_cache", "face_paths",
           "face_planes", "face_points", "iterate", "lookup", "one_more_bounce", "pick", "picks",
           "plane_codes", "relax", "snap_focus", "texel_places", "triangles_key", "with_faces"]

FACE_OFFSET = 0.75       # voxels from the centre to a face's ray origin where it has no surface
FACE_CLEARANCE = 0.02    # voxels in front of its surface a face's rays start (``_face_origins``)
FACE_AXIS_COSINE = 0.2   # a voxel holds the faces of the axes its triangles' normals reach
# a face still inside a solid at FACE_OFFSET is not held where the solid's back lies within a
# voxel and across its axis (the back's normal within 25 degrees of it: a wall,
# ``_backs_in_solids``)
WALL_FACING = 0.9
# an axis whose n² is under this weighs nothing in a lookup (``lookup``): the GPU then fetches
# no texel of it (cache_lookup.glsl CACHE_AXIS_BLEND), 8 not 24 at a wall's or a floor's hit
AXIS_BLEND = 1e-6
# A lookup reads a neighbour's face only where that face's ray origin — its surface — is not
# more than this many voxels behind the point's tangent plane, unless none of the neighbours'
# faces of that axis is: a panel 5 cm under a ceiling read, through the ceiling's voxels above
# it, the light caught between the two (docs/gi_pipeline.md "Faces behind the point")
PLANE_TOLERANCE = 0.25
PLANE_STEPS = 63.5  # the faces' planes as the GPU holds them: 1/63.5 voxel steps in [-1, 1]
PICK_STREAM = 0x7C0A  # hash stream of the face a cache ray's hit reads (``pick``)
# A face's brightest ray, where it alone is far brighter than all the others (over
# OUTLIER_RATIO × the second brightest, in the largest channel) and its hit a metal (Metallic
# ≥ ``exact_indirect.METAL_FOLLOWED``), carries at most the larger of that and OUTLIER_FLOOR
# (Cycles' default Clamp Indirect) in its own light (``tamed``): one ray of a face's few that
# meets a caustic (a floor's ray on the spot of a gold head that mirrors the sun toward it) lit
# the whole voxel, a blob where Cycles draws a few fireflies (docs/gi_pipeline.md "A caustic
# in the cache's rays")
OUTLIER_RATIO = 4.0
OUTLIER_FLOOR = 10.0
FACES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@dataclass(frozen=True, eq=False)
class RadianceCache:
    """grids : the cache's ``CascadeGrid`` list, finest first (a point reads the finest that
    holds it). cells : per grid the (N_i, 3) int32 voxels (sorted, unique). faces : per grid
    (N_i, 6, 3) float32 indirect light (E/π) through each face (+x, −x, +y, −y, +z, −z).
    iterations : bounces beyond the first that it carries (0: an empty cache, all zeros).
    present : per grid (N_i, 6) bool, the faces it holds: both faces of every axis along which
    a triangle touching the voxel faces by more than ``FACE_AXIS_COSINE`` (a floor's voxels hold
    ±z only); a lookup blends each axis over the voxels that hold it. origins : per grid
    (N_i, 6, 3) float32 where each face's rays start, in voxels from the voxel's centre
    (``_face_origins``; empty: ``FACE_OFFSET`` along the face's axis). ahead : per grid the
    faces of the next iteration (as ``faces``), from which ``one_more_bounce`` takes the
    light a glossy scatter leaves to come; empty: none kept. earlier : the faces of the
    iterations before, latest first (``iterations`` − 1 of them: ``cache_levels``); empty: none
    kept."""

    grids: tuple
    cells: tuple
    faces: tuple
    iterations: int = 0
    present: tuple = ()
    origins: tuple = ()
    ahead: tuple = ()
    earlier: tuple = ()

    @property
    def voxel_count(self) -> int:
        return sum(len(c) for c in self.cells)

    @property
    def nbytes(self) -> int:
        return sum(f.nbytes + c.nbytes for f, c in zip(self.faces, self.cells))


def cache_grids(tris, resolution: int = 32, count: int = 1, focus=None) -> list:
    """``count`` nested grids of ``resolution``³ voxels (finest first), the coarsest a cube over
    the triangles' bounding box (2% margin), each finer one half the size of the next, on its
    lattice (so its voxels split the coarser ones in eight): centred on ``focus`` (a world
    point: the camera), kept inside the coarser grid; without one, its middle half
    (cascades' layout, docs/gi_pipeline.md "Conventions")."""
    if resolution < 2 or resolution & (resolution - 1):
        raise VoxGIError(f"the radiance cache's resolution must be a power of two ≥ 2, "
                         f"not {resolution}")
    if count < 1:
        raise VoxGIError(f"the radiance cache needs at least one grid, not {count}")
    lo, hi = _bounds(tris)
    size = max(float((hi - lo).max()) * 1.02, 1e-3)
    centre = 0.5 * (lo + hi)
    span = size / resolution
    grids = [CascadeGrid(count - 1, span, resolution, centre - 0.5 * resolution * span)]
    for index in range(count - 2, -1, -1):
        outer = grids[0]
        if focus is None:
            start = np.full(3, resolution // 4)
        else:
            at = (np.asarray(focus, np.float64).reshape(3) - outer.origin) / outer.span
            start = np.clip(np.round(at - resolution / 4), 0, resolution // 2)
        grids.insert(0, CascadeGrid(index, outer.span / 2, resolution,
                                    outer.origin + start * outer.span))
    return grids


_BOUNDS: dict[int, tuple] = {}  # id(positions) → (weak reference to them, (lo, hi))


def _bounds(tris) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) (3,) read-only float64: the box the cache's grids cover — ``tris``' corners,
    or the box of the bulk of their area where a stray few triangles far away make the whole
    box over STRAY_SHRINK times larger (``scene.geometry.bulk_bounds``; the strays then lie
    outside every grid: their hits read no cache). Kept per positions array while it lives:
    every viewport slice asks again (``preview.gather.focused``), and on a 140k-triangle scene
    the min/max took 35 ms of a 30 ms draw (docs/gi_pipeline.md "Entering Rendered mode")."""
    positions = tris.positions
    kept = _BOUNDS.get(id(positions))
    if kept is not None and kept[0]() is positions:
        return kept[1]
    if np.size(positions) == 0:
        raise VoxGIError("the radiance cache needs triangles")
    # the finite triangles' (none finite: a point at the origin)
    lo, hi = bulk_bounds(positions) or (np.zeros(3), np.zeros(3))
    lo.setflags(write=False)
    hi.setflags(write=False)
    try:
        ref = weakref.ref(positions, lambda _, key=id(positions): _BOUNDS.pop(key, None))
    except TypeError:  # not weakly referable (a list): not kept
        return lo, hi
    _BOUNDS[id(positions)] = (ref, (lo, hi))
    return lo, hi


def snap_focus(tris, focus):
    """``focus`` (a world point, the camera; None: none) on a lattice of a sixteenth of the
    cache's coarsest grid's size (a quarter of its third nested grid): the nested grids of
    ``cache_grids`` move in those steps, so a camera moving within one step keeps the cache
    (the viewport's orbit). None outside the scene's grid (no grids nest there, and a camera
    orbiting outside keeps the cache)."""
    if focus is None:
        return None
    lo, hi = _bounds(tris)
    size = max(float((hi - lo).max()) * 1.02, 1e-3)
    centre = 0.5 * (lo + hi)
    point = np.asarray(focus, np.float64).reshape(3)
    if (np.abs(point - centre) >= size / 2).any():
        return None  # outside the scene's grid: one grid, whatever the camera does
    step, origin = size / 16, centre - size / 2
    return tuple(float(v) for v in origin + (np.floor((point - origin) / step) + 0.5) * step)


_EMITTERS: dict[int, tuple] = {}  # id(positions) → (weak reference, emission bytes, centre)


def emitters_centre(tris, emission):
    """The emitting triangles' centre (3,) weighted by their power (luminance × area), or None
    without any: where a camera outside the scene nests the cache's finer grids
    (``preview.gather.focused``). emission : (M + 1, 3) per material, as
    ``light_injection.material_emission``. Kept per positions array and emission while they
    live (the viewport asks every slice)."""
    from .emitters import LUMINANCE
    from .light_injection import emissive_triangles

    emission = np.asarray(emission, np.float64).reshape(-1, 3)
    positions = tris.positions
    key = emission.tobytes()
    kept = _EMITTERS.get(id(positions))
    if kept is not None and kept[0]() is positions and kept[1] == key:
        return kept[2]
    corners, radiance = emissive_triangles(tris, emission)
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                         corners[:, 2] - corners[:, 0]), axis=1)
    weight = (radiance @ LUMINANCE) * area  # as the emitters' power (emitters.emitter_light)
    centre = tuple(float(v) for v in (weight[:, None] * corners.mean(axis=1)).sum(axis=0)
                   / weight.sum()) if weight.sum() > 0 else None
    try:  # kept while the positions live (a list is not weakly referable: not kept)
        ref = weakref.ref(positions, lambda _, k=id(positions): _EMITTERS.pop(k, None))
    except TypeError:
        return centre
    _EMITTERS[id(positions)] = (ref, key, centre)
    return centre


def _sites(tris, grids, origins: bool = True, voxelized: dict | None = None) \
        -> tuple[list, list, list]:
    """Per grid the (N_i, 3) int32 cells its triangles touch (a coarser grid leaving out the
    cells the next finer grid covers), their (N_i, 6) present faces and their faces' (N_i, 6, 3)
    ray origins (``RadianceCache``; origins False: none, for Auto's count of the faces).
    voxelized : a dict kept across calls on the same ``tris`` (``build_cache``'s Auto counts
    the faces of the grids it tries, then builds the chosen ones): each grid's triangles are
    voxelized once."""
    corners = np.asarray(tris.positions, np.float64)
    signed = np.asarray(tris.normals, np.float64)
    normals = np.abs(signed)
    triangles = np.arange(len(corners) * 3).reshape(-1, 3)
    voxelized = {} if voxelized is None else voxelized
    out, present, starts = [], [], []
    for index, grid in enumerate(grids):
        local = (corners - np.asarray(grid.origin)).reshape(-1, 3)
        key = (tuple(float(v) for v in grid.origin), float(grid.span))
        if key not in voxelized:
            surface = voxelize_triangles(local, triangles, float(grid.span))
            reach = np.zeros((len(surface.cells), 3))
            np.maximum.at(reach, surface.cell_of_pair, normals[surface.triangle_of_pair])
            voxelized[key] = (surface, reach)
        surface, reach = voxelized[key]
        cells = surface.cells.astype(np.int64)
        res = grid.resolution
        keep = cells_within(cells, 0, res)
        if index > 0:  # the finer grid covers cells [start, start + res/2) of this one
            finer = grids[index - 1]
            start = np.round((np.asarray(finer.origin) - np.asarray(grid.origin))
                             / grid.span).astype(np.int64)
            keep &= ~cells_within(cells, start, start + res // 2)
        out.append(cells[keep].astype(np.int32))
        present.append(np.repeat(reach[keep] > FACE_AXIS_COSINE, 2, axis=1))
        if origins:
            begin, backs = _face_origins(cells[keep], surface,
                                         local.reshape(-1, 3, 3) / grid.span, signed, keep)
            begin, dropped = _backs_in_solids(tris, grid, cells[keep], begin, backs)
            present[-1] = present[-1] & ~dropped
            starts.append(begin)
    return out, present, starts


def _backs_in_solids(tris, grid, cells, origins, backs) -> tuple[np.ndarray, np.ndarray]:
    """``origins`` (N, 6, 3) with the faces started on triangles' backs (``backs`` (N, 6))
    moved back to ``FACE_OFFSET`` where those backs lie inside a solid: the first triangle
    straight out along the face's axis shows its back too (a 2 cm slab's far side). Those
    rays would gather the slab's inside, which the trilinear lookups across it pass from the
    lit room to the dark one (2.5% of its light, tests/blender/test_multibounce.py). Also
    (N, 6) bool: the faces still inside the solid at ``FACE_OFFSET``, its back within a voxel
    of that point (a wall thinner than the voxel lying across it), which the voxel then does
    not hold: their rays gathered the wall's inside wherever they started, and the lookups on
    the wall's lit side blended them in (a 0.1 m-walled room at 0.198 m voxels: its later
    bounces 18% short, docs/gi_pipeline.md "An interior lit through a window, tuned for
    nothing"). Deep in a thick solid a face keeps its ``FACE_OFFSET`` start, as before (a
    street's blocks: dropped there, its nested cache read 0.124 of exact light off, not 0.080),
    and by a curved solid's rim (a sphere's back there lies oblique: ``WALL_FACING``)."""
    dropped = np.zeros(backs.shape, bool)
    voxel, face = np.nonzero(backs)
    if len(voxel) == 0:
        return origins, dropped
    from ..scene.bvh import closest_hits  # the GPU scene's BVH, built once (``bvh_of``)

    centres = np.asarray(grid.origin) + (np.asarray(cells, np.float64)[voxel] + 0.5) * grid.span
    normals = np.asarray(tris.normals, np.float64)

    def in_solid(offsets, within=np.inf, facing=0.0):
        t, tri, _, _ = closest_hits(tris, centres + grid.span * offsets, FACES[face])
        return (tri >= 0) & (t < within) & \
            (np.einsum("ij,ij->i", normals[np.maximum(tri, 0)], FACES[face]) > facing)

    inside = in_solid(np.asarray(origins[voxel, face], np.float64))
    out = origins.copy()
    out[voxel[inside], face[inside]] = (FACE_OFFSET * FACES[face[inside]]).astype(np.float32)
    # (a solid's back within a voxel and across the axis: a thin wall; deep in a thick solid,
    # or by a curved one's rim, the face keeps its FACE_OFFSET start, as before)
    still = inside & in_solid(FACE_OFFSET * FACES[face], grid.span, WALL_FACING)
    dropped[voxel[still], face[still]] = True
    return out, dropped


_CLIP_VERTICES = 9  # a triangle clipped by a box's six planes has at most 3 + 6 corners


def _clip_to_cells(tris):
    """((P, 9, 3) float32 corners, (P,) count) of triangles ``tris`` (P, 3, 3) clipped to the
    unit cell [0, 1]³ (Sutherland–Hodgman, one plane at a time, each on the polygons it cuts
    only)."""
    poly = np.zeros((len(tris), _CLIP_VERTICES, 3), np.float32)
    poly[:, :3] = tris
    count = np.full(len(tris), 3)
    slots = np.arange(_CLIP_VERTICES)
    for axis in range(3):
        for sign, bound in ((1.0, 0.0), (-1.0, 1.0)):
            side = sign * (poly[:, :, axis] - bound)                      # (P, 9) ≥ 0: kept
            cut = np.flatnonzero(any_along((side < 0) & (slots[None] < count[:, None])))
            if len(cut) == 0:
                continue
            p, n, d = poly[cut], count[cut], side[cut]
            following = (slots[None] + 1) % np.maximum(n, 1)[:, None]
            nxt = np.take_along_axis(p, following[:, :, None], axis=1)
            nd = np.take_along_axis(d, following, axis=1)
            valid = slots[None] < n[:, None]
            inside, ninside = d >= 0, nd >= 0
            t = d / np.where(d != nd, d - nd, np.float32(1.0))
            cross = p + t[:, :, None] * (nxt - p)
            # per corner: the corner if kept, then the edge's crossing if it changes sides
            candidates = np.stack([p, cross], axis=2).reshape(len(p), -1, 3)
            emit = np.stack([valid & inside, valid & (inside != ninside)], axis=2)
            emit = emit.reshape(len(p), -1)
            # the emitted ones packed in order (a scatter: an argsort and a gather took 45 of
            # the columned hall's 75 ms here)
            slot = np.cumsum(emit, axis=1) - 1
            row, column = np.nonzero(emit & (slot < _CLIP_VERTICES))
            packed = np.zeros_like(p)
            packed[row, slot[row, column]] = candidates[row, column]
            poly[cut] = packed
            count[cut] = np.minimum(emit.sum(axis=1), _CLIP_VERTICES)
    return poly, count


def _covering(tris):
    """((P,) bool, (P,) int axis) of triangles ``tris`` (P, 3, 3) in a cell's coordinates: those
    lying in a plane across one axis (their three corners' coordinate the same, within the
    cell) whose projection holds all four corners of the cell's square across it — their part
    in the cell is that square, as ``_clip_to_cells`` would cut it (most pairs of a room's
    walls and floors, which cover many cells each)."""
    covered = np.zeros(len(tris), bool)
    axis = np.zeros(len(tris), np.int64)
    for a in range(3):
        level = tris[:, 0, a]
        flat = np.flatnonzero((tris[:, 1, a] == level) & (tris[:, 2, a] == level) &
                              (level >= 0) & (level <= 1) & ~covered)
        if len(flat) == 0:
            continue
        u, v = (a + 1) % 3, (a + 2) % 3
        t = tris[flat][:, :, [u, v]].astype(np.float64)          # (F, 3, 2)
        edge = np.roll(t, -1, axis=1) - t                          # corner k → k + 1
        area = edge[:, 0, 0] * edge[:, 1, 1] - edge[:, 0, 1] * edge[:, 1, 0]
        inside = area != 0
        for corner in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)):
            to = np.asarray(corner) - t                            # (F, 3, 2)
            side = (edge[..., 0] * to[..., 1] - edge[..., 1] * to[..., 0]) * np.sign(area)[:, None]
            inside &= side.min(axis=1) >= 0
        covered[flat[inside]] = True
        axis[flat[inside]] = a
    return covered, axis


def _face_origins(cells, surface, corners, normals, keep) -> np.ndarray:
    """(N, 6, 3) float32: where the rays of each face of the kept ``cells`` start, in voxels
    from the voxel's centre (docs/gi_pipeline.md "Multi-bounce radiance cache", "Faces start
    on their surfaces"). A face stands for the light reaching the voxel's surfaces that face
    its way (the lookups of points with such normals), so its rays start on them: take the
    parts, inside the voxel, of its triangles facing that way by more than
    ``FACE_AXIS_COSINE`` and start just in front (``FACE_CLEARANCE``) of their farthest
    corner that way, across the axis at the voxel's centre kept within their extent (a
    hair inside it). Starting 0.75 voxel off the voxel's centre instead put a ceiling's rays
    6 cm below it or, where its voxels' centres lie outside a room, the walls' rays above the
    roof (a sunlit hall's walls read 15–40 × their light under the ceiling). Across the axis
    the centre, not the parts' middle: a voxel straddling a thin wall keeps its faces on its
    centre's side, as before. A face no triangle faces that way starts, the same way, on the
    backs of the triangles facing the other way (of several, those nearest the voxel's
    centre along the axis): a one-sided plane is two-sided to the rays
    (an emissive panel's back, lit by the ceiling a few cm above it, is what the ceiling's
    rays meet). ``FACE_OFFSET`` off the centre instead put the panel's back face beyond the
    ceiling where the voxels are coarser than the gap: the cavity read black, and the panel
    and the ceiling around it read it through trilinear weights (the emissive room at 32³:
    its cache 0.77 of path-traced light, Combined 0.077 instead of 0.047;
    docs/gi_pipeline.md "Multi-bounce radiance cache", "One-sided planes have backs"). Only
    a face of an axis no triangle in the voxel faces keeps ``FACE_OFFSET``, and one on backs
    inside a solid (``_backs_in_solids``).
    cells : (N_all, 3) the grid's cells (``surface.cells``); corners : (T, 3, 3) triangles
    in voxels from the grid's origin; normals : (T, 3) their unit normals; keep : (N_all,)
    the cells kept. Returns (the origins, (N, 6) bool: the faces started on backs)."""
    origins = np.zeros((len(cells), 6, 3))
    backs = np.zeros((len(cells), 6), bool)
    for face in range(6):
        origins[:, face] = FACE_OFFSET * FACES[face]
    pair_cell, tri = surface.cell_of_pair, surface.triangle_of_pair
    row = np.cumsum(keep) - 1
    pairs = np.flatnonzero(keep[pair_cell])
    if len(pairs) == 0:
        return origins.astype(np.float32), backs
    pairs = pairs[np.argsort(pair_cell[pairs], kind="stable")]  # cell by cell
    pair_cell, tri = row[pair_cell[pairs]], tri[pairs]
    # the lattice's cells are shifted by voxelize's LATTICE_OFFSET (a plane on a lattice plane
    # lies in the cell above it)
    lo = cells[pair_cell] - LATTICE_OFFSET
    # each pair's triangle in its cell (float32 holds it), clipped to the cell only where a
    # corner lies outside it (most triangles of a large scene lie within one voxel): the
    # parts' boxes, from the voxel's centre
    local = (corners[tri] - lo[:, None]).astype(np.float32)
    high = np.maximum(np.maximum(local[:, 0], local[:, 1]), local[:, 2])   # (P, 3)
    low = np.minimum(np.minimum(local[:, 0], local[:, 1]), local[:, 2])
    some = np.ones(len(local), bool)
    cut = np.flatnonzero(any_along((high > 1) | (low < 0)))
    if len(cut):  # a wall's or a floor's triangle across the whole cell: its part is the cell's
        # square in its plane, without clipping
        square, axis = _covering(local[cut])
        plane = local[cut[square], 0, axis[square]]
        high[cut[square]], low[cut[square]] = 1.0, 0.0
        high[cut[square], axis[square]] = low[cut[square], axis[square]] = plane
        cut = cut[~square]
    if len(cut):
        poly, count = _clip_to_cells(local[cut])
        valid = (np.arange(_CLIP_VERTICES)[None] < count[:, None])[:, :, None]
        high[cut] = max_along(np.where(valid, poly, -np.inf), 1)
        low[cut] = min_along(np.where(valid, poly, np.inf), 1)
        some[cut] = count > 0
    high -= np.float32(0.5 + LATTICE_OFFSET)                      # from the voxel's centre
    low -= np.float32(0.5 + LATTICE_OFFSET)
    for axis in range(3):
        along = normals[tri, axis]
        for sign, face in ((1.0, 2 * axis), (-1.0, 2 * axis + 1)):
            for facing in (-1.0, 1.0):  # the backs of those facing away, then their fronts
                chosen = np.flatnonzero((facing * sign * along > FACE_AXIS_COSINE) & some)
                if not len(chosen):
                    continue
                if facing < 0:  # of several backs, the nearest the centre (a panel's, not
                    # the ceiling's a few cm over it, whose back is the roof's outside)
                    level = np.abs((high if sign > 0 else low)[chosen, axis])
                    begins = _runs(pair_cell[chosen])
                    nearest = np.minimum.reduceat(level, begins)
                    chosen = chosen[level <= np.repeat(
                        nearest, np.diff(np.r_[begins, len(level)])) + 1e-6]
                begins = _runs(pair_cell[chosen])   # the chosen pairs, cell by cell
                top = np.maximum.reduceat(high[chosen], begins)
                bottom = np.minimum.reduceat(low[chosen], begins)
                held = np.isfinite(top[:, axis])
                top, bottom = top[held], bottom[held]
                margin = np.minimum(0.25 * (top - bottom), FACE_CLEARANCE)
                point = np.clip(0.0, bottom + margin, top - margin)   # the centre, kept on them
                point[:, axis] = sign * ((top if sign > 0 else -bottom)[:, axis] + FACE_CLEARANCE)
                voxels = pair_cell[chosen[begins[held]]]
                origins[voxels, face] = point
                backs[voxels, face] = facing < 0
    return origins.astype(np.float32), backs


def _runs(sorted_keys: np.ndarray) -> np.ndarray:
    """The first index of each run of equal values in ``sorted_keys`` (``reduceat``'s
    starts)."""
    return np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])


def _dense_index(grid, cells) -> np.ndarray:
    res = grid.resolution
    index = np.full(res ** 3, -1, np.int64)
    c = np.asarray(cells, np.int64)
    index[(c[:, 0] * res + c[:, 1]) * res + c[:, 2]] = np.arange(len(c))
    return index


def face_planes(cache: RadianceCache) -> tuple:
    """Per grid (N_i, 6) float64: each face's ray origin along its own axis (where its surface
    lies), in voxels from the voxel's centre, quantized as the GPU holds it (7 bits,
    ``plane_codes``)."""
    out = []
    for g, cells in enumerate(cache.cells):
        if cache.origins:
            along = np.asarray(cache.origins[g], np.float64)[:, np.arange(6), np.arange(6) // 2]
        else:
            along = np.broadcast_to(FACE_OFFSET * FACES.sum(axis=1), (len(cells), 6))
        out.append(np.round(np.clip(along, -1.0, 1.0) * PLANE_STEPS + PLANE_STEPS)
                   / PLANE_STEPS - 1.0)
    return tuple(out)


def plane_codes(planes) -> np.ndarray:
    """(N, 2) float32 of one grid's ``face_planes`` (N, 6): faces +x, −x, +y and −y, +z, −z
    packed as q₀ + 128 q₁ + 16384 q₂ with q = the plane's 7-bit step (exact in float32;
    ``cache_texels``' id rows .z, .w; cache_lookup.glsl ``cache_planes``)."""
    q = np.round((np.asarray(planes, np.float64) + 1.0) * PLANE_STEPS).astype(np.int64)
    return np.stack([q[:, 0] + 128 * q[:, 1] + 16384 * q[:, 2],
                     q[:, 3] + 128 * q[:, 4] + 16384 * q[:, 5]], axis=1).astype(np.float32)


def _in_front(grid, cell, planes, p, n) -> np.ndarray:
    """(K, 3) bool per axis: is the face of voxel ``cell`` (K, 3) with planes ``planes`` (K, 3,
    the axes' faces' ``face_planes``) at most PLANE_TOLERANCE voxels behind the tangent plane
    of points ``p`` with normals ``n`` (K, 3)? Its ray origin: the voxel's centre moved along
    the face's axis to its plane."""
    centre = np.asarray(grid.origin) + (np.asarray(cell, np.float64) + 0.5) * grid.span
    base = np.einsum("kc,kc->k", centre - p, n)
    return base[:, None] + grid.span * planes * n >= -PLANE_TOLERANCE * grid.span


def one_more_bounce(cache: RadianceCache) -> tuple:
    """Per grid (N_i, 6) float64: how much more light each face carries with one more
    diffuse bounce, (Σ ahead − Σ faces) / Σ faces over rgb (0 without an ``ahead`` or where a
    face is dark). The gathers' hits reflect the cache by their glossy lobes × (1 + it): a
    glossy scatter leaves a diffuse bounce to come (``exact_indirect.RayPaths.with_cache``;
    on the GPU the .a of the faces' texels, ``cache_texels``)."""
    if not cache.ahead:
        return tuple(np.zeros(f.shape[:2]) for f in cache.faces)
    out = []
    for faces, ahead in zip(cache.faces, cache.ahead):
        lit = np.asarray(faces, np.float64).sum(axis=2)
        more = np.asarray(ahead, np.float64).sum(axis=2) - lit
        out.append(np.where(lit > 0, np.maximum(more, 0.0) / np.maximum(lit, 1e-30), 0.0))
    return tuple(out)


def cache_levels(cache: RadianceCache) -> tuple:
    """The cache's faces per iteration count, latest first: (``faces``, then ``earlier``'s),
    ``iterations`` of them — level f holds bounces 2 … N − f, what a gather ray followed f
    bounces past a near hit reads where it lands (``exact_indirect._follow_near``). Empty where
    the cache keeps fewer (``iterate`` alone)."""
    if len(cache.earlier) != max(cache.iterations - 1, 0):
        return ()
    return (cache.faces, *cache.earlier)


def cell_size(cache: RadianceCache, points) -> np.ndarray:
    """(K,) the cell size of the finest grid of ``cache`` holding each of ``points`` (K, 3), 0
    outside every grid (cache_lookup.glsl ``cache_cell_size``)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    out = np.zeros(len(p))
    todo = np.ones(len(p), bool)
    for grid in cache.grids:
        inside = todo & cells_within((p - np.asarray(grid.origin)) / grid.span, 0,
                                     grid.resolution)
        out[inside] = grid.span
        todo &= ~inside
    return out


def lookup(cache: RadianceCache | None, points, normals, more: bool = False):
    """(K, 3) float64 indirect light (E/π) at ``points`` (K, 3) for unit ``normals`` (K, 3):
    per axis the face n faces, trilinear (node-centred) over the voxels of the finest grid
    holding the point that hold that face, then the axes blended by n² (over the axes some
    neighbour holds; an axis with n² under ``AXIS_BLEND`` weighs nothing); where no
    neighbour there holds a face n faces, the next coarser grid holding the point; 0 where
    none does. more : also return (K,) the faces' ``one_more_bounce`` as the ratio of the
    more light and the light, each blended as the light is (Σ w · light · ratio over Σ w ·
    light, per axis and over the axes): a nearly dark face's ratio, however large, adds only
    the little light it stands for."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3))
    ratio = np.zeros(len(p))
    if cache is None or cache.iterations == 0 or len(p) == 0:
        return (out, ratio) if more else out
    ratios = one_more_bounce(cache)
    face = np.where(n < 0, 1, 0) + np.array([0, 2, 4])  # (K, 3) face per axis
    blend = np.where(n ** 2 >= AXIS_BLEND, n ** 2, 0.0)
    todo = np.ones(len(p), bool)
    for grid, cells, faces, present, gain, planes in zip(cache.grids, cache.cells, cache.faces,
                                                         cache.present, ratios,
                                                         face_planes(cache)):
        if not todo.any():
            break
        g = (p - np.asarray(grid.origin)) / grid.span
        res = grid.resolution
        inside = todo & cells_within(g, 0, res)
        rows = np.flatnonzero(inside)
        if len(rows) == 0 or len(cells) == 0:
            continue
        index = _dense_index(grid, cells)
        gg = g[rows] - 0.5
        base = np.floor(gg).astype(np.int64)
        frac = gg - base
        # (k, axis, rgb), (k, axis), (k, axis): over the faces in front (``_in_front``), [0],
        # and over all held, [1], which an axis takes where none is in front
        total = np.zeros((2, len(rows), 3, 3))
        gains = np.zeros((2, len(rows), 3))
        lights = np.zeros((2, len(rows), 3))
        weight = np.zeros((2, len(rows), 3))
        for corner in range(8):
            offset = np.array([(corner >> 2) & 1, (corner >> 1) & 1, corner & 1])
            c = base + offset
            w = np.prod(np.where(offset == 1, frac, 1.0 - frac), axis=1)
            ok = cells_within(c, 0, res)
            key = np.where(ok, (c[:, 0] * res + c[:, 1]) * res + c[:, 2], 0)
            site = np.where(ok, index[key], -1)
            safe = np.maximum(site, 0)[:, None]
            held = (site >= 0)[:, None] & present[safe, face[rows]]      # (k, 3 axes)
            front = held & _in_front(grid, c, planes[safe, face[rows]], p[rows], n[rows])
            light = faces[safe, face[rows]]
            lit = np.maximum(np.asarray(light, np.float64).sum(axis=2), 0.0)
            for which, mask in enumerate((front, held)):
                wa = np.where(mask, w[:, None], 0.0)
                total[which] += wa[:, :, None] * light
                gains[which] += wa * lit * gain[safe, face[rows]]
                lights[which] += wa * lit
                weight[which] += wa
        strict = weight[0] > 1e-6
        total = np.where(strict[:, :, None], total[0], total[1])
        gains = np.where(strict, gains[0], gains[1])
        lights = np.where(strict, lights[0], lights[1])
        weight = np.where(strict, weight[0], weight[1])
        axis_ok = weight > 1e-6
        mean = total / np.maximum(weight, 1e-6)[:, :, None]
        share = np.where(axis_ok, blend[rows], 0.0)
        norm = share.sum(axis=1)
        value = (share[:, :, None] * mean).sum(axis=1) / np.maximum(norm, 1e-12)[:, None]
        found = norm > 1e-6  # else the next coarser grid (a point off its finer grid's voxels)
        out[rows[found]] = value[found]
        safe_weight = np.maximum(weight, 1e-6)
        ratio[rows[found]] = ((share * gains / safe_weight).sum(axis=1) /
                              np.maximum((share * lights / safe_weight).sum(axis=1), 1e-30))[found]
        todo[rows[found]] = False
    return (out, ratio) if more else out


# Auto resolution (``build_cache(resolution=0)``): the finest of these whose faces' rays (traced
# once for all iterations, ``face_paths``) are at most BASE_RAYS — a quarter of the rays of a
# diffuse gather at GI Resolution Auto (about 160 × 120 points) and the default 64 GI Rays —
# then grids nested around a focus while all the faces' rays stay within that budget (around
# a camera) or RAYS_PER_ITERATION, half that gather (around the emitters, ``nest_rays``): the
# whole cache costs at most half a gather (docs/gi_pipeline.md "The radiance cache at 8 rays a
# face").
AUTO_RESOLUTIONS = (64, 32, 16)
BASE_RAYS = 160 * 120 * 64 // 4
RAYS_PER_ITERATION = 160 * 120 * 64 // 2
# With a focus (the camera) inside the scene, Auto also nests up to this many grids around it
# while the rays stay within the budget (``build_cache``).
AUTO_GRIDS = 3


def build_cache(tris, resolution: int = 32, count: int = 1, rays: int = 8,
                focus=None, nest_rays: int = 0) -> RadianceCache:
    """An empty cache (iteration 0, all zeros) on ``cache_grids`` of ``tris``. resolution 0:
    Auto, the finest of ``AUTO_RESOLUTIONS`` whose faces × ``rays`` (rays per face) stay within
    ``BASE_RAYS`` (the coarsest otherwise), then, with a ``focus`` inside the scene's grid (a
    camera among the geometry: an interior, a street; else the emitters, ``preview.gather
    .focused``), as many nested grids around it (up to ``AUTO_GRIDS``) as keep all the faces'
    rays within ``nest_rays`` (0: ``BASE_RAYS``; the emitters' focus: ``RAYS_PER_ITERATION``):
    finer voxels near the camera or the emitters, the whole scene at least as fine as one grid
    would be. Without a focus (``snap_focus`` gives none outside the scene's grid) one grid."""
    voxelized: dict = {}  # each grid tried voxelized once (``_sites``)
    if resolution == 0:  # the layouts are counted without their faces' origins (the most
        # of a layout's time), then the chosen one is built
        def within(choice, grids, budget):
            return sum(int(p.sum()) for p in _sites(tris, cache_grids(
                tris, choice, grids, focus), origins=False, voxelized=voxelized)[1]) \
                * rays <= budget
        for resolution in AUTO_RESOLUTIONS:
            if within(resolution, count, BASE_RAYS):
                break
        if focus is not None and _inside(cache_grids(tris, resolution, count, focus)[-1], focus):
            while count < AUTO_GRIDS and within(resolution, count + 1, nest_rays or BASE_RAYS):
                count += 1
    grids = cache_grids(tris, resolution, count, focus)
    cells, present, origins = _sites(tris, grids, voxelized=voxelized)
    faces = tuple(np.zeros((len(c), 6, 3), np.float32) for c in cells)
    return RadianceCache(tuple(grids), tuple(cells), faces, 0, tuple(present), tuple(origins))


def _inside(grid, point) -> bool:
    lo, hi = grid.extent
    return bool(((np.asarray(point, np.float64) >= lo) & (np.asarray(point) < hi)).all())


def _rays(cache: RadianceCache, rays: int) -> int:
    """The rays of one iteration of ``cache`` at ``rays`` rays per face."""
    return sum(int(p.sum()) for p in cache.present) * rays


def face_points(cache: RadianceCache) -> tuple[np.ndarray, np.ndarray]:
    """((F, 3) ray origins, (F, 3) unit axes) of the present faces of ``cache``, voxel by voxel
    (grids finest first), faces in the order +x, −x, +y, −y, +z, −z: the gather points of
    ``iterate``, whose sample id is the row (the GPU lays them out as the pixels of an image,
    ``render/gpu_gather.py`` ``cache_gpu``)."""
    points, axes = [np.zeros((0, 3))], [np.zeros((0, 3))]
    origins = cache.origins or [FACE_OFFSET * np.broadcast_to(FACES, (len(c), 6, 3))
                                for c in cache.cells]
    for grid, cells, present, origin in zip(cache.grids, cache.cells, cache.present, origins):
        centres = np.asarray(grid.origin) + (np.asarray(cells, np.float64) + 0.5) * grid.span
        voxel, face = np.nonzero(present)
        points.append(centres[voxel] + grid.span * np.asarray(origin, np.float64)[voxel, face])
        axes.append(FACES[face])
    return np.concatenate(points), np.concatenate(axes)


def with_faces(cache: RadianceCache, values) -> RadianceCache:
    """The next iteration of ``cache`` holding ``values`` ((F, 3), ``face_points``' order)."""
    values = np.asarray(values, np.float32).reshape(-1, 3)
    faces, start = [], 0
    for cells, present in zip(cache.cells, cache.present):
        grid_faces = np.zeros((len(cells), 6, 3), np.float32)
        count = int(present.sum())
        grid_faces[present] = values[start:start + count]
        faces.append(grid_faces)
        start += count
    return RadianceCache(cache.grids, cache.cells, tuple(faces), cache.iterations + 1,
                         cache.present, cache.origins)


def face_paths(cache: RadianceCache, tris, lights, albedo, emission, rays: int = 8,
               seed: int = 0, world=(0.0, 0.0, 0.0), hit_samples: int = 1,
               hit_glossy: bool = True):
    """The ``exact_indirect.RayPaths`` of every face's ``rays`` gather rays (``face_points``,
    sample id = the face's row; the diffuse gather's rays, ``exact_indirect.gather_rays``),
    face by face: traced and lit once, then every iteration only looks the cache up at their
    hits (``relax``). lights, albedo, emission, world, hit_samples, hit_glossy : as the
    gather's. A metal hit is followed one reflection further (``follow_metals``)."""
    from .exact_indirect import gather_rays, ray_paths

    points, axes = face_points(cache)
    origins, dirs, ids = gather_rays(points, axes, np.arange(len(points)), rays, seed)
    paths = ray_paths(origins, dirs, ids, tris, lights, albedo, emission, seed, world,
                      hit_samples, hit_glossy)
    return follow_metals(paths, dirs, ids, tris, lights, albedo, emission, seed)


def follow_metals(paths, dirs, ids, tris, lights, albedo, emission, seed: int = 0):
    """``paths`` with each metal hit (Metallic ≥ ``exact_indirect.METAL_FOLLOWED``) followed
    one reflection further, as the gathers follow theirs (``exact_indirect.ray_radiance``;
    docs/gi_pipeline.md "Metals reflect where they point"): the record adds the metal's Glossy
    Color × the second hit's own light, and reads one face — the first hit's, for its diffuse
    share, or the second hit's, for the Glossy Color × that hit's weight — chosen by those
    weights' sums with the record's hash (``exact_indirect.CONTINUE_STREAM`` + 1) and divided
    by its chance, so the relaxation's single lookup per record stays unbiased
    (cache_paths.glsl does the same)."""
    from .exact_indirect import CONTINUE_STREAM, METAL_FOLLOWED, follow_metal_hits

    if paths.metallic is None or not len(paths.hit):
        return paths
    metal = np.flatnonzero(paths.metallic >= METAL_FOLLOWED)
    if not len(metal):
        return paths
    rays = paths.hit[metal]
    normals = paths.normals[metal]
    glossy = paths.glossy[metal]
    diffuse = paths.weight[metal] - glossy
    radiance = np.array(paths.radiance, np.float64)
    points, normals_out = paths.points.copy(), paths.normals.copy()
    weight, glossy_out = paths.weight.copy(), paths.glossy.copy()
    second_weight = np.zeros_like(glossy)
    second_glossy = np.zeros_like(glossy)
    second_points = paths.points[metal].copy()
    second_normals = normals.copy()
    up, second = follow_metal_hits(paths, metal, dirs, ids, tris, lights, albedo, emission, seed)
    if second is not None:
        radiance[rays[up]] += glossy[up] * second.radiance
        landed = up[second.hit]
        second_weight[landed] = glossy[landed] * second.weight
        second_glossy[landed] = glossy[landed] * second.glossy
        second_points[landed], second_normals[landed] = second.points, second.normals
    a, b = diffuse.sum(axis=1), second_weight.sum(axis=1)
    u = unit_float(point_streams(rays, CONTINUE_STREAM + 1, seed))
    first = u * (a + b) < a
    total = a + b
    scale = np.where(first, total / np.maximum(a, 1e-30), total / np.maximum(b, 1e-30))
    weight[metal] = np.where(first[:, None], diffuse, second_weight) * scale[:, None]
    glossy_out[metal] = np.where(first[:, None], 0.0, second_glossy) * scale[:, None]
    points[metal] = np.where(first[:, None], paths.points[metal], second_points)
    normals_out[metal] = np.where(first[:, None], normals, second_normals)
    return replace(paths, radiance=radiance, points=points, normals=normals_out, weight=weight,
                   glossy=glossy_out)


def _held(cache: RadianceCache) -> np.ndarray:
    """(F + 1, 3) float64 the present faces' values in ``face_points``' order, then a 0 row
    (what ``picks`` points at where a hit reads nothing)."""
    return np.concatenate([f[q] for f, q in zip(cache.faces, cache.present)] +
                          [np.zeros((1, 3), np.float32)]).astype(np.float64)


def relax(cache: RadianceCache, paths, rays: int, chosen=None,
          level: RadianceCache | None = None) -> RadianceCache:
    """One more bounce: each face's value is the mean over its ``rays`` ``paths`` of what they
    return with ``cache`` at their hits — the hit's exact direct light plus its weight × the
    cache there, read at the one face the ray picks (``picks``; on average the ``lookup``).
    A face's lone outlier ray is tamed first (``tamed``).
    From the empty cache this is iteration 1 (the two-bounce light); each relaxation adds a
    diffuse bounce. A hit's glossy scatter does not count toward Cycles' diffuse bounces, so
    the glossy share of its weight (``RayPaths.glossy_share``) reads ``level``, an estimate
    of the iteration being made (the same relaxation without it), where the diffuse share
    reads ``cache``; without ``level`` both read ``cache`` (docs/gi_pipeline.md
    "Multi-bounce radiance cache", "Glossy scatters between diffuse bounces"). chosen :
    ``picks(cache, paths)`` made already (None: made here)."""
    count = len(paths.radiance) // max(rays, 1)
    values = np.zeros((count, 3))
    if count:
        out = tamed(paths.radiance, rays, metal_hits(paths))
        if (cache.iterations or level is not None) and len(paths.hit):
            chosen = picks(cache, paths) if chosen is None else chosen
            before = _held(cache)[chosen] if cache.iterations else 0.0
            same = _held(level)[chosen] if level is not None else before
            share = paths.glossy_share[:, None]
            out[paths.hit] += paths.weight * ((1.0 - share) * before + share * same)
        values = out.reshape(count, rays, 3).mean(axis=1)
    return with_faces(cache, values)


def metal_hits(paths) -> np.ndarray:
    """(K,) bool: the rays of ``paths`` whose (first) hit is a metal (Metallic ≥
    ``exact_indirect.METAL_FOLLOWED``, as ``follow_metals`` follows)."""
    from .exact_indirect import METAL_FOLLOWED

    metal = np.zeros(len(paths.radiance), bool)
    if paths.metallic is not None and len(paths.hit):
        metal[paths.hit] = np.asarray(paths.metallic) >= METAL_FOLLOWED
    return metal


def tamed(radiance, rays: int, metal) -> np.ndarray:
    """(K, 3) the cache's rays' own light (``RayPaths.radiance``, face by face, ``rays`` each)
    with each face's brightest ray scaled down, its colour kept, to the larger of
    ``OUTLIER_FLOOR`` and ``OUTLIER_RATIO`` × the face's second brightest (largest channels)
    where it is brighter than that and its hit is a metal (``metal`` (K,) bool, ``metal_hits``):
    a lone outlier among a face's rays off a metal, a caustic a few rays cannot average
    (cache_relax.glsl does the same). Rays that agree, light that several of a face's rays
    see, and a lone diffuse hit's (the bright spot by a small lamp) are kept whole."""
    out = np.array(radiance, np.float64).reshape(-1, max(rays, 1), 3)
    metal = np.asarray(metal, bool).reshape(len(out), -1)
    if not out.size:
        return out.reshape(-1, 3)
    peak = out.max(axis=2)
    faces = np.arange(len(out))
    order = np.argsort(peak, axis=1, kind="stable")
    top = order[:, -1]
    second = peak[faces, order[:, -2]] if out.shape[1] > 1 else np.zeros(len(out))
    brightest = peak[faces, top]
    most = np.maximum(OUTLIER_FLOOR, OUTLIER_RATIO * second)
    lone = (brightest > most) & metal[faces, top]
    out[faces, top] *= np.where(lone, most / np.maximum(brightest, 1e-30), 1.0)[:, None]
    return out.reshape(-1, 3)


def picks(cache: RadianceCache, paths) -> np.ndarray:
    """(H,) int64 per hit of ``paths`` (the cache's rays, ``face_paths``: ray i is face
    i // rays' ray i % rays) the row of the face it reads among the cache's present faces
    (``face_points``' order; the row after the last: none, 0), ``pick`` drawn by the ray's
    hash (``PICK_STREAM``, seed 0). The same for every iteration of a layout."""
    u = unit_float(point_streams(paths.hit, PICK_STREAM))
    compact = pick(cache, paths.points, paths.normals, u)
    # compact index (voxel id · 6 + face) → row among the present faces
    present = np.concatenate([np.asarray(q, bool) for q in cache.present]).reshape(-1)
    rows = np.cumsum(present) - 1
    return np.where(compact >= 0, rows[np.maximum(compact, 0)], int(present.sum()))


def _masks(present) -> np.ndarray:
    """(N,) the faces each voxel holds as Σ 2^f (``cache_texels``' id rows, .y)."""
    return (np.asarray(present, np.int64) << np.arange(6)).sum(axis=1)


def pick(cache: RadianceCache, points, normals, u) -> np.ndarray:
    """(K,) int64: the face ``lookup`` reads at each point drawn by ``u`` (K,) in [0, 1) with
    the lookup's own weights — in the finest grid holding the point where some neighbour
    holds a face n faces, an axis by its share of the blend, then a corner voxel by its
    trilinear weight among those holding that axis' face — as its compact index (voxel id ·
    6 + face, the voxels numbered as ``cache_texels``'), -1 where the lookup reads 0. The
    face's value there has the lookup's expectation over u (``cache_lookup.glsl``
    ``cache_pick``, its twin; docs/gi_pipeline.md "Multi-bounce radiance cache", "Each ray
    picks one face")."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    u = np.asarray(u, np.float64).reshape(-1)
    out = np.full(len(p), -1, np.int64)
    face = np.where(n < 0, 1, 0) + np.array([0, 2, 4])  # (K, 3) face per axis
    blend = np.where(n ** 2 >= AXIS_BLEND, n ** 2, 0.0)
    todo = np.ones(len(p), bool)
    starts = _voxel_starts(cache)
    for g, (grid, cells, present, planes) in enumerate(zip(cache.grids, cache.cells,
                                                           cache.present, face_planes(cache))):
        if not todo.any():
            break
        at = (p - np.asarray(grid.origin)) / grid.span
        res = grid.resolution
        rows = np.flatnonzero(todo & cells_within(at, 0, res))
        if len(rows) == 0 or len(cells) == 0:
            continue
        index = _dense_index(grid, cells)
        k = np.arange(len(rows))
        gg = at[rows] - 0.5
        base = np.floor(gg).astype(np.int64)
        frac = gg - base
        held = np.zeros((2, len(rows), 8, 3))  # in front, [0], and all held, [1] (``lookup``)
        ids = np.full((len(rows), 8), -1, np.int64)
        for corner in range(8):
            offset = np.array([(corner >> 2) & 1, (corner >> 1) & 1, corner & 1])
            c = base + offset
            w = np.prod(np.where(offset == 1, frac, 1.0 - frac), axis=1)
            ok = cells_within(c, 0, res)
            site = np.where(ok, index[np.where(ok, (c[:, 0] * res + c[:, 1]) * res + c[:, 2],
                                               0)], -1)
            safe = np.maximum(site, 0)[:, None]
            holds = (site >= 0)[:, None] & present[safe, face[rows]]
            front = holds & _in_front(grid, c, planes[safe, face[rows]], p[rows], n[rows])
            held[0, :, corner] = np.where(front, w[:, None], 0.0)
            held[1, :, corner] = np.where(holds, w[:, None], 0.0)
            ids[:, corner] = np.where(site >= 0, starts[g] + site, -1)
        held = np.where((held[0].sum(axis=1) > 1e-6)[:, None, :], held[0], held[1])
        weight = held.sum(axis=1)
        share = np.where(weight > 1e-6, blend[rows], 0.0)
        norm = share.sum(axis=1)
        found = norm > 1e-6  # else the next coarser grid, as ``lookup``
        target = u[rows] * norm
        last = np.where(share[:, 2] > 0, 2, np.where(share[:, 1] > 0, 1, 0))
        axis = np.where((share[:, 0] > 0) & (target < share[:, 0]), 0,
                        np.where((share[:, 1] > 0) & (target < share[:, 0] + share[:, 1]), 1,
                                 last))
        before = np.where(axis == 0, 0.0, np.where(axis == 1, share[:, 0],
                                                   share[:, 0] + share[:, 1]))
        v = np.clip((target - before) / np.maximum(share[k, axis], 1e-30), 0.0, 1.0) * \
            weight[k, axis]
        w = held[k, :, axis]                                     # (k, 8)
        passed = (w > 0) & (np.cumsum(w, axis=1) - w <= v[:, None])
        corner = 7 - np.argmax(passed[:, ::-1], axis=1)          # the last that passed
        chosen = ids[k, corner] * 6 + face[rows][k, axis]
        out[rows[found]] = chosen[found]
        todo[rows[found]] = False
    return out


def iterate(cache: RadianceCache, tris, lights, albedo, emission, rays: int = 8, seed: int = 0,
            world=(0.0, 0.0, 0.0), hit_samples: int = 1, hit_glossy: bool = True) -> RadianceCache:
    """One more bounce: every voxel face gathers ``rays`` exact rays shaded by
    ``exact_indirect.ray_radiance`` with ``cache`` at their hits (see the module doc) — the
    diffuse gather at ``face_points``, sample id = the face's row (``face_paths`` then
    ``relax``, twice: the glossy shares read the first pass; ``cached_cache`` traces the
    paths once for all its iterations)."""
    paths = face_paths(cache, tris, lights, albedo, emission, rays, seed, world, hit_samples,
                       hit_glossy)
    chosen = picks(cache, paths)
    return relax(cache, paths, rays, chosen, level=relax(cache, paths, rays, chosen))


def _value_key(value):
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, hash(value.tobytes()))
    if isinstance(value, (list, tuple)):
        return tuple(_value_key(v) for v in value)
    if hasattr(value, "__dataclass_fields__"):
        return tuple((name, _value_key(getattr(value, name))) for name in value.__dataclass_fields__)
    return value if isinstance(value, (int, float, str, bool, type(None))) else id(value)


def cache_key(lights, albedo, emission, *settings) -> tuple:
    """What a cache of the same triangles depends on besides them, by content (lights are
    rebuilt for every viewport slice; hashing their arrays costs far less than a cache)."""
    return (_value_key(list(lights)), _value_key(albedo), _value_key(np.asarray(emission)),
            settings)


_MEMO: dict = {}


def triangles_key(tris) -> tuple:
    """The triangles by content (a snapshot taken again makes new arrays of the same values)."""
    return tuple(_value_key(getattr(tris, name, None)) for name in
                 ("positions", "materials", "corner_normals", "visibility"))


def cached_cache(tris, lights, albedo, emission, bounces: int, rays: int = 8,
                 resolution: int = 0, world=(0.0, 0.0, 0.0), hit_samples: int = 1,
                 hit_glossy: bool = True, focus=None, nest_rays: int = 0) -> RadianceCache | None:
    """The cache of ``bounces`` − 1 iterations for these triangles, lights and materials (None
    for ``bounces`` < 1; at 1, no iteration of its own and the first one ahead: the light a
    glossy scatter carries past Cycles' Diffuse 1, ``exact_indirect.RayPaths.with_cache``),
    with the next iteration ``ahead`` (``one_more_bounce``), kept for the
    next call with the same inputs (the viewport's slices ask for the same cache). focus : the
    camera or the emitters (Auto nests grids around it within ``nest_rays``, ``build_cache``;
    ``snap_focus``'d here)."""
    if bounces < 1:
        return None
    focus = snap_focus(tris, focus)
    key = (triangles_key(tris), cache_key(lights, albedo, emission, bounces, rays, resolution,
                                           tuple(float(w) for w in world), hit_samples,
                                           hit_glossy, focus, nest_rays))
    held = _MEMO.get("entry")
    if held is not None and held[0] == key:
        return held[1]
    cache = build_cache(tris, resolution, rays=rays, focus=focus, nest_rays=nest_rays)
    paths = face_paths(cache, tris, lights, albedo, emission, rays, world=world,
                       hit_samples=hit_samples, hit_glossy=hit_glossy)
    chosen = picks(cache, paths)  # and the faces their hits read: picked once
    earlier = ()  # the iterations before the latest, latest first (``cache_levels``)
    for _ in range(bounces):  # the same rays every iteration: traced once
        # each iteration twice: its glossy shares read the first pass (``relax``)
        made = relax(cache, paths, rays, chosen, level=relax(cache, paths, rays, chosen))
        if made.iterations == bounces:  # one iteration ahead: ``one_more_bounce``
            cache = replace(cache, ahead=made.faces, earlier=earlier)
        else:
            if cache.iterations:
                earlier = (cache.faces, *earlier)
            cache = made
    _MEMO["entry"] = (key, cache)
    return cache


def _texel_width(cache: RadianceCache) -> int:
    return max(cache.grids[0].resolution ** 2, len(cache.grids) + 1)


def _voxel_starts(cache: RadianceCache) -> np.ndarray:
    """(count + 1,) each grid's first voxel id in ``cache_texels``' voxel order (grids finest
    first), and the voxels in all."""
    return np.concatenate([[0], np.cumsum([len(c) for c in cache.cells])]).astype(np.int64)


def texel_places(cache: RadianceCache, part: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """((F,) rows, (F,) columns) of each present face (``face_points``' order) in the texels of
    ``cache_texels`` (part 1: of its ``ahead`` iteration)."""
    res = cache.grids[0].resolution
    count = len(cache.grids)
    width = _texel_width(cache)
    starts = _voxel_starts(cache)
    first_row = 1 + count * res
    rows, columns = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for g, present in enumerate(cache.present):
        voxel, face = np.nonzero(present)
        texel = (part * starts[-1] + starts[g] + voxel) * 6 + face
        rows.append(first_row + texel // width)
        columns.append(texel % width)
    return np.concatenate(rows), np.concatenate(columns)


def cache_texels(cache: RadianceCache, layout: bool = False, ahead: bool = False) -> np.ndarray:
    """(H, W, 4) float32 texels of ``cache`` for the GPU (``shaders/cache_lookup.glsl``
    ``cache_indirect``), W = res²: row 0 the header — texel i = (origin xyz, span) of grid i,
    the last texel (res, grid count, 2 × the iterations ``faces`` holds + 1 with the ahead
    and earlier parts, voxels V in all); then per grid g
    and z the row 1 + g·res + z of each cell's voxel id (texel x + y·res: .x, the grids' voxels
    numbered finest grid first; -1 where the grid has no voxel), the faces it holds (.y,
    Σ 2^f over its present faces f: ``pick`` reads them without the faces) and where their
    surfaces lie (.z, .w: ``plane_codes``); then the faces, compact:
    face f of voxel v in part p (0: ``faces``; where the cache keeps an ``ahead`` and its
    ``earlier`` iterations, 1: ``ahead``, 1 + f: ``cache_levels`` f ≥ 1, which a gather ray
    followed f bounces past a near hit reads) is texel (p·V + v)·6 + f, counted along the rows
    after the ids,
    holding (rgb, 1 where the voxel holds the face). Only voxels that exist take texels (a
    dense grid of faces put the HDRI courtyard's 23 k faces in 4.7 M texels: docs/gi_pipeline.md
    "Multi-bounce radiance cache", "Compact texels"). layout : instead of the rgb, (the face's
    row in ``face_points``, p, 0) — a cache's texels before its first iteration — with the
    ahead part when ``ahead`` (the GPU's build adds the earlier ones: ``gpu_gather
    .cache_stages``)."""
    res = cache.grids[0].resolution
    count = len(cache.grids)
    width = _texel_width(cache)
    starts = _voxel_starts(cache)
    levels = () if layout else cache_levels(cache)
    if layout:
        parts = 2 if ahead else 1
    else:  # the earlier iterations only with an ahead one (their part numbers follow it)
        parts = 1 + len(levels) if cache.ahead and levels else 1
    face_rows = -(-(parts * int(starts[-1]) * 6) // width)
    texels = np.zeros((1 + count * res + face_rows, width, 4), np.float32)
    for g, grid in enumerate(cache.grids):
        texels[0, g] = (*grid.origin, grid.span)
    texels[0, width - 1] = (res, count, 2 * cache.iterations + (parts > 1), starts[-1])
    texels[1:1 + count * res, :res * res, 0] = -1.0
    for g, (cells, present, planes) in enumerate(zip(cache.cells, cache.present,
                                                    face_planes(cache))):
        c = np.asarray(cells, np.int64)
        at = (1 + g * res + c[:, 2], c[:, 0] + c[:, 1] * res)
        texels[at[0], at[1], 0] = starts[g] + np.arange(len(c))
        texels[at[0], at[1], 1] = _masks(present)
        texels[at[0], at[1], 2:4] = plane_codes(planes)
    for part, faces in enumerate((cache.faces, cache.ahead, *levels[1:])[:parts]):
        rows, columns = texel_places(cache, part)
        if layout:
            texels[rows, columns, 0] = np.arange(len(rows))
            texels[rows, columns, 1] = part
            texels[rows, columns, 3] = 1.0
        else:
            texels[rows, columns, :3] = np.concatenate(
                [f[present] for f, present in zip(faces, cache.present)])
            # .a: 1, and in part 0 + the face's ``one_more_bounce`` (held faces read > 0.5)
            texels[rows, columns, 3] = 1.0 if part else 1.0 + np.concatenate(
                [m[present] for m, present in zip(one_more_bounce(cache), cache.present)])
    return texels
