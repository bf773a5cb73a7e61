"""The GPU side of VoxGI (Blender's ``gpu`` module): the "VoxGI" render engine and the GPU tracer.

Data flows one way: the engine's numpy results (octree, cone settings) → ``gpu_volume``
(atlas + parameter table textures) → ``gbuffer`` (rasterized primary visibility) →
``gpu_tracer`` (compute kernels in ``shaders/``) → ``gpu_preview`` (Cycles-named passes) →
``pipeline`` (shared by ``engine``, F12, and ``voxgi.render_preview``). ``gpu_context`` decides whether the
GPU can be used and falls back to the numpy tracer otherwise.
"""
from __future__ import annotations

import atexit
import importlib
import sys

from ..registration import register_modules, unregister_modules
from . import engine

modules = (engine,)

classes = tuple(cls for module in modules for cls in module.classes)


def release_gpu_resources() -> None:
    """Free the compiled shaders kept between renders while Blender's GPU module is still up:
    on unregister and, since the bpy module never unregisters add-ons, at exit before bpy's own
    exit handler (docs/gi_pipeline.md, "GPU resources at exit"). Each module's release
    unbinds the context's shader before it drops its own (``gpu_shaders.forget``)."""
    for name in ("viewport", "kernel_warmup", "debug_draw", "gpu_shaders", "gpu_bvh",
                 "gpu_gather", "gpu_principled", "gpu_compose", "gpu_accumulation",
                 "gpu_gather_sums", "gpu_tails"):
        module = sys.modules.get(f"{__name__}.{name}")  # not imported: nothing cached
        if module is not None:
            module.release()


def register() -> None:
    register_modules(modules)
    # The viewport's modules now rather than on a view's first view_update, which they held
    # 60-65 ms more on the main thread (docs/gi_pipeline.md "Entering Rendered mode"). Only
    # sys.modules holds them, as after that first call: the engine's globals, which Blender
    # keeps to its exit, would keep their GPU objects alive past its GPU's teardown.
    importlib.import_module(f"{__name__}.viewport")
    # the views' scene-independent kernels compiled while a VoxGI file is open in the UI,
    # one per timer tick, before a view enters Rendered mode (kernel_warmup)
    importlib.import_module(f"{__name__}.kernel_warmup").register()
    atexit.unregister(release_gpu_resources)
    atexit.register(release_gpu_resources)


def unregister() -> None:
    warmup = sys.modules.get(f"{__name__}.kernel_warmup")
    if warmup is not None:
        warmup.unregister()
    atexit.unregister(release_gpu_resources)
    unregister_modules(modules)
    release_gpu_resources()
