"""Occlusion masks (Bowald 2016, 3.1.2.1; docs/probes.md "Occlusion masks").

Each active volume is split into 4 × 4 × 4 sub-volumes; each of its 8 corner probes gets a
64-bit mask of the sub-volumes it may light. From the probe's corner, paths walk towards the
opposite faces one sub-volume at a time, each step moving one sub-volume away from the corner
along one axis (so every monotone path is tried, branching where two steps are equally good).
An empty sub-volume is passed; one with geometry is passed only when the share of its surface
that faces the probe exceeds the threshold (eq. 3.1, default 50 %); a path ends at a blocked
sub-volume, which is not lit. A sub-volume is lit when some path reaches it.

The facing test, per triangle piece clipped to the sub-volume: the piece faces the probe when
the probe lies in front of the piece's plane (normal · (probe − piece centroid) > 0), and it
counts with its area projected towards the probe (area · |cos|), i.e. by how much of the probe's
view it fills. Bowald's test uses the volume centre and the plain area; a floor piece seen edge-on
from a probe at floor height then outweighs the thin wall that faces away from it and lets the
probe's light through the wall (docs/probes.md explains the case).
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import norm3
from .placement import SUBDIVISIONS, ProbeLayout

__all__ = ["ALL_SUBVOLUMES", "occlusion_masks", "passable_subvolumes", "path_search"]

ALL_SUBVOLUMES = np.uint64(0xFFFFFFFFFFFFFFFF)
_BITS = np.left_shift(np.uint64(1), np.arange(64, dtype=np.uint64))


def passable_subvolumes(layout: ProbeLayout, positions, threshold: float) -> np.ndarray:
    """(V, 8, 64) bool: may light pass sub-volume s of volume v for corner probe c?"""
    g = layout.geometry
    v_count = len(layout.volume_cells)
    probes = layout.volume_probes[g.volume_row]  # (Q, 8)
    to_probe = np.asarray(positions, np.float64)[probes] - g.centroid[:, None, :]  # (Q, 8, 3)
    dist = norm3(to_probe)
    cos = np.einsum("qj,qcj->qc", g.normal, to_probe) / np.maximum(dist, 1e-12)
    weight = g.area[:, None] * np.abs(cos)
    key = (g.volume_row[:, None] * 8 + np.arange(8)[None]) * 64 + g.sub[:, None]
    size = v_count * 8 * 64
    total = np.bincount(key.ravel(), weight.ravel(), minlength=size)
    front = np.bincount(key.ravel(), (weight * (cos > 0)).ravel(), minlength=size)
    return ((total <= 0) | (front > threshold * total)).reshape(v_count, 8, 64)


def path_search(passable: np.ndarray) -> np.ndarray:
    """(V, 8) uint64 masks: sub-volumes reachable from each corner through passable ones
    (``passable`` (V, 8, 64) bool, bit ``sx + 4·(sy + 4·sz)``)."""
    n = SUBDIVISIONS
    v_count = len(passable)
    masks = np.zeros((v_count, 8), np.uint64)
    for c in range(8):
        # Index [z, y, x]; mirror the axes so that the corner probe sits at (0, 0, 0).
        grid = passable[:, c, :].reshape(v_count, n, n, n)
        flip = [axis for axis, bit in ((3, c & 1), (2, c & 2), (1, c & 4)) if bit]
        if flip:
            grid = np.flip(grid, axis=flip)
        seen = np.zeros_like(grid)
        for z in range(n):
            for y in range(n):
                for x in range(n):
                    if x == y == z == 0:
                        reach = np.ones(v_count, bool)
                    else:
                        reach = np.zeros(v_count, bool)
                        if x:
                            reach |= seen[:, z, y, x - 1]
                        if y:
                            reach |= seen[:, z, y - 1, x]
                        if z:
                            reach |= seen[:, z - 1, y, x]
                    seen[:, z, y, x] = reach & grid[:, z, y, x]
        if flip:
            seen = np.flip(seen, axis=flip)
        masks[:, c] = np.bitwise_or.reduce(np.where(seen.reshape(v_count, 64), _BITS, np.uint64(0)),
                                           axis=1)
    return masks


def occlusion_masks(layout: ProbeLayout, positions, threshold: float = 0.5) -> np.ndarray:
    """(V, 8) uint64 occlusion masks of every active volume's corner probes at ``positions``."""
    if len(layout.volume_cells) == 0:
        return np.zeros((0, 8), np.uint64)
    return path_search(passable_subvolumes(layout, positions, threshold))
