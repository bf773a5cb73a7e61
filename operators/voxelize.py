"""``voxgi.voxelize``: snapshot the scene and build the per-mesh voxel caches.

The operator reads the scene (main thread) into a ``SceneSnapshot`` and hands only
that to the engine's ``build_scene_caches``, which runs on the engine worker thread
(``engine_jobs``); the engine never sees bpy. The outcome is applied on the main thread:
results and report lines go to the add-on session, not to ID properties. Interactively
the operator returns right after submitting; in background mode it waits for the job
and reports its lines like any synchronous operator.
"""
from __future__ import annotations

import traceback

import bpy

from ..blender import jobs as engine_jobs
from ..blender.operator_poll import VoxGISceneOperator
from ..blender.reports import cascade_lines, timing_line, warning_lines
from ..blender.session import scene_session
from ..blender.snapshot import snapshot_or_error, snapshot_summary
from ..render.pipeline import view_fit_for
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.voxelize.scene_caches import build_scene_caches

CANCELLED_MESSAGE = "Voxelization cancelled; previous caches kept"
JOB_LABEL = "Voxelizing"


class VOXGI_OT_voxelize(VoxGISceneOperator, bpy.types.Operator):
    """Voxelize every visible mesh at each cascade's span (Auto: the span fitted to the view) and keep the caches for this session"""  # noqa: E501 - the tooltip is one line

    bl_idname = "voxgi.voxelize"
    bl_label = "Voxelize"
    bl_options = {"REGISTER"}

    def execute(self, context):
        scene_name = context.scene.name_full
        settings = context.scene.voxgi
        base_span, cascade_count = settings.base_span, settings.cascade_count
        try:
            snapshot, snapshot_seconds = snapshot_or_error(context)
            fit = view_fit_for(context.scene, snapshot)  # Auto: the span fitted to the view
            if fit is not None:
                base_span, cascade_count = fit.base_span, fit.cascade_count
        except VoxGIError as error:
            engine_jobs.cancel(scene_name, discard=True)  # it would describe another scene
            _apply_error(scene_name, error)
            return self._finish(scene_session(scene_name).last_report, {"CANCELLED"})

        def job(cancel):  # worker thread: engine code on the snapshot only
            return build_scene_caches(snapshot, base_span=base_span,
                                      cascade_count=cascade_count, cancel=cancel)

        submitted = engine_jobs.submit(
            scene_name, job, label=JOB_LABEL,
            on_done=lambda result: _apply_result(scene_name, snapshot, snapshot_seconds, result),
            on_cancel=lambda: _apply_cancel(scene_name),
            on_error=lambda error: _apply_error(scene_name, error),
        )
        if submitted.state == "running":  # interactive: the timer applies it later
            count = len(snapshot.meshes)
            self.report({"INFO"}, f"Voxelizing {count} mesh{'es' if count != 1 else ''} "
                                  "in the background…")
            return {"FINISHED"}
        status = {"FINISHED"} if submitted.state == "done" else {"CANCELLED"}
        return self._finish(scene_session(scene_name).last_report, status)

    def _finish(self, lines, status):
        for level, message in lines:
            self.report({level}, message)
        return status


# Outcomes, applied on the main thread (by engine_jobs.drain).

def _apply_result(scene_name, snapshot, snapshot_seconds, result) -> None:
    session = scene_session(scene_name)
    timings = {"snapshot": snapshot_seconds, **result.timings}
    session.snapshot_summary = snapshot_summary(snapshot)
    session.caches = result
    session.span_caches = [result]  # caches of other spans may describe an older scene
    session.timings = timings
    session.last_report = [*cascade_lines(result), *warning_lines(snapshot.warnings, result),
                           timing_line(timings)]


def _apply_cancel(scene_name) -> None:
    scene_session(scene_name).last_report = [("INFO", CANCELLED_MESSAGE)]


def _apply_error(scene_name, error) -> None:
    session = scene_session(scene_name)
    if isinstance(error, VoxGIError):
        # Results of an earlier run no longer describe this scene.
        session.caches = session.snapshot_summary = None
        session.timings = {}
        session.last_report = [("ERROR", str(error))]
    else:  # a bug: keep the previous caches, say so, and leave the trace in the console
        traceback.print_exception(error)
        session.last_report = [("ERROR", f"Voxelization failed: {type(error).__name__}: {error} "
                                         "(see the system console)")]


classes = (VOXGI_OT_voxelize,)
