"""The VoxGI engine's settings in Render Properties (shown when the render engine is VoxGI):
voxels and cascades, cone tracing, the viewport, debug views and the last update's statistics.
The same settings live in the 3D view's sidebar (``panel.py``, ``viewport_panel.py``)."""
from __future__ import annotations

import bpy

from .viewport_panel import draw_debug_settings, draw_job, draw_live_stats, draw_viewport_settings, split_column

VOXEL_SETTINGS = ("base_span", "cascade_count", "grid_resolution", "view_ahead", "dense_depth")
CONE_SETTINGS = ("quality", "gi_rays", "bounce_source", "bounces", "glossy_indirect", "cone_angle", "diffuse_cones",
                 "sample_factor", "falloff", "max_distance", "ao_distance", "gi_intensity",
                 "ao_intensity", "light_samples", "shadows", "gi_resolution", "sparse_gathers", "seed",
                 "use_animated_seed", "tracer")


class _RenderPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"VOXGI"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and hasattr(context.scene, "voxgi")


class VOXGI_PT_render_voxels(_RenderPanel, bpy.types.Panel):
    bl_label = "Voxels"
    bl_idname = "VOXGI_PT_render_voxels"

    def draw(self, context):
        column = split_column(self.layout)
        for name in VOXEL_SETTINGS:
            column.prop(context.scene.voxgi, name)
        self.layout.operator("voxgi.voxelize", icon="MESH_GRID")


class VOXGI_PT_render_cones(_RenderPanel, bpy.types.Panel):
    bl_label = "Cone Tracing"
    bl_idname = "VOXGI_PT_render_cones"

    def draw(self, context):
        column = split_column(self.layout)
        for name in CONE_SETTINGS:
            column.prop(context.scene.voxgi, name)


class VOXGI_PT_render_viewport(_RenderPanel, bpy.types.Panel):
    bl_label = "Viewport"
    bl_idname = "VOXGI_PT_render_viewport"

    def draw(self, context):
        draw_viewport_settings(self.layout, context.scene)
        draw_job(self.layout, context.scene)


class VOXGI_PT_render_debug(_RenderPanel, bpy.types.Panel):
    bl_label = "Debug Views"
    bl_idname = "VOXGI_PT_render_debug"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_debug_settings(self.layout, context.scene)


class VOXGI_PT_render_stats(_RenderPanel, bpy.types.Panel):
    bl_label = "Statistics"
    bl_idname = "VOXGI_PT_render_stats"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        draw_live_stats(self.layout, context.scene)


classes = (VOXGI_PT_render_voxels, VOXGI_PT_render_cones, VOXGI_PT_render_viewport,
           VOXGI_PT_render_debug, VOXGI_PT_render_stats)
