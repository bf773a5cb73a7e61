"""Blender UI: the sidebar panels (settings live in ``blender/settings.py``)."""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import panel, probe_draw, probe_panel

modules = (panel, probe_panel, probe_draw)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
