"""Blender operators, one verb each; the services they use live in ``blender/``."""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import (
    add_demo_scene,
    bake_probes,
    cancel_job,
    gfg_export,
    gfg_import,
    refresh_viewport,
    render_preview,
    update,
    voxelize,
)

modules = (voxelize, update, render_preview, cancel_job, add_demo_scene, gfg_export, gfg_import,
           refresh_viewport, bake_probes)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
