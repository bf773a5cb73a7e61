"""The sub-pixel passes' samples summed into the pixels their filter reaches, on the GPU:
``GPUTails`` is the GPU statement of ``voxgi_addon.preview.passes.stacked_tails`` (numpy, the
readable reference it is tested against, tests/blender/test_gpu_tails.py) plus each edge
pixel's own weighted sum, so a preview reads back one value per reached pixel instead of every
pass's sample of every edge pixel (docs/gi_pipeline.md "The samples' tails on the GPU").

Per raster of the sub-pixel passes (``gpu_preview._subpixel_passes``) the samples lie in
``aa_resolve.glsl``'s outputs, one row block per pass; the samples a pass shades itself are
placed among them (``place``, ``shaders/aa_place.glsl``, which also lists the edge pixels
in an image of the frame's size), then ``add`` sums them into one
read-write storage image per sum texture over the list of reached pixels (the edge pixels and
their 8 neighbours; ``shaders/aa_tails.glsl``). ``read`` returns those pixels and their sums.
Needs a GPU context.
"""
from __future__ import annotations

import math

import gpu
import numpy as np

from .gpu_shaders import LOCAL_SIZE, build_compute, forget
from .gpu_tracer import read_texture
from .gpu_volume import float_texture

NAMES = ("a", "b", "c", "d", "e", "f", "g")  # the sum textures sum_a … sum_g
_shaders: dict[str, object] = {}


def _shader(kernel: str):
    if kernel not in _shaders:
        if kernel == "aa_tails":
            _shaders[kernel] = build_compute(
                ("aa_tails",), ("reached", "index", "weights", *(f"sample_{k}" for k in NAMES)),
                ("tails",), (), read_write=tuple(f"sums_{k}" for k in NAMES))
        elif kernel == "aa_index":
            _shaders[kernel] = build_compute(("aa_place",), ("places",), (), ("out_index",),
                                             {"INDEX": "1"}, name="aa_index")
        else:
            _shaders[kernel] = build_compute(("aa_place",), ("places", *(f"sum_{k}" for k in NAMES)),
                                             (), tuple(f"out_{k}" for k in NAMES))
    return _shaders[kernel]


def release() -> None:
    """Drop the cached kernels (Blender frees a ``GPUShader`` with its last reference)."""
    forget(_shaders)


def _dispatch(shader, width: int, height: int) -> None:
    gpu.compute.dispatch(shader, math.ceil(width / LOCAL_SIZE), math.ceil(height / LOCAL_SIZE), 1)


def reached_pixels(listed: np.ndarray, width: int, height: int) -> np.ndarray:
    """(M,) ascending: the flat pixels (row 0 on top) of the ``listed`` ones and their 8
    neighbours inside the image: where their samples' filter reaches."""
    y, x = np.divmod(np.asarray(listed, np.int64), width)
    reach = np.zeros((height + 2, width + 2), bool)
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            reach[y + dy, x + dx] = True
    return np.flatnonzero(reach[1:-1, 1:-1])


def _zeros(size):
    texture = gpu.types.GPUTexture(size, format="RGBA32F")
    texture.clear(format="FLOAT", value=(0.0, 0.0, 0.0, 0.0))
    return texture


class GPUTails:
    """The sums of the edge pixels' sub-pixel samples in the pixels they reach.

    pixels, list_size : the edge pixels' list texture and its (w, h) (``gpu_preview.
    _pixel_list``: texel t row-major = (x, y, id, 1), GL coordinates); image_size : (W, H);
    reached, reached_size : the same kind of list of ``at``, the pixels reached
    (``reached_pixels``)."""

    def __init__(self, pixels, list_size, image_size, at, reached, reached_size):
        self.list_size, self.at = list_size, at
        self.reached, self.reached_size = reached, reached_size
        self.index = _zeros(image_size)
        shader = _shader("aa_index")
        shader.bind()
        shader.uniform_sampler("places", pixels)
        shader.image("out_index", self.index)
        _dispatch(shader, *list_size)
        self.sums = {k: _zeros(reached_size) for k in NAMES}

    def place(self, samples: dict, shaded: dict, places: np.ndarray, size) -> None:
        """Write a pass's own shaded samples ``shaded`` (sum_a … sum_g textures over a list of
        ``size``) into its raster's ``samples`` (out_a … out_g, ``aa_resolve``'s textures) at
        the texels ``places`` (N, 2) (x, y in GL coordinates; list entry i → places[i])."""
        table = np.zeros((size[0] * size[1], 4), np.float32)
        table[:len(places), :2] = places
        table[:len(places), 3] = 1.0
        places = float_texture(table, size)  # held until dispatched: a freed one reads zeros
        shader = _shader("aa_place")
        shader.bind()
        shader.uniform_sampler("places", places)
        for k in NAMES:
            shader.uniform_sampler(f"sum_{k}", shaded[f"sum_{k}"])
            shader.image(f"out_{k}", samples[f"out_{k}"])
        _dispatch(shader, *size)

    def add(self, samples: dict, weights: np.ndarray) -> None:
        """Add one raster's samples (out_a … out_g: pass k's sample of list entry t at
        (t.x, t.y + k × the list's rows)), pass k's sample of pixel p + e counting in p with
        ``weights[k]`` (K, 3, 3) at [ey + 1, ex + 1] (its own pixel's at [1, 1])."""
        weights = np.asarray(weights, np.float32).reshape(len(weights), 9)
        table = np.zeros((9, 16, 4), np.float32)  # (pass, direction): one shape, one JIT
        if len(weights) > 16:
            raise ValueError(f"{len(weights)} passes in one raster: at most 16")
        table[:, :len(weights), 0] = weights.T
        table = float_texture(table, (16, 9))  # held until dispatched: a freed one reads zeros
        shader = _shader("aa_tails")
        shader.bind()
        shader.uniform_float("tails", (float(len(weights)), float(self.list_size[1]),
                                       float(self.list_size[0]), 0.0))
        shader.uniform_sampler("reached", self.reached)
        shader.uniform_sampler("index", self.index)
        shader.uniform_sampler("weights", table)
        for k in NAMES:
            shader.uniform_sampler(f"sample_{k}", samples[f"out_{k}"])
        for k in NAMES:
            shader.image(f"sums_{k}", self.sums[k])
        _dispatch(shader, *self.reached_size)

    def read(self) -> dict:
        """name "sum_a" … → (M, 4) float32: the sums at the reached pixels ``at``."""
        count = len(self.at)
        return {f"sum_{k}": read_texture(texture).reshape(-1, 4)[:count]
                for k, texture in self.sums.items()}
