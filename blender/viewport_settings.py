"""Viewport settings of VoxGI: ``Scene.voxgi_viewport`` (a ``VoxGIViewportSettings``).

Kept apart from ``Scene.voxgi`` (``settings.py``: voxelization, cascades, cones) because
they change only what the 3D view shows: how large the viewport's GI image is, which pass it
shows, and the debug views drawn over any shading mode.
"""
# No `from __future__ import annotations` here: bpy property annotations must stay objects.
import bpy

from .redraw import tag_3d_views

# Enum identifier → the Cycles-named pass the viewport draws.
VIEWPORT_PASSES = {
    "COMBINED": "Combined",
    "DIFFUSE_INDIRECT": "Diffuse Indirect",
    "AMBIENT_OCCLUSION": "Ambient Occlusion",
    "GLOSSY_INDIRECT": "Glossy Indirect",
    "DIFFUSE_DIRECT": "Diffuse Direct",
}
DEBUG_VIEWS = ("NONE", "VOXELS", "OCTREE")
DEBUG_COLOURS = ("ALBEDO", "NORMAL", "OCCLUSION", "LIGHT")


class VoxGIViewportSettings(bpy.types.PropertyGroup):
    """What the 3D view shows of VoxGI."""

    resolution_fraction: bpy.props.FloatProperty(
        name="Viewport Resolution",
        description="Trace the viewport's GI at this fraction of the 3D view's size in pixels "
                    "(scaled up to fill it); lower is faster",
        subtype="FACTOR", default=0.25, min=0.05, max=1.0, update=tag_3d_views,
    )
    samples: bpy.props.IntProperty(
        name="Viewport Samples",
        description="Samples the Rendered view accumulates before it stops refining; each "
                    "redraw traces a small slice of one sample (a tile), so the view never "
                    "freezes. The samples share F12's rays (GI Rays, Light Samples) and each "
                    "has its own sub-pixel offset, so the converged view is F12's image",
        default=16, min=1, max=4096, update=tag_3d_views,
    )
    coarse_first: bpy.props.BoolProperty(
        name="Coarse First Image",
        description="After a change of the view, the scene or a setting, first trace the whole "
                    "view at low resolution (one slice) so it shows at once; off: the previous "
                    "image stays under the new tiles until they cover it",
        default=True, update=tag_3d_views,
    )
    viewport_pass: bpy.props.EnumProperty(
        name="Pass",
        description="Which pass the Rendered viewport shows",
        items=[(key, name, f"Show the {name} pass") for key, name in VIEWPORT_PASSES.items()],
        default="COMBINED", update=tag_3d_views,
    )
    debug_view: bpy.props.EnumProperty(
        name="Debug View",
        description="Draw VoxGI's voxels over the 3D view in any shading mode",
        items=(("NONE", "None", "No debug drawing"),
               ("VOXELS", "Cascade Voxels", "The voxels of one cascade as cubes"),
               ("OCTREE", "Octree Nodes", "The nodes of one octree level as cubes")),
        default="NONE", update=tag_3d_views,
    )
    debug_cascade: bpy.props.IntProperty(
        name="Cascade", description="Which cascade's voxels to draw (0 = finest)",
        default=0, min=0, max=7, update=tag_3d_views,
    )
    debug_level: bpy.props.IntProperty(
        name="Octree Level", description="Which octree level's nodes to draw (0 = the root)",
        default=6, min=0, max=16, update=tag_3d_views,
    )
    debug_colour: bpy.props.EnumProperty(
        name="Colour",
        description="What the debug cubes' colour shows",
        items=(("ALBEDO", "Albedo", "The voxels' surface colour"),
               ("NORMAL", "Normal", "The voxels' normal, as 0.5 + 0.5·n"),
               ("OCCLUSION", "Occlusion", "How much of the node is filled (leaves: 1)"),
               ("LIGHT", "Injected Light", "The direct light injected into the voxels")),
        default="ALBEDO", update=tag_3d_views,
    )
    show_bounds: bpy.props.BoolProperty(
        name="Cascade Bounds", description="Draw every cascade's box as a wire frame",
        default=False, update=tag_3d_views,
    )


classes = (VoxGIViewportSettings,)


def register() -> None:
    bpy.types.Scene.voxgi_viewport = bpy.props.PointerProperty(
        type=VoxGIViewportSettings, name="VoxGI Viewport",
        description="What the 3D view shows of VoxGI")


def unregister() -> None:
    del bpy.types.Scene.voxgi_viewport
