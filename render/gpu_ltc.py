"""LTC integrals of the Principled GGX lobe on the GPU (``shaders/ltc.glsl``, the port of
``voxgi_addon/gi/ltc.py``; docs/gi_pipeline.md "LTC: the glossy lobe over polygons").

To use it in a kernel: put ``"ltc"`` in the kernel's source files before the file that calls
``ltc_triangle``, add the sampler ``"ltc_table"`` bound to ``ltc_texture()`` and pass ``DEFINES``
to ``build_compute``. ``evaluate`` runs ``ltc_triangle`` on given inputs (tests). Needs a GPU
context.
"""
from __future__ import annotations

import math

import gpu
import numpy as np

from ..voxgi_addon.gi.ltc import load_table, table_texels
from .gpu_shaders import LOCAL_SIZE, build_compute, forget
from .gpu_tracer import read_texture
from .gpu_volume import float_texture

_TEXELS = table_texels()
DEFINES = {"LTC_ROUGH_SIZE": str(_TEXELS.shape[0]), "LTC_VIEW_SIZE": str(_TEXELS.shape[1]),
           "LTC_ROUGH_MIN": repr(float(load_table()["rough_min"]))}
_TEST_INPUTS = ("in_p", "in_n", "in_v", "in_c0", "in_c1", "in_c2")
_cache: dict[str, object] = {}


def ltc_texture():
    """The cached RGBA32F texture of ``table_texels()``: x = view axis, y = roughness."""
    if "table" not in _cache:
        _cache["table"] = float_texture(_TEXELS, (_TEXELS.shape[1], _TEXELS.shape[0]))
    return _cache["table"]


def evaluate(p, n, v, roughness, corners) -> np.ndarray:
    """``ltc_triangle`` for N points and N triangles (numpy p, n, v (N, 3), roughness (N,),
    corners (N, 3, 3)) in one dispatch: (N,) float32."""
    count = len(p)
    side = max(1, math.ceil(math.sqrt(count)))
    rows = math.ceil(count / side)

    def texture(*columns):
        texels = np.zeros((rows * side, 4), np.float32)
        at = 0
        for column in columns:
            column = np.asarray(column, np.float32).reshape(count, -1)
            texels[:count, at:at + column.shape[1]] = column
            at += column.shape[1]
        return float_texture(texels.reshape(rows, side, 4), (side, rows))

    corners = np.asarray(corners, np.float32)
    inputs = {"in_p": texture(p, roughness), "in_n": texture(n), "in_v": texture(v),
              "in_c0": texture(corners[:, 0]), "in_c1": texture(corners[:, 1]),
              "in_c2": texture(corners[:, 2])}
    if "test" not in _cache:
        _cache["test"] = build_compute(("ltc",), ("ltc_table",) + _TEST_INPUTS, (), ("out_image",),
                                       {**DEFINES, "LTC_TEST_KERNEL": "1"})
    shader = _cache["test"]
    image = gpu.types.GPUTexture((side, rows), format="RGBA32F")
    shader.bind()
    shader.uniform_sampler("ltc_table", ltc_texture())
    for name, value in inputs.items():
        shader.uniform_sampler(name, value)
    shader.image("out_image", image)
    gpu.compute.dispatch(shader, math.ceil(side / LOCAL_SIZE), math.ceil(rows / LOCAL_SIZE), 1)
    return read_texture(image).reshape(-1, 4)[:count, 0]


def release() -> None:
    """Drop the cached texture and shader."""
    forget(_cache)
