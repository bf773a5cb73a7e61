"""Exact ray casting on the GPU: the scene's BVH as textures and the kernels that trace it.

``GPUBVH`` uploads ``voxgi_addon.scene.bvh``'s packed textures (nodes, triangles, shading normals) and
keeps them while the triangles stay the same: ``update`` rebuilds only for another
``SceneTriangles`` whose corners, materials or normals differ from the uploaded ones
(``world_triangles`` makes a new object per preview, so identity alone would re-upload every
time). Kernels (``shaders/``, each prefixed with ``bvh_common.glsl``):

* ``bvh_probe`` — one ray per texel (closest hit, any hit) and the sample patterns (tests).
* ``bvh_direct`` — Diffuse Direct over a G-buffer, every light of the snapshot, shadow rays
  (``bvh_lights.glsl``, the port of ``direct_light.diffuse_direct``); or the emitters' exact
  unshadowed sum alone, which the preview evaluates at its gather points and brings to the
  pixels as a field (``gpu_gather.upsample_field``).
* ``bvh_emitter_glossy`` — the emitters' glossy light (``exact_glossy.emitters_shine``): its
  unshadowed field at the gather points, and from that field at the pixels.
* ``bvh_gather`` — the Accurate final gather: exact AO and the one-bounce diffuse-indirect
  estimate with their variances (``voxgi_addon.gi.exact_indirect``; run by ``gpu_gather``).
* ``bvh_glossy`` — the glossy gather: exact one-bounce Glossy Indirect and its variance
  (``voxgi_addon.gi.exact_glossy``; run by ``gpu_gather``).

Needs a GPU context.
"""
from __future__ import annotations

import math
import sys
import time

import gpu
import numpy as np

from ..voxgi_addon.gi.emitters import NEAR_STEP, emitter_table
from ..voxgi_addon.gi.exact_glossy import (
    EMITTER_GLOSSY_STREAM,
    GLOSSY_STREAM,
    HORIZON_LIFT,
    METAL_RAY_FACTOR,
    WORLD_GLOSSY_STREAM,
)
from ..voxgi_addon.gi.exact_indirect import (
    CONTINUE_STREAM,
    LAMP_PICK_FLOOR,
    LAMP_PICK_STREAM,
    LOBE_FOLLOW_STREAM,
    MAX_FOLLOWS,
    METAL_FOLLOWED,
    NEAR_FACING,
    NEAR_FIELD,
    NEAREST_HIT,
    RAY_STREAM,
    SURFACE_EPSILON,
)
from ..voxgi_addon.gi.radiance_cache import PICK_STREAM
from ..voxgi_addon.gi.surface_lookup import REACH as FIND_REACH
from ..voxgi_addon.gi.surface_lookup import TRUST
from ..voxgi_addon.gi.terminator import OFFSET as TERMINATOR_OFFSET
from ..voxgi_addon.gi.world_light import world_table
from ..voxgi_addon.preview.gather import VIEW_BACKOFF
from ..voxgi_addon.preview.light_table import LIGHT_TEXELS, light_table
from ..voxgi_addon.preview.upsample import PLANE_TOLERANCE
from ..voxgi_addon.scene.bvh import (
    DET_EPSILON,
    LEAF_BIAS,
    ORDERS,
    SHADOW_LAYOUT,
    TEXTURE_WIDTH,
    bvh_of,
    pack_bvh,
)
from ..voxgi_addon.scene.raycast import SHADOW_EPSILON
from ..voxgi_addon.scene.snapshot import RAY_ALL, RAY_CAMERA, RAY_DIFFUSE, RAY_GLOSSY, RAY_SHADOW
from ..voxgi_addon.scene.textures import CUTOUT_LAYERS, METALLIC_LEVELS, ROUGHNESS_LEVELS
from .gpu_ltc import DEFINES as LTC_DEFINES
from .gpu_ltc import ltc_texture
from .gpu_principled import DEFINES as PRINCIPLED_DEFINES
from .gpu_principled import lut_texture
from .gpu_shaders import LOCAL_SIZE, build_compute, forget, note_upload, size_like
from .gpu_tracer import read_texture
from .gpu_volume import float_texture

_BVH = ("bvh_nodes", "bvh_triangles")
# Kernel → (GLSL files after bvh_common.glsl, 2D samplers, VEC4 push constants).
# Cut-outs (textures.cutout_hits): kernels with textures.glsl trace through them.
_TEXTURES = ("texture_table", "texture_atlas")
KERNELS = {
    "bvh_probe": (("textures", "bvh_probe"), _BVH + ("ray_origin", "ray_direction") + _TEXTURES,
                  ("mode",)),
    "bvh_direct": (("textures", "light_outline", "world_map", "bvh_lights", "same_surface", "bvh_direct"),
                   _BVH + ("bvh_normals", "lights", "world_map", "emitters", "gbuffer_position",
                           "gbuffer_normal", "gbuffer_view", "centre_position", "centre_normal",
                           "centre_view", "centre_unshadowed", "emitter_field",
                           "world_fewer", "world_hidden", "diffuse_colour") + _TEXTURES,
                   ("sampling", "strata", "hidden", "shown")),
    "bvh_gather": (("pixels", "principled", "light_outline", "world_map", "bvh_lights", "textures",
                    "cache_lookup", "ltc", "glossy_ltc", "bvh_shade", "gather_point", "bvh_gather"),
                   _BVH + ("bvh_normals", "lights", "world_map", "emitters", "materials",
                           "gbuffer_position",
                           "gbuffer_normal", "gbuffer_view", "principled_lut", "partial_image",
                           "partial_variance", "partial_hidden", "texture_table", "texture_atlas",
                           "radiance_cache", "ltc_table"),
                   ("sampling", "world", "grid", "chunk")),
}
# The glossy gather reads the same inputs as the diffuse one. (Every kernel that shades bounce
# hits has ltc.glsl and glossy_ltc.glsl: a metal hit's lobe over an area lamp; the world-mode
# glossy gather's lobe over the emitters.)
KERNELS["bvh_glossy"] = (KERNELS["bvh_gather"][0][:-1] + ("bvh_glossy",),
                         tuple(name for name in KERNELS["bvh_gather"][1] if name != "partial_hidden"),
                         KERNELS["bvh_gather"][2])
# The radiance cache's rays, traced and lit once (gpu_gather.cache_stages): the gather's inputs,
# radiance_cache the layout's texels (each hit picks the face it reads, cache_lookup.glsl).
KERNELS["bvh_cache_paths"] = (
    ("principled", "light_outline", "world_map", "bvh_lights", "textures", "cache_lookup", "ltc",
     "glossy_ltc", "bvh_shade", "cache_paths"),
    _BVH + ("bvh_normals", "lights", "world_map", "emitters", "materials", "gbuffer_position",
            "gbuffer_normal", "principled_lut", "texture_table", "texture_atlas",
            "radiance_cache", "ltc_table"),
    ("sampling", "world", "chunk"))
# The emitters' glossy light: its unshadowed field at the gather points, and from the field at
# the pixel centres and the sub-pixel passes' points (exact_glossy.emitters_shine).
_CENTRE = ("centre_position", "centre_normal", "centre_view", "centre_shine")
KERNELS["bvh_emitter_glossy"] = (
    ("principled", "light_outline", "world_map", "bvh_lights", "textures", "ltc", "glossy_ltc", "same_surface",
     "bvh_emitter_glossy"),
    _BVH + ("lights", "world_map", "emitters", "materials", "principled_lut", "gbuffer_position",
            "gbuffer_normal", "gbuffer_view", "gbuffer_base", "ltc_table") + _CENTRE
    + ("emitter_field",) + _TEXTURES,
    ("sampling",))
_BLANK: dict[str, object] = {}


def _blank_texture():
    """A 1 × 1 RGBA32F texture of zeros (the texture samplers of a scene without textures)."""
    if "blank" not in _BLANK:
        _BLANK["blank"] = float_texture(np.zeros((1, 1, 4), np.float32), (1, 1))
    return _BLANK["blank"]


# Samplers that hold constants of the code, not of the scene: bound when a dispatch's inputs
# leave them out (the texture samplers of a BVH without cut-outs are never read).
CONSTANT_SAMPLERS = {"ltc_table": ltc_texture, "texture_table": _blank_texture,
                     "texture_atlas": _blank_texture,
                     # no multi-bounce cache (gpu_gather.cache_texture): one bounce
                     "radiance_cache": _blank_texture}
# Kernels with more than one output image (the others write ``out_image``).
OUTPUTS = {"bvh_gather": ("out_image", "out_variance", "out_hidden"),
           "bvh_cache_paths": ("out_image", "out_pick"),
           "bvh_glossy": ("out_image", "out_variance")}
_shaders: dict[str, object] = {}


# The kinds of light a kernel can leave out (bvh_lights.glsl BVH_NO_*), by the snapshot's
# light types that need them.
LIGHT_FEATURES = {"SUN": ("SUN",), "AREA": ("AREA",), "POINT": ("POINT", "SPOT"),
                  "WORLD": ("WORLD",), "EMITTERS": ("EMITTERS",)}


EMITTERS_ONLY = ("AREA", "POINT", "SUN", "WORLD")  # a variant with the emitters' code only


def absent_lights(lights, metals: bool = True, direct: bool = False) -> tuple[str, ...]:
    """The ``LIGHT_FEATURES`` no light of ``lights`` (``Light``s with a ``type``) needs, and
    "METAL_AREA" (a metal hit's glossy lobe over an area lamp, bvh_shade.glsl) where the scene
    has an area lamp and no metal (``metals``, ``has_metals``), and "METALS" (a metal hit's
    lamp picks by its lobe, bvh_shade.glsl hit_lamp_weight) where it has no metal. direct :
    the direct-light dispatches' variant, which traces a map's sun as a sun lamp too for the
    pixels' glossy lobes (``world_light.sun_lamp``; the gathers' variants need no lamp code
    for it)."""
    types = {light.type for light in lights}
    if direct and any(getattr(light, "sun", None) is not None for light in lights):
        types.add("SUN")
    absent = [k for k, needs in LIGHT_FEATURES.items() if not types & set(needs)]
    if not metals and "AREA" not in absent:
        absent.append("METAL_AREA")
    if not metals:
        absent.append("METALS")
    return tuple(sorted(absent))


def has_metals(principled, tris) -> bool:
    """Whether a bounce hit can be a metal (Metallic ≥ ``METAL_FOLLOWED``): a material of the
    Principled table ``principled`` (``passes.principled_table``; None: unknown) is one, or
    one sets its Metallic per texel (``tris``' textures' ``param_slots``)."""
    if principled is None:
        return True
    if (np.asarray(principled[1], np.float64)[:, 0] >= METAL_FOLLOWED).any():
        return True
    slots = getattr(getattr(tris, "textures", None), "param_slots", None)
    return slots is not None and bool((np.asarray(slots) >= 0).any())


# Push constants only the world's code reads (bvh_lights.glsl WORLD_HIDDEN): a variant without
# a world declares none (its compiler would drop it, and setting it would fail)
WORLD_CONSTANTS = {"bvh_direct": ("hidden",)}


def variant_constants(kernel: str, absent=()) -> tuple[str, ...]:
    """The push constants of ``kernel``'s variant that leaves out the kinds of light
    ``absent``."""
    names = KERNELS[kernel][2]
    if "WORLD" in absent:
        names = tuple(name for name in names if name not in WORLD_CONSTANTS.get(kernel, ()))
    return names


def bvh_shader(kernel: str, cutouts: bool = True, textures: bool = True,
               absent: tuple[str, ...] = (), hidden: bool = True):
    """The cached compute shader of ``kernel`` (see ``KERNELS``) with only the code the scene
    needs: cutouts : trace through cut-outs (``BVH_CUTOUTS``); textures : the bounce hits'
    materials sample textures (``BVH_TEXTURES``, bvh_shade.glsl); absent : the kinds of light
    the scene has none of (``absent_lights``: ``BVH_NO_<kind>``, bvh_lights.glsl); hidden :
    some triangle is hidden from a kind of ray (``BVH_HIDDEN``, ray visibility). A variant
    built without them has no Alpha lookup in its traversal's triangle loop and no texture
    sampling or unused light model at its hits: llvmpipe pays for a branch's code whether a
    lane takes it or not (the cut-out test alone made every ray 3–4× slower,
    docs/gi_pipeline.md "Where a preview's time goes")."""
    key = (kernel, cutouts, textures, tuple(absent), hidden)
    if key not in _shaders:
        files, samplers, _ = KERNELS[kernel]
        constants = variant_constants(kernel, absent)
        defines = {"BVH_WIDTH_LOG2": str(int(math.log2(TEXTURE_WIDTH))),
                   "SHADOW_EPSILON": repr(float(SHADOW_EPSILON)),
                   "SURFACE_EPSILON": repr(float(SURFACE_EPSILON)),
                   "DET_EPSILON": repr(float(DET_EPSILON)), "RAY_STREAM": f"{RAY_STREAM}u",
                   # the kind of ray a kernel's closest hits are (ray visibility, bvh_common)
                   "BVH_RAY_SHADOW": str(RAY_SHADOW), "BVH_LEAF_BIAS": str(LEAF_BIAS),
                   "BVH_ORDERS": str(ORDERS), "BVH_SHADOW_LAYOUT": str(SHADOW_LAYOUT),
                   "BVH_CLOSEST_RAY": {"bvh_glossy": str(RAY_GLOSSY),
                                       "bvh_probe": "int(mode.y)",
                                       # (its one closest hit: the triangle under a pixel,
                                       # for the shadow terminator's lift)
                                       "bvh_direct": str(RAY_CAMERA)}.get(kernel,
                                                                          str(RAY_DIFFUSE)),
                   "TERMINATOR_OFFSET": repr(float(TERMINATOR_OFFSET)),
                   "TERMINATOR_REACH": repr(float(FIND_REACH)),
                   "TERMINATOR_TRUST": repr(float(TRUST))}
        if "principled" in files:
            defines.update(PRINCIPLED_DEFINES)
        if "textures" in files:
            if cutouts:
                defines["BVH_CUTOUTS"] = "1"
                defines["BVH_CUTOUT_LAYERS"] = str(CUTOUT_LAYERS)
            if textures:
                defines["BVH_TEXTURES"] = "1"
            defines["ROUGHNESS_LEVELS"] = str(ROUGHNESS_LEVELS)
            defines["METALLIC_LEVELS"] = str(METALLIC_LEVELS)
        for kind in absent:
            defines[f"BVH_NO_{kind}"] = "1"
        if hidden:
            defines["BVH_HIDDEN"] = "1"
        if kernel == "bvh_direct":
            defines["STRATA_BLOCK"] = "ivec3(strata.xyz)"
            defines["WORLD_STRATA"] = "int(strata.w)"
            if "WORLD" not in absent:
                defines["WORLD_HIDDEN"] = "hidden"
        if "same_surface" in files:
            defines["PLANE_TOLERANCE"] = repr(float(PLANE_TOLERANCE))
            defines["NEAR_STEP"] = repr(float(NEAR_STEP))
        if "bvh_shade" in files:  # a metal hit followed one reflection further (ray_radiance)
            defines["CONTINUE_STREAM"] = f"{CONTINUE_STREAM}u"
            defines["LOBE_FOLLOW_STREAM"] = f"{LOBE_FOLLOW_STREAM}u"
            defines["LAMP_PICK_STREAM"] = f"{LAMP_PICK_STREAM}u"
            defines["LAMP_PICK_FLOOR"] = repr(float(LAMP_PICK_FLOOR))
            defines["METAL_FOLLOWED"] = repr(float(METAL_FOLLOWED))
            defines["NEAR_FIELD"] = repr(float(NEAR_FIELD))
            defines["MAX_FOLLOWS"] = str(MAX_FOLLOWS)
            defines["NEAR_FACING"] = repr(float(NEAR_FACING))
        if kernel in ("bvh_gather", "bvh_glossy", "bvh_cache_paths"):
            defines["VIEW_BACKOFF"] = repr(float(VIEW_BACKOFF))
            defines["GLOSSY_STREAM"] = f"{GLOSSY_STREAM}u"
            defines["WORLD_GLOSSY_STREAM"] = f"{WORLD_GLOSSY_STREAM}u"
            defines["EMITTER_GLOSSY_STREAM"] = f"{EMITTER_GLOSSY_STREAM}u"
            defines["METAL_RAY_FACTOR"] = str(METAL_RAY_FACTOR)
            defines["NEAREST_HIT"] = repr(float(NEAREST_HIT))
        if kernel == "bvh_cache_paths":
            defines["CACHE_PICK_STREAM"] = f"{PICK_STREAM}u"
        if kernel == "bvh_emitter_glossy":
            defines["EMITTER_GLOSSY_STREAM"] = f"{EMITTER_GLOSSY_STREAM}u"
        if "ltc" in files:
            defines.update(LTC_DEFINES)
            defines["HORIZON_LIFT"] = repr(float(HORIZON_LIFT))
        _shaders[key] = build_compute(("sampling", "bvh_common") + files, samplers, constants,
                                      OUTPUTS.get(kernel, ("out_image",)), defines)
    return _shaders[key]


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a.shape == b.shape and np.array_equal(a, b)


class GPUBVH:
    """The BVH textures of the latest ``SceneTriangles`` (see the module doc).

    nodes, triangles, normals : RGBA32F GPUTextures (``voxgi_addon.scene.bvh.BVHTextures``).
    surface : the texture samplers its cut-outs' Alpha is read from (``texture_table``,
    ``texture_atlas``: ``gpu_scene.GPUScene`` sets them with the triangles'; empty: none).
    uploaded_bytes : bytes the last ``update`` sent (0 = unchanged); resident_bytes : bytes of
    the textures on the GPU; build_seconds : the last BVH build's time.
    cutouts, hidden : some triangle is a cut-out / is hidden from some kind of ray (ray
    visibility); ``inputs`` carries them as "bvh_cutouts" and "bvh_hidden", from which
    ``dispatch_bvh`` picks the kernels' variant (``bvh_shader``).
    """

    def __init__(self):
        self.nodes = self.triangles = self.normals = None
        self.surface: dict[str, object] = {}
        self.uploaded_bytes = 0
        self.resident_bytes = 0
        self.build_seconds = 0.0
        self.cutouts = self.hidden = True
        self._tris = None

    def _unchanged(self, tris) -> bool:
        old = self._tris
        if old is None:
            return False
        if old is tris:
            return True
        return (_same(old.positions, tris.positions) and _same(old.materials, tris.materials)
                and _same(getattr(old, "visibility", None), getattr(tris, "visibility", None))
                and _same(old.corner_normals, tris.corner_normals)
                and _same(_cutout(old), _cutout(tris)))

    def update(self, tris) -> GPUBVH:
        """Upload the BVH of ``tris`` unless the uploaded one is of the same triangles."""
        for _ in self.upload_steps(tris, self.pack(tris)):
            pass
        return self

    def pack(self, tris):
        """(the packed BVH textures of ``tris``, ``scene.bvh.pack_bvh``; seconds to build
        them), or None when the uploaded BVH is of the same triangles. CPU only (numpy): the
        viewport packs on the worker thread and uploads with ``upload_steps``."""
        if self._unchanged(tris):
            return None
        t0 = time.perf_counter()
        packed = pack_bvh(bvh_of(tris), tris)  # built once per instanced mesh
        return packed, time.perf_counter() - t0

    def upload_steps(self, tris, packed, part_bytes: int = 0, sent: int = 0):
        """Upload ``packed`` (``pack(tris)``) a texture per step (a generator: nodes, triangles,
        normals) — consecutive ones together while their bytes stay within ``part_bytes``, a
        scene part — the BVH switching to them at the last; None (unchanged): only remember
        ``tris``. sent : bytes of the step under way that other parts sent already (its scene
        part counted: the nodes go with them while they fit). Main thread."""
        self.uploaded_bytes = 0
        if packed is None:
            self._tris = tris
            return
        packed, seconds = packed
        step = [int(sent)]
        if step[0] and step[0] + packed.nodes.nbytes > part_bytes:
            step[0] = 0
            yield

        def upload(texels, part):
            if step[0] and step[0] + texels.nbytes > part_bytes:
                step[0] = 0
            if not step[0]:
                note_upload(part)
            step[0] += max(int(texels.nbytes), 1)
            return float_texture(texels, (texels.shape[1], texels.shape[0]))

        nodes = upload(packed.nodes, "bvh nodes")
        if step[0] + packed.triangles.nbytes > part_bytes:
            yield
        triangles = upload(packed.triangles, "bvh triangles")
        if step[0] + packed.normals.nbytes > part_bytes:
            yield
        self.normals = upload(packed.normals, "bvh normals")
        self.nodes, self.triangles = nodes, triangles
        self.build_seconds = seconds
        self.uploaded_bytes = self.resident_bytes = packed.nbytes
        self.cutouts, self.hidden = bvh_features(tris)
        self._tris = tris

    @property
    def scene_triangles(self):
        """The ``SceneTriangles`` of the uploaded BVH (None before the first update)."""
        return self._tris

    @property
    def inputs(self) -> dict[str, object]:
        return {"bvh_nodes": self.nodes, "bvh_triangles": self.triangles,
                "bvh_normals": self.normals, **self.surface, "bvh_cutouts": self.cutouts,
                "bvh_hidden": self.hidden}


def bvh_features(tris) -> tuple[bool, bool]:
    """(cutouts, hidden) of ``tris``: some triangle is a cut-out / is hidden from some kind of
    ray — what ``GPUBVH.inputs`` carries to pick the kernels' variant (``bvh_shader``)."""
    cutout = _cutout(tris)
    visibility = getattr(tris, "visibility", None)
    return (cutout is not None and bool(np.any(cutout)),
            visibility is not None and bool(np.any(~np.asarray(visibility, np.int64) & RAY_ALL)))


def _cutout(tris):
    """(T,) bool cut-out triangles of ``tris`` (packed with a negative scale), or None."""
    surface = getattr(tris, "textures", None)
    return None if surface is None or surface.cutout is None else np.asarray(surface.cutout)


_shared: GPUBVH | None = None


def shared_bvh() -> GPUBVH:
    """One ``GPUBVH`` for the previews of this session (the GPU context's lifetime); the
    Accurate path's ``gpu_scene.GPUScene`` holds it as its ``bvh``."""
    global _shared
    if _shared is None:
        _shared = GPUBVH()
    return _shared


def dispatch_bvh(kernel: str, inputs: dict[str, object], width: int, height: int,
                 constants: dict[str, tuple] | None = None, images=None):
    """Run ``kernel`` over width × height RGBA32F output texture(s) and return it (a tuple for
    the kernels of ``OUTPUTS``). images : the output textures to write (kept from an earlier
    dispatch; None: new ones of width × height)."""
    # the variant of the scene's features (GPUBVH.inputs, GPUScene.gather_tables; unknown: all)
    shader = bvh_shader(kernel, bool(inputs.get("bvh_cutouts", True)),
                        bool(inputs.get("bvh_textures", True)), inputs.get("bvh_absent", ()),
                        bool(inputs.get("bvh_hidden", True)))
    samplers = KERNELS[kernel][1]
    names = variant_constants(kernel, inputs.get("bvh_absent", ()))
    outputs = OUTPUTS.get(kernel, ("out_image",))
    if images is None:
        images = [gpu.types.GPUTexture((width, height), format="RGBA32F") for _ in outputs]
    shader.bind()
    for name in samplers:
        shader.uniform_sampler(name, inputs[name] if name in inputs else CONSTANT_SAMPLERS[name]())
    for name in names:
        value = (constants or {}).get(name, (0.0, 0.0, 0.0, 0.0))
        shader.uniform_float(name, tuple(float(v) for v in value))
    for name, image in zip(outputs, images):
        shader.image(name, image)
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)
    return images[0] if len(images) == 1 else tuple(images)


def lights_texture(lights, only: int | None = None):
    """The light table (``voxgi_addon.preview.light_table``) as a texture; one padding row of
    type -1 when no light shines. only : keep just the light of that index in ``lights`` (the
    other rows become padding, so its samples keep their stream)."""
    table = light_table(lights)
    if only is not None:
        table = table.copy()
        table[table[:, 0, 3] != only, 0, 0] = -1.0
    if len(table) == 0:
        table = np.zeros((1, LIGHT_TEXELS, 4), np.float32)
        table[0, 0, 0] = -1.0
    return float_texture(table, (LIGHT_TEXELS, len(table)))


def world_texture(world, stream: int = 0):
    """``world_light.world_table`` of a ``WorldLight`` (None: no world) as a texture."""
    table = world_table(world, stream)
    return float_texture(table, (table.shape[1], table.shape[0]))


def emitters_texture(emitters, stream: int = 0):
    """``emitters.emitter_table`` of an ``EmitterLight`` (None: nothing emits) as a texture."""
    table = emitter_table(emitters, stream)
    return float_texture(table, (table.shape[1], table.shape[0]))


def scene_light_textures(lights) -> dict:
    """{"world_map", "emitters"} textures of the world and emitters in a lights list
    (``world_light.scene_lights``), each with its index as its samples' stream."""
    found = {light.type: (light, index) for index, light in enumerate(lights)
             if light.type in ("WORLD", "EMITTERS")}
    return {"world_map": world_texture(*found.get("WORLD", (None,))),
            "emitters": emitters_texture(*found.get("EMITTERS", (None,)))}


def strata_side(samples: int) -> int:
    """m of the m × m strata ``direct_light`` uses for ``samples`` shadow rays."""
    return max(1, math.ceil(math.sqrt(samples)))


def direct_light_texture(bvh: GPUBVH, gbuffer_inputs, lights, samples: int = 16, seed: int = 0,
                         only: int | None = None, world=None, emitters=None, strata_block=None,
                         table=None, absent: tuple[str, ...] = (), centre=None, field=None,
                         world_strata: int = 0, world_fewer=None, world_hidden=None,
                         colour=None):
    """Diffuse Direct over a G-buffer (``shaders/bvh_direct.glsl``), an RGBA32F texture of the
    G-buffer's size (bottom row first), rgb in Cycles' units; ``only`` : of that lamp alone
    (``lights_texture``; -1: none); world, emitters : a ``world_texture`` / ``emitters_texture``
    to add their light (None: not). strata_block : (M, row, column, m) — draw only the m × m
    block at (row, column) of the M × M strata (``direct_light.diffuse_direct``'s
    ``strata_block``); None: all ``strata_side(samples)``². table : a
    ``lights_texture(lights, only)`` made already. absent : the kinds of light this dispatch
    has none of (``absent_lights``; the kernel's variant leaves their code out).
    centre : a pass of the anti-aliased preview: {"gbuffer_position", "gbuffer_normal",
    "gbuffer_view"} of the pixel centres' G-buffer at the same texels and "unshadowed", the
    emitters' unshadowed field there (``gpu_gather.upsample_field``'s second); the texels whose
    pass sees the surface their centre sees take the emitters' unshadowed sum from it where
    the field holds (bvh_direct.glsl), the others from ``field`` (the field at the pass's own
    points, ``gpu_gather.upsample_field_list``'s second; None: none) where it holds, and
    evaluate it elsewhere (centre None: all do); the shadow rays are the pass's own
    everywhere. world_strata : the side of the strata of the world's map and cosine rays
    (``direct_light.diffuse_direct``'s; 0: the lamps' side) at the texels world_fewer flags
    (``world_fewer_texture``; required with a world_strata). world_hidden : the rest of the
    world map's hidden part at every texel (the diffuse gather's, ``bvh_gather.glsl``
    out_hidden, filtered and upsampled: F12's pixel centres), which the texels take instead
    of tracing their own rays for it (the map's sun keeps its rays); None: they trace them.
    (Where that would leave the dispatch no ray to trace, ``gpu_compose.shade_stages`` runs
    ``world_given.glsl`` instead.) colour : the Diffuse Color at the same texels
    (``aa_surface.glsl`` out_colour), when the light is only ever read times it: a texel
    whose Diffuse Color is 0 (a full metal, a black surface) shows none of it, so it traces
    nothing and reads 0 (None: every texel is lit)."""
    position = gbuffer_inputs["gbuffer_position"]
    if world_strata and world_fewer is None:
        raise ValueError("world_strata without the texels that take it (world_fewer)")
    side = strata_side(samples)
    block = strata_block or (side, 0, 0, side)
    given = centre or {"unshadowed": position, **gbuffer_inputs}  # not read without centre
    inputs = {**bvh.inputs, **gbuffer_inputs,
              "lights": table if table is not None else lights_texture(lights, only),
              "world_map": world if world is not None else world_texture(None),
              "emitters": emitters if emitters is not None else emitters_texture(None),
              "centre_position": given["gbuffer_position"],
              "centre_normal": given["gbuffer_normal"], "centre_view": given["gbuffer_view"],
              "centre_unshadowed": given["unshadowed"],
              "emitter_field": position if field is None else field,  # not read without
              "world_fewer": position if world_fewer is None else world_fewer,  # (the same)
              "world_hidden": position if world_hidden is None else world_hidden,
              "diffuse_colour": position if colour is None else colour,  # (not read without)
              "bvh_absent": tuple(absent)}
    return dispatch_bvh("bvh_direct", inputs, position.width, position.height,
                        {"sampling": (seed, block[3], 0 if centre is None else 1,
                                      0 if field is None else 1),
                         "strata": (*block[:3], world_strata),
                         "hidden": (0.0 if world_hidden is None else 1.0, 0.0, 0.0, 0.0),
                         "shown": (0.0 if colour is None else 1.0, 0.0, 0.0, 0.0)})


def world_fewer_texture(fewer):
    """The work groups whose texels' world rays go over fewer strata
    (``passes.world_fewer_pixels``, (H, W) bool, row 0 on top, whole LOCAL_SIZE blocks from the
    bottom row) as ``bvh_direct``'s world_fewer: texel (i, j) is 1 where work group (i, j)'s are.
    Read at the group's id, the flag is uniform over the group, which the compiler sees: its
    loop over the strata and the strata's draw branch as on a push constant (read per texel,
    every group ran both draws, masked: the city's direct light took 5.2 s instead of 4.7 s
    with all strata). Its size keeps the class of the G-buffer's (``size_like``): llvmpipe
    builds a kernel's code again for another."""
    fewer = np.flipud(np.asarray(fewer, bool))
    height, width = fewer.shape
    flags = fewer[::LOCAL_SIZE, ::LOCAL_SIZE]  # (every texel of a group alike)
    packed = np.zeros((size_like(flags.shape[0], height), size_like(flags.shape[1], width), 4),
                      np.float32)
    packed[:flags.shape[0], :flags.shape[1], 0] = flags
    return float_texture(packed, (packed.shape[1], packed.shape[0]))


def emitters_unshadowed_texture(bvh: GPUBVH, gbuffer_inputs, emitters, lights=None, world=None,
                                field=None, absent: tuple[str, ...] = EMITTERS_ONLY):
    """The emissive triangles' exact unshadowed Diffuse Direct over a G-buffer (``bvh_direct``'s
    mode 2, ``bvh_lights.glsl`` emitters_unshadowed, the port of ``emitters.unshadowed_sum``):
    an RGBA32F texture of the G-buffer's size (bottom row first), (sum, the distance to the
    nearest emissive triangle that can light the point), at the points
    ``direct_light_texture`` lights: the field ``gpu_gather.upsample_field`` brings from the
    gather points to every pixel. field : that field over this G-buffer: (its sum where it
    holds, else the exact one, 0) instead — the pixel centres' sums, ``direct_light_texture``'s
    centre "unshadowed". emitters : an ``emitters_texture``; lights, world : the scene's
    ``lights_texture`` / ``world_texture`` (read by no code path here; bound because
    bvh_lights.glsl declares them; None: empty ones). absent : the variant's kinds of light
    left out (``absent_lights``; the scene's, so that this mode shares the scene's one
    ``bvh_direct`` variant: the default, the emitters' code only, is a variant of its own)."""
    position = gbuffer_inputs["gbuffer_position"]
    inputs = {**bvh.inputs, **gbuffer_inputs, "emitters": emitters,
              "lights": lights if lights is not None else lights_texture([], None),
              "world_map": world if world is not None else world_texture(None),
              "centre_position": position, "centre_normal": position, "centre_view": position,
              "centre_unshadowed": position, "world_fewer": position,  # not read
              "world_hidden": position, "diffuse_colour": position,
              "emitter_field": position if field is None else field,
              "bvh_absent": tuple(absent)}
    return dispatch_bvh("bvh_direct", inputs, position.width, position.height,
                        {"sampling": (0, 1, 2, 0 if field is None else 1),
                         "strata": (1, 0, 0, 0)})


def emitter_glossy_texture(bvh: GPUBVH, gbuffer_inputs, emitters, materials, rays: int,
                           seed: int = 0, lights=None, world=None, centre=None, field=None,
                           unshadowed: bool = False):
    """The glossy light the emissive triangles send toward the viewer over a G-buffer
    (``shaders/bvh_emitter_glossy.glsl``, the port of ``exact_glossy.emitters_shine``): an
    RGBA32F texture of the G-buffer's size (bottom row first), rgb = Glossy Color × their
    Glossy Direct. emitters : an ``emitters_texture``; materials : the
    ``principled_materials_texture``; rays : shadow rays per pixel for the visible share;
    lights, world : the scene's ``lights_texture`` / ``world_texture`` (read by no code path
    here; bound because bvh_lights.glsl declares them; None: empty ones).
    unshadowed : the field at the gather points instead (mode 2): (the unshadowed light over
    the point's Glossy Color, 0), no rays. field : the field at these texels
    (``gpu_gather.upsample_field``'s first, or ``upsample_field_list``'s): the unshadowed light
    is taken from it where it holds and evaluated elsewhere (None: everywhere).
    centre : a sub-pixel pass over the edge pixels' list: {"gbuffer_position",
    "gbuffer_normal", "gbuffer_view"} of the pixel centres' G-buffer at the same texels and
    "shine", this function's texture there; the texels whose pass sees the surface their
    centre sees take the centre's value, the others are as without (None: all are)."""
    position = gbuffer_inputs["gbuffer_position"]
    given = centre or {"shine": position, **gbuffer_inputs}  # not read without centre
    inputs = {**bvh.inputs, **gbuffer_inputs, "emitters": emitters, "materials": materials,
              "principled_lut": lut_texture(),
              "lights": lights if lights is not None else lights_texture([], None),
              "world_map": world if world is not None else world_texture(None),
              "centre_position": given["gbuffer_position"],
              "centre_normal": given["gbuffer_normal"], "centre_view": given["gbuffer_view"],
              "centre_shine": given["shine"],
              "emitter_field": position if field is None else field,  # not read without
              "bvh_absent": EMITTERS_ONLY}
    mode = 2 if unshadowed else 0 if centre is None else 1
    return dispatch_bvh("bvh_emitter_glossy", inputs, position.width, position.height,
                        {"sampling": (seed, max(1, int(rays)), mode, 0 if field is None else 1)})


def trace_rays(bvh: GPUBVH, origins, directions, t_min=0.0, t_max=np.inf, any_hit=False,
               ray: int = RAY_DIFFUSE):
    """Trace N rays on the GPU (``bvh_probe``). Closest hit: (t (inf = miss), triangle (-1),
    u, v) of rays of kind ``ray`` (a ``snapshot.RAY_*`` bit: the triangles they see); any hit
    (shadow rays, ``raycast.occluded`` with max_t = t_max): (N,) bool."""
    o = np.asarray(origins, np.float32).reshape(-1, 3)
    d = np.asarray(directions, np.float32).reshape(-1, 3)
    n = len(o)
    side = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / side)
    t_min = np.broadcast_to(np.asarray(t_min, np.float64), (n,))
    t_max = np.minimum(np.broadcast_to(np.asarray(t_max, np.float64), (n,)), 1e30)
    ray_o = np.zeros((rows * side, 4), np.float32)
    ray_d = np.zeros((rows * side, 4), np.float32)
    ray_o[:n, :3], ray_o[:n, 3] = o, t_min
    ray_d[:n, :3], ray_d[:n, 3] = d, t_max
    inputs = {**bvh.inputs, "ray_origin": float_texture(ray_o, (side, rows)),
              "ray_direction": float_texture(ray_d, (side, rows))}
    out = read_texture(dispatch_bvh("bvh_probe", inputs, side, rows,
                                    {"mode": (1.0 if any_hit else 0.0, ray, 0, 0)}))
    out = out.reshape(-1, 4)[:n]
    if any_hit:
        return out[:, 0] > 0.5
    hit = out[:, 1] >= 0
    t = np.where(hit, out[:, 0], np.inf)
    return t, np.where(hit, np.rint(out[:, 1]), -1).astype(np.int64), out[:, 2], out[:, 3]


def sample_patterns(width: int, height: int) -> np.ndarray:
    """(height · width, 4) of ``bvh_probe``'s mode 2 (texel k = row-major from the bottom)."""
    empty = float_texture(np.zeros((1, 1, 4)), (1, 1))
    rays = float_texture(np.zeros((height, width, 4)), (width, height))
    inputs = {"bvh_nodes": empty, "bvh_triangles": empty, "ray_origin": rays,
              "ray_direction": rays}
    return read_texture(dispatch_bvh("bvh_probe", inputs, width, height,
                                     {"mode": (2.0, 0, 0, 0)})).reshape(-1, 4)


def release() -> None:
    """Drop the cached shaders and the shared BVH textures (docs/gi_pipeline.md, "GPU resources
    at exit")."""
    global _shared
    forget(_shaders)
    _BLANK.clear()
    _shared = None
    scene = sys.modules.get(f"{__package__}.gpu_scene")  # it holds the shared BVH too
    if scene is not None:
        scene.release()
