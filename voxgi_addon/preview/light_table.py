"""The snapshot's lights as a small RGBA32F table for the GPU direct-light kernels.

``render/shaders/bvh_lights.glsl`` evaluates ``direct_light.diffuse_direct``'s light models from
this table; everything that does not depend on the shading point is computed here, in float64,
with ``direct_light``'s own helpers (``light_frame``, ``area_outline``). One row per light (row
= texture y), ``LIGHT_TEXELS`` texels wide:

======  ==========================================================================
texel   contents
======  ==========================================================================
0       type (0 sun, 1 point, 2 spot, 3 area), round shape (1 = disk/ellipse), outline
        vertex count K, stream (the light's index in the snapshot's list: its samples'
        hash stream, as ``diffuse_direct(sample_ids=…)`` numbers it)
1       colour rgb, power (W, or W/m² for a sun)
2       position xyz (m), radius (point/spot, m)
3       half extent along the light's X (area: ½·size·x axis, m), tan(½ sun angle)
4       half extent along Y (area: ½·size_y·y axis), cos(½ spot size)
5       emission direction (unit, the light's −Z), spot blend
6       area (m²), radiance P/(π·area), 1 when it casts no shadow (Cast Shadow off), 0
8 …     the area light's outline (world xyz, counter-clockwise; K ≤ ``MAX_OUTLINE``)
======  ==========================================================================

Lights of other types and lights of zero power are left out (they add nothing).
"""
from __future__ import annotations

import math

import numpy as np

from ..gi.direct_light import area_outline, light_frame

__all__ = ["LIGHT_TEXELS", "LIGHT_TYPES", "MAX_OUTLINE", "light_table"]

LIGHT_TYPES = {"SUN": 0, "POINT": 1, "SPOT": 2, "AREA": 3}
MAX_OUTLINE = 64
LIGHT_TEXELS = 8 + MAX_OUTLINE


def light_table(lights, first_stream: int = 0) -> np.ndarray:
    """(L, LIGHT_TEXELS, 4) float32 rows (see the module doc); L may be 0. Light i's samples
    take stream ``first_stream`` + i (its index in the scene's lights list)."""
    rows = []
    for index, light in enumerate(lights, first_stream):
        kind = LIGHT_TYPES.get(light.type)
        if kind is None or light.power == 0:
            continue
        row = np.zeros((LIGHT_TEXELS, 4))
        centre, x, y, emit = light_frame(light)
        round_shape = light.shape in ("DISK", "ELLIPSE")
        outline = np.zeros((0, 3))
        area = radiance = 0.0
        ex = ey = np.zeros(3)
        if kind == 3:
            outline, area = area_outline(light)
            if area <= 0:
                continue
            radiance = light.power / (math.pi * area)
            sx = float(light.size)
            sy = float(light.size_y) if light.shape in ("RECTANGLE", "ELLIPSE") else sx
            ex, ey = 0.5 * sx * x, 0.5 * sy * y
        row[0] = (kind, float(round_shape), len(outline), index)
        row[1, :3], row[1, 3] = np.asarray(light.color, np.float64)[:3], light.power
        row[2, :3], row[2, 3] = centre, float(light.radius)
        row[3, :3], row[3, 3] = ex, math.tan(0.5 * float(light.angle))
        row[4, :3], row[4, 3] = ey, math.cos(0.5 * float(light.spot_size))
        row[5, :3], row[5, 3] = emit, float(light.spot_blend)
        row[6, :3] = area, radiance, 0.0 if getattr(light, "cast_shadow", True) else 1.0
        row[8:8 + len(outline), :3] = outline
        rows.append(row)
    if not rows:
        return np.zeros((0, LIGHT_TEXELS, 4), np.float32)
    return np.stack(rows).astype(np.float32)
