"""Blender UI: the sidebar panels, Render Properties panels, the debug-view draw handler and
the Esc key map (settings live in ``blender/settings.py`` and ``blender/viewport_settings.py``)."""
from __future__ import annotations

from ..registration import register_modules, unregister_modules
from . import debug_draw, panel, probe_draw, probe_panel, render_properties, viewport_panel

modules = (panel, viewport_panel, probe_panel, render_properties, debug_draw, probe_draw)

classes = tuple(cls for module in modules for cls in module.classes)


def register() -> None:
    register_modules(modules)


def unregister() -> None:
    unregister_modules(modules)
