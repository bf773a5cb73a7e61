"""``import_scene.gfg``: File › Import › GFG (VoxGI) (.gfg).

Reads a GFG-like file (``docs/gfg.md``; every checksum and bound is verified first) and adds
its objects to the active collection: meshes, materials, armatures with pose and animation.
Voxel caches and probe grids are attached to the scene's VoxGI session.
"""
from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from ..blender.gfg.scene_import import ImportOptions, import_scene
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.files.gfg import read_gfg


class VOXGI_OT_import_gfg(bpy.types.Operator, ImportHelper):
    """Import a GFG file: meshes, materials, armatures with animation, and its VoxGI voxel caches and probes"""

    bl_idname = "import_scene.gfg"
    bl_label = "Import GFG"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".gfg"
    filter_glob: StringProperty(default="*.gfg", options={"HIDDEN"})

    import_animation: BoolProperty(name="Animation", default=True,
                                   description="Create actions for the file's skeletal animations")
    attach_voxel_caches: BoolProperty(name="Voxel Caches", default=True,
                                      description="Attach the file's voxel caches to this scene's VoxGI "
                                                  "session (replacing the caches it has)")
    attach_probes: BoolProperty(name="Light Probes", default=True,
                                description="Attach the file's light-probe grids to this scene's VoxGI session")

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to import (bones are built in Edit Mode)")
            return False
        return context.scene is not None

    def execute(self, context):
        path = bpy.path.abspath(self.filepath)
        warnings: list[str] = []
        try:
            gfg = read_gfg(path)
            summary = import_scene(context, gfg, ImportOptions(self.import_animation, self.attach_voxel_caches,
                                                               self.attach_probes),
                                   os.path.dirname(path), warnings)
        except (VoxGIError, OSError) as error:
            self.report({"ERROR"}, f"GFG import failed: {error}")
            return {"CANCELLED"}
        view_layer = context.view_layer
        for obj in view_layer.objects:
            obj.select_set(False)
        for obj in summary.objects:
            if obj.name in view_layer.objects:
                obj.select_set(True)
        if summary.objects:
            view_layer.objects.active = summary.objects[0]
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Imported {len(summary.objects)} objects, {summary.meshes} meshes, "
                              f"{summary.materials} materials, {summary.armatures} armatures, "
                              f"{summary.animations} animations, {summary.voxel_caches} voxel caches "
                              f"from {path}")
        return {"FINISHED"}


def _menu_entry(self, context):
    self.layout.operator(VOXGI_OT_import_gfg.bl_idname, text="GFG (VoxGI) (.gfg)")


classes = (VOXGI_OT_import_gfg,)


def register() -> None:
    bpy.types.TOPBAR_MT_file_import.append(_menu_entry)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_import.remove(_menu_entry)
