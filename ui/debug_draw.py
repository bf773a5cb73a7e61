"""The add-on's SpaceView3D draw handler: debug views over the 3D view in any shading mode
(drawing in ``render/debug_draw.py``; settings in ``Scene.voxgi_viewport``).

Added on register, removed on unregister together with every GPU object it made, so enabling
and disabling the add-on leaves no draw callback or texture behind.
"""
from __future__ import annotations

import bpy
import numpy as np

from ..blender.viewport_session import current_state
from ..render.debug_draw import DebugDrawer, draw_debug, eye_of

_handle = None
_drawers: dict[str, DebugDrawer] = {}


def draw_callback() -> None:
    context = bpy.context
    scene = context.scene
    settings = getattr(scene, "voxgi_viewport", None)
    if settings is None or (settings.debug_view == "NONE" and not settings.show_bounds):
        return
    region_data = context.region_data
    state = current_state(scene.name_full)
    if region_data is None or state is None:
        return
    view = np.array(region_data.view_matrix, np.float64)
    window = np.array(region_data.window_matrix, np.float64)
    drawer = _drawers.get(scene.name_full)
    if drawer is None:
        drawer = _drawers[scene.name_full] = DebugDrawer()
    draw_debug(drawer, state, settings, window @ view, eye_of(view, window))


def handler_installed() -> bool:
    return _handle is not None


classes = ()


def register() -> None:
    global _handle
    if _handle is None:
        _handle = bpy.types.SpaceView3D.draw_handler_add(draw_callback, (), "WINDOW", "POST_VIEW")


def unregister() -> None:
    global _handle
    if _handle is not None:
        bpy.types.SpaceView3D.draw_handler_remove(_handle, "WINDOW")
        _handle = None
    for drawer in _drawers.values():
        drawer.free()
    _drawers.clear()
