"""The VoxGI sidebar panel of the 3D view (N panel, tab 'VoxGI')."""
from __future__ import annotations

import bpy

from ..blender import jobs as engine_jobs
from ..blender.reports import MEGABYTE, cascade_cover_rows, panel_lines
from ..blender.session import peek_session
from ..blender.snapshot.left_out import MARK, is_left_out

LEVEL_ICONS = {"ERROR": "CANCEL", "WARNING": "ERROR", "INFO": "INFO"}


class _SidebarPanel:
    """Where VoxGI's panels live (3D view sidebar, tab 'VoxGI') and when they show."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "VoxGI"

    @classmethod
    def poll(cls, context):
        return context.scene is not None and hasattr(context.scene, "voxgi")


def _settings_column(layout, context, names):
    """Lay out the named ``Scene.voxgi`` settings in Blender's split style."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    column = layout.column()
    for name in names:
        column.prop(context.scene.voxgi, name)


class VOXGI_PT_main(_SidebarPanel, bpy.types.Panel):
    """Settings, the Voxelize button, the running job and the last run's statistics."""

    bl_idname = "VOXGI_PT_main"
    bl_label = "VoxGI"

    def draw(self, context):
        layout = self.layout
        if context.scene.voxgi.span_mode == "AUTO":
            names = ("span_mode", "memory_budget", "cascade_count")
        else:
            names = ("span_mode", "base_span", "cascade_count", "grid_resolution")
        _settings_column(layout, context, names)
        row = layout.row(align=True)
        row.operator("voxgi.voxelize", icon="MESH_GRID")
        row.operator("voxgi.add_demo_scene", text="", icon="SCENE_DATA")
        _draw_job(layout, engine_jobs.running_job(context.scene.name_full))
        _draw_results(layout, peek_session(context.scene.name_full))


def _draw_job(layout, job) -> None:
    """The running background job: what, for how long, and its Cancel button."""
    if job is None:
        return
    row = layout.box().row()
    text = "Cancelling" if job.cancel_requested else job.label
    row.label(text=f"{text}… {job.elapsed:.1f} s", icon="SORTTIME")
    row.operator("voxgi.cancel_job", text="Cancel", icon="CANCEL")


def _draw_results(layout, session) -> None:
    if session is None:
        return
    result = session.caches
    if result is not None:
        box = layout.box()
        box.label(text="Voxel caches", icon="MESH_GRID")
        for stats in result.cascade_stats:
            row = box.row()
            row.label(text=f"Cascade {stats.cascade} ({stats.span:g} m)")
            row.label(text=f"{stats.voxel_count:,} voxels")
            row.label(text=f"{stats.nbytes / MEGABYTE:.2f} MB")
        row = box.row()
        row.label(text="Total")
        row.label(text=f"{result.total_voxels:,} voxels")
        row.label(text=f"{result.total_bytes / MEGABYTE:.2f} MB")
    # What the preview leaves out, each object once (blender/snapshot/left_out.py), in its
    # own box so that other messages do not push it out.
    missing = list(dict.fromkeys(m for _, m in session.last_report if is_left_out(m)))
    if missing:
        box = layout.box()
        box.label(text="Not rendered by the preview yet", icon="ERROR")
        for message in missing:  # the object, then what of it (the sidebar is narrow)
            name, what = message.split(MARK, 1)
            box.label(text=f"{name}:")
            box.label(text=f"    {what}")
    # Background runs cannot reach the Info editor: the last run's messages are shown here.
    lines, left_out = panel_lines([(level, m) for level, m in session.last_report
                                   if not is_left_out(m)])
    if lines:
        column = layout.column(align=True)
        for level, message in lines:
            column.label(text=message, icon=LEVEL_ICONS.get(level, "INFO"))
        if left_out:
            column.label(text=f"… and {left_out} more")
    if result is not None and session.timings:
        box = layout.box()
        box.label(text="Stage timings", icon="TIME")
        for name, seconds in session.timings.items():
            row = box.row()
            row.label(text=name)
            row.label(text=f"{seconds * 1000:.1f} ms")


class VOXGI_PT_gi(_SidebarPanel, bpy.types.Panel):
    """Cascades, cones, the Update / Render Preview buttons and the last update's statistics."""

    bl_idname = "VOXGI_PT_gi"
    bl_label = "Global Illumination"
    bl_parent_id = "VOXGI_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.voxgi
        manual = ("view_ahead",) if settings.span_mode == "MANUAL" else ()
        # Accurate traces exact rays for every pass: the cone and voxel settings apply to Fast
        # only. Both read the radiance cache (Bounces).
        trace = (("gi_rays", "bounce_source", "bounces") if settings.quality == "ACCURATE"
                 else ("bounce_source", "bounces", "diffuse_cones", "falloff", "gi_intensity",
                       "ao_intensity", "shadows", *manual, "dense_depth", "cone_angle",
                       "sample_factor", "max_distance"))
        _settings_column(layout, context, (
            "quality", *trace, "glossy_indirect", "ao_distance", "light_samples", "gi_resolution", "sparse_gathers",
            "seed", "use_animated_seed", "tracer"))
        row = layout.row(align=True)
        row.operator("voxgi.update", icon="FILE_REFRESH")
        row.operator("voxgi.render_preview", icon="RENDER_STILL")
        _draw_gi_state(layout, peek_session(context.scene.name_full))


def _draw_gi_state(layout, session) -> None:
    """Voxels per cascade and octree memory of the last voxel update, then the tracer, GPU
    memory and stage timings of the last preview."""
    if session is None:
        return
    state = session.gi_state
    if state is not None:
        box = layout.box()
        box.label(text="Last update", icon="LIGHT")
        fit = session.view_fit
        box.label(text="Auto: fitted to the view" if fit is not None else
                  "Manual: anchored ahead of the camera")
        # Per cascade: span, extent, share of the visible points it is the finest cascade of.
        for name, extent, share, count in cascade_cover_rows(state):
            row = box.row()
            row.label(text=name)
            row.label(text=extent.split(",")[0])
            row.label(text=share.replace(" of the view", " of view"))
            row.label(text=count)
        stats = state.octree.stats()
        row = box.row()
        row.label(text=f"Octree: {len(stats)} levels")
        row.label(text=f"{sum(s.nodes for s in stats):,} nodes")
        row.label(text=f"{sum(s.bytes for s in stats) / MEGABYTE:.2f} MB")
    if not (session.tracer_used or session.gi_timings):
        return
    box = layout.box()
    row = box.row()
    if session.tracer_used:
        row.label(text=f"Last preview traced with: {session.tracer_used}", icon="RENDER_STILL")
    if session.tracer_used == "GPU":
        from ..render.gpu_bvh import shared_bvh

        volume = session.gpu_volume
        if volume is not None and volume.resident_bytes:
            row.label(text=f"atlas {volume.resident_bytes / MEGABYTE:.1f} MB on the GPU")
        if shared_bvh().resident_bytes:
            row.label(text=f"BVH {shared_bvh().resident_bytes / MEGABYTE:.1f} MB on the GPU")
    for name, seconds in session.gi_timings.items():
        row = box.row()
        row.label(text=name)
        row.label(text=f"{seconds * 1000:.1f} ms")


classes = (VOXGI_PT_main, VOXGI_PT_gi)
