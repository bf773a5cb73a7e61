"""Blender operators: the only code that reads the scene and runs engine jobs."""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import demo_scene, engine_jobs, gfg_export, gfg_import, gi_preview, session, voxelize

# Registered in this order, unregistered in reverse (jobs stop before the session is cleared).
modules = (session, engine_jobs, voxelize, gi_preview, demo_scene, gfg_export, gfg_import)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
