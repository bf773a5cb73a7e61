"""Blender UI: scene settings and the sidebar panel."""
from __future__ import annotations

import bpy

from . import panel, properties

# Registered in this order (settings before the panel that draws them), unregistered in reverse.
modules = (properties, panel)

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
