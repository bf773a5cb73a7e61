"""The GI preview's passes with the GPU tracer: the same stages and outputs as
``voxgi_addon.preview.render_passes`` (the numpy reference), with primary visibility
rasterized (``gbuffer``) and the cone tracing done by compute shaders (``gpu_tracer``).

Direct diffuse light: with shadows "RAYS" the reference's exact light models and shadow rays,
traced through the scene's BVH on the GPU (``gpu_bvh``, ``shaders/bvh_direct.glsl``; the same
samples as the numpy reference, see docs/gi_pipeline.md "Exact rays on the GPU"); with "CONES"
the unshadowed light (numpy, cheap) times one soft-shadow cone per light traced on the GPU
(``shaders/shadow.glsl``). Needs a GPU context.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.cone_bounces import fast_cache_settings
from ..voxgi_addon.gi.light_injection import material_emission
from ..voxgi_addon.preview import transmission
from ..voxgi_addon.preview.denoise import GLOSSY_SIGMA_LUMINANCE, SIGMA_LUMINANCE
from ..voxgi_addon.preview.film import background
from ..voxgi_addon.preview.gather import VIEW_BACKOFF, GatherSettings, focused, uses_cache
from ..voxgi_addon.preview.passes import (
    AA_SIDE,
    NO_TAILS,
    WORLD_NOISE_TARGET,
    Tails,
    centre_pass,
    check_request,
    edge_pixels,
    finish_passes,
    hidden_variances,
    lamp_light,
    light_edge_pixels,
    material_indices,
    pass_tail_weights,
    pass_weights,
    rest_spread,
    shows_diffuse,
    subpixel_passes,
    subpixel_reach,
    world_fewer_pixels,
    world_filter_passes,
    world_rest_share,
    world_strata_side,
)
from ..voxgi_addon.preview.progressive import LATTICE_CELLS, LATTICE_RAYS
from ..voxgi_addon.preview.resolve import SPREAD
from ..voxgi_addon.preview.sparse_gather import (
    gather_lists,
    glossy_cells,
    sparse_glossy_settings,
    sparse_plan,
    sparse_settings,
)
from ..voxgi_addon.preview.upsample import field_stride, low_shape, sample_pixels
from ..voxgi_addon.scene.camera import DEFAULT_FILTER_WIDTH, camera_frame, filter_on_grid
from ..voxgi_addon.scene.glass import is_glass
from ..voxgi_addon.scene.textures import TEXTURE_TAPS
from .frame import Frame, Stage, finish
from .frame import run as run_stages
from .gbuffer import PixelMask, gbuffer_shader, rasterize, rasterize_stages, read_gbuffer, vertex_batch
from .gpu_accumulation import SUM_NAMES, GPUSums
from .gpu_bvh import (
    emitter_glossy_texture,
    emitters_unshadowed_texture,
    strata_side,
    world_fewer_texture,
)
from .gpu_compose import COMPACT_SAMPLERS as _COMPACT_SAMPLERS
from .gpu_compose import MASK_SAMPLERS as _MASK_SAMPLERS
from .gpu_compose import RESOLVE_OUTPUTS as _RESOLVE_OUTPUTS
from .gpu_compose import RESOLVE_SAMPLERS as _RESOLVE_SAMPLERS
from .gpu_compose import SURFACE_SUMS as _SURFACE_SUMS
from .gpu_compose import run as _run
from .gpu_compose import shade_stages
from .gpu_fast import fast_passes, fast_sums
from .gpu_gather import (
    TRAVERSALS_PER_DISPATCH,
    cache_layout_ahead,
    cache_texture,
    denoise,
    gather,
    gather_steps,
    spread_spikes,
    upsample,
    upsample_field,
    upsample_field_list,
)
from .gpu_scene import GPUScene, current_scene
from .gpu_shaders import LOCAL_SIZE, size_like
from .gpu_tails import GPUTails, reached_pixels
from .gpu_tracer import read_texture
from .gpu_volume import GPUVolume, float_texture


def render_passes_gpu(*args, **kwargs):
    """(passes, timings): ``render_passes_stages`` run to its end in one call (F12,
    ``render_preview``, probe previews)."""
    return finish(render_passes_stages(*args, **kwargs))




def render_passes_stages(snapshot, gi_state, width: int, height: int, cones,
                         light_samples: int = 16, volume: GPUVolume | None = None,
                         shadows: str = "RAYS", gi_stride: int = 1, quality: str = "ACCURATE",
                         gather_settings: GatherSettings | None = None,
                         glossy_indirect: bool = True,
                         filter_width: float = DEFAULT_FILTER_WIDTH,
                         gpu_scene: GPUScene | None = None, gather_hook=None, raster=None,
                         cache_source=None, on_gpu: bool = False, batch=None,
                         world_glossy: bool = True, lamp_glossy: bool = True,
                         denoise: bool = True, centre=None,
                         traversals: int = TRAVERSALS_PER_DISPATCH, lattice: bool = False,
                         texture_filter=None):
    """A generator that yields between the GPU stages (G-buffer, each gather, each light's
    direct light, each sub-pixel pass, …) and returns (passes, timings) like
    ``preview.render_passes`` (``filter_width`` included). ``volume`` : a ``GPUVolume`` kept
    between calls so an unchanged octree is not uploaded again (a new one when None); Fast
    quality only: Accurate uses neither it nor ``gi_state`` (None is fine).
    quality "ACCURATE": exact direct light and the exact-ray final gather (``gpu_gather``);
    "FAST": cone tracing through the octree (shadows as ``shadows`` says).
    gpu_scene : the ``gpu_scene.GPUScene`` Accurate draws from, updated to ``snapshot`` here
    (None: the session's, ``gpu_scene.current_scene``).
    gather_hook : Accurate only: ``hook(kind, values, variance)`` → (values, variance) gets
    each gather's raw low-resolution textures before the à-trous filter (kind: "diffuse",
    "glossy", "world glossy") and returns what is filtered instead: the viewport's
    progressive accumulation adds them to its sums and returns the sums' mean (None: the
    gather's own, as F12).
    raster : the G-buffer raster shader (``gbuffer.gbuffer_shader``) of the current GPU
    context, kept by the caller between calls in that context (the viewport); None: a new one.
    cache_source : the viewport's ``viewport_cache.ViewportCache`` (its radiance cache built a
    stage at a time, the last complete one read meanwhile); None: the whole cache is built
    before the gathers (``gpu_gather.cache_texture``, F12).
    on_gpu : no glass in the scene and Accurate point-sampled (Filter Size 0), or Fast with
    shadow rays (``gpu_fast.fast_sums``): return the pass's sums as textures
    (``gpu_accumulation.GPUSums``, read by nothing on the CPU) instead of the passes: the
    viewport's slices, which add them to their sums on the GPU. Otherwise the passes, as
    always.
    batch : Accurate: the vertex batch of the scene's triangles for ``raster`` that the caller
    keeps (the viewport's ``gbuffer.ChunkedBatch``, sent a chunk per draw); None: made here for
    this render (``gbuffer.vertex_batch``).
    world_glossy : Accurate: the world's and emitters' Glossy Direct gathered (the
    ``bvh_glossy`` world-mode gather); False leaves it out (the viewport's first coarse image
    while that kernel is not compiled yet: docs/gi_pipeline.md "Entering Rendered mode").
    lamp_glossy : Accurate: the lamps' glossy light (``glossy_direct.glsl``) composed; False
    leaves it out. denoise : Accurate: the gathers filtered (``gpu_gather.denoise``); False
    takes them raw (and dense: the sparse gather's holes are the filter's to fill). Both
    False only in the viewport's first coarse image, while those kernels are not compiled.
    centre : Accurate: the pixel centres' ``gbuffer.GBuffer`` of this camera and size drawn
    already with the scene's batch, textures and Filter Size (the viewport's quick image's,
    which is its first coarse image's: ``viewport_prepare``); None: drawn here.
    traversals : Accurate: BVH traversals one gather invocation makes per dispatch
    (``gpu_gather.gather_steps``, which yields between them): the viewport's slices take
    fewer, so a larger tile's gather is several steps within a stage's budget.
    lattice : Accurate with a ``gather_hook``: the diffuse gather traces only the lattice of
    its cells (``gpu_gather.gather_steps``' lattice) with ``LATTICE_RAYS`` × the rays, the
    others holes that the filter fills (the viewport's first sample: docs/gi_pipeline.md
    "The view's first sample at the lattice").
    texture_filter : Accurate: (Filter Size, tap shift) the centre G-buffer's textures are
    sampled with (``TEXTURE_TAPS`` taps over each pixel's square, moved by the shift from each
    pixel's camera ray: ``gbuffer.rasterize``'s ``tap_shift``) instead of ``filter_width``'s:
    a view's sample is point-sampled (Filter Size 0) with its camera moved sub-pixel, yet its
    textures are its pixels' own squares', as F12's are (docs/gi_pipeline.md "A sample's
    textures over its pixel's square"). None: ``filter_width``'s, unmoved.
    The viewport's slices run the stages over several draws (``progressive``); the textures
    live in the generator between them, so nothing but its own next stage runs in a draw."""
    check_request(snapshot, width, height, gi_stride, quality)
    # glass' two layers are composed on the CPU: the sums stay on the GPU only without it
    on_gpu = on_gpu and not any(is_glass(m) for m in snapshot.materials)
    if quality == "ACCURATE":
        gather_settings = gather_settings or GatherSettings(ao_distance=cones.ao_distance)
        ahead = None
        if cache_source is None and uses_cache(gather_settings):
            def ahead(tris):  # F12: the cache's layout made while the BVH is built
                cache_layout_ahead(tris, focused(gather_settings, snapshot.camera, tris,
                                                 material_emission(snapshot)))
        t0 = time.perf_counter()
        # only what changed is sent
        scene = (gpu_scene or current_scene()).update(snapshot, on_triangles=ahead)
        built = time.perf_counter() - t0
        # the G-buffer's variant follows the scene's textures (gbuffer.gbuffer_shader: the
        # plain one where no material has any)
        raster = raster or gbuffer_shader(textured=scene.textured)
        layer = (width, height, light_samples, gi_stride, gather_settings,
                 glossy_indirect, filter_width, scene)
        front, timings = yield from _accurate_stages(snapshot, *layer, gather_hook, raster,
                                                     cache_source, on_gpu=on_gpu, batch=batch,
                                                     world_glossy=world_glossy,
                                                     lamp_glossy=lamp_glossy, denoise=denoise,
                                                     centre=centre, traversals=traversals,
                                                     lattice=lattice, texture_filter=texture_filter)
        if scene.uploaded:  # rebuilt and uploaded only what changed
            timings = {"scene build + upload": built, **timings}
        glass = transmission.glass_materials(snapshot, scene.tris)
        if glass is None:
            return front, timings
        # glass in view: what is behind it, seen through it (preview.transmission); the
        # viewport's accumulation keeps the behind layer's gathers apart from the front's
        t0 = time.perf_counter()
        weight = _glass_weight(snapshot, scene, raster, width, height, filter_width)
        hook = None if gather_hook is None else \
            (lambda kind, *given, **how: gather_hook(f"behind {kind}", *given, **how))
        behind, _ = yield from _accurate_stages(
            snapshot, *layer, hook, raster, cache_source,
            camera_tris=transmission.behind_glass(scene.tris, glass),
            only=transmission.behind_pixels(weight), world_glossy=world_glossy,
            lamp_glossy=lamp_glossy, denoise=denoise, traversals=traversals, lattice=lattice,
            texture_filter=texture_filter)
        world = background(snapshot.world, snapshot.camera, width, height, filter_width)
        timings["behind glass"] = time.perf_counter() - t0
        return transmission.composite(front, behind, weight, world), timings
    gather_settings = gather_settings or GatherSettings(ao_distance=cones.ao_distance)
    fast = (snapshot, gi_state, width, height, cones, light_samples, volume, shadows, gi_stride,
            gather_settings, glossy_indirect)
    given = {}
    if cache_source is not None and uses_cache(gather_settings):
        # the viewport: its cache built a stage at a time, the last complete one reflected
        # meanwhile (one bounce before the first), never the whole build in one draw
        scene = current_scene(snapshot)
        settings = fast_cache_settings(gather_settings, scene.bvh.scene_triangles)
        texture = yield from cache_source.stage(scene.bvh, scene.lights, scene.principled,
                                                scene.emission, settings, scene.gather_tables())
        given["radiance"] = cache_source.cache if texture is not None else None
    if on_gpu and shadows == "RAYS":
        # the viewport's slices: composed on the GPU, nothing read back
        return (yield from fast_sums(*fast, raster=raster, **given))
    front, timings = fast_passes(*fast, **given)
    scene = current_scene(snapshot)
    glass = transmission.glass_materials(snapshot, scene.tris)
    if glass is None:
        return front, timings
    t0 = time.perf_counter()  # Fast is point-sampled: the glass' weight at pixel centres
    weight = _glass_weight(snapshot, scene, raster or gbuffer_shader(scene.textured), width,
                           height, 0.0)
    behind, _ = fast_passes(*fast, camera_tris=transmission.behind_glass(scene.tris, glass),
                            **given)
    world = background(snapshot.world, snapshot.camera, width, height, 0.0)
    timings["behind glass"] = time.perf_counter() - t0
    return transmission.composite(front, behind, weight, world), timings


def _glass_weight(snapshot, scene, raster, width, height, filter_width):
    """``transmission.glass_weight`` from the G-buffer raster of ``scene``'s triangles."""
    def hits_at(offset):
        seen = read_gbuffer(rasterize(scene.tris, snapshot.camera, scene.rough, width, height,
                                      offset, shader=raster, textures=scene.raster_textures(),
                                      filter_width=filter_width))
        return seen["material"], np.einsum("hwi,hwi->hw", seen["normal"], seen["direction"])

    return transmission.glass_weight(snapshot.materials, hits_at, width, height, filter_width)


# ---------------------------------------------------------------- Accurate: sub-pixel passes

def _pixel_list(listed, width: int, height: int, fine: int = 1, sub=(0, 0)):
    """(texture, (w, h)) of the edge pixels' list (aa_compact.glsl): texel t (row-major from
    the texture's first row) = (x, y, id, 1) of pixel id = listed[t] (flat, row 0 on top; GL
    y = height − 1 − row), padded with zeros to w × h, w a multiple of the work group size.
    fine, sub : (x, y) read in a G-buffer ``fine`` times the image's size (``rasterize``'s
    supersample) at the pixel's sample sub = (i, j) (x right, y down)."""
    # the sides keep the frame's power-of-two class: one JIT per kernel (gpu_shaders.size_like)
    side = size_like(math.ceil(math.sqrt(len(listed))), width, LOCAL_SIZE)
    rows = size_like(math.ceil(len(listed) / side), height)
    texels = np.zeros((rows * side, 4), np.float32)
    texels[:len(listed)] = np.stack([
        fine * (listed % width) + sub[0],
        fine * (height - 1 - listed // width) + fine - 1 - sub[1], listed,
        np.ones(len(listed))], axis=1)
    return float_texture(texels.reshape(rows, side, 4), (side, rows)), (side, rows)


# Most texels of a supersampled sub-pixel raster (``supersampling``): its G-buffer's four
# RGBA32F targets and depth hold 68 bytes a texel (285 MB at this size)
SUPERSAMPLE_TEXELS = 1 << 22
# Longest side of one (OpenGL's GL_MAX_TEXTURE_SIZE is at least this on llvmpipe and on the
# GPUs Blender supports): a panorama strip's raster stays drawable
SUPERSAMPLE_SIDE = 16384


def supersampling(width: int, height: int, filter_width: float) -> int:
    """K, the sub-pixel passes' rasters' scale: the largest divisor of AA_SIDE whose K·width ×
    K·height G-buffer stays within ``SUPERSAMPLE_TEXELS`` and ``SUPERSAMPLE_SIDE`` — one
    raster draws K² of the AA_SIDE² passes (the sample grid of ``camera.filter_samples``): at
    160 × 120 all 16 in one, at 640 × 480 four in each of four, at 1920 × 1080 one each. 1
    where the filter's samples are not that grid (a filter narrower than Cycles' default:
    drawn by importance)."""
    fine = AA_SIDE if filter_on_grid(filter_width, AA_SIDE) else 1
    while fine > 1 and (AA_SIDE % fine or fine * fine * width * height > SUPERSAMPLE_TEXELS
                        or fine * max(width, height) > SUPERSAMPLE_SIDE):
        fine -= 1
    return fine


def _raster_shift(group: int, fine: int) -> float:
    """The offset (pixels) of the raster that draws the passes ``group``, ``group`` + AA_SIDE /
    fine, … along one axis: its fine × fine samples of a pixel then lie at the centres of those
    passes' cells of ``camera.filter_samples``' grid ((i + ½) / AA_SIDE − ½)."""
    return (group + 0.5) / AA_SIDE - 0.5 / fine


def _gather_list(stride: int, width: int, height: int):
    """(texture, (wl, hl)) of the gather points as a pixel list (aa_compact.glsl's ``pixels``):
    texel (i, r) = (x, y, id, 1) of the pixel ``upsample.sample_pixels`` traces for cell (row
    hl − 1 − r from the top, column i), so a kernel over the list writes a low-resolution
    texture in the gathers' layout (rows from the bottom, ``upsample.glsl``'s low_image)."""
    rows, cols = sample_pixels(height, width, stride)
    rows = rows[::-1]  # texture row r: cell row hl − 1 − r
    texels = np.empty((len(rows), len(cols), 4), np.float32)
    texels[..., 0] = cols[None, :]
    texels[..., 1] = (height - 1 - rows)[:, None]
    texels[..., 2] = rows[:, None] * width + cols[None, :]
    texels[..., 3] = 1.0
    return float_texture(texels, (len(cols), len(rows))), (len(cols), len(rows))


def _eye(camera):
    """upsample.glsl's eye: (camera position, 1), zeros for an orthographic camera."""
    if camera.type == "ORTHO":
        return (0.0, 0.0, 0.0, 0.0)
    return (*camera_frame(camera)[1], 1.0)


def emitter_fields(scene, gbuffer_inputs, stride: int, width: int, height: int, eye):
    """The emitters' unshadowed glossy light and Diffuse Direct at the field's points, one
    per ``stride`` × ``stride`` block (``upsample.field_stride``) — the only place their
    per-triangle sums are evaluated everywhere (docs/gi_pipeline.md "Where a preview's time
    goes") — as (low glossy, low diffuse, full glossy, full diffuse) textures: the points'
    (``emitter_glossy_texture(unshadowed=True)``, ``emitters_unshadowed_texture``) and
    ``upsample_field``'s at every pixel. eye : ``_eye`` of the camera."""
    bvh = scene.bvh
    if stride == 1:
        points = gbuffer_inputs
    else:
        pixels, size = _gather_list(stride, width, height)
        points = _compact("aa_list", {**gbuffer_inputs, "pixels": pixels}, size)
        points["gbuffer_base"] = scene.zeros(*size) if not scene.textured else _compact(
            "aa_list_raw", {"gbuffer_position": gbuffer_inputs["gbuffer_base"],
                            "gbuffer_normal": gbuffer_inputs["gbuffer_base"],
                            "gbuffer_view": gbuffer_inputs["gbuffer_base"], "pixels": pixels},
            size)["gbuffer_position"]
    glossy = emitter_glossy_texture(bvh, points, scene.emitters, scene.materials, 1, 0,
                                    scene.no_lamp, scene.world_map, unshadowed=True)
    diffuse = emitters_unshadowed_texture(bvh, points, scene.emitters, scene.no_lamp,
                                          scene.world_map, absent=scene.direct_absent)
    return (glossy, diffuse,
            *upsample_field(glossy, diffuse, gbuffer_inputs, stride, width, height, eye))


def _compact(kernel, inputs, size):
    """The G-buffer (or the three centre terms, kernel "aa_list_raw") at the edge pixels' list
    (aa_compact.glsl), as G-buffer inputs of the list's ``size``."""
    out = _run(kernel, _COMPACT_SAMPLERS, inputs, ("out_position", "out_normal", "out_view"),
               *size)
    return {"gbuffer_position": out["out_position"], "gbuffer_normal": out["out_normal"],
            "gbuffer_view": out["out_view"]}


def _sums_of(texel):
    """preview.passes.SUMS by name from the sum textures' texels (name → (N, 4))."""
    return {
        "emission": texel["sum_a"][:, :3], "coverage": texel["sum_a"][:, 3],
        "diffuse_color": texel["sum_b"][:, :3], "ao": texel["sum_b"][:, 3],
        "glossy_color": texel["sum_c"][:, :3], "holdout": texel["sum_c"][:, 3],
        "diffuse_indirect": texel["sum_d"][:, :3],
        "glossy_indirect": texel["sum_e"][:, :3], "glossy_direct": texel["sum_f"][:, :3],
        "diffuse_direct": texel["sum_g"][:, :3]}


def _accurate_stages(snapshot, width, height, light_samples, gi_stride, gather_settings,
                     glossy_indirect, filter_width, scene=None, gather_hook=None, raster=None,
                     cache_source=None, camera_tris=None, only=None, on_gpu=False,
                     batch=None, world_glossy=True, lamp_glossy=True, denoise=True,
                     centre=None, traversals=TRAVERSALS_PER_DISPATCH, lattice=False,
                     texture_filter=None):
    """Accurate quality on the GPU: ``ACCURATE_STAGES`` run over one layer of the image (the
    front one, or with ``camera_tris`` and ``only`` what glass hides), a generator returning
    (passes, timings) — or, with ``on_gpu`` and no edge pixels (point-sampled), (``GPUSums``
    of the centre pass, timings), nothing read back.
    Triangles, BVH, materials and light tables come from ``scene`` (a ``GPUScene`` updated to
    ``snapshot``: ``render_passes_stages`` updates it). camera_tris : what the G-buffers draw
    (None: the scene's triangles; ``transmission.behind_glass`` hides glass from them); only :
    (H, W) bool the pixels to shade (None: all; the others are background to every kernel).
    The other arguments are ``render_passes_stages``' (each stage's function says what it
    does with them)."""
    if len(scene.tris) == 0:
        raise VoxGIError("the scene has no triangles to render")
    request = {"snapshot": snapshot, "scene": scene, "width": width, "height": height,
               "light_samples": light_samples, "gi_stride": gi_stride,
               "settings": gather_settings, "glossy_indirect": glossy_indirect,
               "filter_width": filter_width, "gather_hook": gather_hook, "raster": raster,
               "cache_source": cache_source, "camera_tris": camera_tris, "only": only,
               "on_gpu": on_gpu, "batch": batch, "world_glossy": world_glossy,
               "lamp_glossy": lamp_glossy, "denoise": denoise, "traversals": traversals,
               "lattice": lattice and gather_hook is not None and denoise,
               "texture_filter": texture_filter,
               # a given centre G-buffer is the front layer's (no glass pixels left out)
               "given_centre": centre if camera_tris is None and only is None else None}
    frame = yield from run_stages(ACCURATE_STAGES, Frame(request, given=set(request)))
    result = frame["result"] if frame["result"] is not None else frame["passes"]
    return result, frame.timings


# ---- The Accurate frame's stages (docs/gi_pipeline.md "The frame's stages"), in order: each
# takes the Frame and returns the values it declares.

def _plan(f):
    """The sub-pixel passes' plan (``preview.passes.subpixel_passes``), the G-buffer raster
    and vertex batch of this render (the caller's, or made here), the triangles the camera sees
    and the gathers' settings with the radiance cache focused on the camera."""
    scene, camera_tris = f["scene"], f["camera_tris"]
    raster = f["raster"] or gbuffer_shader(scene.textured)  # this context's, for its G-buffers
    seen_tris = scene.tris if camera_tris is None else camera_tris
    batch = f["batch"]
    # one vertex batch for every G-buffer of this render (gbuffer.vertex_batch), or the
    # caller's of the scene's triangles (the viewport's chunked one: rasterize_stages)
    if batch is None or camera_tris is not None:
        batch = vertex_batch(seen_tris, scene.rough, raster, scene.raster_textures() is not None)
    # the radiance cache nests finer grids around the camera (a tile's camera: the view's), or
    # around the emitters where the camera stands outside
    return {"plan": subpixel_passes(f["filter_width"], f["light_samples"]),
            "raster_shader": raster, "vertex_batch": batch, "seen_tris": seen_tris,
            "tables": scene.gather_tables(),
            "focused": focused(f["settings"], f["snapshot"].camera, scene.tris,
                               material_emission(f["snapshot"]))}


def _visibility(f):
    """The pixel centres' G-buffer (``gbuffer.rasterize_stages``: a stage per chunk of the
    viewport's batch), the pixels outside ``only`` made background; the caller's when it
    gave one (``render_passes_stages``' centre)."""
    scene, width, height = f["scene"], f["width"], f["height"]
    if f["given_centre"] is not None:
        return {"centre": f["given_centre"]}
    # the textures' filter: the render's, or the view's sample's own (``texture_filter``)
    textures_width, shift = f["texture_filter"] or (f["filter_width"], (0.0, 0.0))
    centre = yield from rasterize_stages(f["seen_tris"], f["snapshot"].camera, scene.rough, width,
                                         height, shader=f["raster_shader"],
                                         textures=scene.raster_textures(),
                                         filter_width=textures_width, batch=f["vertex_batch"],
                                         texture_taps=TEXTURE_TAPS, tap_shift=shift)
    if f["only"] is not None:  # the other pixels' coverage 0: background to every kernel
        centre.position = _run("aa_mask", _MASK_SAMPLERS, {
            "gbuffer_position": centre.position,
            "pixels": float_texture(np.flipud(f["only"]).astype(np.float32), (width, height),
                                    "R32F")},
            ("out_position",), width, height)["out_position"]
    return {"centre": centre}


def _wants_cache(f) -> bool:
    return uses_cache(f["focused"])


def _radiance_cache(f):
    """The radiance cache's texture for bounces 2 … N (``gpu_gather.cache_texture``: kept
    while the triangles, lights, materials and settings are the same), or, in the viewport,
    one stage of its build (``viewport_cache.ViewportCache``) with the last complete one —
    none before the first is complete: one bounce until then."""
    scene, settings = f["scene"], f["focused"]
    source = f["cache_source"]
    if source is None:
        return {"cache": cache_texture(scene.bvh, scene.lights, scene.principled,
                                       scene.emission, settings, f["tables"]),
                "gather_settings": settings}
    cache = yield from source.stage(scene.bvh, scene.lights, scene.principled, scene.emission,
                                    settings, f["tables"])
    if cache is None:  # none complete yet: one bounce until there is
        settings = dataclasses.replace(settings, bounces=1, glossy_chains=False)
    return {"cache": cache, "gather_settings": settings}


def _low(f, kind, kernel="bvh_gather", world_mode=False, kept=None):
    """One gather's filtered low-resolution texture (``gpu_gather.gather`` then ``denoise``),
    its raw result replaced by ``gather_hook``'s when there is one (the viewport's
    accumulation). kept : a dict that gets the diffuse gather's raw "hidden" texture (the
    world's rest hidden from its points, ``bvh_gather.glsl`` out_hidden) when it traced."""
    scene, settings = f["scene"], f["gather_settings"]
    centre, stride, width, height = f["centre"], f["gi_stride"], f["width"], f["height"]
    cache = f["cache"]
    if world_mode and cache is not None:  # reads no cache: an empty one of its JIT class
        cache = _empty_like(cache)
    rays = settings.rays if kind.endswith("diffuse") else settings.glossy_rays
    if rays == 0 and f["gather_hook"] is not None:
        # a viewport sample after the gathering ones (preview.progressive.sample_settings):
        # its gathered light is not added (its gather weight is 0), the world's glossy light,
        # direct light, is the samples' sums
        low_h, low_w = low_shape(height, width, stride)
        values = variance = scene.zeros(low_w, low_h)
        if not kind.endswith("world glossy"):
            return values
    else:
        # the viewport's first sample: the diffuse gather at the lattice of its cells, with
        # LATTICE_RAYS × the rays (and as many traversals a dispatch per traced cell)
        lattice = f["lattice"] and kernel == "bvh_gather"
        if lattice:
            settings = dataclasses.replace(settings, rays=LATTICE_RAYS * settings.rays)
        values, variance, *hidden = yield from gather_steps(
            scene.bvh, centre.inputs, scene.lights, scene.principled, scene.emission, settings,
            stride, width, height, kernel=kernel, world_mode=world_mode, tables=f["tables"],
            cache=cache, traversals=f["traversals"] * (LATTICE_CELLS if lattice else 1),
            lattice=lattice, sun_apart=_sun_apart(f))
        if kept is not None and hidden:
            kept["hidden"] = hidden[0]
        yield  # the filter is a step of its own
        if lattice:  # the hook spreads the lattice over the grid; the filter fills its holes
            values, variance = f["gather_hook"](kind, values, variance, lattice=True)
            return denoise(values, variance, centre.inputs, stride, width, height,
                           settings.denoise_iterations, fit=True, holes=True)[0]
    if f["gather_hook"] is not None:
        values, variance = f["gather_hook"](kind, values, variance)
    if not f["denoise"]:  # (raw: the filter's kernel not even bound)
        return values
    if not kind.endswith("diffuse"):  # a glossy gather's spikes spread first: a step too
        values, variance = spread_spikes(values, variance, centre.inputs, stride, width, height)
        yield
    return denoise(values, variance, centre.inputs, stride, width, height,
                   settings.denoise_iterations, fit=kind.endswith("diffuse"),
                   sigma=SIGMA_LUMINANCE if kind.endswith("diffuse") else GLOSSY_SIGMA_LUMINANCE)[0]


def _empty_like(texture):
    """An empty radiance cache (zero texels: no grid) in the power-of-two class of
    ``texture`` (``gpu_shaders.size_like``): the world-mode glossy gather reads none, and a
    1 × 1 one made llvmpipe compile ``bvh_glossy`` a second time (0.4 s of a first preview)."""
    size = (size_like(1, texture.width), size_like(1, texture.height))
    return float_texture(np.zeros((size[1], size[0], 4), np.float32), size)


def _diffuse_gather(f):
    """Diffuse Indirect and AO at the gather points (``bvh_gather``), filtered: at one cell in
    four where the light is smooth and at the cells where it is not (``_sparse_diffuse``), or
    — the viewport's accumulated slices, or ``sparse`` off — at every cell. With them, the
    world's rest that a surface hides from each traced point (``hidden_cells``: the gather's
    own rays that do not reach the sky, ``bvh_gather.glsl`` out_hidden), for
    ``_world_points``: (hidden (Hl, Wl, 4), the rays of each cell (Hl, Wl), the cells
    traced (None: every cell that sees a surface), the cells whose surface shows diffuse
    light (None: all)); None for the viewport's slices, which do not take it."""
    if _sparse(f):
        low, hidden = yield from _sparse_diffuse(f)
        return {"low_diffuse": low, "hidden_cells": hidden}
    kept = {}
    low = yield from _low(f, "diffuse", kept=kept)
    hidden = None
    if "hidden" in kept and _takes_world_points(f):
        cells = np.flipud(read_texture(kept["hidden"]))
        hidden = (cells, np.full(cells.shape[:2], f["gather_settings"].rays), None, None)
    return {"low_diffuse": low, "hidden_cells": hidden}


def _sun_apart(f) -> bool:
    """The pixel centres trace a map's sun apart (``bvh_lights.glsl`` world_direct_lobe's
    sunny: two strata a side at least), so the gathers leave it out of the world's rest."""
    return strata_side(f["light_samples"]) >= 2


def _sparse(f) -> bool:
    # (its holes are the filter's to fill: dense without it)
    return f["gather_hook"] is None and f["focused"].sparse and f["denoise"]


def _sparse_cells(f, seen):
    """(valid, points, normals, diffuse, plan) of the gathers' grid (Hl, Wl) from the read-back
    G-buffer ``seen``: the cells that see a surface, their points stepped back along the camera
    rays (as the numpy tracer's), their normals, whether their surface shows diffuse light
    (``passes.shows_diffuse``), and the cells ``sparse_plan`` traces — planned once for the
    diffuse and the glossy gather."""
    rows, cols = sample_pixels(f["height"], f["width"], f["gi_stride"])
    valid = seen["hit"][rows][:, cols]
    cell_p = seen["position"][rows][:, cols] - VIEW_BACKOFF * seen["direction"][rows][:, cols]
    cell_n = seen["normal"][rows][:, cols]
    shown = shows_diffuse(f["snapshot"])[material_indices(f["snapshot"], seen["material"])]
    return valid, cell_p, cell_n, shown[rows][:, cols], sparse_plan(valid, cell_p, cell_n)


def _sparse_diffuse(f):
    """The diffuse gather over the cells ``preview.sparse_gather.sparse_plan`` picks from the
    read-back G-buffer, then over the holes ``noisy_holes`` picks from the first list's
    variances (``_gather_cells``), the other cells holes that the à-trous filter's first pass
    fills (``denoise.glsl``, as the numpy tracer's ``gather_gi``)."""
    centre = f["centre"]
    stride, width, height = f["gi_stride"], f["width"], f["height"]
    valid, cell_p, cell_n, diffuse, traced = f["cells"]
    if not traced.any():  # nothing seen: the dense gather writes its zeros
        return (yield from _low(f, "diffuse")), None
    grid = [np.zeros(valid.shape + (4,), np.float32) for _ in range(2)]
    hidden = np.zeros(valid.shape + (4,), np.float32), np.zeros(valid.shape, np.int32)
    settings = sparse_settings(f["gather_settings"], np.count_nonzero(valid),
                               np.count_nonzero(traced))

    def trace(cells, at):
        values, variance, rest = _gather_cells(f, cells, at)
        return values, variance, rest, at.rays

    traced = gather_lists(traced, valid, diffuse, *grid, settings, trace, hidden)
    # the holes the filter's first pass fills (z = 1, denoise.glsl); a traced cell keeps −its
    # reach there (bvh_gather.glsl)
    grid[1][..., 2] = np.where(valid & ~traced, 1.0, np.where(traced, np.minimum(grid[1][..., 2], 0.0), 0.0))
    grid[1][..., 3] = valid & ~diffuse  # the points whose light no pass shows: no taps of it
    grid = [float_texture(np.flipud(cells), (cells.shape[1], cells.shape[0])) for cells in grid]
    return denoise(grid[0], grid[1], centre.inputs, stride, width, height,
                   settings.denoise_iterations, fit=True, holes=bool((valid & ~traced).any()),
                   unseen=True)[0], (*hidden, traced, diffuse)


def _gather_cells(f, cells, settings, kernel="bvh_gather"):
    """The diffuse gather (or ``kernel``'s) at the grid's ``cells`` (a list, ``_compact``: each
    point draws its pixel's samples, with the rays of ``settings``), read back: ((N, 4)
    values, (N, 4) variances[, (N, 4) the world's rest hidden]) in row-major order."""
    scene, centre = f["scene"], f["centre"]
    width, height = f["width"], f["height"]
    rows, cols = sample_pixels(height, width, f["gi_stride"])
    cell_rows, cell_cols = np.nonzero(cells)
    listed = rows[cell_rows] * width + cols[cell_cols]
    pixels, size = _pixel_list(listed, width, height)
    inputs = _compact("aa_list", {**centre.inputs, "pixels": pixels}, size)
    textures = gather(scene.bvh, inputs, scene.lights, scene.principled, scene.emission,
                      settings, 1, size[0], size[1], kernel=kernel,
                      tables=f["tables"], cache=f["cache"], sun_apart=_sun_apart(f))
    return tuple(read_texture(texture).reshape(-1, 4)[:len(listed)] for texture in textures)


def _glossy_gather(f):
    """Glossy Indirect at the gather points (``bvh_glossy``), filtered: at the cells of
    ``preview.sparse_gather.glossy_cells`` (sparse where the cells are pixels), or every cell."""
    if _sparse(f):
        valid, cell_p, cell_n, diffuse, plan = f["cells"]
        traced = glossy_cells(valid, cell_p, cell_n, f["gi_stride"], True, diffuse, plan)
        if traced.any() and (valid & ~traced).any():
            return {"low_glossy": (yield from _sparse_glossy(f, valid, traced))}
    return {"low_glossy": (yield from _low(f, "glossy", "bvh_glossy"))}


def _sparse_glossy(f, valid, traced):
    """The glossy gather over the ``traced`` cells of the grid's ``valid`` ones, the others
    holes that the filter's first pass fills (no spikes spread first: the fill compares each
    tap with a hole's traced neighbours; as numpy's ``gather._glossy_cells``)."""
    stride, width, height, centre = f["gi_stride"], f["width"], f["height"], f["centre"]
    settings = sparse_glossy_settings(f["gather_settings"], np.count_nonzero(valid),
                                      np.count_nonzero(traced))
    grid = [np.zeros(valid.shape + (4,), np.float32) for _ in range(2)]
    grid[0][traced], grid[1][traced] = _gather_cells(f, traced, settings, "bvh_glossy")
    grid[1][..., 2:] = 0.0
    grid[1][..., 2] = valid & ~traced  # the holes (denoise.glsl)
    grid = [float_texture(np.flipud(cells), (cells.shape[1], cells.shape[0])) for cells in grid]
    yield  # the filter is a step of its own
    return denoise(grid[0], grid[1], centre.inputs, stride, width, height,
                   settings.denoise_iterations, fit=False, holes=True,
                   sigma=GLOSSY_SIGMA_LUMINANCE)[0]


def _upsample(f):
    """The gathers at every pixel (``upsample.glsl``; Glossy Indirect 0 without its gather)."""
    full = upsample(f["low_diffuse"], f["centre"].inputs, f["gi_stride"], f["width"],
                    f["height"], f["low_glossy"])
    if f["low_glossy"] is None:
        return {"diffuse_ao": full, "glossy": f["scene"].zeros(f["width"], f["height"])}
    diffuse_ao, glossy = full
    return {"diffuse_ao": diffuse_ao, "glossy": glossy}


def _with_world_glossy(f) -> bool:
    return f["world_glossy"] and f["scene"].has_scene_lights


def _world_glossy(f):
    """Glossy Direct of the world and emitters (``bvh_glossy`` in world mode), at the gather
    points (``_world_upsample`` brings it to every pixel)."""
    return {"low_world": (yield from _low(f, "world glossy", "bvh_glossy", world_mode=True))}


def _no_world_glossy(f):
    return {"low_world": f["scene"].zeros(f["width"], f["height"])}


def _world_upsample(f):
    """The world's glossy light and the rest of its light hidden from the gather points at
    every pixel: both upsampled in one dispatch where both were gathered (one kernel's
    weights for the two: ``gpu_gather.upsample``'s pair)."""
    inputs, stride, width, height = f["centre"].inputs, f["gi_stride"], f["width"], f["height"]
    low_world, low_hidden = f["low_world"], f["low_hidden"]
    glossy = _with_world_glossy(f)
    if glossy and low_hidden is not None:
        world, hidden = upsample(low_world, inputs, stride, width, height, low_hidden)
        return {"glossy_world": world, "world_hidden": hidden}
    return {"glossy_world": upsample(low_world, inputs, stride, width, height) if glossy
            else low_world,
            "world_hidden": None if low_hidden is None
            else upsample(low_hidden, inputs, stride, width, height)}


def _has_emitters(f) -> bool:
    return any(light.type == "EMITTERS" for light in f["scene"].lights)


def _emitter_field(f):
    """The emitters' unshadowed glossy light (exact_glossy.emitters_shine) and Diffuse Direct
    (emitters.unshadowed_sum) at the field's points (``upsample.field_stride``: one per 2 × 2
    block at least), upsampled to every pixel (evaluated where the field does not hold: near
    the emitters): ``emitter_fields``."""
    return {"fields": emitter_fields(f["scene"], f["centre"].inputs, field_stride(f["gi_stride"]),
                                     f["width"], f["height"], _eye(f["snapshot"].camera))}


def _emitter_shine(f):
    """The pixel centres' glossy light of the emitters from the field, with their own visible
    share (for the centre pass and the sub-pixel passes that see their centre's surface)."""
    scene, settings, centre = f["scene"], f["gather_settings"], f["centre"]
    return {"shine": emitter_glossy_texture(
        scene.bvh, centre.inputs, scene.emitters, scene.materials, settings.glossy_rays,
        settings.seed, scene.no_lamp, scene.world_map, field=f["fields"][2])}


def _emitter_unshadowed(f):
    """The pixel centres' unshadowed Diffuse Direct of the emitters, from the field."""
    scene, centre = f["scene"], f["centre"]
    return {"unshadowed": emitters_unshadowed_texture(
        scene.bvh, centre.inputs, scene.emitters, scene.no_lamp, scene.world_map,
        field=f["fields"][3], absent=scene.direct_absent)}


def _reads_gbuffer(f) -> bool:
    return bool(subpixel_reach(f["plan"])) or _sparse(f)


def _read_gbuffer(f):
    """The centre G-buffer read back (``gbuffer.read_gbuffer``): the edge test's and the
    sparse gather's (the viewport's point-sampled slices read nothing back)."""
    seen = read_gbuffer(f["centre"])
    return {"seen": seen, "cells": _sparse_cells(f, seen) if _sparse(f) else None}


def _edge_pixels(f):
    """The pixels on the geometry's edges (``preview.passes.edge_pixels`` on the read-back
    centre G-buffer, the numpy tracer's test): they get the sub-pixel passes; none when
    point-sampled."""
    reach = subpixel_reach(f["plan"])
    if not reach:
        return {"edge": np.zeros((f["height"], f["width"]), bool)}
    seen = f["seen"]
    return {"edge": edge_pixels(seen["hit"], material_indices(f["snapshot"], seen["material"]),
                                seen["position"], seen["normal"], reach)}


_SUM_TEXTURES = (*(f"sum_{k}" for k in _SURFACE_SUMS), "sum_g")


def _has_world(f) -> bool:
    return any(light.type == "WORLD" for light in f["scene"].lights)


# F12's pixel centres take the rest of the world's hidden light from the gather points
# (``_world_points``); False: from their own rays, as the numpy tracer's (tests compare the two)
WORLD_AT_POINTS = True


def _takes_world_points(f) -> bool:
    """F12's centre pass takes the rest of the world map's hidden part from the gather points
    where there is a world and the gathers' filter (not the viewport's slices, whose samples
    average their own rays, and whose draws read nothing back)."""
    return WORLD_AT_POINTS and not f["on_gpu"] and f["denoise"] and f["gather_hook"] is None \
        and _has_world(f) and _reads_gbuffer(f)


def _wants_world_points(f) -> bool:
    """``_takes_world_points``, where the diffuse gather traced."""
    return _takes_world_points(f) and f["hidden_cells"] is not None


def _world_points(f):
    """The rest of the world map's hidden part at the gather points, from the diffuse gather's
    own rays (``_diffuse_gather``'s hidden_cells: each ray that a surface stops adds the
    world's rest along it): at the cells it traced — a cell in four where the surface is
    smooth, the creases, contacts and noisy holes — then the diffuse gather's à-trous filter
    (its holes filled from their neighbours; a point whose surface shows no diffuse light,
    which drew a few rays for its AO alone, lends its neighbours nothing) and upsample: every
    pixel centre's (``_world_upsample``), which F12's centre pass subtracts from the world's
    exact unshadowed light instead of tracing its own rays for it (docs/gi_pipeline.md "The
    world's light at the gather points")."""
    hidden, rays, traced, shown = f["hidden_cells"]
    stride, width, height, centre = f["gi_stride"], f["width"], f["height"], f["centre"]
    rows, cols = sample_pixels(height, width, stride)
    valid = f["seen"]["hit"][rows][:, cols]
    traced = valid if traced is None else traced & valid
    if not traced.any():
        return {"low_hidden": None}
    grid = [np.zeros(valid.shape + (4,), np.float32) for _ in range(2)]
    grid[0][traced] = hidden[traced]
    grid[1][traced, :2] = hidden_variances(hidden[traced], rays[traced],
                                           rest_spread(f["scene"].lights, _sun_apart(f)))
    holes = valid & ~traced
    grid[1][..., 2] = holes  # the holes the filter's first pass fills (denoise.glsl)
    if shown is not None:
        grid[1][..., 3] = valid & ~shown  # their light lends no taps (denoise.glsl)
    grid = [float_texture(np.flipud(cells), (cells.shape[1], cells.shape[0])) for cells in grid]
    return {"low_hidden": denoise(grid[0], grid[1], centre.inputs, stride, width, height,
                                  f["gather_settings"].denoise_iterations, fit=True,
                                  holes=bool(holes.any()), unseen=shown is not None)[0]}


def _no_world_points(f):
    return {"low_hidden": None}


def _shade(f, inputs, sums, terms, blank, size, block, lamps=None, glow=None, centre=None,
           field=None, smooth=None, world_hidden=None):
    """``gpu_compose.shade_stages`` of this frame's scene and snapshot; with ``smooth`` (the
    centre pass's world filter) the world's rays over ``world_strata_side``'s strata at the
    pixels away from the geometry's edges (``world_fewer_pixels``)."""
    fewer = None if smooth is None else world_fewer_pixels(f["edge"], f["light_samples"])
    world_strata = 0 if fewer is None else world_strata_side(
        f["light_samples"], f["width"], f["height"], world_rest_share(f["scene"].lights))
    return shade_stages(f["scene"], f["snapshot"], inputs, sums, terms, blank, size,
                        f["light_samples"], f["gather_settings"].seed, block, lamps, glow,
                        centre, field, lamp_glossy=f["lamp_glossy"], smooth=smooth,
                        sun_glossy=f["lamp_glossy"] and _with_world_glossy(f),
                        world_strata=world_strata,
                        world_fewer=None if fewer is None else world_fewer_texture(fewer),
                        world_hidden=world_hidden)


def _world_smooth(f):
    """The filter of the centre pass's world light (``gpu_compose.shade_stages``' smooth):
    the diffuse gather's à-trous filter over the image's pixels, its variance the world's
    hidden part's (docs/gi_pipeline.md "The world's light filtered"). None where the world
    sheds no light, and for the viewport's slices (their samples average it, and a tile's
    filter would end at the tile's edge)."""
    if f["on_gpu"] or not f["denoise"] or \
            not _has_world(f):
        return None
    width, height, inputs = f["width"], f["height"], f["centre"].inputs

    def smooth(direct):
        return denoise(direct, direct, inputs, 1, width, height,
                       world_filter_passes(width, height), alpha_variance=True,
                       noise_target=WORLD_NOISE_TARGET)[0]
    return smooth


def _centres(f):
    """The pixel centres' G-buffer with the emitters' light there (None without emitters)."""
    if f["shine"] is None:
        return None
    return {**f["centre"].inputs, "shine": f["shine"], "unshadowed": f["unshadowed"]}


def _centre_pass(f):
    """The centre pass over the whole image, all strata: the sums' textures (the edge pixels'
    are what their sub-pixel samples resolve from, ``preview.resolve``, and are then replaced
    by the samples' sums), and the lamps' light apart where there are sub-pixel passes (for
    ``light_edge_pixels``). With ``on_gpu`` and no sub-pixel passes, the frame's result: the
    sums as ``GPUSums``."""
    centre, width, height = f["centre"], f["width"], f["height"]
    scene = f["scene"]
    reach = subpixel_reach(f["plan"])
    inputs = dict(centre.inputs)
    zero = scene.zeros(width, height)
    lamps = {}
    centres = _centres(f)
    hidden = f["world_hidden"]
    # the world's light filtered over the image only where no gather points gave its rest (a
    # map's sun, the pixels' own rays, is a lamp's light: its penumbrae unfiltered as a lamp's)
    smooth = _world_smooth(f) if hidden is None else None
    sums = yield from _shade(f, inputs, {name: zero for name in _SUM_TEXTURES},
                             (f["diffuse_ao"], f["glossy"], f["glossy_world"]), zero,
                             (width, height), centre_pass(f["light_samples"])[1],
                             lamps if reach else None, f["shine"], centres,
                             smooth=smooth, world_hidden=hidden)
    result = None
    if f["on_gpu"] and not reach:  # the viewport adds them to its sums on the GPU
        result = GPUSums({name: sums[name] for name in SUM_NAMES}, width, height,
                         surface=(inputs["gbuffer_position"], inputs["gbuffer_normal"],
                                  inputs["gbuffer_view"], inputs["gbuffer_base"]))
    return {"sums": sums, "lamps": lamps, "result": result}


def _reads_back(f) -> bool:
    return f["result"] is None


def _subpixel_passes(f):
    """The sub-pixel passes over the edge pixels (``edge_all``), rendered over a list of them
    (aa_compact.glsl): per pass its samples of a G-buffer ``supersampling`` times finer than
    the image — one raster for all sixteen at 160 × 120 — (the listed pixels only where that
    pays: ``gbuffer.PixelMask``), the gathered terms and the
    emitters' light — the centre's where the pass sees its centre's surface, else the gathers
    and the field at the pass's own point (docs/gi_pipeline.md "Anti-aliasing") — and the
    pass's direct light; summed on the GPU (``gpu_tails.GPUTails``, the statement of
    ``preview.passes.stacked_tails``) into the edge pixel, each pass weighted by its cell's
    share of the filter (``preview.passes.pass_weights``), and into the neighbours its filter
    tails reach (``pass_tail_weights``): the edge pixels' sums are all in the returned tails,
    read back once a reached pixel."""
    scene, snapshot, plan = f["scene"], f["snapshot"], f["plan"]
    width, height, gi_stride = f["width"], f["height"], f["gi_stride"]
    texel, edge, listed = f["centre_texel"], f["edge_all"], f["listed"]
    if not len(listed):
        return {"texel": texel, "tails": NO_TAILS}
    pixels, list_size = _pixel_list(listed, width, height)
    zero = scene.zeros(width, height)
    centre = f["centre"]
    # the gathers at the gather points and at the centres, for each pass's samples
    low_diffuse = f["low_diffuse"]
    low_zero = zero if gi_stride == 1 else scene.zeros(low_diffuse.width, low_diffuse.height)
    gathers = ((low_diffuse, f["low_glossy"] if f["low_glossy"] is not None else low_zero,
                f["low_world"] if _with_world_glossy(f) else low_zero),
               (f["diffuse_ao"], f["glossy"], f["glossy_world"]))
    eye = _eye(snapshot.camera)
    centres = _centres(f)
    fields = f["fields"]
    # every pass's samples, one block a sum texture (names' order: each read-back one copy);
    # a sample takes the centres' sums around it where they see its surface and their light is smooth
    # (a textured sample their light, coloured by its own texel: aa_resolve.glsl,
    # preview.resolve), the others are shaded below
    names = _SUM_TEXTURES
    # summed on the GPU into the pixels they reach, each pass weighted by its cell's share of
    # the filter in its own pixel and by the filter at its place in the neighbours'
    reached = reached_pixels(listed, width, height)
    reach = GPUTails(pixels, list_size, (width, height), reached,
                     *_pixel_list(reached, width, height))
    share = pass_weights(plan, f["filter_width"]) / len(plan)
    reach_weights = pass_tail_weights(plan, f["filter_width"]) * share[:, None, None]
    reach_weights[:, 1, 1] = share
    # the passes draw the listed pixels only where the raster has the texture code (its
    # fragments cost 3× the mask's full-screen pass: 47 → 14 ms a pass, textured room at
    # 640 × 480); the plain variant's are cheaper than the mask (9 → 10 ms, the box)
    fine = supersampling(width, height, f["filter_width"])
    mask = None if scene.raster_textures() is None else \
        PixelMask(np.repeat(np.repeat(edge, fine, axis=0), fine, axis=1))
    settings = f["gather_settings"]

    def place(index):  # ((tx, gx), (ty, gy)): pass (a, b) is sample (tx, ty) of raster (gx, gy)
        return (divmod(index // AA_SIDE, AA_SIDE // fine),
                divmod(index % AA_SIDE, AA_SIDE // fine))

    groups: dict[tuple[int, int], list[int]] = {}  # the passes of each raster, in order
    for index in range(len(plan)):
        (_, gx), (_, gy) = place(index)
        groups.setdefault((gx, gy), []).append(index)
    # the passes raster by raster (one G-buffer held at a time, drawn again for the next
    # raster); all the raster's passes resolved in one dispatch, the centres around each
    # pixel read once for all of them
    gbuffer = None
    for (gx, gy), indices in sorted(groups.items()):
        gbuffer = rasterize(
            f["seen_tris"], snapshot.camera, scene.rough, width, height,
            plan[indices[0]][0] if fine == 1 else
            (_raster_shift(gx, fine), _raster_shift(gy, fine)),
            shader=f["raster_shader"],
            textures=scene.raster_textures(), filter_width=f["filter_width"],
            batch=f["vertex_batch"], mask=mask, texture_share=AA_SIDE, supersample=fine,
            into=gbuffer)
        table = np.zeros((1, AA_SIDE * AA_SIDE, 4), np.float32)
        for k, index in enumerate(indices):
            (tx, _), (ty, _) = place(index)
            table[0, k] = (*plan[index][0], tx, ty)
        blended = _run("aa_resolve", _RESOLVE_SAMPLERS, {
            **gbuffer.inputs, "pixels": pixels, "centre_position": centre.position,
            "centre_normal": centre.normal, "centre_view": centre.view,
            "centre_base": centre.base, **f["sums"],
            "offsets": float_texture(table, (AA_SIDE * AA_SIDE, 1)),
            "materials": scene.materials, "principled_lut": scene.lut},
            _RESOLVE_OUTPUTS, list_size[0], list_size[1] * len(indices),
            constants={"resolve": (float(len(indices)), SPREAD, float(fine),
                                   float(list_size[1]))}, over=list_size)
        # the resolved samples' mark: out_d's alpha (aa_resolve.glsl)
        marks = read_texture(blended["out_d"])[..., 3].reshape(len(indices), -1)
        for row, index in enumerate(indices):  # the samples left, shaded over their own list
            offset, block = plan[index]
            (tx, _), (ty, _) = place(index)
            left = np.flatnonzero(marks[row, :len(listed)] < 0.5)
            if not len(left):
                continue
            sub_pixels, sub_size = (pixels, list_size) if len(left) == len(listed) else \
                _pixel_list(listed[left], width, height)
            at = sub_pixels if fine == 1 else \
                _pixel_list(listed[left], width, height, fine, (tx, ty))[0]
            inputs = _compact("aa_list", {**gbuffer.inputs, "pixels": at}, sub_size)
            blank = scene.zeros(*sub_size)
            inputs["gbuffer_base"] = blank if not scene.textured else _compact(
                "aa_list_raw", {"gbuffer_position": gbuffer.base,
                                "gbuffer_normal": gbuffer.base, "gbuffer_view": gbuffer.base,
                                "pixels": at}, sub_size)["gbuffer_position"]
            listed_centres = None if centres is None else \
                _listed_centres(centre, centres, sub_pixels, sub_size)
            # the gathered terms, the emitters' glossy light and unshadowed sum: the centre's
            # where this pass sees its surface, else the gathers and the field at the pass's
            # own point (the field evaluated where it does not hold), in one dispatch
            strides = (gi_stride, field_stride(gi_stride))
            together = centres is not None and strides[0] == strides[1]
            *terms, field_glossy, field_diffuse = upsample_field_list(
                *(fields[:2] if together else (None, None)), centre.inputs, inputs,
                sub_pixels, sub_size, gi_stride, width, height, eye, offset, terms=gathers)
            if centres is not None and not together:  # the field on its own grid
                field_glossy, field_diffuse = upsample_field_list(
                    *fields[:2], centre.inputs, inputs, sub_pixels, sub_size, strides[1],
                    width, height, eye, offset)
            glow = None
            if centres is not None:
                glow = emitter_glossy_texture(
                    scene.bvh, inputs, scene.emitters, scene.materials, settings.glossy_rays,
                    settings.seed, scene.no_lamp, scene.world_map, centre=listed_centres,
                    field=field_glossy)
            # this pass's shaded samples, put among the raster's resolved ones
            textures = yield from _shade(f, inputs, {name: blank for name in names}, terms,
                                         blank, sub_size, block, glow=glow,
                                         centre=listed_centres, field=field_diffuse)
            side, rows = list_size
            reach.place(blended, textures, np.stack(
                [left % side, left // side + row * rows], axis=1), sub_size)
        reach.add(blended, reach_weights[indices])
    # the edge pixels' own sums are in their tails (``finish_passes`` adds both)
    for name in names:
        texel[name][listed] = 0.0
    tails = Tails(reached, _sums_of(reach.read()))
    return {"texel": texel, "tails": tails}


def _listed_centres(centre, centres, pixels, size):
    """The pixel centres' G-buffer and the emitters' light there (``_centres``) at the
    ``pixels`` list."""
    listed = _compact("aa_list", {**centre.inputs, "pixels": pixels}, size)
    raw = _compact("aa_list_raw", {
        "gbuffer_position": centres["shine"], "gbuffer_normal": centres["unshadowed"],
        "gbuffer_view": centres["unshadowed"], "pixels": pixels}, size)
    listed["shine"] = raw["gbuffer_position"]
    listed["unshadowed"] = raw["gbuffer_normal"]
    return listed


def _read_back(f):
    """The centre pass's sums read back; its shadow and light edges (``light_edge_pixels``,
    from the lamps' light in the same read-back: no read per light) join the edge pixels
    (``edge_all``, ``listed`` their flat indices)."""
    sums, lamps, edge, seen = f["sums"], f["lamps"], f["edge"], f["seen"]
    plan = f["plan"]
    reach = subpixel_reach(plan)
    read = {name: np.flipud(read_texture(texture)) for name, texture in sums.items()}
    texel = {name: image.reshape(-1, 4) for name, image in read.items()}  # float32 copies
    if reach:
        lamp_g = np.flipud(read_texture(lamps["sum_g"])) if "sum_g" in lamps else read["sum_g"]
        lamp_f = np.flipud(read_texture(lamps["sum_f"])) if "sum_f" in lamps else read["sum_f"]
        light = lamp_light(lamp_g[..., :3], read["sum_b"][..., :3], lamp_f[..., :3],
                           read["sum_c"][..., :3])
        edge = edge | light_edge_pixels(light, seen["hit"] & ~edge, reach, len(plan))
    return {"centre_texel": texel, "edge_all": edge, "listed": np.flatnonzero(edge.ravel())}


def _has_passes(f) -> bool:
    return f["result"] is None and len(f["plan"]) > 1


def _no_passes(f):
    if f["result"] is not None:  # the viewport's sums stay on the GPU
        return {"texel": None, "tails": None}
    return {"texel": f["centre_texel"], "tails": NO_TAILS}


def _finish(f):
    """The passes from the sums (``preview.passes.finish_passes``: each pixel's samples
    averaged, the sub-pixel passes' filter tails added)."""
    count = np.where(f["edge_all"].ravel(), len(f["plan"]), 1)
    return {"passes": finish_passes(_sums_of(f["texel"]), count, f["width"], f["height"],
                                    f["filter_width"], f["tails"])}


def _skip_passes(f):
    return {"passes": None}


ACCURATE_STAGES = (
    Stage("", (), ("plan", "raster_shader", "vertex_batch", "seen_tris", "tables", "focused"),
          _plan, slice_end=False),
    Stage("visibility (GPU)", ("seen_tris", "raster_shader", "vertex_batch"), ("centre",),
          _visibility),
    Stage("radiance cache", ("focused", "tables"), ("cache", "gather_settings"),
          _radiance_cache, when=_wants_cache, slice_end=False,
          skipped=lambda f: {"cache": None, "gather_settings": f["focused"]}),
    Stage("G-buffer read-back", ("centre", "plan", "focused"), ("seen", "cells"), _read_gbuffer,
          when=_reads_gbuffer, slice_end=False),
    Stage("diffuse+ao gather (GPU)", ("centre", "cache", "gather_settings", "tables", "cells",
                                      "focused", "plan"),
          ("low_diffuse", "hidden_cells"), _diffuse_gather),
    Stage("glossy gather (GPU)", ("centre", "cache", "gather_settings", "tables", "cells",
                                  "focused"),
          ("low_glossy",), _glossy_gather, when=lambda f: f["glossy_indirect"]),
    Stage("upsample", ("centre", "low_diffuse", "low_glossy"), ("diffuse_ao", "glossy"), _upsample,
          slice_end=False),
    Stage("world glossy gather (GPU)", ("centre", "cache", "gather_settings", "tables"),
          ("low_world",), _world_glossy, when=_with_world_glossy,
          skipped=_no_world_glossy),
    Stage("emitters' light field (GPU)", ("centre",), ("fields",), _emitter_field,
          when=_has_emitters),
    Stage("emitters' glossy light (GPU)", ("centre", "fields", "gather_settings"), ("shine",),
          _emitter_shine, when=_has_emitters),
    Stage("emitters' unshadowed light (GPU)", ("centre", "fields"), ("unshadowed",),
          _emitter_unshadowed, when=_has_emitters),
    Stage("edge pixels", ("plan", "seen"), ("edge",), _edge_pixels, slice_end=False),
    Stage("world light at the gather points (GPU)", ("centre", "plan", "focused", "seen",
                                                     "hidden_cells", "gather_settings"),
          ("low_hidden",), _world_points, when=_wants_world_points, skipped=_no_world_points),
    Stage("world upsample", ("centre", "low_world", "low_hidden"), ("glossy_world", "world_hidden"),
          _world_upsample, slice_end=False),
    Stage("direct (GPU)", ("centre", "plan", "diffuse_ao", "glossy", "glossy_world", "shine",
                           "unshadowed", "gather_settings", "edge", "world_hidden"),
          ("sums", "lamps", "result"), _centre_pass, slice_end=False),
    Stage("read-back", ("sums", "lamps", "edge", "seen", "plan", "result"),
          ("centre_texel", "edge_all", "listed"), _read_back, when=_reads_back,
          slice_end=False),
    Stage("sub-pixel passes (GPU)", ("centre_texel", "edge_all", "listed", "centre", "sums",
                                     "plan",
                                     "seen_tris", "raster_shader", "vertex_batch",
                                     "low_diffuse", "low_glossy", "low_world", "diffuse_ao",
                                     "glossy", "glossy_world", "fields", "shine", "unshadowed",
                                     "gather_settings", "result"),
          ("texel", "tails"), _subpixel_passes, when=_has_passes, skipped=_no_passes,
          slice_end=False),
    Stage("finish", ("texel", "tails", "edge_all", "plan", "result"), ("passes",), _finish,
          when=_reads_back, skipped=_skip_passes, slice_end=False),
)
