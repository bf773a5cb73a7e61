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

