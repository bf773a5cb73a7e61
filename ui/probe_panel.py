"""The Light Probes sub-panel of the VoxGI sidebar (docs/probes.md)."""
from __future__ import annotations

import bpy

from ..blender import jobs as engine_jobs
from ..blender import probe_store
from ..blender.session import peek_session
from ..voxgi_addon.probes.grid import memory_report
from .panel import _settings_column, _SidebarPanel


class VOXGI_PT_probes(_SidebarPanel, bpy.types.Panel):
    """Probe placement and bake settings, the Bake Probes button, progress and the baked grids."""

    bl_idname = "VOXGI_PT_probes"
    bl_label = "Light Probes"
    bl_parent_id = "VOXGI_PT_main"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        _settings_column(layout, context, (
            "indirect_source", "probe_placement", "probe_resolution", "probe_directions",
            "probe_seed", "probe_masks", "probe_mask_threshold", "probe_validity",
            "probe_relocate", "probe_bake_method"))
        layout.operator("voxgi.bake_probes", icon="LIGHTPROBE_VOLUME")
        job = engine_jobs.running_job(scene.name_full)
        share = probe_store.progress(scene.name_full)
        if job is not None and share is not None:
            row = layout.box().row()
            row.label(text=f"{job.label}: {share:.0%} ({job.elapsed:.1f} s)", icon="SORTTIME")
            row.operator("voxgi.cancel_job", text="Cancel", icon="CANCEL")
        _settings_column(layout, context, ("probe_display", "probe_display_size", "probe_selected"))
        session = peek_session(scene.name_full)
        grids = session.probes if session is not None and session.probes else []
        for g in grids:
            box = layout.box()
            box.label(text=f"{g.name or 'Grid'}: {len(g.positions)} probes, "
                           f"{len(g.volume_cells)} volumes", icon="LIGHTPROBE_VOLUME")
            box.label(text=f"{memory_report(g)['total'] / 1024:.1f} KiB")


classes = (VOXGI_PT_probes,)
