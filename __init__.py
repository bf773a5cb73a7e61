"""VoxGI: voxel cone-traced global illumination previews for Blender.

Registration only: the Blender side lives in ``operators/``, ``ui/`` and ``render/`` (the
VoxGI render engine and the GPU tracer), the engine in ``voxgi_addon/`` (which never imports
bpy).
"""
from __future__ import annotations

from . import operators, render, ui

_packages = (operators, ui, render)


def register() -> None:
    for package in _packages:
        package.register()


def unregister() -> None:
    for package in reversed(_packages):
        package.unregister()
