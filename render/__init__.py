"""The GPU side of VoxGI (Blender's ``gpu`` module): the "VoxGI" render engine and the GPU tracer.

Data flows one way: the engine's numpy results (octree, cone settings) → ``gpu_volume``
(atlas + parameter table textures) → ``gbuffer`` (rasterized primary visibility) →
``gpu_tracer`` (compute kernels in ``shaders/``) → ``gpu_preview`` (Cycles-named passes) →
``pipeline`` (shared by ``engine``, F12, and ``voxgi.render_preview``). ``gpu_context`` decides whether the
GPU can be used and falls back to the numpy tracer otherwise.
"""
from __future__ import annotations

import atexit
import sys

import bpy

from ..registration import register_modules, unregister_modules
from . import engine

modules = (engine,)

classes = tuple(cls for module in modules for cls in module.classes)


def release_gpu_resources() -> None:
    """Free the compiled shaders kept between renders while Blender's GPU module is still up:
    on unregister and, since the bpy module never unregisters add-ons, at exit before bpy's own
    exit handler (docs/gi_pipeline.md, "GPU resources at exit")."""
    for name in ("viewport", "debug_draw", "gbuffer", "gpu_shaders", "gpu_bvh", "gpu_gather",
                 "gpu_principled", "gpu_preview"):
        module = sys.modules.get(f"{__name__}.{name}")  # not imported: nothing cached
        if module is not None:
            module.release()


@bpy.app.handlers.persistent
def _release_on_load(*_args) -> None:
    # The G-buffer's raster shader (and the vertex arrays Blender keeps with it) belongs to the
    # GPU context it was made in; after another file is loaded the next F12 or preview may draw
    # in another one, where it rasterized a partial G-buffer (docs/gi_pipeline.md, "One file's
    # state"). Compute shaders and textures are shared between contexts and stay.
    module = sys.modules.get(f"{__name__}.gbuffer")
    if module is not None:
        module.release()


def register() -> None:
    register_modules(modules)
    atexit.unregister(release_gpu_resources)
    atexit.register(release_gpu_resources)
    if _release_on_load not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(_release_on_load)


def unregister() -> None:
    if _release_on_load in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_release_on_load)
    atexit.unregister(release_gpu_resources)
    unregister_modules(modules)
    release_gpu_resources()
