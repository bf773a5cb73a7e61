"""Scene settings of VoxGI: ``Scene.voxgi`` (a ``VoxGISceneSettings``)."""
# No `from __future__ import annotations` here: bpy property annotations must stay objects.
import bpy

GRID_RESOLUTIONS = (32, 64, 128, 256, 512)


class VoxGISceneSettings(bpy.types.PropertyGroup):
    """Per-scene voxelization and cascade settings."""

    base_span: bpy.props.FloatProperty(
        name="Base Span",
        description="Edge length of a voxel in the finest cascade, in metres; "
                    "each coarser cascade doubles it",
        subtype="DISTANCE",
        unit="LENGTH",
        default=0.1,
        min=0.001,
        soft_max=1.0,
        precision=3,
    )
    cascade_count: bpy.props.IntProperty(
        name="Cascades",
        description="Number of nested camera-centred grids (cascades); cascade i has "
                    "voxels of Base Span x 2^i metres",
        subtype="NONE",
        default=3,
        min=1,
        max=6,
    )
    grid_resolution: bpy.props.EnumProperty(
        name="Grid Resolution",
        description="Voxels along each axis of every cascade grid (a power of two); "
                    "memory grows with its cube",
        items=[(str(n), f"{n}\u00b3", f"{n} voxels per axis in each cascade") for n in GRID_RESOLUTIONS],
        default="64",
    )


def grid_resolution(settings: VoxGISceneSettings) -> int:
    """The per-cascade grid resolution of ``settings`` in voxels per axis."""
    return int(settings.grid_resolution)


classes = (VoxGISceneSettings,)


def register() -> None:
    bpy.types.Scene.voxgi = bpy.props.PointerProperty(
        type=VoxGISceneSettings,
        name="VoxGI",
        description="VoxGI voxel global illumination settings of this scene",
    )


def unregister() -> None:
    del bpy.types.Scene.voxgi
