"""Compute shaders of the GPU tracer, built once per kernel and cached.

Sources live in ``shaders/``: ``cone_common.glsl`` (the march, a port of
``voxgi_addon/conetrace.py``) is prepended to each kernel; the parameter-table rows of
``voxgi_addon/trace_params`` come in as defines. Needs a GPU context.
"""
from __future__ import annotations

import pathlib

import gpu

from ..voxgi_addon.gi.svo_sampling import TAU_ALPHA_CAP
from ..voxgi_addon.preview.trace_params import MAX_CASCADES, MAX_LEVELS, ROWS

SHADER_DIR = pathlib.Path(__file__).resolve().parent / "shaders"
LOCAL_SIZE = 8  # 8×8 pixels per work group
# Kernel name → G-buffer inputs it reads (2D RGBA32F samplers).
KERNELS = {
    "diffuse_ao": ("gbuffer_position", "gbuffer_normal"),
    "glossy": ("gbuffer_position", "gbuffer_normal", "gbuffer_view"),
    "shadow": ("gbuffer_position", "gbuffer_normal"),
    "upsample": ("gbuffer_position", "gbuffer_normal", "low_image"),
    "probe": ("gbuffer_position", "gbuffer_normal", "gbuffer_view"),  # tests: raw samples
    "probe_bake": ("probe_positions", "probe_dirs"),  # light probes (render/gpu_probes.py)
    "probe_sh": ("probe_radiance", "probe_dirs"),
}
# Kernel name → its VEC4 push constants.
PUSH_CONSTANTS = {"shadow": ("light_position", "light_size"), "diffuse_ao": ("sampling",),
                  "glossy": ("sampling",), "upsample": ("sampling",),
                  "probe_bake": ("sampling", "world"), "probe_sh": ("sampling",)}
_cache: dict[str, object] = {}


def kernel_source(kernel: str) -> str:
    """The compute source of ``kernel``: the pixel mapping, the shared march, then the kernel's
    ``main``."""
    return "".join((SHADER_DIR / f"{name}.glsl").read_text()
                   for name in ("pixels", "cone_common", kernel))


def compute_shader(kernel: str):
    """The cached ``GPUShader`` of ``kernel`` (see ``KERNELS``)."""
    key = kernel
    if key not in _cache:
        info = gpu.types.GPUShaderCreateInfo()
        info.local_group_size(LOCAL_SIZE, LOCAL_SIZE, 1)
        for name, row in ROWS.items():
            info.define(name, str(row))
        info.define("MAX_LEVELS", str(MAX_LEVELS))
        info.define("MAX_CASCADES", str(MAX_CASCADES))
        info.define("TAU_ALPHA_CAP", repr(float(TAU_ALPHA_CAP)))
        info.sampler(0, "FLOAT_3D", "atlas")
        info.sampler(1, "FLOAT_2D", "params")
        for i, name in enumerate(KERNELS[kernel]):
            info.sampler(2 + i, "FLOAT_2D", name)
        for name in PUSH_CONSTANTS.get(kernel, ()):
            info.push_constant("VEC4", name)
        info.image(0, "RGBA32F", "FLOAT_2D", "out_image", qualifiers={"WRITE"})
        info.compute_source(kernel_source(kernel))
        _cache[key] = gpu.shader.create_from_info(info)
    return _cache[key]


def build_compute(files: tuple[str, ...], samplers: tuple[str, ...], constants: tuple[str, ...],
                  outputs: tuple[str, ...] = ("out_image",), defines: dict[str, str] | None = None,
                  read_write: tuple[str, ...] = ()):
    """A compute shader from ``shaders/<file>.glsl`` sources in order: 2D float ``samplers``,
    VEC4 push ``constants``, write-only RGBA32F 2D images ``outputs``, ``defines``, and
    read-write RGBA32F 2D images ``read_write`` (image slots after the outputs'); work groups
    of LOCAL_SIZE × LOCAL_SIZE."""
    info = gpu.types.GPUShaderCreateInfo()
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE, 1)
    for name, value in (defines or {}).items():
        info.define(name, value)
    for slot, name in enumerate(samplers):
        info.sampler(slot, "FLOAT_2D", name)
    for name in constants:
        info.push_constant("VEC4", name)
    for slot, name in enumerate(outputs):
        info.image(slot, "RGBA32F", "FLOAT_2D", name, qualifiers={"WRITE"})
    for slot, name in enumerate(read_write, start=len(outputs)):
        info.image(slot, "RGBA32F", "FLOAT_2D", name, qualifiers={"READ", "WRITE"})
    info.compute_source("".join((SHADER_DIR / f"{name}.glsl").read_text() for name in files))
    return gpu.shader.create_from_info(info)


def release() -> None:
    """Drop the cached shaders (Blender frees a ``GPUShader`` with its last reference)."""
    _cache.clear()
