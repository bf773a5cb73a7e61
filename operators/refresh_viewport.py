"""``voxgi.refresh_viewport``: read the whole scene again and rebuild the viewport's GI (the
caches whose fingerprint is unchanged are kept; ``blender/viewport_session.py``)."""
from __future__ import annotations

import bpy

from ..blender import jobs
from ..blender.viewport_session import live_gi


class VOXGI_OT_refresh_viewport(bpy.types.Operator):
    """Read the whole scene again and rebuild the viewport's global illumination"""

    bl_idname = "voxgi.refresh_viewport"
    bl_label = "Refresh Viewport GI"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        scene = context.scene
        if scene is None or not hasattr(scene, "voxgi"):
            cls.poll_message_set("No scene with VoxGI settings")
            return False
        if scene.render.engine != "VOXGI":
            cls.poll_message_set("Set the render engine to VoxGI (Render Properties) to see "
                                 "live GI in the viewport")
            return False
        if jobs.running_job(scene.name_full) is not None:
            cls.poll_message_set("A VoxGI job is running for this scene: wait or cancel it")
            return False
        return True

    def execute(self, context):
        scene = context.scene
        live = live_gi(scene.name_full)
        live.rescan = "refresh requested"
        live.update(scene, context.evaluated_depsgraph_get(), records=[])
        if live.error:
            self.report({"ERROR"}, live.error)
            return {"CANCELLED"}
        return {"FINISHED"}


classes = (VOXGI_OT_refresh_viewport,)
