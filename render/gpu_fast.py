"""Fast quality on the GPU: primary visibility rasterized (``gbuffer``), direct light with exact
shadow rays through the BVH (``shaders/bvh_direct.glsl``) or one soft-shadow cone per light
(``shaders/shadow.glsl``), and diffuse/AO and glossy light cone-traced through the octree
(``gpu_tracer``, ``shaders/cone_*.glsl``). The numpy reference is ``voxgi_addon.preview``'s
Fast path; ``gpu_preview.render_passes_gpu`` is the entry point that picks this or Accurate.
"""
from __future__ import annotations

import time

import numpy as np

from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.cone_shadows import shadow_cone
from ..voxgi_addon.preview.passes import compose_passes, direct_light, material_indices, material_table
from ..voxgi_addon.preview.upsample import low_shape
from ..voxgi_addon.scene.geometry import world_triangles
from .gbuffer import rasterize, read_gbuffer
from .gpu_bvh import direct_light_texture, shared_bvh
from .gpu_tracer import dispatch, read_texture
from .gpu_volume import GPUVolume


def fast_passes(snapshot, gi_state, width, height, cones, light_samples, volume, shadows,
                gi_stride, gather_settings, glossy_indirect):
    """(passes, timings) of Fast quality; ``volume`` a ``GPUVolume`` kept between calls (a new
    one when None) so that an unchanged octree is not uploaded again."""
    timings = {}
    t0 = time.perf_counter()
    volume = volume or GPUVolume()
    volume.update(gi_state.octree, cones)
    timings["upload"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    tris = world_triangles(snapshot)
    if len(tris) == 0:
        raise VoxGIError("the scene has no triangles to render")
    _, rough, _, _ = material_table(snapshot)
    gbuffer = rasterize(tris, snapshot.camera, rough, width, height)
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
        image = read_texture(dispatch("shadow", volume, gbuffer.inputs, width, height, constants))
        return np.flipud(image)[..., 0].ravel()[hit[lit]]

    t0 = time.perf_counter()
    if shadows == "RAYS":
        bvh = shared_bvh().update(tris)  # rebuilt and uploaded only for changed triangles
        if bvh.uploaded_bytes:
            timings["BVH build + upload"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        # Light by light: one dispatch stays within llvmpipe's loop limit
        # (docs/blender_facts.md "llvmpipe's loop limit").
        direct = np.zeros((len(hit), 3))
        for index in range(len(snapshot.lights)):
            direct += pixels(direct_light_texture(bvh, gbuffer.inputs, snapshot.lights,
                                                  light_samples, seed=gather_settings.seed,
                                                  only=index))
    else:
        direct = direct_light(None, p, n, snapshot.lights, tris, cones, light_samples, shadows,
                              visibility)
    timings["direct"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    low_h, low_w = low_shape(height, width, gi_stride)
    sampling = {"sampling": (gi_stride, width, height, 0)}

    def traced(kernel):
        low = dispatch(kernel, volume, gbuffer.inputs, low_w, low_h, sampling)
        if gi_stride > 1:  # shaders/upsample.glsl, the port of gi_upsample.upsample
            low = dispatch("upsample", volume, {**gbuffer.inputs, "low_image": low}, width,
                           height, sampling)
        return np.flipud(read_texture(low))

    diffuse_ao = traced("diffuse_ao")
    timings["diffuse+ao cones (GPU)"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if glossy_indirect:
        glossy = traced("glossy")
        timings["glossy cones (GPU)"] = time.perf_counter() - t0
    else:  # as Cycles with no glossy bounces
        glossy = np.zeros((height, width, 4), np.float32)

    flat_da = diffuse_ao.reshape(-1, 4)[hit]
    terms = (direct, flat_da[:, :3], flat_da[:, 3], glossy.reshape(-1, 4)[hit, :3])
    return compose_passes(snapshot, width, height, hit, mat, *terms), timings
