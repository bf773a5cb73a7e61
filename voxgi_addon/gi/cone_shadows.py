"""Direct diffuse light with cone-traced soft shadows (Yalçıner 2016 §4.8: one cone per light).

The fast alternative to ``direct_light``'s exact shadow rays: each light's unshadowed Diffuse
Direct (``direct_light.diffuse_direct`` without occluders, Cycles' units) times the visibility
of one cone from the lifted surface point to the light through the voxel octree, as wide as
the light seen from the point (``conetrace.trace_shadow``). Shadows come out soft, and thin
occluders below the voxel size cast too little; the GPU tracer runs the same cones in
``render/shaders/shadow.glsl``.
"""
from __future__ import annotations

import math

import numpy as np

from .conetrace import ConeSettings, offset_origins, trace_shadow
from .direct_light import area_outline, diffuse_direct, light_frame

SHADOWED_TYPES = ("SUN", "POINT", "SPOT", "AREA")


def shadow_cone(light) -> tuple[np.ndarray, float, bool]:
    """(target, size, is_sun) of a light's shadow cone: the light's centre and radius in metres,
    or for a sun the unit direction towards it and tan(half its angle)."""
    centre, _, _, emit = light_frame(light)
    if light.type == "SUN":
        return -emit, math.tan(0.5 * float(light.angle)), True
    if light.type == "AREA":
        _, area = area_outline(light)
        return centre, math.sqrt(max(area, 0.0) / math.pi), False
    return centre, float(light.radius), False


def cone_shadowed_direct(volume, points, normals, lights, cones: ConeSettings,
                         samples: int = 16, visibility=None) -> np.ndarray:
    """(N, 3) float32 Diffuse Direct with one shadow cone per light.

    points, normals : (N, 3) surface points and unit normals facing the viewer.
    visibility : optional ``fn(light, lit_indices) -> (n,)`` replacing the numpy cone (the GPU
        tracer passes its own); default ``conetrace.trace_shadow`` on ``volume``.
    """
    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3), np.float64)
    for light in lights:
        if light.type not in SHADOWED_TYPES or light.power == 0:
            continue
        value = diffuse_direct(p, n, [light], None, samples=samples).astype(np.float64)
        lit = np.flatnonzero(value.max(axis=1) > 0)
        if len(lit) == 0:
            continue
        if visibility is not None:
            seen = visibility(light, lit)
        else:
            target, size, is_sun = shadow_cone(light)
            if is_sun:
                origins = offset_origins(p[lit], n[lit], volume, cones.start_offset)
                targets = origins + target * cones.max_distance
                radius = size * cones.max_distance
            else:
                targets, radius = np.broadcast_to(target, (len(lit), 3)), size
            seen = trace_shadow(volume, p[lit], n[lit], targets, radius, cones)
        out[lit] += value[lit] * np.asarray(seen, np.float64)[:, None]
    return out.astype(np.float32)
