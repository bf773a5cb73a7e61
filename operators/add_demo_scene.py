"""``voxgi.add_demo_scene``: add the demo Cornell box (``blender/demo_scene.py``)."""
from __future__ import annotations

import bpy

from ..blender.demo_scene import build_demo_scene


class VOXGI_OT_add_demo_scene(bpy.types.Operator):
    """Add a Cornell box with a skinned tube, a rotating sphere, a light and a camera"""

    bl_idname = "voxgi.add_demo_scene"
    bl_label = "Add VoxGI Demo Scene"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if context.scene is None:
            return False
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to add the demo scene")
            return False
        return True

    def execute(self, context):
        try:
            objects = build_demo_scene(context.scene)
        except RuntimeError as error:  # bpy raises RuntimeError when an edit is refused
            self.report({"ERROR"}, f"Could not build the demo scene: {error}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Added the VoxGI demo scene ({len(objects)} objects)")
        return {"FINISHED"}


classes = (VOXGI_OT_add_demo_scene,)
