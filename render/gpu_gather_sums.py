"""The samples' raw gathers per cell of the image's low-resolution gather grid, summed on the
GPU: ``GPUGatherSums`` is the GPU statement of ``voxgi_addon.preview.progressive.GatherSums``
(numpy, the readable reference it is tested against, tests/blender/test_gpu_gather_sums.py),
so the viewport's progressive image (``render/progressive.py`` ``gather_hook``) hands the
à-trous filter the mean over every sample so far without reading a tile's gather back.

``shaders/gather_sums.glsl`` adds one tile's gather textures to the kind's sums and writes the
tile's mean and pooled variance. The sums stay in one read-write storage image per kind
(``gpu_shaders.build_compute``'s ``read_write``; no ping-pong): an RGBA32F texture of
(Wl, 3 Hl), the image's low grid (``upsample.low_shape``) three times stacked — Σ values,
Σ variances, (Σ luminance², count, 0, 0) — each layer in GL rows (row 0 at the bottom).

Orientation: the tile textures are GL textures (row 0 at the bottom) of the tile's low shape;
the tile ``rect`` (x0, y0, w, h) is in image pixels with y0 from the image's top, as
``GatherSums``' (whose arrays have row 0 on top). Needs a GPU context.
"""
from __future__ import annotations

import math

import gpu

from ..voxgi_addon.preview.upsample import low_shape
from .gpu_shaders import LOCAL_SIZE, build_compute, forget

_SAMPLERS = ("gather_values", "gather_variance")
_OUTPUTS = ("out_mean", "out_pooled")
_shaders: dict[str, object] = {}


def _shader():
    if "gather_sums" not in _shaders:
        _shaders["gather_sums"] = build_compute(("gather_sums",), _SAMPLERS, ("cells",), _OUTPUTS,
                                                read_write=("sums",))
    return _shaders["gather_sums"]


def release() -> None:
    """Drop the cached kernel (Blender frees a ``GPUShader`` with its last reference)."""
    forget(_shaders)


class GPUGatherSums:
    """``GatherSums`` on the GPU: per kind ("diffuse", "glossy", "world glossy", "behind …")
    the sums of the samples' raw gathers over the ``width`` × ``height`` image's gather grid
    at ``stride`` (``low_shape``), in one storage texture each (``sums``; see the module)."""

    def __init__(self, width: int, height: int, stride: int):
        self.width, self.height, self.stride = width, height, stride
        self.shape = low_shape(height, width, stride)  # (Hl, Wl)
        self.sums: dict[str, gpu.types.GPUTexture] = {}
        self.rays: dict[str, int] = {}  # per kind the rays of the samples summed

    def _storage(self, kind: str):
        texture = self.sums.get(kind)
        if texture is None:
            low_h, low_w = self.shape
            texture = gpu.types.GPUTexture((low_w, 3 * low_h), format="RGBA32F")
            texture.clear(format="FLOAT", value=(0.0, 0.0, 0.0, 0.0))
            self.sums[kind] = texture
        return texture

    def add(self, kind: str, rect, values, variance, rays: int, lattice: bool = False):
        """Add one sample's raw gather of the tile ``rect`` (x0, y0, w, h; x0, y0 multiples
        of the stride, y0 from the image's top; it may reach past the image): ``values``,
        ``variance`` RGBA32F textures of the tile's low shape (``low_shape(h, w, stride)``),
        row 0 at the bottom; rays : its rays per point. Returns new (mean, pooled) RGBA32F
        textures of that size: over every sample so far in the image's cells, the tile's own
        gather (NaN as 0) past them. Nothing is read back. rays 0 (a sample after the
        gathering ones): nothing is added, ``values`` and ``variance`` only give the tile's
        shape, and its cells past the image take the nearest cell's (``GatherSums.add``).
        lattice : ``values`` and ``variance`` hold the tile's lattice only (``gpu_gather
        .gather_steps``' lattice: its shape ``low_shape`` of the tile's low shape at stride
        2); the tile's other cells add nothing. A cell no sample has reached is a hole: its
        pooled variance's .z is 1 (``gpu_gather.denoise(holes=True)`` fills it)."""
        x0, y0, w, h = rect
        s = self.stride
        if x0 % s or y0 % s:
            raise ValueError(f"a tile at ({x0}, {y0}) does not start on a stride-{s} block")
        low_h, low_w = low_shape(h, w, s)
        given_h, given_w = low_shape(low_h, low_w, 2) if lattice else (low_h, low_w)
        for texture in (values, variance):
            if (texture.width, texture.height) != (given_w, given_h):
                raise ValueError(f"a {texture.width}×{texture.height} gather for a tile of "
                                 f"{given_w}×{given_h} cells")
        sums = self._storage(kind)
        shader = _shader()
        outputs = {name: gpu.types.GPUTexture((low_w, low_h), format="RGBA32F") for name in _OUTPUTS}
        shader.bind()
        shader.uniform_sampler("gather_values", values)
        shader.uniform_sampler("gather_variance", variance)
        if rays:
            self.rays[kind] = rays
        shader.uniform_float("cells", (float(x0 // s), float(y0 // s),
                                       float(rays or self.rays.get(kind, 1)),
                                       1.0 if not rays else 2.0 if lattice else 0.0))
        for name, texture in outputs.items():
            shader.image(name, texture)
        shader.image("sums", sums)
        gpu.compute.dispatch(shader, math.ceil(low_w / LOCAL_SIZE), math.ceil(low_h / LOCAL_SIZE), 1)
        return outputs["out_mean"], outputs["out_pooled"]

    def free(self) -> None:
        """Drop the kinds' sum textures (Blender frees a ``GPUTexture`` with its last
        reference); the next ``add`` of a kind starts it anew."""
        self.sums.clear()
        self.rays.clear()
