"""Cone tracing on the GPU: dispatch the compute kernels over a G-buffer, read the passes back.

Inputs are what ``voxgi_addon.preview`` computes on the CPU side — a G-buffer of (H, W, 4)
float32 arrays (position + hit flag, normal + roughness, view direction) — and a
``GPUVolume`` uploaded for the current octree. Outputs are numpy arrays in the numpy tracer's
units. Needs a GPU context (``gpu_context``).
"""
from __future__ import annotations

import math

import numpy as np
import gpu

from .gpu_shaders import KERNELS, LOCAL_SIZE, compute_shader
from .gpu_volume import float_texture


def read_texture(texture) -> np.ndarray:
    """(H, W, 4) float32 copy of a 2D RGBA32F texture."""
    # The Buffer holds C-ordered floats but describes itself with Fortran strides (bpy 5.0.1),
    # so take its memory in the order it lies in.
    flat = np.asarray(texture.read(), dtype=np.float32).ravel(order="F")
    return flat.reshape(texture.height, texture.width, 4).copy()


def dispatch(kernel: str, volume, inputs: dict[str, object], width: int, height: int):
    """Run ``kernel`` over a width × height image; returns its RGBA32F output texture."""
    shader = compute_shader(kernel)
    out = gpu.types.GPUTexture((width, height), format="RGBA32F")
    shader.bind()
    shader.uniform_sampler("atlas", volume.atlas)
    shader.uniform_sampler("params", volume.params)
    for name in KERNELS[kernel]:
        shader.uniform_sampler(name, inputs[name])
    shader.image("out_image", out)
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)
    return out


def trace_cones(volume, position: np.ndarray, normal: np.ndarray, view: np.ndarray):
    """Diffuse indirect (H, W, 3), AO (H, W), glossy indirect (H, W, 3), all float32.

    position : (H, W, 4) xyz + 1 where a surface was hit (0 = background);
    normal : (H, W, 4) unit normal facing the camera + roughness; view : (H, W, 4) unit
    camera → point direction in xyz.
    """
    height, width = position.shape[:2]
    inputs = {name: float_texture(array, (width, height))
              for name, array in (("gbuffer_position", position), ("gbuffer_normal", normal),
                                  ("gbuffer_view", view))}
    diffuse_ao = read_texture(dispatch("diffuse_ao", volume, inputs, width, height))
    glossy = read_texture(dispatch("glossy", volume, inputs, width, height))
    return diffuse_ao[..., :3], diffuse_ao[..., 3], glossy[..., :3]
