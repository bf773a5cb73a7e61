"""``voxgi.render_preview``: one GI update, then the scene camera's passes (Cycles' names and
meanings) into one multilayer OpenEXR file, with per-stage timings. Runs to completion (it is a
render) through the same ``render.pipeline`` as F12."""
from __future__ import annotations

import os

import bpy

from ..blender.operator_poll import VoxGISceneOperator
from ..blender.session import scene_session
from ..blender.settings import pixel_filter_width
from ..render.pipeline import render_scene_passes
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.files.exr import write_exr
from ..voxgi_addon.preview.film import snapshot_combined


class VOXGI_OT_render_preview(VoxGISceneOperator, bpy.types.Operator):
    """Render the GI preview of the scene camera to a multilayer OpenEXR file with Cycles-named passes"""

    bl_idname = "voxgi.render_preview"
    bl_label = "Render GI Preview"
    bl_options = {"REGISTER"}

    filepath: bpy.props.StringProperty(name="File Path", description="Output .exr file",
                                       subtype="FILE_PATH", default="//voxgi_preview.exr")
    resolution_x: bpy.props.IntProperty(name="Width", description="Image width in pixels; "
                                        "0 = the scene's", default=0, min=0, max=8192)
    resolution_y: bpy.props.IntProperty(name="Height", description="Image height in pixels; "
                                        "0 = the scene's", default=0, min=0, max=8192)
    indirect_source: bpy.props.EnumProperty(
        name="Indirect Light", description="Where Diffuse Indirect comes from",
        items=(("SCENE", "Scene Setting", "The scene's Indirect Light setting"),
               ("CONES", "Cone Tracing", "Cones through the voxel octree"),
               ("PROBES", "Light Probes", "The baked light probes")),
        default="SCENE")

    def execute(self, context):
        scene = context.scene
        render = scene.render
        width = self.resolution_x or render.resolution_x * render.resolution_percentage // 100
        height = self.resolution_y or render.resolution_y * render.resolution_percentage // 100
        path = bpy.path.abspath(self.filepath)
        try:
            source = None if self.indirect_source == "SCENE" else self.indirect_source
            passes, lines = render_scene_passes(context, scene, None, width, height, source)
            # the film: Combined RGBA with the world behind the geometry (or alpha with
            # Film › Transparent); the other passes as traced
            combined = snapshot_combined(scene_session(scene.name_full).snapshot, passes,
                                         pixel_filter_width(scene))
            images = {name: image for name, image in passes.items()
                      if name != "Alpha" and not name.startswith("_")}
            images["Combined"] = combined
            os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
            write_exr(path, images)
        except (VoxGIError, OSError) as error:
            self.report({"ERROR"}, f"GI preview failed: {error}")
            return {"CANCELLED"}
        session = scene_session(scene.name_full)
        message = f"GI preview {width}×{height} written to {path}"
        session.last_report = [("INFO", message), *lines]
        for level, line in session.last_report:
            print(f"VoxGI: {line}" if not line.startswith("VoxGI") else line)
            self.report({level}, line)
        return {"FINISHED"}


classes = (VOXGI_OT_render_preview,)
