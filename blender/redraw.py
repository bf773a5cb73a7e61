"""Asking Blender to redraw the 3D views after new results, progress or a changed setting."""
from __future__ import annotations

import bpy


def view3d_areas():
    """Every 3D view area of every window."""
    for wm in bpy.data.window_managers:
        for window in wm.windows:
            if window.screen is None:
                continue
            yield from (area for area in window.screen.areas if area.type == "VIEW_3D")


def tag_3d_views(_self=None, _context=None) -> None:
    """Redraw every 3D view (also usable as a property's ``update`` callback)."""
    for area in view3d_areas():
        area.tag_redraw()


def tag_sidebars() -> None:
    """Redraw the sidebar (N panel) of every 3D view."""
    for area in view3d_areas():
        for region in area.regions:
            if region.type == "UI":
                region.tag_redraw()
