"""``voxgi.render_preview``: one GI update, then the scene camera's passes (Cycles' names and
meanings) into one multilayer OpenEXR file, with per-stage timings. It is F12: the operator runs
``bpy.ops.render.render()`` with the VoxGI engine (``f12_settings``) and writes what that render
traced (``render.engine.captured``), so the scene is read as Blender renders it (modifiers at
their render levels and toggles, objects hidden in the viewport but not in renders), a Render
Region included: the region alone is traced, and the file holds it cropped, or placed into an
empty frame (Crop to Render Region off), as F12 writes it. The Render Result shows the preview."""
from __future__ import annotations

import os
from contextlib import contextmanager

import bpy
import numpy as np

from ..blender.operator_poll import VoxGISceneOperator
from ..blender.session import scene_session
from ..render.engine import captured, render_region
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.files.exr import write_exr


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
            if scene.camera is None:  # before Blender's own refusal, in the preview's words
                raise VoxGIError("the scene has no camera to render the preview from")
            source = None if self.indirect_source == "SCENE" else self.indirect_source
            with f12_settings(scene, width, height), captured(scene, source) as capture:
                try:
                    bpy.ops.render.render()
                except RuntimeError as error:  # Blender refused the render (one running …)
                    raise VoxGIError(str(error).strip()) from error
            if capture.error is not None or capture.passes is None:
                raise VoxGIError(capture.error or "the render did not run (is another render "
                                 "running?)")
            images = {name: image for name, image in capture.passes.items()
                      if name != "Alpha" and not name.startswith("_")}
            # the film: Combined RGBA with the world behind the geometry (or alpha with
            # Film › Transparent); the other passes as traced
            images["Combined"] = capture.combined
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
        session.last_report = [("INFO", message), *capture.report]
        for level, line in session.last_report:
            print(f"VoxGI: {line}" if not line.startswith("VoxGI") else line)
            self.report({level}, line)
        return {"FINISHED"}


@contextmanager
def f12_settings(scene, width: int, height: int):
    """The scene set to render its active view layer's preview at ``width`` × ``height`` with
    F12: the VoxGI engine, the one camera (no stereo views), the render itself (not the
    compositor's or the sequencer's image). Every setting is put back on exit."""
    render = scene.render
    wanted = {"engine": "VOXGI", "resolution_x": width, "resolution_y": height,
              "resolution_percentage": 100, "use_single_layer": True, "use_multiview": False,
              "use_compositing": False, "use_sequencer": False}
    before = {name: getattr(render, name) for name in wanted}
    try:
        for name, value in wanted.items():
            if before[name] != value:
                setattr(render, name, value)
        yield
    finally:
        for name, value in before.items():
            if getattr(render, name) != value:
                setattr(render, name, value)


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
