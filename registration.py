"""Loud, ordered registration shared by ``operators/`` and ``ui/``.

Each module lists its ``classes``; modules register in order (classes, then the module's own
``register()`` if any) and unregister in reverse.
"""
from __future__ import annotations

import bpy


def register_modules(modules) -> None:
    for module in modules:
        for cls in module.classes:
            bpy.utils.register_class(cls)
        if hasattr(module, "register"):
            module.register()


def unregister_modules(modules) -> None:
    for module in reversed(modules):
        if hasattr(module, "unregister"):
            module.unregister()
        for cls in reversed(module.classes):
            bpy.utils.unregister_class(cls)


def add_handlers(pairs) -> None:
    """Append each (``bpy.app.handlers`` list name, function) of ``pairs`` once."""
    for name, fn in pairs:
        handlers = getattr(bpy.app.handlers, name)
        if fn not in handlers:
            handlers.append(fn)


def remove_handlers(pairs) -> None:
    """Remove every occurrence of each (list name, function) of ``pairs``."""
    for name, fn in pairs:
        handlers = getattr(bpy.app.handlers, name)
        while fn in handlers:
            handlers.remove(fn)
