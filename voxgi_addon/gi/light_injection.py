"""Direct light injected into cascade voxels (Yalçıner 2016 4.5, "inject" step).

Each voxel's outgoing diffuse radiance = albedo × (Diffuse Direct + world ambient), in Cycles'
units (``direct_light`` holds the light models; shadows march through the voxel occupancy
instead of the triangles). The octree then averages it upward.
"""
from __future__ import annotations

import numpy as np

from .direct_light import diffuse_direct
from .voxel_shadows import CascadeOccupancy

# Shadow rays start this many voxels off the surface so a voxel does not shadow itself.
SHADOW_START_VOXELS = 1.5


def voxel_centres(cascade) -> np.ndarray:
    """(N, 3) float64 world-space centres of a CascadeVoxels' cells."""
    g = cascade.grid
    return np.asarray(g.origin, np.float64) + (np.asarray(cascade.cells, np.float64) + 0.5) * g.span


def inject_direct_light(cascades, snapshot, occupancy: CascadeOccupancy | None = None,
                        samples: int = 4) -> list[np.ndarray]:
    """Outgoing radiance (N_i, 3) float32 of every cascade's voxels.

    cascades : list of CascadeVoxels (finest first); snapshot : for lights and world.
    occupancy : shadow casters (defaults to the cascades' own voxels).
    """
    from .world_light import scene_lights

    occupancy = occupancy or CascadeOccupancy(cascades)
    # The world lights the voxels as a light (its map, shadowed by the voxels) where it has a
    # map; a world known only by its colour adds it unshadowed, as before.
    lights = scene_lights(snapshot)
    ambient = np.zeros(3) if getattr(snapshot.world, "radiance", None) is not None else \
        np.asarray(snapshot.world.color, np.float64) * float(snapshot.world.strength)
    out = []
    for cv in cascades:
        if cv.voxel_count == 0:
            out.append(np.zeros((0, 3), np.float32))
            continue
        normals = np.asarray(cv.normal, np.float64)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        start = voxel_centres(cv) + normals * (SHADOW_START_VOXELS * cv.grid.span)
        direct = diffuse_direct(start, normals, lights, occupancy, samples=samples)
        out.append((np.asarray(cv.albedo, np.float64) * (direct + ambient)).astype(np.float32))
    return out
