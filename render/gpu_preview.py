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
from ..voxgi_addon.preview import transmission
from ..voxgi_addon.preview.film import background
from ..voxgi_addon.preview.gather import GatherSettings, focused
from ..voxgi_addon.preview.passes import (
    centre_pass,
    check_request,
    edge_pixels,
    finish_passes,
    lamp_light,
    light_edge_pixels,
    material_indices,
    new_sums,
    pass_tail_weights,
    stacked_tails,
    subpixel_passes,
    subpixel_reach,
)
from ..voxgi_addon.preview.upsample import sample_pixels
from ..voxgi_addon.scene.camera import DEFAULT_FILTER_WIDTH, camera_frame
from ..voxgi_addon.scene.glass import is_glass
from .gbuffer import PixelMask, gbuffer_shader, rasterize, rasterize_stages, read_gbuffer, vertex_batch
from .gpu_accumulation import SUM_NAMES, GPUSums
from .gpu_bvh import emitter_glossy_texture, emitters_unshadowed_texture
from .gpu_compose import COMPACT_SAMPLERS as _COMPACT_SAMPLERS
from .gpu_compose import MASK_SAMPLERS as _MASK_SAMPLERS
from .gpu_compose import SURFACE_SUMS as _SURFACE_SUMS
from .gpu_compose import run as _run
from .gpu_compose import shade_stages
from .gpu_fast import fast_passes, fast_sums
from .gpu_gather import denoise, gather, gather_low, upsample, upsample_field, upsample_field_list
from .gpu_scene import GPUScene, current_scene
from .gpu_shaders import LOCAL_SIZE
from .gpu_tracer import read_texture
from .gpu_volume import GPUVolume, float_texture


def render_passes_gpu(*args, **kwargs):
    """(passes, timings): ``render_passes_stages`` run to its end in one call (F12,
    ``render_preview``, probe previews)."""
    return finish(render_passes_stages(*args, **kwargs))


def finish(stages):
    """Run a ``render_passes_stages`` generator to its end: its result."""
    while True:
        try:
            next(stages)
        except StopIteration as end:
            return end.value


def render_passes_stages(snapshot, gi_state, width: int, height: int, cones,
                         light_samples: int = 16, volume: GPUVolume | None = None,
                         shadows: str = "RAYS", gi_stride: int = 1, quality: str = "ACCURATE",
                         gather_settings: GatherSettings | None = None,
                         glossy_indirect: bool = True,
                         filter_width: float = DEFAULT_FILTER_WIDTH,
                         gpu_scene: GPUScene | None = None, gather_hook=None, raster=None,
                         cache_source=None, on_gpu: bool = False, batch=None,
                         world_glossy: bool = True):
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
    The viewport's slices run the stages over several draws (``progressive``); the textures
    live in the generator between them, so nothing but its own next stage runs in a draw."""
    check_request(snapshot, width, height, gi_stride, quality)
    # glass' two layers are composed on the CPU: the sums stay on the GPU only without it
    on_gpu = on_gpu and not any(is_glass(m) for m in snapshot.materials)
    if quality == "ACCURATE":
        t0 = time.perf_counter()
        scene = (gpu_scene or current_scene()).update(snapshot)  # only what changed is sent
        built = time.perf_counter() - t0
        # the G-buffer's variant follows the scene's textures (gbuffer.gbuffer_shader: the
        # plain one where no material has any)
        raster = raster or gbuffer_shader(textured=scene.textured)
        layer = (width, height, light_samples, gi_stride,
                 gather_settings or GatherSettings(ao_distance=cones.ao_distance),
                 glossy_indirect, filter_width, scene)
        front, timings = yield from _accurate_stages(snapshot, *layer, gather_hook, raster,
                                                     cache_source, on_gpu=on_gpu, batch=batch,
                                                     world_glossy=world_glossy)
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
            (lambda kind, values, variance: gather_hook(f"behind {kind}", values, variance))
        behind, _ = yield from _accurate_stages(
            snapshot, *layer, hook, raster, cache_source,
            camera_tris=transmission.behind_glass(scene.tris, glass),
            only=transmission.behind_pixels(weight), world_glossy=world_glossy)
        world = background(snapshot.world, snapshot.camera, width, height, filter_width)
        timings["behind glass"] = time.perf_counter() - t0
        return transmission.composite(front, behind, weight, world), timings
    gather_settings = gather_settings or GatherSettings(ao_distance=cones.ao_distance)
    fast = (snapshot, gi_state, width, height, cones, light_samples, volume, shadows, gi_stride,
            gather_settings, glossy_indirect)
    given = {}
    if cache_source is not None and gather_settings.bounces > 1:
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

def _pixel_list(listed, width: int, height: int):
    """(texture, (w, h)) of the edge pixels' list (aa_compact.glsl): texel t (row-major from
    the texture's first row) = (x, y, id, 1) of pixel id = listed[t] (flat, row 0 on top; GL
    y = height − 1 − row), padded with zeros to w × h, w a multiple of the work group size."""
    side = LOCAL_SIZE * max(1, math.ceil(math.sqrt(len(listed)) / LOCAL_SIZE))
    rows = math.ceil(len(listed) / side)
    texels = np.zeros((rows * side, 4), np.float32)
    texels[:len(listed)] = np.stack([listed % width, height - 1 - listed // width, listed,
                                     np.ones(len(listed))], axis=1)
    return float_texture(texels.reshape(rows, side, 4), (side, rows)), (side, rows)


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


def emitter_fields(scene, gbuffer_inputs, gi_stride: int, width: int, height: int, eye):
    """The emitters' unshadowed glossy light and Diffuse Direct at the gather points — the
    only place their per-triangle sums are evaluated everywhere (docs/gi_pipeline.md "Where a
    preview's time goes") — as (low glossy, low diffuse, full glossy, full diffuse) textures:
    the gather points' (``emitter_glossy_texture(unshadowed=True)``,
    ``emitters_unshadowed_texture``) and ``upsample_field``'s at every pixel. eye : ``_eye``
    of the camera."""
    bvh = scene.bvh
    if gi_stride == 1:
        points = gbuffer_inputs
    else:
        pixels, size = _gather_list(gi_stride, width, height)
        points = _compact("aa_list", {**gbuffer_inputs, "pixels": pixels}, size)
        points["gbuffer_base"] = scene.zeros(*size) if not scene.textured else _compact(
            "aa_list_raw", {"gbuffer_position": gbuffer_inputs["gbuffer_base"],
                            "gbuffer_normal": gbuffer_inputs["gbuffer_base"],
                            "gbuffer_view": gbuffer_inputs["gbuffer_base"], "pixels": pixels},
            size)["gbuffer_position"]
    glossy = emitter_glossy_texture(bvh, points, scene.emitters, scene.materials, 1, 0,
                                    scene.no_lamp, scene.world_map, unshadowed=True)
    diffuse = emitters_unshadowed_texture(bvh, points, scene.emitters, scene.no_lamp,
                                          scene.world_map)
    return (glossy, diffuse,
            *upsample_field(glossy, diffuse, gbuffer_inputs, gi_stride, width, height, eye))


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
                     batch=None, world_glossy=True):
    """Accurate quality on the GPU: the gathers and the emitters' unshadowed glossy light and
    Diffuse Direct at the gather points of the pixel centres' G-buffer (``emitter_fields``),
    the latter upsampled to the centres, then one rasterized G-buffer, direct light
    (``bvh_direct``, a block of the shadow-ray strata) and glossy light of the lamps per
    sub-pixel pass (``preview.passes.subpixel_passes``; the gathered terms and the emitters'
    glossy light and unshadowed sum from the gathers and their field at the pass's own points
    where the pass sees another surface than its pixel's centre, one ``upsample_field_list``
    dispatch), summed on the GPU (``shaders/aa_surface.glsl``,
    ``aa_light.glsl``) and read back once.
    Triangles, BVH, materials and light tables come from ``scene`` (a ``GPUScene`` updated to
    ``snapshot``: ``render_passes_stages`` updates it). camera_tris : what the G-buffers draw (None: the
    scene's triangles; ``transmission.behind_glass`` hides glass from them); only : (H, W)
    bool the pixels to shade (None: all; the others are background to every kernel).
    on_gpu : return the centre pass's sums as textures (``GPUSums``) when there are no edge
    pixels (point-sampled), nothing read back."""
    timings = {}
    tris, rough, emission = scene.tris, scene.rough, scene.emission
    if len(tris) == 0:
        raise VoxGIError("the scene has no triangles to render")
    # the radiance cache nests finer grids around the camera (a tile's camera: the view's)
    gather_settings = focused(gather_settings, snapshot.camera, tris)
    t0 = time.perf_counter()
    plan = subpixel_passes(filter_width, light_samples)
    raster = raster or gbuffer_shader(scene.textured)  # this context's, for its G-buffers
    seen_tris = tris if camera_tris is None else camera_tris
    # one vertex batch for every G-buffer of this render (gbuffer.vertex_batch), or the
    # caller's of the scene's triangles
    if batch is None or camera_tris is not None:
        batch = vertex_batch(seen_tris, rough, raster, scene.raster_textures() is not None)
    # (the viewport's chunked batch: a stage per chunk in view, gbuffer.rasterize_stages)
    centre = yield from rasterize_stages(seen_tris, snapshot.camera, rough, width, height,
                                         shader=raster, textures=scene.raster_textures(),
                                         filter_width=filter_width, batch=batch)
    if only is not None:  # the other pixels' coverage 0: background to every kernel
        centre.position = _run("aa_mask", _MASK_SAMPLERS, {
            "gbuffer_position": centre.position,
            "pixels": float_texture(np.flipud(only).astype(np.float32), (width, height), "R32F")},
            ("out_position",), width, height)["out_position"]
    timings["visibility (GPU)"] = time.perf_counter() - t0
    yield

    t0 = time.perf_counter()
    bvh, principled, lights = scene.bvh, scene.principled, scene.lights
    tables = scene.gather_tables()
    cache = None
    if cache_source is not None and gather_settings.bounces > 1:
        # the viewport's cache: one stage of its build, the last complete one read meanwhile
        cache = yield from cache_source.stage(bvh, lights, principled, emission,
                                              gather_settings, tables)
        if cache is None:  # none complete yet: one bounce until there is
            gather_settings = dataclasses.replace(gather_settings, bounces=1)
        timings["radiance cache stage"] = time.perf_counter() - t0
    gathered = (bvh, centre.inputs, lights, principled, emission, gather_settings, gi_stride,
                width, height)

    def low(kind, kernel="bvh_gather", world_mode=False):
        """One gather's filtered low-resolution texture (``gpu_gather.gather_low``), its raw
        result replaced by ``gather_hook``'s when there is one."""
        given = {"cache": cache} if cache is not None and not world_mode else {}
        if gather_hook is None and not given:
            return gather_low(*gathered, kernel=kernel, world_mode=world_mode, tables=tables)
        values, variance = gather(*gathered, kernel=kernel, world_mode=world_mode,
                                  tables=tables, **given)
        if gather_hook is not None:
            values, variance = gather_hook(kind, values, variance)
        return denoise(values, variance, centre.inputs, gi_stride, width, height,
                       gather_settings.denoise_iterations, fit=kind.endswith("diffuse"))[0]

    low_diffuse = low("diffuse")
    timings["diffuse+ao gather (GPU)"] = time.perf_counter() - t0
    yield
    t0 = time.perf_counter()
    zero = scene.zeros(width, height)
    low_glossy = low("glossy", "bvh_glossy") if glossy_indirect else None
    if glossy_indirect:
        timings["glossy gather (GPU)"] = time.perf_counter() - t0
        yield
    t0 = time.perf_counter()
    full = upsample(low_diffuse, centre.inputs, gi_stride, width, height, low_glossy)
    diffuse_ao, glossy = full if glossy_indirect else (full, zero)
    timings["upsample"] = time.perf_counter() - t0
    glossy_world = low_world = zero
    world_glossy = world_glossy and scene.has_scene_lights
    if world_glossy:  # Glossy Direct of the world and emitters
        t0 = time.perf_counter()
        low_world = low("world glossy", "bvh_glossy", world_mode=True)
        glossy_world = upsample(low_world, centre.inputs, gi_stride, width, height)
        timings["world glossy gather (GPU)"] = time.perf_counter() - t0
        yield
    centres = None  # the pixel centres with the emitters' light there
    if any(light.type == "EMITTERS" for light in lights):
        # the emitters' unshadowed glossy light (exact_glossy.emitters_shine) and Diffuse
        # Direct (emitters.unshadowed_sum) at the gather points, upsampled to every pixel
        # (evaluated where the field does not hold: near the emitters); the centres' glossy
        # light from it with their own visible share, for the centre pass and the sub-pixel
        # passes that see their centre's surface
        t0 = time.perf_counter()
        eye = _eye(snapshot.camera)
        fields = emitter_fields(scene, centre.inputs, gi_stride, width, height, eye)
        timings["emitters' light field (GPU)"] = time.perf_counter() - t0
        yield
        t0 = time.perf_counter()
        centres = {**centre.inputs, "shine": emitter_glossy_texture(
            bvh, centre.inputs, scene.emitters, scene.materials, gather_settings.glossy_rays,
            gather_settings.seed, scene.no_lamp, scene.world_map, field=fields[2])}
        timings["emitters' glossy light (GPU)"] = time.perf_counter() - t0
        yield
        t0 = time.perf_counter()
        centres["unshadowed"] = emitters_unshadowed_texture(
            bvh, centre.inputs, scene.emitters, scene.no_lamp, scene.world_map, field=fields[3])
        timings["emitters' unshadowed light (GPU)"] = time.perf_counter() - t0
        yield

    t0 = time.perf_counter()
    # The edge pixels (preview.passes.edge_pixels on the read-back centre G-buffer, the numpy
    # tracer's test) get the sub-pixel passes, over a list of them (aa_compact.glsl); the
    # others the centre pass with all strata, over the image.
    reach = subpixel_reach(plan)
    if reach:
        seen = read_gbuffer(centre)
        edge = edge_pixels(seen["hit"], material_indices(snapshot, seen["material"]),
                           seen["position"], seen["normal"], reach)
    else:  # point-sampled (the viewport's slices): no edge pixels, nothing to read back
        edge = np.zeros((height, width), bool)
    timings["edge pixels"] = time.perf_counter() - t0
    t0 = time.perf_counter()

    def shade(inputs, sums, terms, blank, size, block, lamps=None, glow=None, centre=None,
              field=None):
        """``gpu_compose.shade_stages`` of this scene and snapshot."""
        return shade_stages(scene, snapshot, inputs, sums, terms, blank, size, light_samples,
                            gather_settings.seed, block, lamps, glow, centre, field)

    # The centre pass over the image off the geometry's edges (preview.passes.edge_pixels on
    # the read-back centre G-buffer, the numpy tracer's test; the edge pixels as background, so
    # every kernel returns early there), then its shadow and light edges
    # (light_edge_pixels) join them, and the sub-pixel passes render the edge pixels over a
    # list of them (aa_compact.glsl); their sums replace the centre pass's at read-back.
    inputs = dict(centre.inputs)
    if edge.any():
        keep = np.flipud(~edge).astype(np.float32)
        inputs["gbuffer_position"] = _run("aa_mask", _MASK_SAMPLERS, {
            "gbuffer_position": centre.position,
            "pixels": float_texture(keep, (width, height), "R32F")},  # aa_mask reads .x
            ("out_position",), width, height)["out_position"]
    names = (*(f"sum_{k}" for k in _SURFACE_SUMS), "sum_g")
    lamps = {}
    sums = yield from shade(inputs, {name: zero for name in names},
                            (diffuse_ao, glossy, glossy_world), zero, (width, height),
                            centre_pass(light_samples)[1], lamps if reach else None,
                            None if centres is None else centres["shine"], centres)
    if on_gpu and not reach:  # the viewport adds them to its sums on the GPU
        timings["direct (GPU)"] = time.perf_counter() - t0
        return GPUSums({name: sums[name] for name in SUM_NAMES}, width, height), timings
    read = {name: np.flipud(read_texture(texture)) for name, texture in sums.items()}
    texel = {name: image.reshape(-1, 4).astype(np.float64) for name, image in read.items()}
    if reach:  # the centre pass's lamp light, from the same read-back (no read per light)
        lamp_g = np.flipud(read_texture(lamps["sum_g"])) if "sum_g" in lamps else read["sum_g"]
        lamp_f = np.flipud(read_texture(lamps["sum_f"])) if "sum_f" in lamps else read["sum_f"]
        light = lamp_light(lamp_g[..., :3], read["sum_b"][..., :3], lamp_f[..., :3],
                           read["sum_c"][..., :3])
        edge = edge | light_edge_pixels(light, seen["hit"] & ~edge, reach, len(plan))
    listed = np.flatnonzero(edge.ravel())
    if len(listed):
        pixels, list_size = _pixel_list(listed, width, height)
        blank = scene.zeros(*list_size)
        # the gathers at the gather points and at the centres, for each pass's samples: the
        # centre's where the sample sees its centre's surface, else the gathers at the sample's
        # own point (docs/gi_pipeline.md "Anti-aliasing")
        low_zero = zero if gi_stride == 1 else scene.zeros(low_diffuse.width, low_diffuse.height)
        gathers = ((low_diffuse, low_glossy if glossy_indirect else low_zero,
                    low_world if world_glossy else low_zero),
                   (diffuse_ao, glossy, glossy_world))
        eye = _eye(snapshot.camera)
        listed_centres = None
        if centres is not None:  # the centres' G-buffer and emitters' light there
            listed_centres = _compact("aa_list", {**centre.inputs, "pixels": pixels}, list_size)
            raw = _compact("aa_list_raw", {
                "gbuffer_position": centres["shine"], "gbuffer_normal": centres["unshadowed"],
                "gbuffer_view": centres["unshadowed"], "pixels": pixels}, list_size)
            listed_centres["shine"] = raw["gbuffer_position"]
            listed_centres["unshadowed"] = raw["gbuffer_normal"]
        # every pass's samples, the sum textures' texels side by side (names' order)
        samples = np.empty((len(plan), len(listed), 4 * len(names)), np.float32)
        # the passes draw the listed pixels only where the raster has the texture code (its
        # fragments cost 3× the mask's full-screen pass: 47 → 14 ms a pass, textured room at
        # 640 × 480); the plain variant's are cheaper than the mask (9 → 10 ms, the box)
        mask = PixelMask(edge) if scene.raster_textures() is not None else None
        for index, (offset, block) in enumerate(plan):
            gbuffer = rasterize(seen_tris, snapshot.camera, rough, width, height, offset,
                                shader=raster, textures=scene.raster_textures(),
                                filter_width=filter_width, batch=batch, mask=mask)
            inputs = _compact("aa_list", {**gbuffer.inputs, "pixels": pixels}, list_size)
            inputs["gbuffer_base"] = blank if not scene.textured else _compact(
                "aa_list_raw", {"gbuffer_position": gbuffer.base, "gbuffer_normal": gbuffer.base,
                                "gbuffer_view": gbuffer.base, "pixels": pixels},
                list_size)["gbuffer_position"]
            # the gathered terms, the emitters' glossy light and unshadowed sum: the centre's
            # where this pass sees its surface, else the gathers and the field at the pass's
            # own point (the field evaluated where it does not hold), in one dispatch
            *terms, field_glossy, field_diffuse = upsample_field_list(
                *(fields[:2] if centres is not None else (None, None)), centre.inputs, inputs,
                pixels, list_size, gi_stride, width, height, eye, offset, terms=gathers)
            glow = None
            if centres is not None:
                glow = emitter_glossy_texture(
                    bvh, inputs, scene.emitters, scene.materials, gather_settings.glossy_rays,
                    gather_settings.seed, scene.no_lamp, scene.world_map,
                    centre=listed_centres, field=field_glossy)
            # this pass's samples, read back to count in the neighbours by the filter at
            # their own place (preview.passes.add_tails)
            textures = yield from shade(inputs, {name: blank for name in names}, terms, blank,
                                        list_size, block, glow=glow, centre=listed_centres,
                                        field=field_diffuse)
            for k, name in enumerate(names):
                samples[index, :, 4 * k:4 * k + 4] = \
                    read_texture(textures[name]).reshape(-1, 4)[:len(listed)]
        own = samples.sum(axis=0, dtype=np.float64)
        samples /= len(plan)
        tail = stacked_tails(samples, pass_tail_weights(plan, filter_width), listed, width,
                             height)
        tails = _sums_of({name: tail[:, 4 * k:4 * k + 4] for k, name in enumerate(names)})
        for k, name in enumerate(names):
            texel[name][listed] = own[:, 4 * k:4 * k + 4]
    else:
        tails = new_sums(width * height)
    count = np.where(edge.ravel(), len(plan), 1)
    timings["sub-pixel passes (GPU)" if len(plan) > 1 else "direct (GPU)"] = \
        time.perf_counter() - t0
    t0 = time.perf_counter()
    passes = finish_passes(_sums_of(texel), count, width, height, filter_width, tails)
    timings["read-back"] = time.perf_counter() - t0
    return passes, timings
