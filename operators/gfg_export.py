"""``export_scene.gfg``: File › Export › GFG (VoxGI) (.gfg).

Writes the scene (or the selection) as a GFG-like file (``docs/gfg.md``): GPU-ready meshes,
materials, armatures with pose and animation, and the VoxGI session's voxel caches and probe
grids. The file is written next to its target and renamed into place, so a failed export
never leaves half a file.
"""
from __future__ import annotations

import os

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ExportHelper

from ..blender.gfg.scene_export import ExportOptions, export_scene
from ..voxgi_addon.errors import VoxGIError
from ..voxgi_addon.files.gfg import VertexTypes, write_gfg

POSITION_ITEMS = (
    ("FLOAT_3", "Float", "32-bit floats (exact)"),
    ("HALF_3", "Half", "16-bit floats"),
)
NORMAL_ITEMS = (
    ("FLOAT_3", "Float", "32-bit floats (exact)"),
    ("NORM16_4", "16-bit Normalized", "Signed 16-bit integers per component"),
    ("NORM_2_10_10_10", "10-bit Packed", "One 32-bit word: 10 bits per component"),
    ("CUSTOM_1_15N_16N", "X/Y Packed", "One 32-bit word: x 16 bits, y 15 bits, the sign of z"),
)
UV_ITEMS = (
    ("FLOAT_2", "Float", "32-bit floats (exact)"),
    ("HALF_2", "Half", "16-bit floats"),
    ("UNORM16_2", "16-bit Normalized", "Unsigned 16-bit integers; UVs outside 0..1 are clamped"),
)
WEIGHT_ITEMS = (
    ("UNORM8_4", "8-bit", "Four 8-bit weights summing to 255 (the thesis' runtime)"),
    ("UNORM16_4", "16-bit", "Four 16-bit weights summing to 65535"),
    ("FLOAT_4", "Float", "Four 32-bit floats (16-bit precision, summing to 1)"),
)
WEIGHT_INDEX_ITEMS = (
    ("UINT8_4", "8-bit", "Bone indices as bytes (up to 256 bones)"),
    ("UINT16_4", "16-bit", "Bone indices as 16-bit integers"),
)
LAYOUT_ITEMS = (
    ("INTERLEAVED", "Interleaved", "One vertex buffer holding every component (one upload)"),
    ("SEPARATE", "Separate", "One buffer per component (struct of arrays)"),
)


class VOXGI_OT_export_gfg(bpy.types.Operator, ExportHelper):
    """Export the scene as a GFG file: GPU-ready meshes, materials, armatures with animation, and VoxGI voxel caches and probes"""  # noqa: E501 - the tooltip is one line

    bl_idname = "export_scene.gfg"
    bl_label = "Export GFG"
    bl_options = {"PRESET"}

    filename_ext = ".gfg"
    filter_glob: StringProperty(default="*.gfg", options={"HIDDEN"})

    use_selection: BoolProperty(name="Selected Only", default=False,
                                description="Export only selected objects (and the armatures deforming them)")
    use_apply_modifiers: BoolProperty(name="Apply Modifiers", default=True,
                                      description="Export meshes as the modifiers shape them (Armature "
                                                  "modifiers become skinning when the skeleton is exported)")
    export_skeleton: BoolProperty(name="Skeleton", default=True,
                                  description="Export armatures, skin weights and poses; off: skinned meshes "
                                              "are exported in their current pose")
    export_animation: BoolProperty(name="Animation", default=True,
                                   description="Export each armature's active action (bone rotations and "
                                               "the root bone's location)")
    sample_animation: BoolProperty(name="Sample Every Frame", default=True,
                                   description="Key every frame of the action's range (plays back exactly "
                                               "at whole frames); off: only the frames that have keys")
    export_voxel_caches: BoolProperty(name="Voxel Caches", default=True,
                                      description="Include the voxel caches of this scene's last Voxelize run")
    export_probes: BoolProperty(name="Light Probes", default=True,
                                description="Include this scene's light-probe grids (when it has any)")
    position_type: EnumProperty(name="Positions", items=POSITION_ITEMS, default="FLOAT_3",
                                description="Storage of vertex positions")
    normal_type: EnumProperty(name="Normals", items=NORMAL_ITEMS, default="FLOAT_3",
                              description="Storage of vertex normals")
    uv_type: EnumProperty(name="UVs", items=UV_ITEMS, default="FLOAT_2", description="Storage of UVs")
    weight_type: EnumProperty(name="Weights", items=WEIGHT_ITEMS, default="UNORM8_4",
                              description="Storage of the four bone weights of a skinned vertex")
    weight_index_type: EnumProperty(name="Bone Indices", items=WEIGHT_INDEX_ITEMS, default="UINT8_4",
                                    description="Storage of the four bone indices of a skinned vertex")
    vertex_layout: EnumProperty(name="Layout", items=LAYOUT_ITEMS, default="INTERLEAVED",
                                description="How vertex components are laid out in the file")

    @classmethod
    def poll(cls, context):
        if context.mode != "OBJECT":
            cls.poll_message_set("Switch to Object Mode to export (bones are read in Edit Mode)")
            return False
        return context.scene is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        header, body = layout.panel("VOXGI_gfg_export_include", default_closed=False)
        header.label(text="Include")
        if body:
            body.prop(self, "use_selection")
            body.prop(self, "export_voxel_caches")
            body.prop(self, "export_probes")
        header, body = layout.panel("VOXGI_gfg_export_mesh", default_closed=False)
        header.label(text="Mesh")
        if body:
            body.prop(self, "use_apply_modifiers")
            for name in ("position_type", "normal_type", "uv_type", "vertex_layout"):
                body.prop(self, name)
        header, body = layout.panel("VOXGI_gfg_export_armature", default_closed=False)
        header.label(text="Armature")
        if body:
            body.prop(self, "export_skeleton")
            column = body.column()
            column.enabled = self.export_skeleton
            for name in ("weight_type", "weight_index_type", "export_animation"):
                column.prop(self, name)
            row = column.row()
            row.enabled = self.export_animation
            row.prop(self, "sample_animation")

    def export_options(self) -> ExportOptions:
        return ExportOptions(
            selected_only=self.use_selection, apply_modifiers=self.use_apply_modifiers,
            include_skeleton=self.export_skeleton, include_animation=self.export_animation,
            sample_animation=self.sample_animation, include_voxel_caches=self.export_voxel_caches,
            include_probes=self.export_probes,
            vertex_types=VertexTypes(self.position_type, self.normal_type, self.uv_type, self.weight_type,
                                     self.weight_index_type),
            interleaved=self.vertex_layout == "INTERLEAVED")

    def execute(self, context):
        path = bpy.path.abspath(self.filepath)
        partial = path + ".partial"
        try:
            gfg, warnings = export_scene(context, self.export_options(), os.path.dirname(path))
            size = write_gfg(partial, gfg)
            os.replace(partial, path)
        except (VoxGIError, OSError) as error:
            if os.path.exists(partial):
                os.remove(partial)
            self.report({"ERROR"}, f"GFG export failed: {error}")
            return {"CANCELLED"}
        for warning in warnings:
            self.report({"WARNING"}, warning)
        caches = 0 if gfg.voxels is None else len(gfg.voxels.caches)
        self.report({"INFO"}, f"Exported {len(gfg.nodes)} objects, {len(gfg.meshes)} meshes, "
                              f"{len(gfg.skeletons)} skeletons, {len(gfg.animations)} animations, "
                              f"{caches} voxel caches ({size / 1e6:.2f} MB) to {path}")
        return {"FINISHED"}


def _menu_entry(self, context):
    self.layout.operator(VOXGI_OT_export_gfg.bl_idname, text="GFG (VoxGI) (.gfg)")


classes = (VOXGI_OT_export_gfg,)


def register() -> None:
    bpy.types.TOPBAR_MT_file_export.append(_menu_entry)


def unregister() -> None:
    bpy.types.TOPBAR_MT_file_export.remove(_menu_entry)
