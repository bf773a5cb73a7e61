"""One pass of the GPU tracer's composition over a G-buffer: the surfaces' colours, the
gathered terms and every light's direct and glossy light summed into textures
(``shaders/aa_surface.glsl``, ``aa_light.glsl``; the readable reference:
``voxgi_addon/preview/passes.accumulate_pass``). Accurate's passes (``gpu_preview``) run it
over the pixel centres and each sub-pixel pass; Fast quality's viewport slices over its cones'
terms (``gpu_fast.fast_sums``), so their frame stays on the GPU too. Needs a GPU context.
"""
from __future__ import annotations

import math

import gpu

from ..voxgi_addon.gi.direct_light import world_block
from ..voxgi_addon.preview.resolve import LEAST_CENTRES, LEAST_COLOUR
from ..voxgi_addon.preview.upsample import PLANE_TOLERANCE
from .gpu_bvh import direct_light_texture
from .gpu_gather import glossy_direct_texture
from .gpu_principled import DEFINES as PRINCIPLED_DEFINES
from .gpu_shaders import LOCAL_SIZE, build_compute, forget

# The sums of preview.passes.accumulate_pass as textures: name → (texture, channels) where
# channels name what its rgb and alpha hold (see shaders/aa_surface.glsl).
SURFACE_SUMS = ("a", "b", "c", "d", "e", "f")
SURFACE_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "gbuffer_view", "gbuffer_base",
                     "centre_diffuse",
                     "centre_glossy", "centre_world", "materials", "principled_lut",
                     *(f"sum_{k}" for k in SURFACE_SUMS))
LIGHT_SAMPLERS = ("colour", "direct_image", "shine_image", "sum_f", "sum_g")
MASK_SAMPLERS = ("gbuffer_position", "pixels")
COMPACT_SAMPLERS = ("gbuffer_position", "gbuffer_normal", "gbuffer_view", "pixels")
RESOLVE_SAMPLERS = (*COMPACT_SAMPLERS, "centre_position", "centre_normal", "centre_view",
                    "centre_base", *(f"sum_{k}" for k in (*SURFACE_SUMS, "g")), "offsets",
                    "gbuffer_base", "materials", "principled_lut")
RESOLVE_OUTPUTS = tuple(f"out_{k}" for k in (*SURFACE_SUMS, "g"))
WORLD_GIVEN_SAMPLERS = ("world_map", "gbuffer_position", "gbuffer_normal", "world_hidden")
_aa_shaders: dict[str, object] = {}


def _aa_shader(kernel: str):
    if kernel not in _aa_shaders:
        if kernel == "aa_surface":
            _aa_shaders[kernel] = build_compute(
                ("principled", "surface", "aa_surface"), SURFACE_SAMPLERS, (),
                (*(f"out_{k}" for k in SURFACE_SUMS), "out_colour"), PRINCIPLED_DEFINES)
        elif kernel in ("aa_list", "aa_list_raw"):
            _aa_shaders[kernel] = build_compute(
                ("aa_compact",), COMPACT_SAMPLERS, (), ("out_position", "out_normal", "out_view"),
                {"RAW": "1"} if kernel == "aa_list_raw" else None)
        elif kernel == "aa_resolve":
            _aa_shaders[kernel] = build_compute(
                ("principled", "surface", "aa_resolve"), RESOLVE_SAMPLERS, ("resolve",),
                RESOLVE_OUTPUTS, {**PRINCIPLED_DEFINES,
                                  "PLANE_TOLERANCE": repr(float(PLANE_TOLERANCE)),
                                  "LEAST_CENTRES": str(LEAST_CENTRES),
                                  "LEAST_COLOUR": repr(float(LEAST_COLOUR))})
        elif kernel == "world_given":
            _aa_shaders[kernel] = build_compute(("sampling", "world_map", "world_given"),
                                                WORLD_GIVEN_SAMPLERS, (), ("out_image",))
        elif kernel == "aa_mask":
            _aa_shaders[kernel] = build_compute(("aa_mask",), MASK_SAMPLERS, (),
                                                ("out_position",))
        else:
            _aa_shaders[kernel] = build_compute(("aa_light",), LIGHT_SAMPLERS, (),
                                                ("out_f", "out_g"))
    return _aa_shaders[kernel]


def run(kernel, samplers, inputs, outputs, width, height, constants=None, over=None):
    """Dispatch ``kernel`` over width × height (``constants``: its push constants by name, 4
    floats each); returns its new output textures by name, of that size. over : (w, h) the
    invocations when they are fewer than the outputs' texels (a kernel writing several rows
    of outputs per invocation)."""
    shader = _aa_shader(kernel)
    images = {name: gpu.types.GPUTexture((width, height), format="RGBA32F") for name in outputs}
    width, height = over or (width, height)
    shader.bind()
    for name, value in (constants or {}).items():
        shader.uniform_float(name, value)
    for name in samplers:
        shader.uniform_sampler(name, inputs[name])
    for name, image in images.items():
        shader.image(name, image)
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)
    return images


def release() -> None:
    """Drop the cached composition shaders."""
    forget(_aa_shaders)


def shade_stages(scene, snapshot, inputs, sums, terms, blank, size, light_samples: int,
                 seed: int, block=None, lamps=None, glow=None, centre=None, field=None,
                 lamp_glossy: bool = True, smooth=None, world_strata: int = 0, world_fewer=None,
                 sun_glossy: bool = False, world_hidden=None):
    """(Stages, one per light's dispatches, returning) ``sums`` + one pass over ``inputs``, a
    G-buffer of ``size`` (an image's or the edge pixels' list's) of ``scene`` (a ``GPUScene``
    updated to ``snapshot``): terms = the gathered (Diffuse Indirect, AO), Glossy Indirect and
    world glossy light at the same texels; blank : zeros of ``size``; block : the shadow
    rays' strata block (``direct_light_texture``; None: all).
    lamps : a dict that gets the lamps' sum_g texture before the world's and emitters'
    dispatch adds to it, when it does (their sum_f is the final one: that dispatch adds no
    glossy light), for light_edge_pixels.
    glow : the emitters' glossy light at the pass's texels (``gpu_bvh.emitter_glossy_texture``),
    which the world's and emitters' dispatch adds; None: none (Fast's glossy cones see the
    emission themselves). centre : the pass's pixel centres with the emitters'
    unshadowed field there, for that dispatch (``direct_light_texture``'s; None: it evaluates
    the sum at every texel); field : the field at the pass's own points
    (``direct_light_texture``'s). lamp_glossy : the lamps' glossy light
    (``glossy_direct_texture``); False: none (the viewport's first coarse image, before that
    kernel is compiled: docs/gi_pipeline.md "Entering Rendered mode"). smooth : filters the
    world's and emitters' Diffuse Direct texture (rgb, the world's part's variance) of a whole
    image before it is added (F12's centre pass: docs/gi_pipeline.md "The world's light
    filtered"); None: added as traced. world_strata, world_fewer : the side of the world's
    strata and the texels that take it (``direct_light_texture``'s; 0: the lamps').
    sun_glossy : the map's sun in the pixels' glossy lobes (``scene.sun_table``, a sun lamp
    traced for them alone: its Diffuse Direct is the world's dispatch's;
    ``passes.map_sun_shine``), as the world's glossy gather leaves it out. world_hidden : the
    rest of the world map's hidden part at every texel, from the gather points
    (``direct_light_texture``'s; F12's centre pass); None: the texels trace it."""
    bvh, principled, emission = scene.bvh, scene.principled, scene.emission
    materials, lut = scene.materials, scene.lut
    extra = scene.has_scene_lights
    out = run("aa_surface", SURFACE_SAMPLERS, {
        **inputs, **sums, "centre_diffuse": terms[0], "centre_glossy": terms[1],
        "centre_world": terms[2], "materials": materials, "principled_lut": lut},
        (*(f"out_{k}" for k in SURFACE_SUMS), "out_colour"), *size)
    sums = {**sums, **{f"sum_{k}": out[f"out_{k}"] for k in SURFACE_SUMS}}
    colour = out["out_colour"]
    # Light by light: each lamp's light feeds the glossy lobe, and one dispatch stays within
    # llvmpipe's loop limit (docs/blender_facts.md "llvmpipe's loop limit"). Every dispatch
    # takes the scene's one variant (the code of all its kinds of light): a variant per lamp
    # kind cost a compile each and no time a dispatch (docs/gi_pipeline.md "One direct-light
    # variant per scene")
    absent = scene.direct_absent
    for table in scene.lamp_tables:  # (a lamp's table: its row alone, row 0)
        direct = direct_light_texture(bvh, inputs, snapshot.lights, light_samples, seed=seed,
                                      world=scene.no_world, emitters=scene.no_emitters,
                                      strata_block=block, table=table,
                                      absent=absent)
        shine = glossy_direct_texture(inputs, direct, table, 0, principled, emission,
                                      materials=materials) if lamp_glossy else blank
        out = run("aa_light", LIGHT_SAMPLERS, {
            "colour": colour, "direct_image": direct, "shine_image": shine, **sums},
            ("out_f", "out_g"), *size)
        sums["sum_f"], sums["sum_g"] = out["out_f"], out["out_g"]
        yield
    if lamps is not None and extra:
        lamps["sum_g"], lamps["sum_f"] = sums["sum_g"], sums["sum_f"]
    if extra and world_hidden is not None and not scene.traces_extra_rays:
        # the world's rest given and nothing else of that dispatch to trace: a kernel of its own
        # (world_given.glsl: bvh_direct's set-up alone costs more than this light)
        direct = run("world_given", WORLD_GIVEN_SAMPLERS, {
            **inputs, "world_map": scene.world_map, "world_hidden": world_hidden},
            ("out_image",), *size)["out_image"]
    elif extra:  # the world's and emitters' own dispatch (streams after the lamps)
        direct = direct_light_texture(bvh, inputs, snapshot.lights, light_samples, seed=seed,
                                      world=scene.world_map, emitters=scene.emitters,
                                      strata_block=world_block(block), table=scene.no_lamp,
                                      absent=absent,
                                      centre=centre, field=field, world_strata=world_strata,
                                      world_fewer=world_fewer, world_hidden=world_hidden,
                                      colour=colour if smooth is None else None)
    if extra:
        if smooth is not None:
            direct = smooth(direct)
        out = run("aa_light", LIGHT_SAMPLERS, {
            "colour": colour, "direct_image": direct,
            "shine_image": blank if glow is None else glow, **sums},
            ("out_f", "out_g"), *size)
        sums["sum_f"], sums["sum_g"] = out["out_f"], out["out_g"]
        yield
    if extra and sun_glossy and scene.sun_table is not None:
        direct = direct_light_texture(bvh, inputs, snapshot.lights, light_samples, seed=seed,
                                      world=scene.no_world, emitters=scene.no_emitters,
                                      strata_block=block, table=scene.sun_shadow_table,
                                      absent=absent)
        shine = glossy_direct_texture(inputs, direct, scene.sun_table, 0, principled, emission,
                                      materials=materials, map_sun=True)
        out = run("aa_light", LIGHT_SAMPLERS, {
            "colour": colour, "direct_image": blank, "shine_image": shine, **sums},
            ("out_f", "out_g"), *size)
        sums["sum_f"], sums["sum_g"] = out["out_f"], out["out_g"]
        yield
    return sums
