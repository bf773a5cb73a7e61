"""VoxGI: voxel cone-traced global illumination previews for Blender.

Registration only: the Blender side lives in ``operators/`` and ``ui/``, the engine in
``voxgi_addon/`` (which never imports bpy).
"""
from __future__ import annotations

from . import operators, ui

_packages = (operators, ui)


def register() -> None:
    for package in _packages:
        package.register()


def unregister() -> None:
    for package in reversed(_packages):
        package.unregister()
