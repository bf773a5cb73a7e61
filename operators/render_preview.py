"""``voxgi.render_preview``: one GI update, then the scene camera's passes (Cycles' names and
meanings) into one multilayer OpenEXR file, with per-stage timings. Runs to completion (it is a
render) through the same ``render.pipeline`` as F12, Render Region included: the region alone
is traced, and the file holds it cropped, or placed into an empty frame (Crop to Render Region
off), as F12 writes it."""
from __future__ import annotations

import os

import bpy
import numpy as np

from ..blender.operator_poll import VoxGISceneOperator
from ..blender.session import scene_session
from ..blender.settings import pixel_filter_width
from ..render.engine import render_region
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
        region = render_region(scene, width, height)
        try:
            source = None if self.indirect_source == "SCENE" else self.indirect_source
            passes, lines = render_scene_passes(context, scene, None, width, height, source,
                                                region=region)
            # the film: Combined RGBA with the world behind the geometry (or alpha with
            # Film › Transparent); the other passes as traced
            combined = snapshot_combined(scene_session(scene.name_full).snapshot, passes,
                                         pixel_filter_width(scene))
            images = {name: image for name, image in passes.items()
                      if name != "Alpha" and not name.startswith("_")}
            images["Combined"] = combined
            if region is not None and not render.use_crop_to_border:
                images = {name: placed(image, region, width, height)
                          for name, image in images.items()}
            os.makedirs(os.path.dirname(os.path.abspath(path)) or ".", exist_ok=True)
            write_exr(path, images)
        except (VoxGIError, OSError) as error:
            self.report({"ERROR"}, f"GI preview failed: {error}")
            return {"CANCELLED"}
        session = scene_session(scene.name_full)
        size = (width, height) if region is None or not render.use_crop_to_border else region[2:]
        message = f"GI preview {size[0]}×{size[1]} written to {path}"
        session.last_report = [("INFO", message), *lines]
        for level, line in session.last_report:
            print(f"VoxGI: {line}" if not line.startswith("VoxGI") else line)
            self.report({level}, line)
        return {"FINISHED"}


def placed(image, region, width: int, height: int) -> np.ndarray:
    """A Render Region's ``image`` (h, w, …), row 0 on top, in an empty ``width`` × ``height``
    frame at ``region`` (x0, y0, w, h; pixels from the bottom left), as Blender places a region
    that is not cropped."""
    x0, y0, w, h = region
    image = np.asarray(image)
    frame = np.zeros((height, width) + image.shape[2:], image.dtype)
    frame[height - y0 - h:height - y0, x0:x0 + w] = image
    return frame


classes = (VOXGI_OT_render_preview,)
