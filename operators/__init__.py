"""Blender operators: the only code that reads the scene and runs engine jobs."""
from __future__ import annotations

import bpy

from . import demo_scene, session, voxelize

# Registered in this order, unregistered in reverse.
modules = (session, voxelize, demo_scene)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    for module in modules:
        for cls in module.classes:
            bpy.utils.register_class(cls)
        if hasattr(module, "register"):
            module.register()


def unregister() -> None:
    for module in reversed(modules):
        if hasattr(module, "unregister"):
            module.unregister()
        for cls in reversed(module.classes):
            bpy.utils.unregister_class(cls)
