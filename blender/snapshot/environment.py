"""Lights, camera and world of a scene as snapshot records (main thread).

Matrices are read from evaluated objects (the current frame), 4x4 float64 row-major
with column vectors, as ``Object.matrix_world`` gives them.
"""
from __future__ import annotations

import math

import numpy as np

from ...voxgi_addon.scene.snapshot import LIGHT_TYPES, CameraData, LightData, WorldData
from . import animated, world_map
from .reads import count


def _matrix(matrix) -> np.ndarray:
    return np.array(matrix, dtype=np.float64)


def unnormalized_scale(light) -> float:
    """What Cycles multiplies a light's Power by with Light › Normalize off (its power is then
    per unit of the lamp's size, not shared over it): an area lamp's area, a point or spot
    light's sphere surface 4πr² (4 at radius 0), a sun's disc π sin²(½ angle) (1 at angle 0);
    1 with Normalize on (and before Blender had the setting). Measured off Cycles' Diffuse
    Direct with the setting on and off (docs/blender_facts.md "Light › Normalize")."""
    if getattr(light, "normalize", True):
        return 1.0
    if light.type == "AREA":
        x = float(light.size)
        y = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else x
        return x * y * (math.pi / 4.0 if light.shape in ("DISK", "ELLIPSE") else 1.0)
    if light.type in ("POINT", "SPOT"):
        r = float(light.shadow_soft_size)
        return 4.0 * (math.pi * r * r if r > 0.0 else 1.0)
    if light.type == "SUN":
        half = 0.5 * float(light.angle)
        return math.pi * math.sin(half) ** 2 if half > 0.0 else 1.0
    return 1.0


def read_light(obj, obj_eval) -> LightData | None:
    """``LightData`` of a light object, or None for a light type VoxGI ignores."""
    light = obj_eval.data
    if light.type not in LIGHT_TYPES:
        return None
    extra = {"cast_shadow": bool(getattr(light, "use_shadow", True))}
    if light.type in ("POINT", "SPOT"):
        extra["radius"] = float(light.shadow_soft_size)
    if light.type == "SPOT":
        extra.update(spot_size=float(light.spot_size), spot_blend=float(light.spot_blend))
    if light.type == "SUN":
        extra["angle"] = float(light.angle)
    if light.type == "AREA":
        extra.update(size=float(light.size), size_y=float(light.size_y), shape=str(light.shape))
    color = np.array(light.color[:3], dtype=np.float64)
    if getattr(light, "use_temperature", False):  # Blender 4.5+: × the blackbody's colour
        color = color * np.array(light.temperature_color[:3], dtype=np.float64)
    return LightData(
        name=obj.name_full,
        type=light.type,
        color=color.astype(np.float32),
        power=float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0))
        * unnormalized_scale(light),
        world_matrix=_matrix(obj_eval.matrix_world),
        **extra,
    )


def render_resolution(scene) -> tuple[int, int]:
    """Output size in pixels after the render percentage, as Blender computes it."""
    render = scene.render
    pct = render.resolution_percentage
    return (max(1, render.resolution_x * pct // 100), max(1, render.resolution_y * pct // 100))


def read_camera(scene, depsgraph) -> CameraData | None:
    """``CameraData`` of ``scene.camera`` (a camera object), else None."""
    obj = scene.camera
    if obj is None or obj.type != "CAMERA":
        return None
    obj_eval = obj.evaluated_get(depsgraph)
    camera = obj_eval.data
    width, height = render_resolution(scene)
    projection = obj_eval.calc_matrix_camera(
        depsgraph, x=width, y=height,
        scale_x=scene.render.pixel_aspect_x, scale_y=scene.render.pixel_aspect_y,
    )
    return CameraData(
        name=obj.name_full,
        world_matrix=_matrix(obj_eval.matrix_world),
        projection_matrix=_matrix(projection),
        resolution=(width, height),
        type=str(camera.type),
        angle_x=float(camera.angle_x),
        angle_y=float(camera.angle_y),
        ortho_scale=float(camera.ortho_scale),
        clip_start=float(camera.clip_start),
        clip_end=float(camera.clip_end),
        sensor_fit=str(camera.sensor_fit),
    )


def read_world(scene, warnings: list[str], bake: bool | None = None,
               deferred=None, depsgraph=None) -> WorldData:
    """The scene's world as an equirect radiance map (``world_map.read_world``): uniform
    colours and Environment Textures are read from the nodes, anything else is evaluated by
    Cycles (``bake``: allow that here; None: where a nested render can run; ``deferred``: the
    live viewport's bakes in other processes, ``world_process.WorldBakes``). An animated world
    is read from ``depsgraph`` 's copy: its values at that depsgraph's frame (an animation
    render's; ``animated``)."""
    count("worlds")
    world = scene.world
    if depsgraph is not None and animated.reads_evaluated(world):
        world = getattr(depsgraph.scene_eval, "world", None) or world
    frame = getattr(getattr(depsgraph, "scene_eval", None), "frame_current", scene.frame_current)
    return world_map.read_world(world, warnings, bake, deferred, frame=frame)
