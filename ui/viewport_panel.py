"""The viewport parts of VoxGI's UI: the sidebar's Viewport panel, the draw helpers the Render
Properties panels share (``render_properties.py``), and Esc to cancel a running job.

Esc is an add-on keymap item of the 3D View calling ``voxgi.cancel_job``, whose poll fails
while no job runs, so the key then reaches Blender's own handlers unchanged.
"""
from __future__ import annotations

import bpy

from ..blender import jobs
from ..blender.viewport_session import peek_live_gi
from ..render import warmup_process

LEVEL_ICONS = {"ERROR": "CANCEL", "WARNING": "ERROR", "INFO": "INFO"}
VIEWPORT_SETTINGS = ("resolution_fraction", "samples", "coarse_first", "viewport_pass")


def split_column(layout):
    layout.use_property_split = True
    layout.use_property_decorate = False
    return layout.column()


def draw_viewport_settings(layout, scene) -> None:
    column = split_column(layout)
    for name in VIEWPORT_SETTINGS:
        column.prop(scene.voxgi_viewport, name)
    layout.operator("voxgi.refresh_viewport", icon="FILE_REFRESH")


def draw_debug_settings(layout, scene) -> None:
    settings = scene.voxgi_viewport
    column = split_column(layout)
    column.prop(settings, "debug_view")
    row = column.row()
    row.active = settings.debug_view != "NONE"
    row.prop(settings, "debug_level" if settings.debug_view == "OCTREE" else "debug_cascade")
    row = column.row()
    row.active = settings.debug_view != "NONE"
    row.prop(settings, "debug_colour")
    column.prop(settings, "show_bounds")


def progress_line(job) -> str:
    """'Updating viewport GI 42%: voxelizing 'Cube' (1.2 s)' for the sidebar."""
    progress = job.progress
    if job.cancel_requested:
        return f"Cancelling {job.label.lower()}…"
    done = "" if progress is None else f" {progress.fraction * 100:.0f}%"
    what = "" if progress is None or not progress.text else f": {progress.text}"
    return f"{job.label}{done}{what} ({job.elapsed:.1f} s)"


def draw_job(layout, scene) -> None:
    """The scene's running job as a percent line with its Cancel button (Esc does the same);
    the kernels' warm-up process while it runs (render/warmup_process.py)."""
    building = warmup_process.processes.status()
    if building:
        layout.label(text=building, icon="SORTTIME")
    job = jobs.running_job(scene.name_full)
    if job is None:
        return
    row = layout.box().row()
    row.label(text=progress_line(job), icon="SORTTIME")
    row.operator("voxgi.cancel_job", text="Cancel", icon="CANCEL")


def view_state_line(live) -> str:
    """What the Rendered view shows, for the sidebar: converged (all its samples), refining
    (sample N of M, a coarse first image before) or updating; "" before the first draw."""
    shown = live.view_shown
    if not shown:
        return ""
    if live.running is not None:
        return "Updating: the view shows the previous image"
    if shown == "World":
        return "The world alone: the view layer shows no mesh"
    done, target = getattr(live, "view_samples", (0, 0))
    if shown in ("Cached", "Converged"):
        return f"Converged: {target} of {target} samples"
    if shown == "Coarse":
        return "Refining: a coarse first image"
    if shown == "Refining":
        return f"Refining: sample {min(done + 1, target)} of {target}"
    return "The view shows the previous image"


def draw_live_stats(layout, scene) -> None:
    """The last viewport update: trigger, stages run, meshes voxelized, voxels and MB per
    cascade, octree nodes and MB, seconds per stage; the last error if one happened."""
    live = peek_live_gi(scene.name_full)
    if live is None:
        layout.label(text="No viewport update yet (switch a 3D view to Rendered)", icon="INFO")
        return
    if live.error:
        layout.label(text=live.error, icon=LEVEL_ICONS["ERROR"])
    view = view_state_line(live)
    if view:
        layout.label(text=view, icon="CHECKMARK" if view.startswith("Converged") else "SORTTIME")
    stats = live.stats
    if not stats.stages and not stats.triggers:
        return
    box = layout.box()
    box.label(text="Last update: " + ("; ".join(stats.triggers) or "—"), icon="LIGHT")
    box.label(text="Stages: " + ", ".join(stats.stages))
    box.label(text="Voxelized: " + (", ".join(stats.voxelized) or "nothing (caches reused)"))
    for index, span, voxels, megabytes in stats.cascades:
        row = box.row()
        row.label(text=f"Cascade {index} ({span:g} m)")
        row.label(text=f"{voxels:,} voxels")
        row.label(text=f"{megabytes:.2f} MB")
    row = box.row()
    row.label(text="Octree")
    row.label(text=f"{stats.octree_nodes:,} nodes")
    row.label(text=f"{stats.octree_mb:.2f} MB")
    row = box.row()
    row.label(text="Voxel caches")
    row.label(text=f"{stats.cache_mb:.2f} MB")
    counts = live.planned.snapshot()
    box.label(text="Stages scheduled: " + ", ".join(f"{k} {v}" for k, v in counts.items() if v))
    for name, seconds in stats.timings.items():
        row = box.row()
        row.label(text=name)
        row.label(text=f"{seconds * 1000:.1f} ms")


class VOXGI_PT_viewport(bpy.types.Panel):
    """Viewport resolution and pass, debug views, the running job and the last update."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "VoxGI"
    bl_idname = "VOXGI_PT_viewport"
    bl_label = "Viewport"
    bl_parent_id = "VOXGI_PT_main"

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "voxgi_viewport")

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        draw_viewport_settings(layout, scene)
        draw_debug_settings(layout, scene)
        draw_job(layout, scene)
        draw_live_stats(layout, scene)


classes = (VOXGI_PT_viewport,)
_keymap_items: list = []


def register() -> None:
    keyconfig = bpy.context.window_manager.keyconfigs.addon if bpy.context.window_manager else None
    if keyconfig is None:  # background mode: no key maps
        return
    keymap = keyconfig.keymaps.new(name="3D View", space_type="VIEW_3D")
    item = keymap.keymap_items.new("voxgi.cancel_job", "ESC", "PRESS")
    _keymap_items.append((keymap, item))


def unregister() -> None:
    for keymap, item in _keymap_items:
        keymap.keymap_items.remove(item)
    _keymap_items.clear()
