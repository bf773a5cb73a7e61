"""Direct diffuse light with cone-traced soft shadows (Yalçıner 2016 §4.8: one cone per light).

The fast alternative to ``direct_light``'s exact shadow rays: each light's unshadowed Diffuse
Direct (``direct_light.diffuse_direct`` without occluders, Cycles' units) times the visibility
of one cone from the lifted surface point to the light through the voxel octree, as wide as
the light seen from the point (``conetrace.trace_shadow``). Shadows come out soft, and thin
occluders below the voxel size cast too little; the GPU tracer runs the same cones in
``render/shaders/shadow.glsl``.

The world and the emissive surfaces (``world_light.scene_lights``) have no one direction:

* the world: its exact unshadowed E(n)/π (``world_light.unshadowed``) × the visible share that
  the diffuse cone set sees (``conetrace.trace_world_visibility``: Σ w T L / Σ w L in
  luminance, T each cone's transmittance to the end of its march, L the world prefiltered at
  its aperture);
* the emissive triangles: per connected emitter (``emitter_groups``: a panel, a sphere) its
  exact unshadowed sum (``direct_light.diffuse_direct`` without occluders) × one shadow cone
  towards its power-weighted centre, as wide as the emitter.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..scene.short_axis import max_along, min_along
from .conetrace import (
    LUMINANCE,
    ConeSettings,
    offset_origins,
    trace_shadow,
    trace_world_visibility,
    world_mips,
)
from .direct_light import area_outline, diffuse_direct, light_frame

SHADOWED_TYPES = ("SUN", "POINT", "SPOT", "AREA")
# At most this many shadow cones for the emissive triangles: beyond it the weakest connected
# emitters share one (towards their power-weighted centre), so that a wall of small glowing
# tiles costs a few cones, not one per tile.
MAX_EMITTER_CONES = 8


def emitter_groups(light) -> list:
    """The connected parts of an ``emitters.EmitterLight`` (triangles sharing a corner belong
    together: a panel, a sphere), each an ``EmitterLight`` of its own triangles; the
    MAX_EMITTER_CONES − 1 strongest (area × luminance) stay apart, the others make one
    group."""
    corners = np.asarray(light.corners, np.float64)
    _, vertex = np.unique(corners.reshape(-1, 3), axis=0, return_inverse=True)
    vertex = vertex.reshape(-1, 3)
    label = np.arange(vertex.max() + 1)
    while True:  # each triangle's corners take the smallest label among them, until stable
        low = min_along(label[vertex])
        new = label.copy()
        np.minimum.at(new, vertex.ravel(), np.repeat(low, 3))
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    parts = [np.flatnonzero(label[vertex[:, 0]] == value) for value in np.unique(label[vertex[:, 0]])]
    if len(parts) > MAX_EMITTER_CONES:
        power = light.area * (light.radiance @ LUMINANCE)
        parts.sort(key=lambda members: -power[members].sum())
        keep = MAX_EMITTER_CONES - 1
        parts = parts[:keep] + [np.sort(np.concatenate(parts[keep:]))]
    groups = []
    for members in parts:
        power = light.area[members] * (light.radiance[members] @ LUMINANCE)
        cdf = np.cumsum(power) / max(power.sum(), 1e-30)
        groups.append(dataclasses.replace(
            light, corners=light.corners[members], radiance=light.radiance[members],
            area=light.area[members], cdf=cdf, sides=light.sides[members], exact=True,
            margin=None if light.margin is None else light.margin[members], sums=None))
    return groups


def shadow_cone(light) -> tuple[np.ndarray, float, bool]:
    """(target, size, is_sun) of a light's shadow cone: the light's centre and radius in metres,
    or for a sun the unit direction towards it and tan(half its angle); for emissive triangles
    (one of ``emitter_groups``) their power-weighted centre and the distance from it to their
    farthest corner."""
    if light.type == "EMITTERS":
        weight = light.area * (light.radiance @ LUMINANCE)
        centroid = light.corners.mean(axis=1)
        centre = (weight[:, None] * centroid).sum(axis=0) / max(weight.sum(), 1e-30)
        reach = np.linalg.norm(light.corners.reshape(-1, 3) - centre, axis=1).max()
        return centre, float(reach), False
    centre, _, _, emit = light_frame(light)
    if light.type == "SUN":
        return -emit, math.tan(0.5 * float(light.angle)), True
    if light.type == "AREA":
        _, area = area_outline(light)
        return centre, math.sqrt(max(area, 0.0) / math.pi), False
    return centre, float(light.radius), False


def cone_shadowed_direct(volume, points, normals, lights, cones: ConeSettings,
                         samples: int = 16, visibility=None, world_seen=None) -> np.ndarray:
    """(N, 3) float32 Diffuse Direct with one shadow cone per light (per connected emitter),
    the world's visible share from the diffuse cone set.

    points, normals : (N, 3) surface points and unit normals facing the viewer.
    lights : lamps, and the world and emissive triangles of ``world_light.scene_lights``.
    visibility : optional ``fn(light, lit_indices) -> (n,)`` replacing the numpy cone (the GPU
        tracer passes its own); default ``conetrace.trace_shadow`` on ``volume``.
    world_seen : optional ``fn(lit_indices) -> (n, 4)`` replacing
        ``conetrace.trace_world_visibility`` (the GPU tracer passes its own).
    """
    from .world_light import unshadowed

    p = np.asarray(points, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3), np.float64)
    for light in lights:
        if light.type == "WORLD":
            value = unshadowed(light, n)
            lit = np.flatnonzero(max_along(value) > 0)
            if len(lit):
                seen = world_seen(lit) if world_seen is not None else trace_world_visibility(
                    volume, p[lit], n[lit], cones, world_mips(light.radiance))
                seen = np.asarray(seen, np.float64)
                share = np.clip(np.divide(seen[:, :3] @ LUMINANCE, seen[:, 3],
                                          out=np.ones(len(lit)), where=seen[:, 3] > 0), 0.0, 1.0)
                out[lit] += value[lit] * share[:, None]
            continue
        if light.type == "EMITTERS":
            for group in emitter_groups(light):
                _shadowed(out, diffuse_direct(p, n, [group], None), group, p, n, volume,
                          cones, visibility)
            continue
        if light.type not in SHADOWED_TYPES or light.power == 0:
            continue
        if not getattr(light, "cast_shadow", True):  # Cast Shadow off: no cone
            out += diffuse_direct(p, n, [light], None, samples=samples)
            continue
        _shadowed(out, diffuse_direct(p, n, [light], None, samples=samples), light, p, n,
                  volume, cones, visibility)
    return out.astype(np.float32)


def _shadowed(out, value, light, p, n, volume, cones, visibility) -> None:
    """out += the unshadowed ``value`` (N, 3) × the light's shadow cone where it is lit."""
    value = np.asarray(value, np.float64)
    lit = np.flatnonzero(max_along(value) > 0)
    if len(lit) == 0:
        return
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
