"""Cone tracing on the GPU: dispatch a compute kernel over a G-buffer, read results back.

Inputs are a ``GPUVolume`` uploaded for the current octree and G-buffer textures
(``gbuffer``: position + hit flag, normal + roughness, view direction + material); outputs are
RGBA32F textures in the numpy tracer's units. Needs a GPU context.
"""
from __future__ import annotations

import math

import gpu
import numpy as np

from .gpu_shaders import KERNELS, LOCAL_SIZE, compute_shader


def read_texture(texture) -> np.ndarray:
    """(H, W, 4) float32 copy of a 2D RGBA32F texture."""
    # The Buffer holds C-ordered floats but describes itself with Fortran strides (bpy 5.0.1),
    # so take its memory in the order it lies in.
    flat = np.asarray(texture.read(), dtype=np.float32).ravel(order="F")
    return flat.reshape(texture.height, texture.width, 4).copy()


def dispatch(kernel: str, volume, inputs: dict[str, object], width: int, height: int,
             constants: dict[str, tuple] | None = None):
    """Run ``kernel`` over a width × height output image; returns that RGBA32F texture.
    constants : the kernel's VEC4 push constants by name (``gpu_shaders.PUSH_CONSTANTS``)."""
    shader = compute_shader(kernel)
    out = gpu.types.GPUTexture((width, height), format="RGBA32F")
    shader.bind()
    shader.uniform_sampler("atlas", volume.atlas)
    shader.uniform_sampler("params", volume.params)
    for name in KERNELS[kernel]:
        shader.uniform_sampler(name, inputs[name])
    for name, value in (constants or {}).items():
        shader.uniform_float(name, tuple(float(v) for v in value))
    shader.image("out_image", out)
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)
    return out


def denoise(low, gbuffer_inputs: dict[str, object], stride: int, width: int, height: int,
            iterations: int = 4, volume=None):
    """The edge-aware à-trous filter (``shaders/denoise.glsl``, the port of
    ``voxgi_addon.preview.denoise.atrous_filter``) over a reduced-resolution gather texture
    ``low`` (RGBA32F: mean RGB, variance of the mean's luminance) whose cells are the pixels
    ``traced_pixel`` picks in a ``width`` × ``height`` G-buffer; returns the filtered texture."""
    volume = volume or _unused_volume()
    for it in range(iterations):
        sampling = {"sampling": (stride, width, height, 1 << it)}
        low = dispatch("denoise", volume, {**gbuffer_inputs, "low_image": low}, low.width,
                       low.height, sampling)
    return low


class _NoVolume:
    """1-texel stand-ins for the atlas and parameter table of kernels that do not read them."""

    def __init__(self):
        zero = gpu.types.Buffer("FLOAT", 4, [0.0] * 4)
        self.atlas = gpu.types.GPUTexture((1, 1, 1), format="RGBA16F", data=zero)
        self.params = gpu.types.GPUTexture((1, 1), format="RGBA32F", data=zero)


_no_volume: list[_NoVolume] = []


def _unused_volume() -> _NoVolume:
    if not _no_volume:
        _no_volume.append(_NoVolume())
    return _no_volume[0]


def release() -> None:
    """Drop the stand-in textures (docs/gi_pipeline.md, "GPU resources at exit")."""
    _no_volume.clear()
