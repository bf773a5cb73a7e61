"""``voxgi.update``: transform the voxel caches into cascades, inject direct light, rebuild the
octree, on the engine worker. The main thread takes the snapshot — a posed one when only
matrices, poses, lights, camera or world changed since the last (docs/gi_pipeline.md "Posed
updates") — and, in Auto mode, the first view fit; later fits run on the worker. The caches of
the span are reused, voxelizing first when there are none."""
from __future__ import annotations

import time

import bpy

from ..blender import jobs as engine_jobs
from ..blender.operator_poll import VoxGISceneOperator
from ..blender.reports import coverage_lines, octree_text, timing_text
from ..blender.session import scene_session
from ..blender.snapshot import snapshot_or_error
from ..blender.snapshot.left_out import is_left_out
from ..render.pipeline import gi_inputs, keep_caches, refit_on_worker, refitted_inputs, view_shares
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.gi.update import update_gi


class VOXGI_OT_update(VoxGISceneOperator, bpy.types.Operator):
    """Transform the voxel caches into cascades fitted to the view (or anchored on the camera), inject direct light and rebuild the octree for the current frame"""  # noqa: E501 - the tooltip is one line

    bl_idname = "voxgi.update"
    bl_label = "Update GI"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene_name = context.scene.name_full
        view_ahead = context.scene.voxgi.view_ahead
        try:
            # Only what moved is read when nothing else changed, and after a first fit the view
            # is fitted again on the worker: the main thread's share is the snapshot
            # (docs/gi_pipeline.md "Posed updates").
            snapshot, snap_seconds = snapshot_or_error(context, posed=True)
            refit = refit_on_worker(context.scene, snapshot)
            inputs = gi_inputs(context, snapshot) if refit is None else None
        except VoxGIError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        # what did not change since the last update is taken from it (update_gi checks what)
        previous = scene_session(scene_name).gi_state

        def job(cancel):  # worker thread: engine code only
            start = time.perf_counter()
            caches, settings, anchor, fit = inputs or refitted_inputs(snapshot, *refit)
            fitted = time.perf_counter() - start
            state = update_gi(snapshot, caches, settings, cancel=cancel, anchor=anchor,
                              previous=previous)
            if refit is not None:
                state.timings = {"view fit": fitted, **state.timings}
            state.view_shares = view_shares(snapshot, state.grids, fit)
            return state, caches, fit

        def done(result):
            state, caches, fit = result
            session = scene_session(scene_name)
            if refit is not None:  # what gi_inputs keeps on the main thread
                session.view_fit = fit
                keep_caches(session, caches)
            session.gi_state = state
            session.gi_timings = {"snapshot": snap_seconds, **state.timings}
            counts = ", ".join(f"{n:,}" for n in state.voxel_counts)
            session.last_report = [("INFO", f"GI updated: cascade voxels {counts}"
                                            f"{reuse_text(state)}"),
                                   *coverage_lines(state, fit, view_ahead),
                                   ("INFO", f"octree: {octree_text(state.octree)}"),
                                   ("INFO", timing_text(session.gi_timings)),
                                   *[("WARNING", w) for w in (*(fit.warnings if fit else ()),
                                                              *state.warnings)],
                                   # what the preview leaves out, once per object
                                   *[("WARNING", w) for w in dict.fromkeys(snapshot.warnings)
                                     if is_left_out(w)]]

        def failed(error):
            scene_session(scene_name).last_report = [("ERROR", str(error))]

        submitted = engine_jobs.submit(scene_name, job, label="Updating GI", on_done=done,
                                       on_error=failed)
        if submitted.state == "running":
            self.report({"INFO"}, "Updating GI in the background…")
            return {"FINISHED"}
        for level, message in scene_session(scene_name).last_report:
            self.report({level}, message)
        return {"FINISHED"} if submitted.state == "done" else {"CANCELLED"}


def reuse_text(state) -> str:
    """What the update took from the previous one, for the report line."""
    if state.reused == "all":
        return " (nothing changed: the previous cascades, light and octree kept)"
    if state.reused == "objects":
        moved = ", ".join(f"'{n}'" for n in state.placed_objects[:3])
        more = len(state.placed_objects) - 3
        moved += f" and {more} more" if more > 0 else ""
        return f" (transformed {moved or 'no object'}; the other objects' voxels kept)"
    return ""


classes = (VOXGI_OT_update,)
