"""The Accurate integrator's final gather on the GPU: exact rays at reduced resolution, the
edge-aware à-trous filter, and the joint-bilateral upsample.

``gather_gi`` runs ``shaders/bvh_gather.glsl`` (exact one-bounce Diffuse Indirect and AO with
their variances, one cell per stride × stride block), ``shaders/denoise.glsl`` ``iterations``
times (taps 1, 2, 4, … cells apart) and, for strides above 1, ``shaders/upsample.glsl``. It is
the GPU statement of ``voxgi_addon.preview.gather.gather_gi`` (numpy), which draws the same
rays. Needs a GPU context.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import replace

import gpu
import numpy as np

from ..voxgi_addon.gi.exact_glossy import DISC_SIDES, DISC_WIDEST, HORIZON_LIFT, METAL_RAY_FACTOR
from ..voxgi_addon.gi.exact_indirect import MAX_FOLLOWS
from ..voxgi_addon.gi.radiance_cache import (
    OUTLIER_FLOOR,
    OUTLIER_RATIO,
    build_cache,
    cache_key,
    cache_texels,
    face_points,
    texel_places,
    triangles_key,
    with_faces,
)
from ..voxgi_addon.preview.denoise import (
    AO_TOLERANCE,
    GLOSSY_SIGMA_LUMINANCE,
    GUIDE_WEIGHT,
    HOLE_SPREAD,
    NOISE_TARGET,
    REACH,
    RIDGE,
    SAME_SURFACE,
    SIGMA_LUMINANCE,
)
from ..voxgi_addon.preview.gather import cache_settings, uses_cache
from ..voxgi_addon.preview.light_table import MAX_OUTLINE
from ..voxgi_addon.preview.passes import AREA_GLOSSY_GRID, DISC_FROM, DISC_FULL, LTC_FROM, LTC_FULL
from ..voxgi_addon.preview.upsample import PLANE_TOLERANCE, low_shape
from .frame import finish
from .gpu_bvh import GPUBVH, OUTPUTS, dispatch_bvh, lights_texture, scene_light_textures, strata_side
from .gpu_ltc import DEFINES as LTC_DEFINES
from .gpu_ltc import ltc_texture
from .gpu_principled import DEFINES as PRINCIPLED_DEFINES
from .gpu_principled import lut_texture
from .gpu_shaders import LOCAL_SIZE, build_compute, forget, size_like
from .gpu_tracer import read_texture
from .gpu_volume import float_texture

_DENOISE_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "low_image", "low_variance",
                     "spread_image", "spread_variance")
_UPSAMPLE_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "low_image")
_shaders: dict[str, object] = {}


def _denoise_shader(holes: bool = False):
    """The filter's kernel; ``holes``: its variant that compares a hole's taps with its
    traced neighbours' light (denoise.glsl DENOISE_HOLES), left out of the other, since
    llvmpipe pays for a branch's code where no lane takes it (the dense filter 12% slower)."""
    name = "denoise holes" if holes else "denoise"
    if name not in _shaders:
        defines = {"AO_TOLERANCE": repr(float(AO_TOLERANCE)),
                   "GUIDE_WEIGHT": repr(float(GUIDE_WEIGHT)),
                   "RIDGE": repr(float(RIDGE)),
                   "SAME_SURFACE": repr(float(SAME_SURFACE)),
                   "REACH": repr(float(REACH))}
        if holes:
            defines["DENOISE_HOLES"] = "1"
        _shaders[name] = build_compute(("pixels", "denoise"), _DENOISE_SAMPLERS,
                                       ("grid", "options", "settle"), ("out_image", "out_variance"),
                                       defines)
    return _shaders[name]


def _denoise_dispatch(shader, gbuffer_inputs, values, variance, given, stride, width, height,
                      options):
    """One dispatch of the denoise kernel over ``values``/``variance`` with ``given`` (a pair:
    spread_image, spread_variance; None: the values themselves) and ``options``; returns its
    (out_image, out_variance)."""
    out = [gpu.types.GPUTexture((values.width, values.height), format="RGBA32F")
           for _ in range(2)]
    given = given or (values, variance)
    inputs = {**gbuffer_inputs, "low_image": values, "low_variance": variance,
              "spread_image": given[0], "spread_variance": given[1]}
    shader.bind()
    for name in _DENOISE_SAMPLERS:
        shader.uniform_sampler(name, inputs[name])
    shader.uniform_float("grid", (float(stride), float(width), float(height), 1.0))
    shader.uniform_float("options", options)
    shader.uniform_float("settle", (float(NOISE_TARGET), 0.0, 0.0, 0.0))
    shader.image("out_image", out[0])
    shader.image("out_variance", out[1])
    gpu.compute.dispatch(shader, math.ceil(values.width / LOCAL_SIZE),
                         math.ceil(values.height / LOCAL_SIZE), 1)
    return tuple(out)


def spread_spikes(values, variance, gbuffer_inputs, stride: int, width: int, height: int):
    """(values, variance) textures with the light above its neighbours' spread over its
    surface (``preview.denoise.spread_spikes``): two dispatches of the filter's own kernel
    (denoise.glsl options.w = 3, then 4), before a glossy gather's passes."""
    shader = _denoise_shader()
    given = _denoise_dispatch(shader, gbuffer_inputs, values, variance, None, stride, width,
                              height, (0.0, 1.0, 1.0, 3.0))
    return _denoise_dispatch(shader, gbuffer_inputs, values, variance, given, stride, width,
                             height, (0.0, 1.0, 1.0, 4.0))


def denoise(values, variance, gbuffer_inputs, stride: int, width: int, height: int,
            iterations: int = 4, fit: bool = True, holes: bool = False,
            sigma: float = SIGMA_LUMINANCE, alpha_variance: bool = False,
            unseen: bool = False, noise_target: float = NOISE_TARGET):
    """``iterations`` passes of the à-trous filter over the low-resolution ``values`` (light rgb,
    AO) and ``variance`` textures whose cells trace the pixels ``traced_pixel`` picks in the
    ``width`` × ``height`` G-buffer; returns the filtered (values, variance) textures. fit :
    the local linear fit, else the weighted mean (``preview.denoise.atrous_filter``'s). holes :
    the values have holes (the sparse gather's): the first pass's kernel stretched over
    ``HOLE_SPREAD`` × its width, as numpy's. unseen : the variance's .w is 1 at the cells
    whose light no pass shows (``atrous_filter``'s unseen): no taps of the others' light.
    noise_target : ``atrous_filter``'s (a cell within it of its value is kept as it is)."""
    shader = _denoise_shader(holes)
    for it in range(iterations):
        out = [gpu.types.GPUTexture((values.width, values.height), format="RGBA32F")
               for _ in range(2)]
        shader.bind()
        inputs = {**gbuffer_inputs, "low_image": values, "low_variance": variance,
                  "spread_image": values, "spread_variance": variance}
        for name in _DENOISE_SAMPLERS:
            shader.uniform_sampler(name, inputs[name])
        shader.uniform_float("grid", (float(stride), float(width), float(height), float(1 << it)))
        spread = float(HOLE_SPREAD) if it == 0 and holes else 1.0  # (denoise.py HOLE_SPREAD)
        # (the first pass reads a pixel's world light's variance from its alpha: denoise.glsl)
        in_alpha = 1.0 if alpha_variance and it == 0 else 0.0
        mode = 2.0 if unseen else in_alpha
        shader.uniform_float("options", (1.0 if fit else 0.0, spread, sigma, mode))
        shader.uniform_float("settle", (float(noise_target), 0.0, 0.0, 0.0))
        shader.image("out_image", out[0])
        shader.image("out_variance", out[1])
        gpu.compute.dispatch(shader, math.ceil(values.width / LOCAL_SIZE),
                             math.ceil(values.height / LOCAL_SIZE), 1)
        values, variance = out
    return values, variance


def principled_materials_texture(principled, emission, slots=None, variants=None, glow=None):
    """(M + 1) × 5 texture of the hits' materials: row 0 base colour, row 1 emission, row 2
    (metallic, Specular IOR Level, roughness) (``preview.passes.principled_table``), row 3
    (Base Color texture slot, Roughness / Metallic texture slot, first variant, 0): ``slots``
    (M + 1,) and ``variants`` ((M + 1,) parameter slots, (M + 1,) first variants) of
    ``scene.textures.SurfaceTextures``, -1 (none) without; row 4 (Emission Color texture slot,
    Strength, 0, 0): ``glow`` ((M + 1,) ``emission_slots``, (M + 1,) ``emission_strength``),
    -1 without (``bvh_shade.glsl`` ``hit_emission``)."""
    base, params = principled
    rows = np.zeros((5, len(base), 4), np.float32)
    rows[0, :, :3], rows[1, :, :3], rows[2, :, :3] = base, emission, params
    rows[3, :, 0] = -1.0 if slots is None else np.asarray(slots, np.float32)
    rows[3, :, 1] = -1.0
    if variants is not None and variants[0] is not None:
        rows[3, :, 1], rows[3, :, 2] = variants
    rows[4, :, 0] = -1.0
    if glow is not None and glow[0] is not None:
        rows[4, :, 0], rows[4, :, 1] = glow
    return float_texture(rows, (len(base), 5))


def no_texture_inputs() -> dict[str, object]:
    """1 × 1 stand-ins for the bounce hits' texture samplers (``bvh_shade.glsl``) of a scene
    whose materials sample no texture (row 3 of the materials texture is -1 throughout)."""
    blank = np.zeros((1, 1, 4), np.float32)
    return {name: float_texture(blank, (1, 1)) for name in ("texture_table", "texture_atlas")}


# The session's last complete radiance cache, whoever built it — F12, ``render_preview`` or a
# Rendered view (``viewport_cache.ViewportCache``): {"entry": (the BVH's node texture, its
# ``cache_key``, its cache (a ``RadianceCache``, or a function reading one back), its
# texture)}. The same triangles (the session's one GPU scene keeps their node texture), lights,
# materials and cache settings give the same cache whoever builds it (a test), so a view
# entered after F12, F12 after a view, and a view switched off and on again read it and build
# none (docs/gi_pipeline.md "One radiance cache for F12 and the Rendered view").
_shared: dict[str, object] = {}


def shared_cache(nodes, key):
    """(cache, texture) of the session's complete radiance cache when it was built over the
    BVH node texture ``nodes`` for ``key`` (``cache_key``), else None."""
    held = _shared.get("entry")
    if held is None or held[0] is not nodes or held[1] != key:
        return None
    return held[2], held[3]


def share_cache(nodes, key, cache, texture) -> None:
    """Keep a complete radiance cache (see ``shared_cache``) for the session's next reader."""
    _shared["entry"] = (nodes, key, cache, texture)


def drop_shared_cache() -> None:
    """Forget the session's radiance cache (a file load: it belongs to the file it came from;
    the views holding it keep theirs)."""
    _shared.clear()


CACHE_IMAGE_WIDTH = 256  # voxel faces per row of the cache's gather "image"
CACHE_STAGE_SECONDS = 0.015  # a chunk of the viewport's staged build (progressive.STAGE_SHARE)
CHUNK_AIM = 0.75    # of it, what the next chunk is sized for by the last one's time
CHUNK_GROWTH = 2.0  # ... growing at most this many times a chunk


def cache_gpu(bvh: GPUBVH, lights, principled, emission, settings, tables=None):
    """The radiance cache of ``settings.bounces`` − 1 iterations (``gi.radiance_cache``)
    gathered on the GPU: ``cache_stages`` with every ray in one chunk."""
    return finish(cache_stages(bvh, lights, principled, emission, settings, tables,
                               budget=math.inf, first_rows=1 << 30))


RECORD_WIDTH = 2048  # rays per row of the cache's ray records (cache_paths.glsl)
_RELAX_SAMPLERS = ("face_places", "radiance_cache", "paths_radiance", "paths_pick",
                   "cache_level")


def _relax_shader():
    if "relax" not in _shaders:
        _shaders["relax"] = build_compute(
            ("cache_lookup", "cache_relax"), _RELAX_SAMPLERS, ("sampling", "levels"),
            ("out_image", "copy_image"),
            defines={"OUTLIER_RATIO": repr(float(OUTLIER_RATIO)),
                     "OUTLIER_FLOOR": repr(float(OUTLIER_FLOOR))})
    return _shaders["relax"]


def face_places(cache):
    """A texture of the cache's faces (``face_points``' order), CACHE_IMAGE_WIDTH to a row:
    face f's texel of ``cache_texels`` and of its ahead part, (column, row, column, row)
    (``radiance_cache.texel_places``) — where ``cache_relax.glsl`` writes it."""
    rows, columns = texel_places(cache, 0)
    ahead_rows, ahead_columns = texel_places(cache, 1)
    count = len(rows)
    height = -(-count // CACHE_IMAGE_WIDTH)
    places = np.zeros((height * CACHE_IMAGE_WIDTH, 4), np.float32)
    places[:count] = np.stack([columns, rows, ahead_columns, ahead_rows], axis=1)
    return float_texture(places.reshape(height, CACHE_IMAGE_WIDTH, 4), (CACHE_IMAGE_WIDTH, height))


def relax_gpu(places, cache_texture, records, rays: int, count: int, out, keep: bool = False,
              empty: bool = False, level=None, copy=None):
    """One iteration over the ray ``records`` (``cache_paths.glsl``'s two textures):
    ``cache_relax.glsl`` writes into ``out`` each of the ``count`` faces' next value from
    ``cache_texture``, the previous iteration, at its texel (``face_places``) — a dispatch over
    the faces only; ``out``'s other texels (the header, the ids, the voxels' absent faces) are
    the layout's, uploaded once (``cache_stages``). keep : ``out`` has the ahead part after
    the first (``cache_texels(ahead=True)``): each face's texel of the first keeps the previous
    iteration, of the second gets the next one, from which the last pass makes the first
    part's .a (``radiance_cache.one_more_bounce``). copy : (texture, part): the faces are
    also written to that part of it (the cache's earlier iterations,
    ``radiance_cache.cache_levels``). empty :
    the previous iteration is the empty cache (the first iteration; ``cache_texture`` is any
    of the cache's texels, not read but its header). level : the same iteration's first pass,
    which the glossy shares of the hits' weights read (``radiance_cache.relax``; None: they
    read ``cache_texture``). With ``keep`` the first part's .a is 1 + the faces'
    ``radiance_cache.one_more_bounce``. Nothing is read back or built on the CPU between
    iterations. Returns ``out``."""
    shader = _relax_shader()
    shader.bind()
    for name, texture in zip(_RELAX_SAMPLERS, (places, cache_texture, *records,
                                               cache_texture if level is None else level)):
        shader.uniform_sampler(name, texture)
    shader.uniform_float("sampling", (float(rays), float(keep), float(count), float(empty)))
    shader.uniform_float("levels", (float(level is not None), float(copy[1] if copy else 0),
                                    0.0, 0.0))
    shader.image("out_image", out)
    shader.image("copy_image", copy[0] if copy else out)
    gpu.compute.dispatch(shader, math.ceil(places.width / LOCAL_SIZE),
                         math.ceil(places.height / LOCAL_SIZE), 1)
    return out


_LAYOUT: dict = {}  # the last cache_layout: (its key, the layout)
_AHEAD: dict = {}   # key → (the thread making that layout, its error if it failed)


def _layout_key(tris, settings) -> tuple:
    return (triangles_key(tris), settings.cache_resolution, settings.cache_rays,
            settings.cache_focus, settings.cache_nest_rays)


def cache_layout(tris, settings, key=None):
    """The CPU half of ``cache_stages`` (numpy only, any thread: the viewport makes it on its
    preparing thread): (the cache's voxels ``build_cache``, its face points and axes
    ``face_points``, its layout texels ``cache_texels(layout=True, ahead=True)``) for ``tris``
    (``SceneTriangles``). Kept for the next call with the same triangles (by content) and
    cache settings: an edit of the lights, the materials or the world, or the Bounces, lays
    nothing out again (docs/gi_pipeline.md "Multi-bounce radiance cache", "What the cache
    costs after the picks"). One made ahead (``cache_layout_ahead``) is waited for. key :
    ``_layout_key(tris, settings)`` when the caller has it (it hashes every triangle)."""
    key = key or _layout_key(tris, settings)
    ahead = _AHEAD.get(key)
    if ahead is not None and ahead[0] is not threading.current_thread():
        ahead[0].join()
        _AHEAD.pop(key, None)
        if "error" in ahead[1]:  # what failed there is raised here, not made again
            raise ahead[1]["error"]
    held = _LAYOUT.get("entry")
    if held is not None and held[0] == key:
        return held[1]
    cache = build_cache(tris, settings.cache_resolution, rays=settings.cache_rays,
                        focus=settings.cache_focus, nest_rays=settings.cache_nest_rays)
    points, axes = face_points(cache)
    layout = (cache, points, axes,
              cache_texels(cache, layout=True, ahead=True) if len(points) else None)
    _LAYOUT["entry"] = (key, layout)
    return layout


def cache_layout_ahead(tris, settings) -> None:
    """Start ``cache_layout(tris, settings)`` on a thread of its own, unless it is made or
    being made: F12's first preview of a scene calls this as soon as its triangles are
    known, so the layout (its voxels and face points, 0.5–1.4 s of numpy on a 0.1–1 M-triangle
    scene) is made while the main thread builds the BVH (numpy releases the GIL in both; the
    layout's last step, the faces' backs in solids, traces that BVH: ``bvh_of`` waits for
    it), not after it. The radiance cache's stage then takes it (``cache_layout``)."""
    key = _layout_key(tris, settings)
    held = _LAYOUT.get("entry")
    if (held is not None and held[0] == key) or key in _AHEAD:
        return

    outcome: dict = {}

    def make():
        try:
            cache_layout(tris, settings, key)
        except Exception as error:  # noqa: BLE001 - raised by the stage's ``cache_layout``
            outcome["error"] = error

    thread = threading.Thread(target=make, name="VoxGI cache layout", daemon=True)
    _AHEAD[key] = (thread, outcome)
    thread.start()


def cache_stages(bvh, lights, principled, emission, settings, tables=None,
                 budget: float = CACHE_STAGE_SECONDS, first_rows: int = 1,
                 read_back: bool = True, layout=None):
    """Generator of the radiance cache of ``settings.bounces`` − 1 iterations, yielding after
    each stage; returns (cache, texture). As numpy's ``radiance_cache.cached_cache``: every
    voxel face's ``settings.cache_rays`` rays (``face_points``, sample id = the face's row,
    seed 0) are traced and lit once (``cache_paths.glsl``, records ``RECORD_WIDTH`` to a row,
    in chunks of rows that start at ``first_rows`` and are resized to ``budget`` seconds by
    the last one's time: the viewport's stages, ``viewport_cache``), then each iteration is two
    lookup passes over the records writing the next cache texture (``relax_gpu``; the
    second's glossy shares read the first's faces, ``radiance_cache.relax``); the faces
    are read back once, at the end — or, read_back False (the viewport, whose Accurate
    gathers read the texture only), the cache is returned as a function that reads them
    back when called (Fast's voxels reflect the numpy cache). The texture also holds the next
    iteration, for the faces' one-more-bounce ratio (``radiance_cache.one_more_bounce``; two
    more lookup passes, the last ``relax_gpu(keep=True)``). layout : ``cache_layout`` of the BVH's triangles made
    already (None: made here)."""
    cache, points, axes, texels = layout or cache_layout(bvh.scene_triangles, settings)
    count = len(points)
    if count == 0:  # nothing to light
        cache = with_faces(cache, np.zeros((0, 3)))
        texels = cache_texels(cache)
        return (cache if read_back else lambda: cache), \
            float_texture(texels, (texels.shape[1], texels.shape[0]))
    width = CACHE_IMAGE_WIDTH
    height = -(-count // width)
    faces = np.zeros((2, height * width, 4), np.float32)
    faces[0, :count, :3], faces[0, :count, 3] = points, 1.0
    faces[1, :count, :3] = axes
    inputs = {**bvh.inputs, **(tables if tables is not None else gather_tables(
        lights, principled, emission)),
              "gbuffer_position": float_texture(faces[0].reshape(height, width, 4),
                                                (width, height)),
              "gbuffer_normal": float_texture(faces[1].reshape(height, width, 4),
                                              (width, height))}
    if "texture_atlas" not in inputs:
        inputs.update(no_texture_inputs())
    rays = settings.cache_rays
    record_rows = -(-count * rays // RECORD_WIDTH)
    records = tuple(gpu.types.GPUTexture((RECORD_WIDTH, record_rows), format="RGBA32F")
                    for _ in range(2))
    # the iterations' texels: three of the first part alone in turn (the previous iteration,
    # the next one's first pass, the next one), then the two parts; each holds the layout's
    # header, voxel ids and absent faces, uploaded once, and a relaxation writes its faces'
    # texels only (a dispatch over the faces). The first is also what the rays' hits pick
    # their faces in (its ids and the faces each voxel holds).
    main = cache_texels(cache, layout=True)
    turns = [float_texture(main, (main.shape[1], main.shape[0])) for _ in range(3)]
    inputs["radiance_cache"] = turns[0]
    constants = {"sampling": (0.0, rays, count, strata_side(settings.hit_samples)),
                 "world": (*settings.world, float(settings.hit_glossy))}
    top, rows = 0, max(1, int(first_rows))
    while top < record_rows:
        t0 = time.perf_counter()
        end = min(record_rows, top + rows)
        dispatch_bvh("bvh_cache_paths", inputs, RECORD_WIDTH, end - top,
                     {**constants, "chunk": (top, end, 0.0, 0.0)}, images=records)
        seconds = time.perf_counter() - t0
        top = end
        # the next chunk at CHUNK_AIM of the budget by this one's time, at most twice its
        # rows: a chunk's rays cost more or less by where its faces lie, and the viewport's
        # other threads share the cores (chunks aimed at the whole budget and grown 4× at a
        # time took 23–42 ms, the draw over its 30 ms)
        rows = max(1, min(record_rows, int(rows * min(CHUNK_GROWTH, CHUNK_AIM * budget /
                                                      max(seconds, 1e-4)))))
        yield
    places = face_places(cache)
    yield

    # the cache the gathers read: its layout's texels (the header, the ids) with ``bounces``
    # parts of faces — the last iteration, the one ahead, the earlier ones latest first
    # (radiance_cache.cache_levels: each written there as it is made)
    parts = max(settings.bounces, 2)  # (one bounce with glossy chains: the empty one, ahead)
    rows = 1 + len(cache.grids) * cache.grids[0].resolution + \
        -(-(parts * int(cache.voxel_count) * 6) // texels.shape[1])
    levels = np.zeros((max(rows, texels.shape[0]), texels.shape[1], 4), np.float32)
    levels[:texels.shape[0]] = texels
    levels[0, -1, 2] = 2 * (settings.bounces - 1) + 1  # iterations, all parts (cache_texels)
    both = float_texture(levels, (levels.shape[1], levels.shape[0]))

    def iteration(previous, out, empty: bool, keep: bool = False, part: int = 0):
        # two passes: the second's glossy shares read the first's faces (radiance_cache.relax's
        # ``level``), the first written in a turn that is neither ``previous`` nor ``out``
        spare = next(t for t in turns if t is not previous and t is not out)
        estimate = relax_gpu(places, previous, records, rays, count, spare, empty=empty)
        yield
        return relax_gpu(places, previous, records, rays, count, out, keep=keep, empty=empty,
                         level=estimate, copy=(both, part) if part else None)

    previous = turns[0]  # the empty cache: its texels not read (relax_gpu empty)
    for k in range(settings.bounces - 1):  # iteration k + 1, kept in part bounces − k − 1
        out = next(t for t in turns if t is not previous)
        part = settings.bounces - k - 1
        previous = yield from iteration(previous, out, empty=k == 0, part=part if part >= 2 else 0)
        yield
    previous = yield from iteration(previous, both, empty=settings.bounces == 1,
                                    keep=True)  # + glossy's
    yield
    def faces():  # the numpy cache with its faces, read back once
        held = read_texture(previous)
        values = with_faces(cache, held[texel_places(cache)][:, :3])
        return replace(values, iterations=settings.bounces - 1,
                       ahead=with_faces(cache, held[texel_places(cache, 1)][:, :3]).faces,
                       earlier=tuple(with_faces(cache, held[texel_places(cache, part)][:, :3])
                                     .faces for part in range(2, settings.bounces)))
    return (faces() if read_back else faces), previous


def gather_tables(lights, principled, emission) -> dict:
    """The light and material textures a gather binds (``gather``'s ``tables``)."""
    return {"lights": lights_texture(lights), **scene_light_textures(lights),
            "materials": principled_materials_texture(principled, emission),
            "principled_lut": lut_texture()}


def cache_texture(bvh: GPUBVH, lights, principled, emission, settings, tables=None):
    """The texture of the radiance cache the diffuse gather reads at its bounce hits for
    ``settings.bounces`` (``cache_gpu``), kept for the next gather with the same triangles,
    lights, materials and cache settings — or the one a Rendered view built for them
    (``shared_cache``)."""
    key = cache_key(lights, principled, emission, *cache_settings(settings))
    # the BVH's node texture is replaced whenever other triangles are uploaded (the same
    # triangles snapshotted again keep it: a viewport slice's)
    held = shared_cache(bvh.nodes, key)
    if held is None:
        held = cache_gpu(bvh, lights, principled, emission, settings, tables)
        share_cache(bvh.nodes, key, *held)
    return held[1]


# Ray traversals (a bounce ray or a shadow ray) one gather invocation may make per dispatch.
# llvmpipe ends an invocation's loops after 65535 iterations in all (docs/blender_facts.md
# "llvmpipe's loop limit"); 32 traversals leave each one about 2000 loop iterations (BVH nodes
# and leaf triangles), several times what the test scenes' rays take (about 110).
TRAVERSALS_PER_DISPATCH = 32
LOOPS_PER_TRAVERSAL = 65535 // TRAVERSALS_PER_DISPATCH
# a lamp's pick weight: one iteration, and at a metal hit an area lamp's outline clipped
# (light_aim), a loop over its corners
PICK_LOOPS_PER_LAMP = 1 + MAX_OUTLINE


def rays_per_dispatch(lamps: int, others: int = 0, hit_samples: int = 1,
                      traversals: int = TRAVERSALS_PER_DISPATCH, followed: bool = False) -> int:
    """Bounce rays per gather dispatch: each ray traverses the BVH once and, at its hit, once
    per shadow sample of the one lamp it picks (``bvh_shade.glsl`` ray_paths: a hit traces one
    of the ``lamps``, picked by weight) and of each of the ``others`` (the world counts twice,
    its two techniques, the emitters once), ``traversals`` in all (at most
    ``TRAVERSALS_PER_DISPATCH``). The pick weighs every lamp twice, at most
    ``PICK_LOOPS_PER_LAMP`` loop iterations each: their share of the loop limit counts as
    traversals of ``LOOPS_PER_TRAVERSAL`` (one up to 15 lamps, two up to 31). Counting every lamp's
    shadow rays, as before the pick, split 27 lamps' 96 rays over 96 dispatches, each paying
    the kernel's set-up (docs/gi_pipeline.md "Many lamps").
    followed : a ray may be followed past near hits (the diffuse gather's near field,
    ``exact_indirect.NEAR_FIELD``, ``MAX_FOLLOWS`` bounces at most): each bounce counted as
    one traversal more. Their light samples (one a light) are not counted: few rays are
    followed (5.5% of the box's, 2–3% of the hall's and the emissive room's, numpy at 48 × 36),
    counting them made the box's preview 15% slower in dispatches, and a point whose every ray
    is followed still makes under 2 × the count, within the loop limit's margin
    (``TRAVERSALS_PER_DISPATCH``)."""
    picks = -(-2 * PICK_LOOPS_PER_LAMP * lamps // LOOPS_PER_TRAVERSAL) if lamps > 1 else 0
    per_ray = 1 + max(min(lamps, 1) + others, 1) * strata_side(hit_samples) ** 2 + picks + \
        (MAX_FOLLOWS if followed else 0)
    return max(1, min(traversals, TRAVERSALS_PER_DISPATCH) // per_ray)


def gather(*args, **kwargs):
    """``gather_steps`` run to its end: the raw gather's (values, variance[, hidden]) textures."""
    return finish(gather_steps(*args, **kwargs))


def gather_steps(bvh: GPUBVH, gbuffer_inputs, lights, principled, emission, settings,
                 stride: int, width: int, height: int, kernel: str = "bvh_gather",
                 world_mode: bool = False, tables=None, cache=None,
                 traversals: int = TRAVERSALS_PER_DISPATCH, lattice: bool = False,
                 sun_apart: bool = False):
    """The raw gather, a generator yielding between its dispatches and returning (values,
    variance) RGBA32F textures of the low-resolution grid — and for "bvh_gather" a third, the
    world's rest hidden from each point (``bvh_gather.glsl`` out_hidden; ``sun_apart``: a
    map's sun left out of it, as the pixels that trace it apart): the rays split over dispatches of
    ``rays_per_dispatch`` (``traversals`` per invocation at most: the viewport's slices take
    fewer, so that a dispatch over a larger tile stays within a stage's budget; the same rays
    whatever the split). kernel : "bvh_gather" (Diffuse
    Indirect and AO, ``settings.rays``) or "bvh_glossy" (Glossy Indirect,
    ``settings.glossy_rays``).
    principled : (base, params) of ``preview.passes.principled_table``;
    settings : ``voxgi_addon.preview.gather.GatherSettings``; world_mode : "bvh_glossy"
    gathers the world's Glossy Direct instead (``exact_glossy.glossy_world_direct``).
    tables : the light and material textures of ``lights``, ``principled`` and ``emission``
    made already (``gpu_scene.GPUScene.gather_tables``); None: made here.
    cache : the radiance cache texture the bounce hits read (``cache_texels``); None: the
    ``cache_texture`` of ``settings.bounces`` (none for one bounce and in ``world_mode``).
    lattice : only the lattice of the grid's cells — odd row, odd column from the top-left,
    clamped to the last row and column (``sparse_gather.sparse_plan``'s first list, which
    needs no G-buffer): the textures are that lattice's (``low_shape`` of the grid's shape at
    stride 2), cell (i, j) the grid's cell (2 i + 1, 2 j + 1) (``gather_point.glsl``)."""
    low_h, low_w = low_shape(height, width, stride)
    if lattice:
        low_h, low_w = low_shape(low_h, low_w, 2)
    placeholder = gpu.types.GPUTexture((size_like(1, low_w), size_like(1, low_h)),
                                       format="RGBA32F")  # the partials' JIT class
    outputs = OUTPUTS[kernel]
    partial = (placeholder,) * len(outputs)
    if tables is None:
        tables = gather_tables(lights, principled, emission)
    inputs = {**bvh.inputs, **gbuffer_inputs, **tables}
    if "texture_atlas" not in inputs:
        inputs.update(no_texture_inputs())
    if cache is not None:
        inputs["radiance_cache"] = cache
    elif uses_cache(settings) and not world_mode:  # bounces 2 … N from the cache
        inputs["radiance_cache"] = cache_texture(bvh, lights, principled, emission, settings,
                                                 tables)
    assert outputs[:2] == ("out_image", "out_variance")
    rays = settings.rays if kernel == "bvh_gather" else settings.glossy_rays
    # metals take METAL_RAY_FACTOR × the glossy rays (exact_glossy.glossy_indirect): the
    # dispatches run to their count when the scene has one
    last = rays
    if kernel == "bvh_glossy" and not world_mode and np.max(principled[1][:, 0]) >= 0.5:
        last = rays * METAL_RAY_FACTOR
    # at a bounce hit the emitters draw one shadow ray per stratum, like a lamp (their plain
    # estimate, emitters.EmitterLight.exact = False), the world two (one per technique)
    worlds = sum(light.type == "WORLD" for light in lights)
    lamps = sum(light.type not in ("WORLD", "EMITTERS") for light in lights)
    step = rays_per_dispatch(lamps, len(lights) - lamps + worlds, settings.hit_samples,
                             traversals,
                             followed=kernel == "bvh_gather" and "radiance_cache" in inputs)
    for first in range(0, max(last, 1), step):
        if first > 0:
            yield
        partial = dispatch_bvh(kernel, {
            **inputs, **{name.replace("out_", "partial_"): texture
                         for name, texture in zip(outputs, partial)}}, low_w, low_h, {
            "sampling": (settings.seed, rays, settings.ao_distance,
                         strata_side(settings.hit_samples)),
            "world": (*settings.world, float(settings.hit_glossy)),
            # flags (gather_point.glsl): 1 world mode, 2 the lattice, 4 the map's sun apart
            "grid": (stride, width, height,
                     float(world_mode) + (2.0 if lattice else 0.0) + (4.0 if sun_apart else 0.0)),
            "chunk": (first, step, float(first > 0), float(first + step >= last))})
    return partial


def upsample(values, gbuffer_inputs, stride: int, width: int, height: int, second=None):
    """The joint-bilateral upsample (``shaders/upsample.glsl``) of a low-resolution texture to
    the full width × height (the texture itself for stride 1). With ``second`` (another
    low-resolution texture of the same grid) both are upsampled in one dispatch with the same
    weights and a pair of textures comes back."""
    if stride == 1:
        return values if second is None else (values, second)
    pair = second is not None
    samplers = _UPSAMPLE_SAMPLERS + (("low_image2",) if pair else ())
    outputs = ("out_image", "out_image2") if pair else ("out_image",)
    shader = _upsample_shader(pair)
    out = [gpu.types.GPUTexture((width, height), format="RGBA32F") for _ in outputs]
    inputs = {**gbuffer_inputs, "low_image": values, "low_image2": second}
    shader.bind()
    for name in samplers:
        shader.uniform_sampler(name, inputs[name])
    shader.uniform_float("sampling", (float(stride), float(width), float(height), 0.0))
    for name, texture in zip(outputs, out):
        shader.image(name, texture)
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)
    return tuple(out) if pair else out[0]


_FIELD_SAMPLERS = _UPSAMPLE_SAMPLERS + ("low_image2",)
_LIST_SAMPLERS = _FIELD_SAMPLERS + ("pixels", "point_position", "point_normal")
# UPSAMPLE_TERMS's: the centres' material (same_surface.glsl), the sample's, the gathers' low
# and full-resolution textures
_TERMS_SAMPLERS = ("gbuffer_view", "point_view", "low_diffuse", "low_glossy", "low_world",
                   "full_diffuse", "full_glossy", "full_world")
_TERMS_OUTPUTS = ("out_diffuse", "out_glossy", "out_world")


def upsample_field(glossy, diffuse, gbuffer_inputs, stride: int, width: int, height: int, eye):
    """The emitters' light from the gather points to every pixel (``shaders/upsample.glsl``
    UPSAMPLE_FIELD; docs/gi_pipeline.md "Where a preview's time goes"): (glossy, diffuse)
    full-resolution textures of ``glossy`` (``gpu_bvh.emitter_glossy_texture``'s field: the
    unshadowed light over the Glossy Color) and ``diffuse`` (``emitters_unshadowed_texture``:
    the unshadowed sum, the distance to the emitters) at the gather points, each with w = how
    far the light's direction turns across the taps (−1: no tap; 0 at stride 1, every pixel's
    own). eye : (camera position, 1), or zeros for an orthographic camera."""
    return _field(_FIELD_SAMPLERS, {**gbuffer_inputs, "low_image": glossy,
                                    "low_image2": diffuse}, stride, width, height, eye,
                  (width, height))


def upsample_field_list(glossy, diffuse, gbuffer_inputs, points, pixels, size, stride: int,
                        width: int, height: int, eye, offset, terms=None):
    """``upsample_field`` at one sub-pixel pass's points over the edge pixels' list
    (UPSAMPLE_LIST): points = the pass's compacted G-buffer ({"gbuffer_position",
    "gbuffer_normal", "gbuffer_view"} of ``size``), pixels = the list
    (``gpu_preview._pixel_list``), offset = the pass's (x right, y down, pixels); the taps are
    the pixel centres' ``gbuffer_inputs``.
    terms : ((low (Diffuse Indirect, AO), low Glossy Indirect, low world glossy light), the
    same upsampled to the centres) — the gathers' textures — to bring them to the pass's
    samples in the same dispatch (UPSAMPLE_TERMS; docs/gi_pipeline.md "Anti-aliasing"): the
    centre's where the sample sees its centre's surface or no gather point fits, else the
    gathers at the sample's own point. Then returns (the three terms at the samples, glossy,
    diffuse), the field's two None when ``glossy`` is None (no emitters: no field)."""
    inputs = {**gbuffer_inputs, "low_image": glossy, "low_image2": diffuse, "pixels": pixels,
              "point_position": points["gbuffer_position"],
              "point_normal": points["gbuffer_normal"]}
    if terms is None:
        return _field(_LIST_SAMPLERS, inputs, stride, width, height, eye, size, offset)
    field = glossy is not None
    inputs.update({"point_view": points["gbuffer_view"],
                   **dict(zip(_TERMS_SAMPLERS[2:], (*terms[0], *terms[1])))})
    samplers = (_LIST_SAMPLERS if field else
                tuple(name for name in _LIST_SAMPLERS if not name.startswith("low_image")))
    out = _field(samplers + _TERMS_SAMPLERS, inputs, stride, width, height, eye, size, offset,
                 terms=True, field=field)
    return (*out[-3:], *(out[:2] if field else (None, None)))


def _field_shader(listed: bool, terms: bool = False, field: bool = True):
    """The compiled ``upsample.glsl`` of ``upsample_field`` (``listed``: of
    ``upsample_field_list``; ``terms``: with the gathered terms, ``field``: and the emitters'
    field)."""
    key = "upsample_field_list" if listed else "upsample_field"
    if terms:
        key = "upsample_terms_list" + ("_field" if field else "")
    if key not in _shaders:
        defines = {"UPSAMPLE_PAIR": "1", "UPSAMPLE_FIELD": "1"} if field else {}
        samplers = _LIST_SAMPLERS if listed else _FIELD_SAMPLERS
        outputs = ("out_image", "out_image2") if field else ()
        files = ("pixels", "upsample")
        if listed:
            defines["UPSAMPLE_LIST"] = "1"
        if terms:
            defines.update({"UPSAMPLE_TERMS": "1", "PLANE_TOLERANCE": repr(float(PLANE_TOLERANCE)),
                            "centre_position": "gbuffer_position",
                            "centre_normal": "gbuffer_normal", "centre_view": "gbuffer_view"})
            if not field:
                samplers = tuple(name for name in samplers if not name.startswith("low_image"))
            samplers += _TERMS_SAMPLERS
            outputs += _TERMS_OUTPUTS
            files = ("pixels", "same_surface", "upsample")
        _shaders[key] = build_compute(files, samplers,
                                      ("sampling",) + (("eye",) if field else ())
                                      + (("shift",) if listed else ()),
                                      outputs, defines, name=key)
    return _shaders[key]


def _field(samplers, inputs, stride, width, height, eye, size, offset=None, terms=False,
           field=True):
    listed = offset is not None
    shader = _field_shader(listed, terms, field)
    outputs = (("out_image", "out_image2") if field else ()) + (_TERMS_OUTPUTS if terms else ())
    out = [gpu.types.GPUTexture(size, format="RGBA32F") for _ in outputs]
    shader.bind()
    for name in samplers:
        shader.uniform_sampler(name, inputs[name])
    shader.uniform_float("sampling", (float(stride), float(width), float(height), 0.0))
    if field:  # (only the field reads the camera's position)
        shader.uniform_float("eye", tuple(float(v) for v in eye))
    if listed:
        shader.uniform_float("shift", (float(offset[0]), float(offset[1]), 0.0, 0.0))
    for name, texture in zip(outputs, out):
        shader.image(name, texture)
    gpu.compute.dispatch(shader, math.ceil(size[0] / LOCAL_SIZE), math.ceil(size[1] / LOCAL_SIZE),
                         1)
    return tuple(out)


def _upsample_shader(pair: bool):
    key = "upsample_pair" if pair else "upsample"
    if key not in _shaders:
        samplers = _UPSAMPLE_SAMPLERS + (("low_image2",) if pair else ())
        outputs = ("out_image", "out_image2") if pair else ("out_image",)
        _shaders[key] = build_compute(("pixels", "upsample"), samplers, ("sampling",), outputs,
                                      {"UPSAMPLE_PAIR": "1"} if pair else None, name=key)
    return _shaders[key]


def gather_low(bvh: GPUBVH, gbuffer_inputs, lights, principled, emission, settings, stride: int,
               width: int, height: int, kernel: str = "bvh_gather", world_mode: bool = False,
               tables=None):
    """The gather's low-resolution result after the à-trous filter (not upsampled): (Diffuse
    Indirect rgb, AO) for "bvh_gather", (Glossy Indirect rgb, 0) for "bvh_glossy", (the world's
    Glossy Direct rgb, 0) for "bvh_glossy" in ``world_mode``; tables : as ``gather``'s."""
    values, variance = gather(bvh, gbuffer_inputs, lights, principled, emission, settings,
                              stride, width, height, kernel=kernel, world_mode=world_mode,
                              tables=tables)[:2]
    if kernel != "bvh_gather":  # a glossy gather's spikes spread first
        values, variance = spread_spikes(values, variance, gbuffer_inputs, stride, width, height)
    values, _ = denoise(values, variance, gbuffer_inputs, stride, width, height,
                        settings.denoise_iterations, fit=kernel == "bvh_gather",
                        sigma=SIGMA_LUMINANCE if kernel == "bvh_gather" else GLOSSY_SIGMA_LUMINANCE)
    return values


def gather_gi(bvh: GPUBVH, gbuffer_inputs, lights, principled, emission, settings, stride: int,
              width: int, height: int):
    """Full-resolution RGBA32F texture (Diffuse Indirect rgb, AO), bottom row first: gather,
    filter, upsample."""
    values = gather_low(bvh, gbuffer_inputs, lights, principled, emission, settings, stride,
                        width, height)
    return upsample(values, gbuffer_inputs, stride, width, height)


def glossy_gi(bvh: GPUBVH, gbuffer_inputs, lights, principled, emission, settings, stride: int,
              width: int, height: int):
    """Full-resolution RGBA32F texture (Glossy Indirect rgb, 0), bottom row first: the glossy
    gather (``shaders/bvh_glossy.glsl``), the same filter and upsample as ``gather_gi``."""
    values = gather_low(bvh, gbuffer_inputs, lights, principled, emission, settings, stride,
                        width, height, kernel="bvh_glossy")
    return upsample(values, gbuffer_inputs, stride, width, height)


_GLOSSY_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "gbuffer_view", "gbuffer_base",
                    "direct_image", "lights", "materials", "principled_lut", "ltc_table")


def glossy_direct_texture(gbuffer_inputs, direct, lights_texture_, light_index: int, principled,
                          emission, materials=None, map_sun: bool = False):
    """The glossy light light ``light_index`` sends to the viewer over the G-buffer
    (``shaders/glossy_direct.glsl``, the port of ``preview.passes.glossy_direct_radiance``);
    direct : that light's Diffuse Direct texture; an RGBA32F texture (bottom row first).
    materials : the ``principled_materials_texture`` of ``principled`` and ``emission`` made
    already (None: made here). map_sun : the lamp is the world map's sun
    (``world_light.sun_lamp``): 0 on mirrors (``passes.map_sun_shine``)."""
    shader = _glossy_shader()
    out = gpu.types.GPUTexture((direct.width, direct.height), format="RGBA32F")
    inputs = {**gbuffer_inputs, "direct_image": direct, "lights": lights_texture_,
              "materials": materials if materials is not None else
              principled_materials_texture(principled, emission),
              "principled_lut": lut_texture(), "ltc_table": ltc_texture()}
    shader.bind()
    for name in _GLOSSY_SAMPLERS:
        shader.uniform_sampler(name, inputs[name])
    shader.uniform_float("light", (float(light_index), 1.0 if map_sun else 0.0, 0.0, 0.0))
    shader.image("out_image", out)
    gpu.compute.dispatch(shader, math.ceil(direct.width / LOCAL_SIZE),
                         math.ceil(direct.height / LOCAL_SIZE), 1)
    return out


def _glossy_shader():
    if "glossy" not in _shaders:
        defines = {**PRINCIPLED_DEFINES, **LTC_DEFINES, "HORIZON_LIFT": repr(float(HORIZON_LIFT)),
                   "AREA_GLOSSY_GRID": str(AREA_GLOSSY_GRID), "LTC_FROM": repr(float(LTC_FROM)),
                   "LTC_FULL": repr(float(LTC_FULL)),
                   "DISC_FROM": repr(float(DISC_FROM)), "DISC_FULL": repr(float(DISC_FULL)),
                   "DISC_SIDES": str(DISC_SIDES), "DISC_WIDEST": repr(float(DISC_WIDEST))}
        _shaders["glossy"] = build_compute(("sampling", "principled", "light_outline", "ltc",
                                            "glossy_ltc", "glossy_direct"),
                                           _GLOSSY_SAMPLERS, ("light",), ("out_image",), defines)
    return _shaders["glossy"]


def release() -> None:
    """Drop the cached shaders, the cache's texture and its layout (docs/gi_pipeline.md, "GPU
    resources at exit")."""
    forget(_shaders)
    _shared.clear()
    _LAYOUT.clear()
