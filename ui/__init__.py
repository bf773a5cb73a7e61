"""Blender UI: scene settings and the sidebar panel."""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import panel, properties

# Registered in this order (settings before the panel that draws them), unregistered in reverse.
modules = (properties, panel)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
