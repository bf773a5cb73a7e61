"""``voxgi.cancel_job``: stop the scene's background job, keeping the previous results."""
from __future__ import annotations

import bpy

from ..blender import jobs


class VOXGI_OT_cancel_job(bpy.types.Operator):
    """Stop the scene's background VoxGI job; the results of the previous run are kept"""

    bl_idname = "voxgi.cancel_job"
    bl_label = "Cancel"
    bl_options = {"REGISTER"}

    @classmethod
    def poll(cls, context):
        job = None if context.scene is None else jobs.running_job(context.scene.name_full)
        if job is None:
            cls.poll_message_set("No VoxGI job is running for this scene")
            return False
        if job.cancel_requested:
            cls.poll_message_set("The job is already being cancelled")
            return False
        return True

    def execute(self, context):
        jobs.cancel(context.scene.name_full)
        jobs.drain()
        jobs.tag_sidebars()
        return {"FINISHED"}


classes = (VOXGI_OT_cancel_job,)
