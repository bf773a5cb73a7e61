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


# Blender's glTF exporter and importer look these names up on the enabled add-on's top module
# (docs/gltf_probes.md "Blender"); they are imported on first use, so the engine needs no bpy.
_GLTF_HOOKS = ("glTF2ExportUserExtension", "glTF2ImportUserExtension", "draw_import")


def __getattr__(name):
    if name in _GLTF_HOOKS:
        from .blender import gltf_probes

        return getattr(gltf_probes, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register() -> None:
    for package in _packages():
        package.register()


def unregister() -> None:
    for package in reversed(_packages()):
        package.unregister()
