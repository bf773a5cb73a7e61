"""The GPU side of VoxGI (Blender's ``gpu`` module): the "VoxGI" render engine and the GPU tracer.

Data flows one way: the engine's numpy results (octree, cone settings) → ``gpu_volume``
(atlas + parameter table textures) → ``gbuffer`` (rasterized primary visibility) →
``gpu_tracer`` (compute kernels in ``shaders/``) → ``gpu_preview`` (Cycles-named passes) →
``pipeline`` (shared by ``engine``, F12, and ``voxgi.render_preview``). ``gpu_context`` decides whether the
GPU can be used and falls back to the numpy tracer otherwise.
"""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import engine

modules = (engine,)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
