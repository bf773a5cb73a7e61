"""VoxGI: real-time global-illumination preview and light-probe authoring for Blender.

Registration only. Imports run one way: ``ui``/``operators`` → ``render`` → ``blender`` (the bpy
services) → ``voxgi_addon`` (the engine, which never imports bpy). The packages are imported
when Blender registers the add-on, so importing ``voxgi.voxgi_addon`` alone needs no bpy.
"""
from __future__ import annotations


def _packages():
    """The add-on's packages in registration order (settings and services before the
    operators, render engine and panels that use them)."""
    from . import blender, operators, render, ui

    return (blender, operators, render, ui)


def register() -> None:
    for package in _packages():
        package.register()


def unregister() -> None:
    for package in reversed(_packages()):
        package.unregister()
