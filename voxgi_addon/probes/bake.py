"""Baking a probe grid end to end (docs/probes.md "Bake").

``bake_probe_grid``: place the probes (``placement``), test and relocate them (``validity``),
build the occlusion masks (``masks``), then give each probe the SH L2 projection (``sh``) of
its incoming radiance. Light off surfaces comes along the bake's directions
(``sh.sample_directions``, the same set for every probe, fixed by the seed): one diffuse
bounce of direct light, exactly as Cycles' ``Diffuse Indirect`` with one bounce sees it — the
closest triangle hit (``scene.raycast``) shaded as the preview's gathers shade their bounce
hits (``gi.exact_indirect.ray_radiance``: Cycles' light models and shadow rays for lamps, the
world and emissive triangles, reflected by the hit's Principled diffuse and glossy lobes
toward the probe). Light straight from the
world and from the emissive surfaces comes by next-event estimation at the probe, combined
with those directions by multiple importance sampling (``direct``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGICancelled, VoxGIError
from ..scene.geometry import SceneTriangles, world_triangles
from .direct import emissive_sides, emitter_probe_sh, world_probe_sh
from .grid import DISABLED, RELOCATED, ProbeGrid
from .masks import ALL_SUBVOLUMES, occlusion_masks
from .placement import place_probes, scene_box
from .sh import project, sample_directions
from .validity import ProbeRays, relocate_probes, trace_probe_rays

__all__ = ["ProbeSettings", "BakeResult", "bake_probe_grid", "hit_radiance", "material_colours",
           "direct_probe_sh"]

_PROBE_CHUNK = 32  # probes whose rays are shaded together (progress and cancel granularity)
# Where emissive triangles light the scene, a bounce hit draws at least this many shadow rays
# (2 × 2 strata) for every light with an extent: the emitters' light at a hit is the plain
# estimate of one point drawn by power, and its 1/r² beside an emitter (a floor by a glowing
# sphere, a ceiling a few centimetres over a panel), reflected by the hit's diffuse and glossy
# lobes, is a spike that a probe's few hundred rays do not average away (docs/probes.md "Bake":
# the emissive room's worst probe 0.37 → 0.12 relative L1 against Cycles, the bake 2× longer)
EMITTER_SAMPLES = 4


@dataclass(frozen=True)
class ProbeSettings:
    """resolution : volumes per axis (k, or (kx, ky, kz)). directions : rays per probe.
    seed : fixes the direction set and the light sampling. use_masks / mask_threshold : the
    occlusion masks and the front-facing share they require (eq. 3.1). validity_threshold :
    back-face share above which a probe is invalid; relocate : move invalid probes out
    (else they are disabled). light_samples : shadow rays per hit for lights with an extent
    (one stratified ray is enough for lamps and the world: the SH projection averages the
    probe's hundreds of hits; at least ``EMITTER_SAMPLES`` where emissive triangles light the
    scene).
    direct_samples : rays per probe drawn by the world map's importance, and as many points
    drawn on the emissive triangles by power, for the light arriving straight from them
    (``direct``; rounded up to a square). radiance_factor : the light off surfaces is gathered
    along ``directions × radiance_factor`` directions: the validity test's (from the probes'
    final places) and radiance_factor − 1 more sets of as many, each under its own rotation.
    A shaded probe beside a sunlit floor sees a sharp-edged patch of bounce light that 256
    directions sample coarsely (docs/probes.md "Lights at the probe"). bounces : the diffuse
    bounces the probes carry (the preview's Bounces): beyond the first, each hit also reflects
    the multi-bounce radiance cache's light there (``gi.radiance_cache``, the preview's)."""

    resolution: int | tuple[int, int, int] = 8
    directions: int = 256
    seed: int = 0
    use_masks: bool = True
    mask_threshold: float = 0.5
    validity_threshold: float = 0.25
    relocate: bool = True
    light_samples: int = 1
    direct_samples: int = 64
    radiance_factor: int = 2
    bounces: int = 1


@dataclass
class BakeResult:
    grid: ProbeGrid
    timings: dict[str, float] = field(default_factory=dict)
    relocated: int = 0
    disabled: int = 0


def material_colours(snapshot) -> tuple[np.ndarray, np.ndarray]:
    """Albedo (M+1, 3) and emission (M+1, 3) per material index; the last row is 'none'."""
    from ..preview.passes import material_table  # the preview's table, imported late (no cycle)

    albedo, _, _, emission = material_table(snapshot)
    return albedo, emission


def hit_radiance(snapshot, tris: SceneTriangles, origins, dirs, t, tri, u, v,
                 light_samples: int = 4, seed: int = 0, seen_world: bool = True,
                 seen_emission: bool = True, cache=None) -> np.ndarray:
    """(N, 3) radiance arriving along rays whose closest hits (t, tri, u, v) are traced: a hit
    shaded as the preview's gathers shade their bounce hits (``exact_indirect.ray_radiance``
    with the Principled table): its emission, every light's direct light (lamps, the world,
    emissive triangles — ``world_light.scene_lights``) by its diffuse weight seen from the
    probe and by its glossy lobe toward the probe, a metal's lobe followed one reflection,
    on the side the ray came from; for a miss (tri = -1) the world in that direction (its
    map; its colour when it has none). That is what a white diffuse surface at the probe
    takes in as Cycles' Diffuse Indirect: the specular layer's share of a hit's light leaves
    its diffuse part and comes back by the glossy lobe (docs/probes.md "Bake").
    ``seen_world`` / ``seen_emission`` False leave out the world's map on a miss / the
    emission of a hit (the bake estimates those by next-event estimation at the probe,
    ``direct``). cache : a ``radiance_cache.RadianceCache`` whose light (bounces 2 … N) the
    hits reflect too (None: one bounce)."""
    from ..gi.exact_indirect import ray_radiance
    from ..gi.world_light import scene_lights, world_light, world_radiance
    from ..preview.passes import principled_table

    origins = np.asarray(origins, np.float64).reshape(-1, 3)
    dirs = np.asarray(dirs, np.float64).reshape(-1, 3)
    tri = np.asarray(tri, np.int64).reshape(-1)
    _, emission = material_colours(snapshot)
    lights = scene_lights(snapshot, tris, emission)
    if any(light.type == "EMITTERS" for light in lights):
        light_samples = max(light_samples, EMITTER_SAMPLES)
    ids = np.arange(len(dirs), dtype=np.uint32)  # each ray's own light samples
    out, _ = ray_radiance(origins, dirs, ids, tris, lights,
                          principled_table(snapshot), emission, seed, hit_samples=light_samples,
                          hit_glossy=True, emission_seen=seen_emission, cache=cache,
                          one_world_ray=False,  # a probe's few rays: both of the world's
                          hits=(np.asarray(t, np.float64).reshape(-1), tri,
                                np.asarray(u, np.float64).reshape(-1),
                                np.asarray(v, np.float64).reshape(-1)))
    miss = np.flatnonzero(tri < 0)
    sky = world_light(snapshot.world)
    if sky is not None:
        out[miss] = world_radiance(sky, dirs[miss]) if seen_world and len(miss) else 0.0
    elif getattr(snapshot.world, "radiance", None) is not None:
        out[miss] = 0.0  # a map with no light in it
    else:
        out[miss] = np.asarray(snapshot.world.color, np.float64)[:3] * float(snapshot.world.strength)
    return out


def direct_probe_sh(snapshot, tris: SceneTriangles, positions, directions, rays,
                    samples: int = 64, seed: int = 0, world: bool = True,
                    emitters: bool = True, first_id: int = 0) -> tuple[np.ndarray, bool, bool]:
    """((P, 9, 3) SH of the light arriving at each probe straight from the world and/or the
    emissive triangles (``direct``), whether the world was, whether the emitters were estimated
    so: each only when it is a light of ``world_light.scene_lights`` (a world with a map that
    sheds light; at most ``emitters.MAX_EMITTER_TRIANGLES`` emissive triangles), else the
    uniform rays keep seeing it. rays : ``validity.ProbeRays`` of ``directions`` from
    ``positions``; the probes' sample ids are their indices in the grid (``first_id`` + row)."""
    from ..gi.world_light import scene_lights

    _, emission = material_colours(snapshot)
    lights = scene_lights(snapshot, tris, emission)
    sky = next((light for light in lights if light.type == "WORLD"), None) if world else None
    glow = next((light for light in lights if light.type == "EMITTERS"), None) if emitters else None
    out = np.zeros((len(positions), 9, 3))
    ids = np.arange(first_id, first_id + len(positions), dtype=np.uint32)
    if sky is not None:
        out += world_probe_sh(tris, sky, positions, directions, rays.triangle, ids, samples, seed)
    if glow is not None:
        radiance, sides = emissive_sides(tris, emission)
        out += emitter_probe_sh(tris, glow, positions, directions, rays, radiance, sides, ids,
                                samples, seed)
    return out, sky is not None, glow is not None


def _rows(rays: ProbeRays, a: int, b: int) -> ProbeRays:
    """Probes a … b − 1 of ``rays``."""
    return ProbeRays(rays.t[a:b], rays.triangle[a:b], rays.u[a:b], rays.v[a:b], rays.back[a:b])


def _join(a: ProbeRays, b: ProbeRays) -> ProbeRays:
    """Each probe's rays of ``a`` then those of ``b``."""
    return ProbeRays(*(np.concatenate([x, y], axis=1) for x, y in
                       zip((a.t, a.triangle, a.u, a.v, a.back), (b.t, b.triangle, b.u, b.v, b.back))))


def _box(tris, box):
    if box is None:
        return scene_box(tris.positions)
    lo, hi = (np.asarray(b, np.float64).reshape(3) for b in box)
    return lo, hi


def _bounce_cache(snapshot, tris, bounces: int):
    """The preview's radiance cache of ``bounces`` − 1 iterations for the snapshot (None for
    one bounce): the same cache the Accurate gathers read, kept between calls."""
    if bounces <= 1:
        return None
    from ..gi.light_injection import material_emission
    from ..gi.radiance_cache import cached_cache
    from ..gi.world_light import scene_lights
    from ..preview.passes import principled_table

    emission = material_emission(snapshot)
    return cached_cache(tris, scene_lights(snapshot, tris, emission), principled_table(snapshot),
                        emission, bounces)


def bake_probe_grid(snapshot, settings: ProbeSettings = ProbeSettings(), box=None,
                    tris: SceneTriangles | None = None, cancel=None, progress=None,
                    name: str = "", sh_fn=None) -> BakeResult:
    """Place, validate, mask and bake one probe grid over ``box`` ((lo, hi) world corners; the
    scene's bounds, grown a little, when None).

    cancel : callable returning True to stop (raises ``VoxGICancelled``); progress : callable
    taking the finished share in [0, 1]. sh_fn : ``sh_fn(positions (P, 3), directions (N, 3))``
    → (P, 9, 3) replaces the exact radiance stage (the octree bakes, ``octree_bake`` and
    ``render/gpu_probes.py``); placement, validity, masks and the world's light straight at the
    probe (``direct_probe_sh``) stay exact, so sh_fn leaves a world that is a light out
    (``octree_world``).
    """
    if settings.directions < 9:
        raise VoxGIError(f"a probe needs at least 9 directions for SH L2, got {settings.directions}")
    timings: dict[str, float] = {}

    def check():
        if cancel is not None and cancel():
            raise VoxGICancelled("probe bake cancelled")

    t0 = time.perf_counter()
    tris = tris if tris is not None else world_triangles(snapshot)
    lo, hi = _box(tris, box)
    layout = place_probes(tris.positions, tris.normals, lo, hi, settings.resolution)
    timings["placement"] = time.perf_counter() - t0
    check()

    t0 = time.perf_counter()
    dirs = sample_directions(settings.directions, settings.seed)
    smallest = float(layout.volume_size.min())
    positions, validity, flags, rays = relocate_probes(
        tris, layout.positions, dirs, settings.validity_threshold, max_offset=0.5 * smallest,
        step=0.05 * smallest, relocate=settings.relocate)
    timings["validity"] = time.perf_counter() - t0
    check()

    t0 = time.perf_counter()
    if settings.use_masks:
        masks = occlusion_masks(layout, positions, settings.mask_threshold)
    else:
        masks = np.full((len(layout.volume_cells), 8), ALL_SUBVOLUMES, np.uint64)
    timings["masks"] = time.perf_counter() - t0
    check()

    t0 = time.perf_counter()
    p_count = len(positions)
    sh = np.zeros((p_count, 9, 3), np.float64)
    if sh_fn is not None:
        # the octree bakes' voxels hold the emission (their cones see it): only the world here
        sh += direct_probe_sh(snapshot, tris, positions, dirs, rays, settings.direct_samples,
                              settings.seed, emitters=False)[0]
        sh += sh_fn(positions, dirs)
        p_count = 0  # nothing left for the exact stage
    # the validity rays (from the final places) and (factor − 1) more rotated sets: near-uniform
    cache = _bounce_cache(snapshot, tris, settings.bounces) if p_count else None
    factor = max(1, int(settings.radiance_factor))
    extra = [sample_directions(len(dirs), settings.seed + 1 + i) for i in range(factor - 1)]
    radiance_dirs = np.concatenate([dirs, *extra])
    n = len(radiance_dirs)
    for a in range(0, p_count, _PROBE_CHUNK):
        b = min(p_count, a + _PROBE_CHUNK)
        chunk = _rows(rays, a, b)
        if extra:
            chunk = _join(chunk, trace_probe_rays(tris, positions[a:b], np.concatenate(extra)))
        direct, by_world, by_emitters = direct_probe_sh(
            snapshot, tris, positions[a:b], radiance_dirs, chunk, settings.direct_samples,
            settings.seed, first_id=a)
        origins = np.repeat(positions[a:b], n, axis=0)
        radiance = hit_radiance(snapshot, tris, origins, np.tile(radiance_dirs, (b - a, 1)),
                                chunk.t.ravel(), chunk.triangle.ravel(), chunk.u.ravel(),
                                chunk.v.ravel(), settings.light_samples, settings.seed + a,
                                seen_world=not by_world, seen_emission=not by_emitters,
                                cache=cache)
        sh[a:b] = direct + project(radiance.reshape(b - a, n, 3), radiance_dirs)
        if progress is not None:
            progress(b / p_count)
        check()
    timings["radiance"] = time.perf_counter() - t0

    grid = ProbeGrid(origin=lo, volume_size=layout.volume_size, dims=layout.dims,
                     positions=positions.astype(np.float32), sh=sh.astype(np.float32),
                     volume_cells=layout.volume_cells.astype(np.uint32),
                     volume_probes=layout.volume_probes.astype(np.uint32), volume_masks=masks,
                     validity=validity, flags=flags,
                     mask_threshold=float(settings.mask_threshold) if settings.use_masks else 0.0,
                     name=name)
    return BakeResult(grid, timings, int(((flags & RELOCATED) != 0).sum()),
                      int(((flags & DISABLED) != 0).sum()))
