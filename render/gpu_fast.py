"""Fast quality on the GPU: primary visibility rasterized (``gbuffer``), direct light with exact
shadow rays through the BVH (``shaders/bvh_direct.glsl``) or one soft-shadow cone per light
(``shaders/shadow.glsl``), and diffuse/AO and glossy light cone-traced through the octree
(``gpu_tracer``, ``shaders/cone_*.glsl``). The numpy reference is ``voxgi_addon.preview``'s
Fast path; ``gpu_preview.render_passes_gpu`` is the entry point that picks this or Accurate.

Every light (docs/gi_pipeline.md "Fast quality: world and emission"): Diffuse Direct has the
lamps, the world and the emissive triangles of ``world_light.scene_lights`` — with shadow rays
as Accurate's (one more ``bvh_direct`` dispatch for the world and emitters), or with shadows
"CONES" the world's visible share from the diffuse cone set (``diffuse_ao`` with
sampling.w = 1) and one shadow cone per connected emitter; the glossy cones see the world
where they leave the voxels (``GPUVolume`` packs the world's prefiltered maps). The lamps'
glossy light is Accurate's centre pass's (``gpu_gather.glossy_direct_texture`` of each lamp's
Diffuse Direct), and the colours are the Principled BSDF's for the view.

Cycles' ray visibility (docs/gi_pipeline.md "Ray visibility and holdouts"): the glossy and
shadow cones read the octrees of what their rays see (``gi.ray_views``), each uploaded in its
own ``GPUVolume`` beside the diffuse cones' where it differs. Bounces > 1 (docs/gi_pipeline.md
"Fast quality's cones"): the radiance cache is gathered on the GPU as Accurate's
(``gpu_gather.cache_gpu``) and the voxels reflect it (``gi.cone_bounces``) before the upload.
"""
from __future__ import annotations

import time
import weakref

import numpy as np

from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.cone_bounces import cone_octrees, fast_cache_settings
from ..voxgi_addon.gi.cone_shadows import cone_shadowed_direct, shadow_cone
from ..voxgi_addon.gi.conetrace import world_mips
from ..voxgi_addon.gi.radiance_cache import cache_key
from ..voxgi_addon.preview.bounced_volumes import BouncedVolumes
from ..voxgi_addon.preview.gather import cache_settings
from ..voxgi_addon.preview.passes import (
    compose_passes,
    material_indices,
    principled_table,
)
from ..voxgi_addon.preview.upsample import low_shape
from ..voxgi_addon.scene.textures import TexelBase
from .gbuffer import rasterize, read_gbuffer
from .gpu_bvh import direct_light_texture
from .gpu_gather import cache_gpu, glossy_direct_texture, share_cache, shared_cache
from .gpu_scene import current_scene
from .gpu_tracer import dispatch, read_texture
from .gpu_volume import GPUVolume, float_texture

# per GPUVolume of the diffuse cones (the caller's, kept between calls) the GPUVolumes of the
# other kinds of cones whose voxels differ (gi/ray_views.py), released with it
_view_volumes: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _radiance_cache(scene, settings):
    """The radiance cache of ``settings.bounces`` (``gi.radiance_cache``; None for one
    bounce) gathered on the GPU (``gpu_gather.cache_gpu``) for the GPU scene ``scene``: the
    session's (``gpu_gather.shared_cache``, whoever built it: Accurate's F12, a Rendered view)
    while its triangles (the BVH's node texture), lights, materials and cache settings stay."""
    if settings.bounces <= 1:
        return None
    key = cache_key(scene.lights, scene.principled, scene.emission, *cache_settings(settings))
    held = shared_cache(scene.bvh.nodes, key)
    if held is None:
        held = cache_gpu(scene.bvh, scene.lights, scene.principled, scene.emission,
                         settings, scene.gather_tables())
        share_cache(scene.bvh.nodes, key, *held)
    if callable(held[0]):  # a view's: its faces read back once, then kept with it
        held = (held[0](), held[1])
        share_cache(scene.bvh.nodes, key, *held)
    return held[0]


_BUILD = object()  # fast_passes' radiance: build (or keep) the whole cache here


def cone_volumes(volume, gi_state, radiance, cones, world_radiance, timings=None):
    """(the diffuse cones' ``GPUVolume``, {"glossy" / "shadow": ``GPUVolume``}) holding the
    octree of each kind of cone (``cone_bounces.cone_octrees``: with Bounces > 1 rebuilt with
    the radiance cache's bounces), uploaded where they changed. ``volume`` : the caller's,
    kept between calls (it keeps the update's own octree: the viewport uploads that one
    between its slices); rebuilt octrees get their own volumes beside it, so neither is
    uploaded again at every call. radiance : None (one bounce), a ``RadianceCache`` (the
    octrees rebuilt here), or ``bounced_volumes.BouncedVolumes`` made off the main thread:
    when made for ``gi_state``, its octrees and atlases are used and nothing is rebuilt.
    world_radiance : the world's equirect map (``WorldData.radiance``) or None. timings : a
    dict that gets "radiance cache" (the rebuild) and "upload" seconds."""
    t0 = time.perf_counter()
    made = None
    if isinstance(radiance, BouncedVolumes):
        made = radiance if radiance.fits(gi_state) else None
        radiance = radiance.cache
    octrees = made.octrees if made is not None else cone_octrees(gi_state, radiance)

    def atlas(octree):  # the worker's layout when it made them, else built at the upload
        return None if made is None else made.atlas(octree)

    t1 = time.perf_counter()
    world = world_mips(world_radiance)
    views = _view_volumes.setdefault(volume, {})
    if octrees["diffuse"] is not getattr(gi_state, "octree", None):
        volume = views.setdefault("bounced", GPUVolume())  # rebuilt with the cache's bounces
    else:
        views.pop("bounced", None)
    volume.update(octrees["diffuse"], cones, atlas=atlas(octrees["diffuse"]), world=world)
    # the glossy and shadow cones' octrees are uploaded beside the diffuse one where they differ
    kinds = {}
    for kind in ("glossy", "shadow"):
        if octrees[kind] is octrees["diffuse"]:
            views.pop(kind, None)
            kinds[kind] = volume
            continue
        kinds[kind] = views.setdefault(kind, GPUVolume())
        kinds[kind].update(octrees[kind], cones, atlas=atlas(octrees[kind]), world=world)
    if timings is not None:
        timings["radiance cache"], timings["upload"] = t1 - t0, time.perf_counter() - t1
    return volume, kinds


def _cone_scene(snapshot, gi_state, cones, volume, gather_settings, radiance, timings):
    """(GPU scene, volume, kinds) Fast quality traces: the session's GPU scene
    (``gpu_scene.GPUScene``, as Accurate's: triangles, BVH, material and light tables,
    uploaded only where they changed) and the octree of each kind of cone (Cycles' ray
    visibility, gi/ray_views.py) — with Bounces > 1 the voxels also reflecting the radiance
    cache (gi/cone_bounces.py; ``radiance`` as ``fast_passes`` takes it, built here by
    default, gathered on the GPU as Accurate's)."""
    t0 = time.perf_counter()
    scene = current_scene(snapshot)
    if len(scene.tris) == 0:
        raise VoxGIError("the scene has no triangles to render")
    if scene.uploaded:
        timings["scene update (GPU)"] = time.perf_counter() - t0
    if radiance is _BUILD:
        radiance = _radiance_cache(scene, fast_cache_settings(gather_settings,
                                                              scene.bvh.scene_triangles))
    volume, kinds = cone_volumes(volume or GPUVolume(), gi_state, radiance, cones,
                                 getattr(snapshot.world, "radiance", None), timings)
    return scene, volume, kinds


def fast_passes(snapshot, gi_state, width, height, cones, light_samples, volume, shadows,
                gi_stride, gather_settings, glossy_indirect, camera_tris=None, radiance=_BUILD):
    """(passes, timings) of Fast quality; ``volume`` a ``GPUVolume`` kept between calls (a new
    one when None) so that an unchanged octree is not uploaded again. camera_tris : what the
    G-buffer draws (None: the scene's triangles; ``transmission.behind_glass`` hides glass).
    radiance : the radiance cache the voxels reflect at Bounces > 1 — by default built whole
    here (F12); the viewport passes the ``BouncedVolumes`` its worker made from its
    ``ViewportCache``'s last complete one (None: one bounce until there is one;
    ``cone_volumes``)."""
    timings = {}
    scene, volume, kinds = _cone_scene(snapshot, gi_state, cones, volume, gather_settings,
                                       radiance, timings)
    tris, rough, emission, lights = scene.tris, scene.rough, scene.emission, scene.lights
    t0 = time.perf_counter()
    gbuffer = rasterize(tris if camera_tris is None else camera_tris, snapshot.camera, rough,
                        width, height,
                        textures=scene.raster_textures())  # Base Color per texel: seen["base"]
    seen = read_gbuffer(gbuffer)
    hit = np.flatnonzero(seen["hit"].ravel())
    p = seen["position"].reshape(-1, 3)[hit].astype(np.float64)
    n = seen["normal"].reshape(-1, 3)[hit].astype(np.float64)
    mat = material_indices(snapshot, seen["material"].ravel()[hit])
    timings["visibility (GPU)"] = time.perf_counter() - t0

    def pixels(texture):  # (N, 3) float64 of the hit pixels, from a bottom-row-first texture
        return np.flipud(read_texture(texture))[..., :3].reshape(-1, 3)[hit].astype(np.float64)

    def visibility(light, lit):  # shaders/shadow.glsl, one dispatch per light
        target, size, is_sun = shadow_cone(light)
        constants = {"light_position": (*target, float(is_sun)), "light_size": (size, 0, 0, 0)}
        image = read_texture(dispatch("shadow", kinds["shadow"], gbuffer.inputs, width, height,
                                      constants))
        return np.flipud(image)[..., 0].ravel()[hit[lit]]

    low_h, low_w = low_shape(height, width, gi_stride)

    def traced(kernel, mode=0, through=volume):
        sampling = {"sampling": (gi_stride, width, height, mode)}
        low = dispatch(kernel, through, gbuffer.inputs, low_w, low_h, sampling)
        if gi_stride > 1:  # shaders/upsample.glsl, the port of gi_upsample.upsample
            low = dispatch("upsample", volume, {**gbuffer.inputs, "low_image": low}, width,
                           height, sampling)
        return np.flipud(read_texture(low))

    t0 = time.perf_counter()
    # the lamps' glossy light (preview.passes.glossy_direct_radiance; the glossy cones see the
    # world and the emission), and the colours for the view as Cycles' Principled BSDF gives them
    principled, materials = scene.principled, scene.materials
    shine = np.zeros((len(hit), 3))
    views = -seen["direction"].reshape(-1, 3)[hit].astype(np.float64)
    if shadows == "RAYS":
        # Light by light: one dispatch stays within llvmpipe's loop limit
        # (docs/blender_facts.md "llvmpipe's loop limit").
        direct = np.zeros((len(hit), 3))
        for table in scene.lamp_tables:  # (a lamp's table: its row alone, row 0)
            lamp = direct_light_texture(scene.bvh, gbuffer.inputs, snapshot.lights,
                                        light_samples, seed=gather_settings.seed,
                                        world=scene.no_world, emitters=scene.no_emitters,
                                        table=table)
            direct += pixels(lamp)
            shine += pixels(glossy_direct_texture(gbuffer.inputs, lamp, table, 0,
                                                  principled, emission, materials))
        if scene.has_scene_lights:  # the world's and emitters' own dispatch
            direct += pixels(direct_light_texture(scene.bvh, gbuffer.inputs, snapshot.lights,
                                                  light_samples, seed=gather_settings.seed,
                                                  world=scene.world_map,
                                                  emitters=scene.emitters, table=scene.no_lamp))
    else:
        world_seen = None
        if any(light.type == "WORLD" for light in lights):  # the cones' view of the world
            world_seen = traced("diffuse_ao", 1, kinds["shadow"]).reshape(-1, 4)[hit].astype(
                np.float64).__getitem__
        lamps = len(snapshot.lights)
        direct = cone_shadowed_direct(None, p, n, lights[lamps:], cones, light_samples,
                                      visibility, world_seen).astype(np.float64)
        for index in range(lamps):
            lamp = cone_shadowed_direct(None, p, n, lights[index:index + 1], cones,
                                        light_samples, visibility).astype(np.float64)
            direct += lamp
            image = np.zeros((height * width, 4), np.float32)
            image[hit, :3] = lamp
            texture = float_texture(np.flipud(image.reshape(height, width, 4)).copy(),
                                    (width, height))
            shine += pixels(glossy_direct_texture(gbuffer.inputs, texture,
                                                  scene.lamp_tables[index], 0, principled,
                                                  emission, materials))
    timings["direct + lamps' glossy light"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    diffuse_ao = traced("diffuse_ao")
    timings["diffuse+ao cones (GPU)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if glossy_indirect:
        glossy = traced("glossy", through=kinds["glossy"])
        timings["glossy cones (GPU)"] = time.perf_counter() - t0
    else:  # as Cycles with no glossy bounces
        glossy = np.zeros((height, width, 4), np.float32)

    flat_da = diffuse_ao.reshape(-1, 4)[hit]
    terms = (direct, flat_da[:, :3], flat_da[:, 3], glossy.reshape(-1, 4)[hit, :3])
    base = None
    if scene.textured:  # the textured pixels' colour, the others their material's
        base = np.where(seen["textured"].ravel()[hit, None], seen["base"].reshape(-1, 3)[hit],
                        principled_table(snapshot)[0][mat]).view(TexelBase)
        # the camera's emission per texel where a material has an emission texture
        base.emission = seen["emission"].reshape(-1, 3)[hit].astype(np.float64)
        base.emissive = seen["emissive"].ravel()[hit]
    return compose_passes(snapshot, width, height, hit, mat, *terms, n, views, shine,
                          base=base, holdout=seen["holdout"].ravel()), timings


def fast_sums(snapshot, gi_state, width, height, cones, light_samples, volume, shadows,
              gi_stride, gather_settings, glossy_indirect, radiance=_BUILD, raster=None):
    """Fast quality's pass through the pixel centres as ``fast_passes`` makes it with shadow
    rays (``shadows`` "RAYS"), composed on the GPU instead of on the CPU: a generator of its
    stages returning (``gpu_accumulation.GPUSums``, timings), nothing read back (the
    viewport's slices). The cones' terms (Diffuse Indirect + AO, Glossy Indirect) stay
    textures and ``gpu_compose.shade_stages`` adds the colours and every light's direct and
    glossy light over the G-buffer, as Accurate's passes do (``preview.passes.
    accumulate_pass``, the numpy statement of ``compose_passes``' sums); the glossy cones see
    the world and the emission, so no world or emitters' glossy light is added. raster : the
    G-buffer shader of this GPU context (None: a new one)."""
    from .gpu_accumulation import SUM_NAMES, GPUSums
    from .gpu_compose import shade_stages

    if shadows != "RAYS":
        raise ValueError("Fast quality's GPU composition takes shadow rays; cone shadows are "
                         "composed on the CPU (fast_passes)")
    timings = {}
    scene, volume, kinds = _cone_scene(snapshot, gi_state, cones, volume, gather_settings,
                                       radiance, timings)
    t0 = time.perf_counter()
    gbuffer = rasterize(scene.tris, snapshot.camera, scene.rough, width, height, shader=raster,
                        textures=scene.raster_textures())
    timings["visibility (GPU)"] = time.perf_counter() - t0
    yield
    low_h, low_w = low_shape(height, width, gi_stride)

    def traced(kernel, through=volume):  # full-resolution textures, as fast_passes' traced
        sampling = {"sampling": (gi_stride, width, height, 0)}
        low = dispatch(kernel, through, gbuffer.inputs, low_w, low_h, sampling)
        if gi_stride > 1:
            low = dispatch("upsample", volume, {**gbuffer.inputs, "low_image": low}, width,
                           height, sampling)
        return low

    t0 = time.perf_counter()
    zero = scene.zeros(width, height)
    diffuse_ao = traced("diffuse_ao")
    glossy = traced("glossy", kinds["glossy"]) if glossy_indirect else zero
    timings["cones (GPU)"] = time.perf_counter() - t0
    yield
    t0 = time.perf_counter()
    sums = yield from shade_stages(scene, snapshot, dict(gbuffer.inputs),
                                   {name: zero for name in SUM_NAMES},
                                   (diffuse_ao, glossy, zero), zero, (width, height),
                                   light_samples, gather_settings.seed)
    timings["direct + composition (GPU)"] = time.perf_counter() - t0
    return GPUSums(sums, width, height), timings
