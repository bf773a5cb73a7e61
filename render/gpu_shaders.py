"""Compute shaders of the GPU tracer, built once per kernel and cached.

Sources live in ``shaders/``: ``cone_common.glsl`` (the march, a port of
``voxgi_addon/conetrace.py``) is prepended to each kernel; the parameter-table rows of
``voxgi_addon/trace_params`` come in as defines. Needs a GPU context.

Every shader of the add-on is made through ``create_shader`` (the compute kernels here, the
G-buffer raster in ``gbuffer.py``), and every scene part sent to the GPU is noted with
``note_upload``: ``counters`` counts both, so the viewport can keep to one compile and one scene
part per draw and the tests can count them per draw (docs/gi_pipeline.md "Entering Rendered
mode").
"""
from __future__ import annotations

import dataclasses
import pathlib
import time

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


@dataclasses.dataclass
class Counters:
    """Shader compiles and scene-part uploads since the process started (``compiles``,
    ``uploads``), the names of the last ones (``compiled``, ``uploaded``: tests and the
    benchmark read the deltas around a draw) and each compile's seconds by name."""

    compiles: int = 0
    uploads: int = 0
    compiled: list = dataclasses.field(default_factory=list)
    uploaded: list = dataclasses.field(default_factory=list)
    compile_seconds: dict = dataclasses.field(default_factory=dict)

    def mark(self) -> tuple[int, int]:
        """(compiles, uploads) now: ``since`` gives what happened after."""
        return self.compiles, self.uploads

    def since(self, mark: tuple[int, int]) -> tuple[list, list]:
        """(shader names compiled, scene parts uploaded) after ``mark``."""
        return (self.compiled[len(self.compiled) - (self.compiles - mark[0]):],
                self.uploaded[len(self.uploaded) - (self.uploads - mark[1]):])


counters = Counters()
_KEEP = 4096  # names kept in ``counters`` (the counts go on)


def create_shader(info, name: str):
    """``gpu.shader.create_from_info(info)``, counted in ``counters`` as ``name``."""
    t0 = time.perf_counter()
    shader = gpu.shader.create_from_info(info)
    counters.compile_seconds[name] = time.perf_counter() - t0
    counters.compiles += 1
    counters.compiled.append(name)
    del counters.compiled[:-_KEEP]
    return shader


def note_upload(part: str) -> None:
    """Count one scene part sent to the GPU (``gpu_scene``, ``gpu_bvh``, the viewport's vertex
    batch)."""
    counters.uploads += 1
    counters.uploaded.append(part)
    del counters.uploaded[:-_KEEP]


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
        _cache[key] = create_shader(info, f"cone {kernel}")
    return _cache[key]


def build_compute(files: tuple[str, ...], samplers: tuple[str, ...], constants: tuple[str, ...],
                  outputs: tuple[str, ...] = ("out_image",), defines: dict[str, str] | None = None,
                  read_write: tuple[str, ...] = (), name: str | None = None):
    """A compute shader from ``shaders/<file>.glsl`` sources in order: 2D float ``samplers``,
    VEC4 push ``constants``, write-only RGBA32F 2D images ``outputs``, ``defines``, and
    read-write RGBA32F 2D images ``read_write`` (image slots after the outputs'); work groups
    of LOCAL_SIZE × LOCAL_SIZE. name : what ``counters`` calls it (the last file's name)."""
    info = gpu.types.GPUShaderCreateInfo()
    info.local_group_size(LOCAL_SIZE, LOCAL_SIZE, 1)
    for key, value in (defines or {}).items():
        info.define(key, value)
    for slot, sampler in enumerate(samplers):
        info.sampler(slot, "FLOAT_2D", sampler)
    for constant in constants:
        info.push_constant("VEC4", constant)
    for slot, image in enumerate(outputs):
        info.image(slot, "RGBA32F", "FLOAT_2D", image, qualifiers={"WRITE"})
    for slot, image in enumerate(read_write, start=len(outputs)):
        info.image(slot, "RGBA32F", "FLOAT_2D", image, qualifiers={"READ", "WRITE"})
    info.compute_source("".join((SHADER_DIR / f"{file}.glsl").read_text() for file in files))
    return create_shader(info, name or files[-1])


def size_like(n: int, like: int, step: int = 1) -> int:
    """The least multiple of ``step`` at or above ``n`` that is a power of two if and only if
    ``like`` is one. llvmpipe keys a kernel's machine code on whether each bound texture's
    width and height are powers of two: a kernel dispatched over a 64-wide list and a 160-wide
    frame, or over a 1 × 1 placeholder and then a real texture, is JIT-compiled twice
    (docs/gi_pipeline.md "Where a preview's time goes"). Textures sized here keep the class of
    the texture they stand beside or in for."""
    size = max(step, -(-n // step) * step)
    while _power_of_two(size) != _power_of_two(like):
        size += step
    return size


def _power_of_two(n: int) -> bool:
    return n > 0 and n & (n - 1) == 0


def forget(*caches) -> None:
    """Clear ``caches`` of shaders (Blender frees a ``GPUShader`` with its last reference),
    the context's bound shader unbound first. The context remembers its bound shader by
    address and skips a bind of the same address: a shader made later where a freed bound one
    lay would not be bound, and its draws or dispatches would run the freed one's program (a
    render after a module's ``release`` rasterized an empty G-buffer about one time in eight:
    docs/gi_pipeline.md "One file's state")."""
    gpu.shader.unbind()
    for cache in caches:
        cache.clear()


def release() -> None:
    """Drop the cached shaders."""
    forget(_cache)
