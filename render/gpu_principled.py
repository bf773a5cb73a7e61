"""The Principled BSDF model on the GPU (``shaders/principled.glsl``, the port of
``voxgi_addon/gi/principled.py``; docs/gi_pipeline.md "Principled materials").

To use it in a kernel: put ``"principled"`` in the kernel's source files before the file that
calls it, add the sampler ``"principled_lut"`` bound to ``lut_texture()``, and pass ``DEFINES``
to ``build_compute``. ``evaluate`` runs every function of the port on given inputs (tests).
Needs a GPU context.
"""
from __future__ import annotations

import math

import gpu
import numpy as np

from ..voxgi_addon.gi.principled import DEFAULT_IOR, LUT_ROWS, lut_texels
from .gpu_shaders import LOCAL_SIZE, build_compute, forget
from .gpu_tracer import read_texture
from .gpu_volume import float_texture

DEFINES = {**{name: str(row) for name, row in LUT_ROWS.items()},
           "PRINCIPLED_IOR": repr(float(DEFAULT_IOR))}
_TEST_INPUTS = ("in_material", "in_params", "in_normal", "in_view", "in_light", "in_irradiance")
_TEST_OUTPUTS = ("out_image", "out_glossy_color", "out_reflectance", "out_radiance")
_cache: dict[str, object] = {}


def lut_texture():
    """The cached RGBA32F texture of ``lut_texels()`` (32 texels wide)."""
    if "lut" not in _cache:
        texels = lut_texels()
        _cache["lut"] = float_texture(texels, (texels.shape[1], texels.shape[0]))
    return _cache["lut"]


def evaluate(base, metallic, level, roughness, normal, view, light, irradiance):
    """Run the GLSL functions on N inputs (numpy (N, 3) / (N,) arrays) in one dispatch.

    Returns a dict of (N, 3) float32: ``diffuse_weight`` (at μ = n·view), ``glossy_color``,
    ``glossy_reflectance`` and ``outgoing_radiance`` (with ``irradiance`` (N, 3))."""
    n = len(base)
    side = max(1, math.ceil(math.sqrt(n)))
    rows = math.ceil(n / side)

    def texture(columns):
        texels = np.zeros((rows * side, 4), np.float32)
        at = 0
        for column in columns:
            column = np.asarray(column, np.float32).reshape(n, -1)
            texels[:n, at:at + column.shape[1]] = column
            at += column.shape[1]
        return float_texture(texels.reshape(rows, side, 4), (side, rows))

    inputs = {"in_material": texture([base, metallic]),
              "in_params": texture([level, roughness, np.zeros(n)]),
              "in_normal": texture([normal]), "in_view": texture([view]),
              "in_light": texture([light, np.zeros(n)]), "in_irradiance": texture([irradiance])}
    if "test" not in _cache:
        _cache["test"] = build_compute(("principled", "principled_test"),
                                       ("principled_lut",) + _TEST_INPUTS, (),
                                       _TEST_OUTPUTS, DEFINES)
    shader = _cache["test"]
    images = [gpu.types.GPUTexture((side, rows), format="RGBA32F") for _ in _TEST_OUTPUTS]
    shader.bind()
    shader.uniform_sampler("principled_lut", lut_texture())
    for name, value in inputs.items():
        shader.uniform_sampler(name, value)
    for name, image in zip(_TEST_OUTPUTS, images):
        shader.image(name, image)
    gpu.compute.dispatch(shader, math.ceil(side / LOCAL_SIZE), math.ceil(rows / LOCAL_SIZE), 1)
    names = ("diffuse_weight", "glossy_color", "glossy_reflectance", "outgoing_radiance")
    return {name: read_texture(image).reshape(-1, 4)[:n, :3] for name, image in zip(names, images)}


def release() -> None:
    """Drop the cached texture and shader."""
    forget(_cache)
