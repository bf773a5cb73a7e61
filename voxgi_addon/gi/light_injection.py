"""Direct light injected into cascade voxels (Yalçıner 2016 4.5, "inject" step).

Each voxel's outgoing radiance = albedo × (Diffuse Direct + world ambient) + emission, in
Cycles' units (``direct_light`` holds the light models; shadows march through the voxel
occupancy instead of the triangles). The lights are every light of the scene: the lamps, the
world map (``world_light``) and the emissive triangles (``emitters``; their shadow rays' plain
estimate, as at the Accurate gathers' bounce hits). The emission is the material's Emission
Color × Strength of the emissive triangles that cross the voxel, weighted by how much of the
voxel they cover (``voxel_emission``); with an emission texture, of the emitters' pieces
(``emitters.emitter_light``: each the texture's mean over it). The octree then averages it upward.

``inject_direct_light`` returns the radiance as an ``InjectedRadiance`` list whose
``emission`` holds the emission part alone, so that ``svo.build_octree`` can keep an emission
octree beside the radiance one (docs/gi_pipeline.md "Fast quality: world and emission").

What an injection leaves for the next is kept (docs/gi_pipeline.md "Posed updates",
``kept_rays``): a voxel's shadow rays are drawn from its cell (``voxel_ids``: the strata are
hashed from it, not drawn in voxel order), so a voxel that stays where it was casts the same
rays as before; a ray that meets no cell whose occupancy changed ends as it did, and a voxel
none of whose rays does, under the same lights, keeps its light. Only the rest is marched and
lit again, with the result of doing it all.
"""
from __future__ import annotations

import dataclasses
import threading

import numpy as np

from .cascades import cells_within
from .direct_light import diffuse_direct
from .kept_rays import KeptRays, ShadowRays, ray_origins
from .voxel_shadows import CascadeOccupancy

# Shadow rays start this many voxels off the surface so a voxel does not shadow itself.
SHADOW_START_VOXELS = 1.5
# Shadow rays to a point on an emissive triangle stop this many voxels (at the point) short of
# it: the emitter's own voxels must not shadow it.
EMITTER_STOP_VOXELS = 2.0


class InjectedRadiance(list):
    """Per cascade (N_i, 3) float32 outgoing radiance (emission included), with ``emission``:
    per cascade the (N_i, 3) float32 emission part (None when nothing emits), and ``rays``:
    what it cast (``kept_rays.ShadowRays``, for the next injection; None when not kept).
    ``marched`` / ``reused``: how many shadow rays were marched and taken from before;
    ``relit``: how many voxels were lit (the others kept their light)."""

    emission: list | None = None
    rays: object = None
    marched: int = 0
    reused: int = 0
    relit: int = 0


def voxel_ids(cascade) -> np.ndarray:
    """(N,) int64 ids of a CascadeVoxels' cells, unique over every cascade of a set (its index
    and its cell): a voxel's shadow rays are drawn from its id (``direct_light``'s
    ``sample_ids``), so a voxel that stays in its cell draws the same ones."""
    res = int(cascade.grid.resolution)
    cells = np.asarray(cascade.cells, np.int64).reshape(-1, 3)
    return ((int(cascade.grid.index) * res + cells[:, 0]) * res + cells[:, 1]) * res + cells[:, 2]


def voxel_centres(cascade) -> np.ndarray:
    """(N, 3) float64 world-space centres of a CascadeVoxels' cells."""
    g = cascade.grid
    return np.asarray(g.origin, np.float64) + (np.asarray(cascade.cells, np.float64) + 0.5) * g.span


def material_emission(snapshot) -> np.ndarray:
    """(M + 1, 3) float64 Emission Color × Strength per material, the last row (no material) 0;
    non-finite or negative values count as 0."""
    rows = [np.asarray(m.emission, np.float64)[:3] for m in snapshot.materials] + [np.zeros(3)]
    return np.maximum(np.nan_to_num(np.array(rows, np.float64).reshape(-1, 3)), 0.0)


def emissive_triangles(tris, emission) -> tuple[np.ndarray, np.ndarray]:
    """(corners (E, 3, 3), radiance (E, 3)) of the triangles of ``tris`` (``SceneTriangles``)
    whose material emits (``emission`` per material as ``material_emission``)."""
    last = len(emission) - 1
    materials = np.asarray(tris.materials)
    materials = np.where((materials >= 0) & (materials < last), materials, last)
    radiance = emission[materials]
    keep = radiance.max(axis=1) > 0 if len(radiance) else np.zeros(0, bool)
    return np.asarray(tris.positions, np.float64)[keep], radiance[keep]


def emissive_objects(snapshot, emission):
    """``snapshot`` with only its objects that have an emissive triangle (``emission`` per
    material as ``material_emission``): the emitters' triangles without placing every other
    mesh of the scene (a posed character's skinning, at each pose)."""
    last = len(emission) - 1
    glowing = emission.max(axis=1) > 0

    def emits(obj):
        mesh = snapshot.meshes.get(obj.mesh)
        if mesh is None or len(mesh.triangles) == 0:
            return False
        materials = np.unique(np.asarray(mesh.triangle_materials, np.int64))
        return bool(glowing[np.where((materials >= 0) & (materials < last), materials, last)].any())

    return dataclasses.replace(snapshot, objects=[obj for obj in snapshot.objects if emits(obj)])


def voxel_emission(cascades, corners, radiance) -> list[np.ndarray]:
    """Per cascade, the (N_i, 3) float32 emission of its voxels: Σ over the emissive triangles
    (``corners`` (E, 3, 3) world, ``radiance`` (E, 3)) that cross the voxel of radiance × the
    area of the triangle inside the voxel / span², the covered share capped at 1 (a triangle
    crossing the whole voxel covers it, as the octree's occlusion reads such a voxel as
    opaque; a voxel the triangle only grazes glows in proportion). Voxels the cascade does not
    hold get nothing."""
    out = []
    for cv in cascades:
        value = np.zeros((cv.voxel_count, 3), np.float64)
        if len(corners) and cv.voxel_count:
            g = cv.grid
            surface, area = _clipped_emitters(corners, g)
            cells = surface.cells.astype(np.int64)
            res = int(g.resolution)
            inside = cells_within(cells, 0, res)
            key = (cells[:, 0] * res + cells[:, 1]) * res + cells[:, 2]
            own = np.asarray(cv.cells, np.int64)
            own_key = (own[:, 0] * res + own[:, 1]) * res + own[:, 2]
            order = np.argsort(own_key)
            at = np.clip(np.searchsorted(own_key[order], key), 0, len(own_key) - 1)
            row = np.where(inside & (own_key[order][at] == key), order[at], -1)
            pair_row = row[surface.cell_of_pair]
            used = pair_row >= 0
            glow = np.zeros((cv.voxel_count, 3))
            cover = np.zeros(cv.voxel_count)
            np.add.at(glow, pair_row[used], area[used, None] * radiance[surface.triangle_of_pair[used]])
            np.add.at(cover, pair_row[used], area[used])
            value = glow / np.maximum(cover, 1.0)[:, None]
        out.append(value.astype(np.float32))
    return out


# (grid origin, span, resolution, emitter corners) → ``_clipped_emitters``' (surface, area):
# a posed update keeps its grids and a still emitter its triangles (on the rig beside a panel,
# 3.3 of the 13 ms injection that lights nothing again)
_CLIPPED: dict[tuple, tuple] = {}
_CLIPPED_LOCK = threading.Lock()  # (the worker's and F12's injections)
MAX_CLIPPED = 8


def _clipped_emitters(corners, grid):
    """The emissive triangles voxelized in ``grid`` and each (cell, triangle) pair's area
    inside the cell (``voxelize_triangles``, ``clip_pairs``), kept for the next injection."""
    from ..voxelize.attributes import clip_pairs
    from ..voxelize.surface import voxelize_triangles

    corners = np.ascontiguousarray(corners, np.float64)
    origin = np.asarray(grid.origin, np.float64)
    key = (origin.tobytes(), float(grid.span), int(grid.resolution), corners.shape,
           corners.tobytes())
    with _CLIPPED_LOCK:
        found = _CLIPPED.get(key)
    if found is None:
        local = (corners - origin).reshape(-1, 3)
        triangles = np.arange(len(local)).reshape(-1, 3)
        surface = voxelize_triangles(local, triangles, float(grid.span))
        # the voxelizer's cells are the cascade's cells (its lattice offset is 2⁻¹⁶ voxel)
        area, _ = clip_pairs(surface, local, triangles)
        found = (surface, np.nan_to_num(area, nan=0.0))
        with _CLIPPED_LOCK:
            while len(_CLIPPED) >= MAX_CLIPPED:
                _CLIPPED.pop(next(iter(_CLIPPED)))
            _CLIPPED[key] = found
    return found


class _StopShort:
    """An occluder that ends each finite shadow ray EMITTER_STOP_VOXELS voxels before its end
    (rays to points on emissive triangles, whose own voxels would block them). ``occupancy``:
    a ``CascadeOccupancy`` or anything with its ``local_span`` and ``occluded``."""

    def __init__(self, occupancy):
        self.occupancy = occupancy

    def occluded(self, origins, dirs, max_t):
        max_t = np.broadcast_to(np.asarray(max_t, np.float64), (len(origins),))
        finite = np.isfinite(max_t)
        ends = origins + dirs * np.where(finite, max_t, 0.0)[:, None]
        span = self.occupancy.local_span(ends)
        short = np.where(finite & np.isfinite(span), max_t - EMITTER_STOP_VOXELS * span, max_t)
        return self.occupancy.occluded(origins, dirs, short)


def lights_key(snapshot, samples: int, emitters=None) -> tuple:
    """What the voxels' direct light depends on besides the voxels and their shadow rays: the
    lamps, the world, the emissive triangles (``emitters``, an ``EmitterLight`` or None: their
    corners, radiance and sides, so an emitter that moves or changes relights every voxel) and
    the samples (plain values and array bytes, comparable with ``==``)."""
    def value(v):
        return (v.dtype.str, v.shape, v.tobytes()) if isinstance(v, np.ndarray) else v

    glow = None if emitters is None else tuple(
        value(np.asarray(getattr(emitters, name))) for name in ("corners", "radiance", "sides"))

    world = snapshot.world
    world_key = (world.key, value(np.asarray(world.color)), world.strength) if world.key else \
        tuple(value(getattr(world, f.name)) for f in dataclasses.fields(world))
    return (tuple(tuple(value(getattr(light, f.name)) for f in dataclasses.fields(light))
                  for light in snapshot.lights), world_key, glow, int(samples))


def inject_direct_light(cascades, snapshot, occupancy: CascadeOccupancy | None = None,
                        samples: int = 4, rays: ShadowRays | None = None,
                        keep_rays: bool = False) -> InjectedRadiance:
    """Outgoing radiance (N_i, 3) float32 of every cascade's voxels (``InjectedRadiance``).

    cascades : list of CascadeVoxels (finest first); snapshot : for lights, world, materials.
    occupancy : shadow casters (defaults to the cascades' own voxels).
    rays : the ``InjectedRadiance.rays`` of an earlier injection: what meets nothing changed
        is not marched or lit again (the module doc); keep_rays : keep what this injection
        cast in the result's ``rays`` (on when ``rays`` is given).
    """
    from ..scene.geometry import world_triangles
    from .emitters import emitter_light
    from .world_light import scene_lights

    occupancy = occupancy or CascadeOccupancy(cascades)
    # The world lights the voxels as a light (its map, shadowed by the voxels) where it has a
    # map; a world known only by its colour adds it unshadowed, as before.
    lights = scene_lights(snapshot)
    ambient = np.zeros(3) if getattr(snapshot.world, "radiance", None) is not None else \
        np.asarray(snapshot.world.color, np.float64) * float(snapshot.world.strength)
    emission = material_emission(snapshot)
    corners = glow = np.zeros((0, 3, 3))
    emitters = None
    if emission.max() > 0:
        tris = world_triangles(emissive_objects(snapshot, emission))
        corners, glow = emissive_triangles(tris, emission)
        emitters = emitter_light(tris, emission)
        if emitters is not None and getattr(getattr(tris, "textures", None), "emission_slots",
                                            None) is not None:
            # emission per texel: the emitters' pieces, each the texture's mean over it
            corners, glow = emitters.corners, emitters.radiance
        if emitters is not None:  # the shadow rays' plain estimate: no exact sum per voxel
            emitters = dataclasses.replace(emitters, exact=False)
    emitted = voxel_emission(cascades, corners, glow) if len(corners) else None
    kept = None
    if rays is not None or keep_rays:
        kept = KeptRays(occupancy, rays, lights_key(snapshot, samples, emitters))
    occluder = occupancy if kept is None else kept

    def light(start, normals, ids):
        """The Diffuse Direct of surface points from every lamp, the world and the emitters."""
        direct = diffuse_direct(start, normals, lights, occluder, samples=samples,
                                sample_ids=ids)
        if emitters is not None:
            direct = direct + diffuse_direct(start, normals, [emitters], _StopShort(occluder),
                                             samples=samples, seed=1, sample_ids=ids)
        return direct

    out, carried, relit = InjectedRadiance(), [], 0
    for index, cv in enumerate(cascades):
        if cv.voxel_count == 0:
            out.append(np.zeros((0, 3), np.float32))
            continue
        normals = np.asarray(cv.normal, np.float64)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        start = voxel_centres(cv) + normals * (SHADOW_START_VOXELS * cv.grid.span)
        ids = voxel_ids(cv)
        if kept is None:
            direct = light(start, normals, ids)
        else:
            origins = ray_origins(start, normals)
            same, direct = kept.light_of(ids, normals, origins)
            lit = ~same
            relit += int(lit.sum())
            if lit.any():
                direct[lit] = light(start[lit], normals[lit], ids[lit])
            kept.keep_light(ids, normals, direct)
            carried.append(origins[same])
        value = np.asarray(cv.albedo, np.float64) * (direct + ambient)
        if emitted is not None:
            value = value + emitted[index]
        out.append(value.astype(np.float32))
    if emitted is not None:
        out.emission = emitted
    if kept is not None:
        out.rays = kept.kept(np.concatenate(carried) if carried else None)
        out.marched, out.reused = kept.marched, kept.reused
        out.relit = relit
    return out
