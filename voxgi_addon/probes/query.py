"""Irradiance at surface points from a probe grid in O(1) per point (Bowald 2016, 3.2;
docs/probes.md "Query").

A point's volume comes from its position (origin, volume size, dims); Bowald's two index arrays
give that volume's 8 corner probes (``sh_index``) and its row of occlusion masks
(``mask_index``); the point's sub-volume picks one bit of each mask. The result is the trilinear
blend of the probes whose bit is set (weights renormalised over them), each probe's irradiance
being its SH convolved with the clamped cosine around the normal (``sh.irradiance``). Where no
probe of the volume sees the sub-volume (all of them blocked, e.g. inside a wall's sub-volume),
the probes in front of the surface (probe − point along the normal > 0) stand in, and failing
those all enabled corner probes. Disabled probes never count. Points outside the box clamp to it.
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import all_along
from .grid import CORNER_OFFSETS, NO_INDEX, ProbeGrid
from .placement import SUBDIVISIONS
from .sh import COSINE_LOBE, sh_basis

__all__ = ["probe_weights", "query_irradiance", "query_grids"]

_CHUNK = 1 << 16


def probe_weights(grid: ProbeGrid, points, normals, use_masks: bool = True):
    """(probes (N, 8) int64, weights (N, 8) float64 summing to 1 or 0) for each point."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    dims = grid.dims
    g = (p - grid.origin) / grid.volume_size
    cell = np.clip(np.floor(g), 0, dims - 1).astype(np.int64)
    f = np.clip(g - cell, 0.0, 1.0)
    corner = cell[:, None, :] + CORNER_OFFSETS[None]  # (N, 8, 3)
    lin = corner[..., 0] + (dims[0] + 1) * (corner[..., 1] + (dims[1] + 1) * corner[..., 2])
    index = np.asarray(grid.sh_index)[lin]
    has = index != NO_INDEX
    probes = np.where(has, index, 0).astype(np.int64)
    if len(np.asarray(grid.enabled)) == 0:  # a grid with no probe (no geometry in its box)
        return probes, np.zeros(probes.shape)
    enabled = has & np.asarray(grid.enabled)[probes]
    w = np.prod(np.where(CORNER_OFFSETS[None] == 1, f[:, None, :], 1.0 - f[:, None, :]), axis=2)
    usable = w * enabled
    if use_masks:
        volume = cell[:, 0] + dims[0] * (cell[:, 1] + dims[1] * cell[:, 2])
        row = np.asarray(grid.mask_index)[volume]
        active = row != NO_INDEX
        sub = np.clip(np.floor(f * SUBDIVISIONS), 0, SUBDIVISIONS - 1).astype(np.int64)
        bit = (sub[:, 0] + SUBDIVISIONS * (sub[:, 1] + SUBDIVISIONS * sub[:, 2])).astype(np.uint64)
        masks = np.asarray(grid.volume_masks, np.uint64)[np.where(active, row, 0).astype(np.int64)]
        seen = ((masks >> bit[:, None]) & np.uint64(1)).astype(bool) | ~active[:, None]
        weights = usable * seen
        total = weights.sum(axis=1)
        lost = total <= 0
        if lost.any():
            front = np.einsum("nkc,nc->nk", np.asarray(grid.positions, np.float64)[probes[lost]]
                              - p[lost, None, :], nrm[lost]) > 0
            weights[lost] = usable[lost] * front
    else:
        weights = usable.copy()
    total = weights.sum(axis=1)
    lost = total <= 0
    weights[lost] = usable[lost]
    total = weights.sum(axis=1)
    weights = np.divide(weights, total[:, None], out=np.zeros_like(weights), where=total[:, None] > 0)
    return probes, weights


def query_irradiance(grid: ProbeGrid, points, normals, use_masks: bool = True) -> np.ndarray:
    """(N, 3) float32 irradiance (W/m² per unit radiance, i.e. ∫ L cos dω) at points with unit
    normals; divide by π for Cycles' ``Diffuse Indirect``. Clamped at 0 (SH ringing)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3), np.float32)
    sh = np.asarray(grid.sh, np.float32)
    for a in range(0, len(p), _CHUNK):
        b = min(len(p), a + _CHUNK)
        probes, w = probe_weights(grid, p[a:b], nrm[a:b], use_masks)
        blended = np.einsum("nk,nkjc->njc", w.astype(np.float32), sh[probes])  # (n, 9, 3)
        basis = (sh_basis(nrm[a:b]) * COSINE_LOBE).astype(np.float32)
        out[a:b] = np.maximum(np.einsum("nj,njc->nc", basis, blended), 0.0)
    return out


def query_grids(grids, points, normals, use_masks: bool = True) -> np.ndarray:
    """``query_irradiance`` over several grids: each point uses the first grid whose box holds it;
    points outside every box use the first grid (clamped to its box)."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    nrm = np.asarray(normals, np.float64).reshape(-1, 3)
    out = np.zeros((len(p), 3), np.float32)
    if not grids:
        return out
    todo = np.ones(len(p), bool)
    for grid in grids:
        hi = grid.origin + grid.dims * grid.volume_size
        inside = todo & all_along((p >= grid.origin) & (p <= hi))
        if inside.any():
            out[inside] = query_irradiance(grid, p[inside], nrm[inside], use_masks)
        todo &= ~inside
    if todo.any():
        out[todo] = query_irradiance(grids[0], p[todo], nrm[todo], use_masks)
    return out
