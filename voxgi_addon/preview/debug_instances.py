"""What the debug views draw, as numpy arrays (the GPU side is ``render/debug_draw.py``).

* ``cascade_instances`` — the voxels of one cascade of a ``GIState``: cube centres, edge and
  colour;
* ``octree_instances`` — the present nodes of one octree level, likewise;
* ``cascade_bounds`` — every cascade's box as 12 line segments;
* ``spread`` — the instances in an order whose every prefix is spread over all of them: the
  debug view draws them a slice per draw (``render/debug_draw.py``), so a view that is still
  filling in shows a thinner cloud of every part rather than one corner.

Colour modes: ALBEDO (surface colour), NORMAL (0.5 + 0.5·n), OCCLUSION (grey: how much of the
node is filled; leaves 1) and LIGHT (the injected direct light, tone-mapped x / (1 + x) so
bright voxels stay distinguishable).
"""
from __future__ import annotations

import numpy as np

from ..gi.morton import morton_decode

__all__ = ["COLOUR_MODES", "Instances", "cascade_instances", "octree_instances", "cascade_bounds",
           "pack_instances", "spread"]

COLOUR_MODES = ("ALBEDO", "NORMAL", "OCCLUSION", "LIGHT")


class Instances:
    """centres (N, 3) float32 world metres, size (N,) float32 cube edges, colours (N, 3)."""

    def __init__(self, centres, size, colours):
        self.centres = np.asarray(centres, np.float32).reshape(-1, 3)
        self.size = np.broadcast_to(np.asarray(size, np.float32), (len(self.centres),)).copy()
        self.colours = np.clip(np.asarray(colours, np.float32).reshape(-1, 3), 0.0, 1.0)

    def __len__(self) -> int:
        return len(self.centres)


def _colours(mode: str, albedo, normal, occlusion, radiance) -> np.ndarray:
    if mode == "ALBEDO":
        return albedo
    if mode == "NORMAL":
        return 0.5 + 0.5 * np.asarray(normal, np.float32)
    if mode == "OCCLUSION":
        return np.repeat(np.asarray(occlusion, np.float32).reshape(-1, 1), 3, axis=1)
    if mode == "LIGHT":
        r = np.maximum(np.asarray(radiance, np.float32), 0.0)
        return r / (1.0 + r)
    raise ValueError(f"colour mode must be one of {COLOUR_MODES}, got {mode!r}")


def cascade_instances(state, cascade: int, mode: str = "ALBEDO") -> Instances:
    """The voxels of cascade ``cascade`` (clamped to the last) of a ``GIState``."""
    cascade = int(np.clip(cascade, 0, len(state.cascades) - 1))
    voxels = state.cascades[cascade]
    grid = voxels.grid
    centres = grid.origin + (voxels.cells + 0.5) * grid.span
    colours = _colours(mode, voxels.albedo, voxels.normal, np.ones(voxels.voxel_count),
                       state.radiance[cascade])
    return Instances(centres, grid.span, colours)


def octree_instances(octree, level: int, mode: str = "ALBEDO") -> Instances:
    """The present nodes of octree level ``level`` (clamped to 0..depth)."""
    level = int(np.clip(level, 0, octree.depth))
    lv = octree.levels[level]
    if lv.kind == "dense":
        present = lv.occlusion > 0
        # [x, y, z] order, as the arrays are indexed (np.argwhere is 10 times slower)
        nodes = np.stack(np.unravel_index(np.flatnonzero(present), present.shape), axis=1)
        albedo, normal = lv.albedo[present], lv.normal[present]
        occlusion, radiance = lv.occlusion[present], lv.radiance[present]
    else:
        nodes = morton_decode(lv.keys)
        albedo, normal, occlusion, radiance = lv.albedo, lv.normal, lv.occlusion, lv.radiance
    size = float(octree.node_size(level))
    centres = np.asarray(octree.root_origin, np.float64) + (nodes + 0.5) * size
    return Instances(centres, size, _colours(mode, albedo, normal, occlusion, radiance))


def spread(instances: Instances, seed: int = 0) -> Instances:
    """The same instances in a fixed pseudo-random order (the same for the same count and
    ``seed``): any prefix is a uniform sample of all of them."""
    order = np.random.default_rng(seed).permutation(len(instances))
    return Instances(instances.centres[order], instances.size[order],
                     instances.colours[order])


_EDGES = np.array([(0, 1), (1, 3), (3, 2), (2, 0), (4, 5), (5, 7), (7, 6), (6, 4),
                   (0, 4), (1, 5), (2, 6), (3, 7)])


def cascade_bounds(grids) -> np.ndarray:
    """(len(grids) · 24, 3) float32 line-segment end points: 12 edges per cascade box."""
    out = []
    for grid in grids:
        lo, hi = grid.extent
        corners = np.array([[(hi if (c >> a) & 1 else lo)[a] for a in range(3)] for c in range(8)])
        out.append(corners[_EDGES].reshape(-1, 3))
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0, 3), np.float32)


def pack_instances(instances: Instances, width: int = 4096) -> tuple[np.ndarray, int]:
    """(rows, width, 4) float32 texels, two per instance side by side — (centre, edge) then
    (colour, 1) — and the texture width. ``width`` must be even."""
    n = len(instances)
    rows = max(1, -(-2 * n // width))
    texels = np.zeros((rows * width, 4), np.float32)
    texels[0:2 * n:2, :3] = instances.centres
    texels[0:2 * n:2, 3] = instances.size
    texels[1:2 * n:2, :3] = instances.colours
    texels[1:2 * n:2, 3] = 1.0
    return texels.reshape(rows, width, 4), width
