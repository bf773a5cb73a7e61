"""``voxgi.voxelize``: snapshot the scene and build the per-mesh voxel caches.

The operator reads the scene (main thread) into a ``SceneSnapshot`` and hands only
that to the engine's ``build_scene_caches``; the engine never sees bpy. For now the
engine runs synchronously; a background worker will take over later, with the same
snapshot/engine split. Results go to the add-on session, not to ID properties.
"""
from __future__ import annotations

import time

import bpy

from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.mesh_caches import build_scene_caches
from .scene_snapshot import snapshot_summary, take_snapshot
from .session import scene_session
from .voxelize_report import cascade_lines, timing_line, warning_lines

NO_MESH_MESSAGE = (
    "Nothing to voxelize: the view layer has no visible mesh object with faces "
    "(add one, or unhide it)"
)


class VOXGI_OT_voxelize(bpy.types.Operator):
    """Voxelize every visible mesh at each cascade's span and keep the caches for this session"""

    bl_idname = "voxgi.voxelize"
    bl_label = "Voxelize"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        if context.scene is None or not hasattr(context.scene, "voxgi"):
            cls.poll_message_set("No scene with VoxGI settings")
            return False
        return True

    def execute(self, context):
        scene = context.scene
        session = scene_session(scene.name_full)
        session.last_report = lines = []
        try:
            result, snapshot, timings = self._run(context)
        except VoxGIError as error:
            # Results of an earlier run no longer describe this scene.
            session.caches = session.snapshot_summary = None
            session.timings = {}
            lines.append(("ERROR", str(error)))
            return self._finish(lines, {"CANCELLED"})
        session.snapshot_summary = snapshot_summary(snapshot)
        session.caches = result
        session.timings = timings
        lines += cascade_lines(result)
        lines += warning_lines(snapshot.warnings, result)
        lines.append(timing_line(timings))
        return self._finish(lines, {"FINISHED"})

    @staticmethod
    def _run(context):
        """Snapshot then engine. Returns (result, snapshot, timings); raises VoxGIError."""
        settings = context.scene.voxgi
        start = time.perf_counter()
        snapshot = take_snapshot(context, context.evaluated_depsgraph_get())
        snapshot_seconds = time.perf_counter() - start
        if not snapshot.objects:
            details = "; ".join(snapshot.warnings)
            raise VoxGIError(NO_MESH_MESSAGE + (f". {details}" if details else ""))
        result = build_scene_caches(
            snapshot, base_span=settings.base_span, cascade_count=settings.cascade_count
        )
        timings = {"snapshot": snapshot_seconds, **result.timings}
        return result, snapshot, timings

    def _finish(self, lines, status):
        for level, message in lines:
            self.report({level}, message)
        return status


classes = (VOXGI_OT_voxelize,)
