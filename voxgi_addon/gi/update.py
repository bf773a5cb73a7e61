"""One GI update: cached voxels → cascades → direct light → octree (no re-voxelization).

Runs on the worker thread on plain data (snapshot + caches); returns a ``GIState`` that the
cone tracer and the preview read.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGICancelled, VoxGIError
from ..scene.snapshot import RAY_ALL
from .cascades import grids_key, place_cascades, place_objects
from .light_injection import inject_direct_light
from .ray_views import view_cascades, view_octrees
from .svo import build_octree
from .voxel_shadows import CascadeOccupancy


@dataclass(frozen=True)
class GISettings:
    """resolution : cells per axis of every cascade (power of two); dense_depth : octree levels
    kept as dense 3D arrays; light_samples : shadow rays per voxel for soft lights (1: a
    voxel is wider than most penumbrae, and per-pixel direct light is sampled separately).
    view_ahead : how far ahead of the camera the cascades are centred, as a fraction of the
    finest cascade's half-extent (0 = on the camera, as in the thesis). Half of a
    camera-centred grid lies behind the camera; 1.0 puts the finest cascade's back face at the
    camera, so it covers twice the depth of view at the same cost. Grids still snap to whole
    coarse voxels, so moving the camera does not make them flicker.
    one_sided_leaves : a voxel's light leaves only through its front (its anisotropic faces
    seen from behind are dark), so a wall lit on one side does not glow on the other:
    thin-wall leak 0.086 → 0.043 of the lit side, Cornell box still 0.22/0.25 vs Cycles
    (the cone tracer's ConeSettings take it on to 0.013, Cornell 0.23/0.23)."""

    resolution: int = 64
    dense_depth: int = 6
    light_samples: int = 1
    view_ahead: float = 1.0
    one_sided_leaves: bool = True


@dataclass
class GIState:
    grids: list
    cascades: list
    radiance: list
    octree: object
    timings: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    # (len(grids) + 1,) share of the visible points whose finest cascade is i, the last entry
    # outside all (view_fit.cascade_shares); set by the caller that probed the view, or None.
    view_shares: object = None
    # What the update could take from the previous state (``update_gi``'s ``previous``):
    # "all" (nothing changed: the previous cascades, light and octree), "objects" (some or all
    # objects' placed voxels) or "" (nothing). placed_objects: the objects transformed anew.
    reused: str = ""
    placed_objects: tuple = ()
    # the per-object placed voxels (cascades.Placement) and the light inputs, for the next update
    placement: object = None
    light_key: tuple = ()
    # Cycles' ray visibility (gi/ray_views.py): ``cascades``/``octree`` are what diffuse rays
    # see; per kind ("glossy", "shadow") whose objects differ, its own ``VoxelView``
    ray_views: dict = field(default_factory=dict)
    settings: object = None  # the GISettings it was made with

    @property
    def voxel_counts(self) -> list[int]:
        return [cv.voxel_count for cv in self.cascades]


def anchor_position(snapshot, ahead: float = 0.0) -> tuple[np.ndarray, list[str]]:
    """Where the cascades are centred: ``ahead`` metres in front of the camera, or the scene's
    centre if there is no camera (with a warning)."""
    if snapshot.camera is not None:
        m = np.asarray(snapshot.camera.world_matrix, np.float64)
        forward = -m[:3, 2] / max(np.linalg.norm(m[:3, 2]), 1e-12)  # cameras look along -Z
        return m[:3, 3] + forward * ahead, []
    centres = [np.asarray(o.world_matrix, np.float64)[:3, 3] for o in snapshot.objects]
    if not centres:
        raise VoxGIError("the scene has neither a camera nor objects to centre the cascades on")
    return np.mean(centres, axis=0), ["the scene has no camera: cascades are centred on the objects"]


def _value_key(value):
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    return value


def light_key(snapshot, settings: GISettings) -> tuple:
    """Everything the injection and the octree read besides the cascades: lights, world, the
    materials' emission and their emission textures' content (voxels glow with it and are lit
    by it), the objects' ray visibility (``ray_views``) and the settings (plain values and
    array bytes, comparable with ``==``)."""
    def fields(item):
        return tuple((f.name, _value_key(getattr(item, f.name))) for f in dataclasses.fields(item))

    world = snapshot.world
    # a world map is known by its content key (hashing megabytes of radiance every update
    # would cost more than what it saves)
    world_key = (world.key, _value_key(world.color), world.strength) if world.key else fields(world)
    textures = getattr(snapshot, "textures", ())

    def texture_key(index):  # an emission texture's content (its mean is in ``emission``)
        texture = textures[index] if 0 <= index < len(textures) else None
        return None if texture is None else (texture.key or _value_key(texture.pixels),
                                             _value_key(np.asarray(texture.uv_transform)))

    emission = tuple((_value_key(m.emission), texture_key(getattr(m, "emission_texture", -1)),
                      getattr(m, "emission_strength", 1.0)) for m in snapshot.materials)
    # Cycles' ray visibility chooses what casts shadows and what each kind of cone sees
    seen_by = {o.name: int(getattr(o, "visibility", RAY_ALL)) for o in snapshot.objects}
    hidden = tuple(sorted((name, bits) for name, bits in seen_by.items() if bits != RAY_ALL))
    return (tuple(fields(light) for light in snapshot.lights), world_key, emission,
            fields(settings), hidden)


def update_gi(snapshot, caches, settings: GISettings = GISettings(), cancel=None,
              anchor=None, previous: GIState | None = None) -> GIState:
    """Transform the caches into camera-anchored cascades, light them and build the octree.

    caches : mesh_caches.CacheBuildResult from the last voxelization (its spans set the
    cascades' spans). cancel : callable returning True to stop between stages.
    anchor : (3,) world centre of the cascades instead of the camera (``view_fit.ViewFit``'s
    centre, docs/gi_pipeline.md "View-fitted cascades"); ``view_ahead`` is then unused.
    previous : the state of an earlier update (any scene or caches: what it may reuse is
    checked). Objects whose caches, matrix and pose did not change on the same grids keep
    their placed voxels (only what moved is transformed: ``reused == "objects"``); when no
    object changed and the lights, world and settings are the same, the previous cascades,
    light and octree are returned as they are (``reused == "all"``).
    """
    if not caches.cascade_stats:
        raise VoxGIError("there are no voxel caches yet: voxelize the scene first")
    timings: dict[str, float] = {}

    def stage(name, fn, *args, **kw):
        if cancel is not None and cancel():
            raise VoxGICancelled("GI update cancelled")
        t0 = time.perf_counter()
        value = fn(*args, **kw)
        timings[name] = time.perf_counter() - t0
        return value

    base_span = caches.cascade_stats[0].span
    if anchor is None:
        ahead = settings.view_ahead * 0.5 * settings.resolution * base_span
        position, warnings = anchor_position(snapshot, ahead)
    else:
        position, warnings = np.asarray(anchor, np.float64), []
    grids = stage("cascades", place_cascades, position, base_span, settings.resolution,
                  len(caches.cascade_stats))
    before = previous.placement if previous is not None else None
    placement = stage("transform", place_objects, caches, snapshot, grids, previous=before)
    warnings.extend(placement.warnings)
    lights = light_key(snapshot, settings)
    reused = "" if before is None or len(placement.placed) == len(placement.objects) else "objects"
    if reused and not placement.placed and placement.objects.keys() == before.objects.keys() \
            and previous.light_key == lights and grids_key(previous.grids) == grids_key(grids):
        return GIState(previous.grids, previous.cascades, previous.radiance, previous.octree,
                       timings, warnings, reused="all", placement=placement, light_key=lights,
                       ray_views=previous.ray_views, settings=previous.settings)
    views = stage("merge", view_cascades, placement, grids, snapshot)
    cascades = views["diffuse"]
    occupancy = stage("occupancy", CascadeOccupancy, views["shadow"])  # what casts shadows
    # the previous injection's shadow rays: those that meet nothing that moved are not
    # marched again (light_injection, docs/gi_pipeline.md "Posed updates")
    rays = getattr(previous.radiance, "rays", None) if previous is not None else None
    radiance = stage("inject", inject_direct_light, cascades, snapshot, occupancy,
                     settings.light_samples, rays=rays, keep_rays=True)
    depth = int(np.log2(settings.resolution)) + len(grids) - 1

    def octree_of(voxels, light):
        return build_octree(voxels, light, min(settings.dense_depth, depth),
                            one_sided_leaves=settings.one_sided_leaves)

    octree = stage("svo", octree_of, cascades, radiance)
    ray_views = stage("ray views", view_octrees, views, snapshot, occupancy, lambda c, s, o:
                      inject_direct_light(c, s, o, settings.light_samples), octree_of)
    return GIState(grids, cascades, radiance, octree, timings, warnings, reused=reused,
                   placed_objects=placement.placed, placement=placement, light_key=lights,
                   ray_views=ray_views, settings=settings)
