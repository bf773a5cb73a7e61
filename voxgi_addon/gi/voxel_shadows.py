"""Shadow rays through the cascades' voxel occupancy (for light injection into voxels).

Each cascade keeps a dense boolean grid of its voxels; a point is occupied when any cascade
containing it has a voxel there (a mesh skipped at a finer span still blocks light with its
coarser voxels). Rays march in steps of half the finest local voxel.
"""
from __future__ import annotations

import numpy as np


class CascadeOccupancy:
    """Dense occupancy of every cascade. ``cascades`` : list of CascadeVoxels (finest first)."""

    def __init__(self, cascades):
        self.grids = []
        for cv in cascades:
            g = cv.grid
            dense = np.zeros((g.resolution,) * 3, dtype=bool)
            if len(cv.cells):
                dense[tuple(np.asarray(cv.cells, np.int64).T)] = True
            self.grids.append((np.asarray(g.origin, np.float64), float(g.span), g.resolution, dense))

    def _cells(self, points, origin, span, res):
        cells = np.floor((points - origin) / span).astype(np.int64)
        inside = ((cells >= 0) & (cells < res)).all(axis=1)
        return np.clip(cells, 0, res - 1), inside

    def occupied(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points → (N,) bool."""
        hit = np.zeros(len(points), dtype=bool)
        for origin, span, res, dense in self.grids:
            cells, inside = self._cells(points, origin, span, res)
            hit |= inside & dense[cells[:, 0], cells[:, 1], cells[:, 2]]
        return hit

    def local_span(self, points: np.ndarray) -> np.ndarray:
        """(N,) span of the finest cascade containing each point (inf outside all)."""
        span_out = np.full(len(points), np.inf)
        for origin, span, res, _ in reversed(self.grids):  # finest last, so it wins
            _, inside = self._cells(points, origin, span, res)
            span_out[inside] = span
        return span_out

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, max_t) -> np.ndarray:
        """Any voxel along each ray from ``origins`` (N, 3) along unit ``dirs`` before ``max_t``?

        Rays leaving every cascade stop (nothing outside can block them).
        """
        n = len(origins)
        max_t = np.broadcast_to(np.asarray(max_t, np.float64), (n,))
        t = np.zeros(n)
        blocked = np.zeros(n, dtype=bool)
        active = np.flatnonzero(max_t > 0)
        while len(active):
            p = origins[active] + dirs[active] * t[active, None]
            blocked[active] = self.occupied(p)
            step = 0.5 * self.local_span(p)
            t[active] += step
            keep = ~blocked[active] & np.isfinite(step) & (t[active] < max_t[active])
            active = active[keep]
        return blocked
