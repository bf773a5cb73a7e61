"""Probe radiance from the voxel octree (docs/probes.md "GPU bake"): the numpy statement of what
``render/shaders/probe_bake.glsl`` computes, and its reference.

Each (probe, direction) pair marches one narrow cone through the octree's injected direct light
(``gi.conetrace.march_cones``, the GI update's one bounce: voxel radiance = albedo × direct +
emission), with the cone settings of the preview. The cone's half-angle covers the direction's
share of the sphere (solid angle 4π/N: cos θ = 1 − 2/N). Cones start ``start_offset`` finest
voxels out from the probe (so a probe next to a wall does not read its own voxel as a
surrounding shell); what the cone leaves unoccluded sees the world colour. The radiance is then
projected on SH L2 (``sh.project``) exactly as the exact bake does.
"""
from __future__ import annotations

import math

import numpy as np

from ..gi.conetrace import ConeSettings, local_voxel_size, march_cones
from .sh import project

__all__ = ["cone_half_angle", "cone_origins", "octree_probe_radiance", "octree_probe_sh"]

START_OFFSET = 1.0  # finest voxels between the probe and a cone's first sample


def cone_half_angle(direction_count: int) -> float:
    """Half-angle (radians) of a cone covering 4π/N steradians."""
    return math.acos(max(-1.0, 1.0 - 2.0 / max(int(direction_count), 1)))


def cone_origins(octree, positions, directions, start_offset: float = START_OFFSET):
    """(P·N, 3) cone origins (probe + direction × offset) and (P·N, 3) directions, probe-major."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    reach = start_offset * local_voxel_size(octree, p)
    origins = (p[:, None, :] + d[None] * reach[:, None, None]).reshape(-1, 3)
    return origins, np.tile(d, (len(p), 1))


def octree_probe_radiance(octree, positions, directions, cones: ConeSettings, world,
                          start_offset: float = START_OFFSET) -> np.ndarray:
    """(P, N, 3) radiance arriving at each probe along each direction, through the octree."""
    origins, dirs = cone_origins(octree, positions, directions, start_offset)
    light, alpha = march_cones(
        octree, origins, dirs, cone_half_angle(len(directions)), cones.max_distance,
        falloff=cones.falloff, sample_factor=cones.sample_factor, start_offset=0.0,
        opacity_scale=cones.opacity_scale, anisotropic=cones.anisotropic,
        radiance_detail=cones.radiance_detail, transmittance_exponent=cones.transmittance_exponent)
    radiance = light + (1.0 - alpha)[:, None] * np.asarray(world, np.float64)[:3]
    return radiance.reshape(len(np.atleast_2d(positions)), len(directions), 3)


def octree_probe_sh(octree, positions, directions, cones: ConeSettings, world,
                    start_offset: float = START_OFFSET) -> np.ndarray:
    """(P, 9, 3) SH of ``octree_probe_radiance``."""
    return project(octree_probe_radiance(octree, positions, directions, cones, world, start_offset),
                   directions)
