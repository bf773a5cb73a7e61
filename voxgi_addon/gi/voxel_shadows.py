"""Shadow rays through the cascades' voxel occupancy (for light injection into voxels).

Each cascade keeps a dense boolean grid of its voxels; a point is occupied when any cascade
containing it has a voxel there (a mesh skipped at a finer span still blocks light with its
coarser voxels). Rays march in steps of half the finest local voxel: a ray is tested at
t = 0, then after each step while t < its length, and stops at the first occupied point or
where it leaves every cascade.

Empty space is skipped (docs/gi_pipeline.md "Posed updates"): for nested cascades (the
update's: same resolution, each twice the span of the one before, cascade i−1 the middle
half of cascade i) every cascade keeps its combined occupancy — its own voxels and its
coarser cascades' over it — and a pyramid of blocks of 2, 4, … cells saying whether a block
holds anything a ray could meet there (a voxel, the finer cascade's region, which has its own
steps). A ray in an empty block takes at once every half-voxel step that stays inside the
block: the same points are tested as one step at a time (those skipped are all empty), so
the result is the march's, at a fraction of its numpy passes (each step is one pass over
the rays still marching; a sun's rays used to take ~200 of them to leave a 64³ × 3 set).
Cascades that do not nest are marched step by step.
"""
from __future__ import annotations

import numpy as np

from .cascades import cells_within

__all__ = ["CascadeOccupancy"]

# When few rays march (BATCH_POINTS / BATCH_STEPS at most), a pass tests BATCH_STEPS points of
# each instead of skipping one block: the same points, in fewer passes.
BATCH_STEPS = 32
BATCH_POINTS = 8192


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
        self.nested = _nested(self.grids)
        self.combined = self.blocks = None
        if self.nested and self.grids:
            self.combined, self.blocks = _skip_tables(self.grids)

    def _cells(self, points, origin, span, res):
        cells = np.floor((points - origin) / span).astype(np.int64)
        inside = cells_within(cells, 0, res)
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

    def _finest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(level (N,) int, -1 outside every cascade; cell (N, 3) int64 in that cascade)."""
        level = np.full(len(points), -1, np.int64)
        cell = np.zeros((len(points), 3), np.int64)
        rows = None  # the points not yet in a finer cascade (None: all of them)
        for index, (origin, span, res, _) in enumerate(self.grids):  # finest first
            at = points if rows is None else points[rows]
            cells = np.floor((at - origin) / span).astype(np.int64)
            inside = cells_within(cells, 0, res)
            found = np.flatnonzero(inside) if rows is None else rows[inside]
            level[found] = index
            cell[found] = cells[inside]
            rows = np.flatnonzero(~inside) if rows is None else rows[~inside]
            if not len(rows):
                break
        return level, cell

    def occluded(self, origins: np.ndarray, dirs: np.ndarray, max_t) -> np.ndarray:
        """Any voxel along each ray from ``origins`` (N, 3) along unit ``dirs`` before ``max_t``?

        Rays leaving every cascade stop (nothing outside can block them).
        """
        origins = np.asarray(origins, np.float64)
        dirs = np.asarray(dirs, np.float64)
        n = len(origins)
        max_t = np.broadcast_to(np.asarray(max_t, np.float64), (n,))
        if not self.nested or not self.grids:
            return self._march(origins, dirs, max_t)
        spans = np.array([g[1] for g in self.grids])
        origin_of = np.array([g[0] for g in self.grids])
        t = np.zeros(n)
        blocked = np.zeros(n, dtype=bool)
        active = np.flatnonzero(max_t > 0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inverse = 1.0 / dirs
            while len(active):
                if len(active) * BATCH_STEPS <= BATCH_POINTS:
                    active = self._batch_step(origins, dirs, max_t, t, blocked, active, spans)
                else:
                    active = self._skip_step(origins, dirs, inverse, max_t, t, blocked, active,
                                             spans, origin_of)
        return blocked

    def _batch_step(self, origins, dirs, max_t, t, blocked, active, spans):
        """One pass of ``occluded`` for a few rays (each pass costs numpy's overhead more than
        its points): test each ray's next ``BATCH_STEPS`` points at once, up to the first that
        is in another cascade (its step differs) or past the ray's end."""
        o, d, ta = origins[active], dirs[active], t[active]
        level, _ = self._finest(o + d * ta[:, None])
        half = 0.5 * spans[np.maximum(level, 0)]
        count = BATCH_STEPS
        steps = np.arange(count, dtype=np.float64)
        tm = ta[:, None] + steps[None, :] * half[:, None]  # (n, K)
        points = (o[:, None, :] + d[:, None, :] * tm[..., None]).reshape(-1, 3)
        levels, cells = self._finest(points)
        levels = levels.reshape(tm.shape)
        occupied = (levels >= 0) & self.combined[np.maximum(levels, 0).ravel(), cells[:, 0],
                                                 cells[:, 1], cells[:, 2]].reshape(tm.shape)
        tested = (levels == level[:, None]) & (level[:, None] >= 0) & \
            ((tm < max_t[active, None]) | (steps[None, :] == 0))
        # points up to the first one not tested this pass (in another cascade, or past the end)
        last = np.where(tested.all(axis=1), count, np.argmin(tested, axis=1))
        within = steps[None, :] < last[:, None]
        hit = (occupied & within).any(axis=1)
        blocked[active] = hit
        t[active] = ta + last * half  # the first point not tested: the next pass starts there
        keep = ~hit & (level >= 0) & (t[active] < max_t[active])
        return active[keep]

    def _skip_step(self, origins, dirs, inverse, max_t, t, blocked, active, spans, origin_of):
        """One pass of ``occluded``: test each marching ray's point, then move it past the
        empty block around it (at least one half-voxel step); returns the rays still
        marching."""
        o, d, ta = origins[active], dirs[active], t[active]
        p = o + d * ta[:, None]
        level, cell = self._finest(p)
        inside = level >= 0
        lv = np.maximum(level, 0)
        hit = inside & self.combined[lv, cell[:, 0], cell[:, 1], cell[:, 2]]
        blocked[active] = hit
        half = 0.5 * spans[lv]
        # the largest empty block around the point (a single cell, its own, at least)
        size = np.ones(len(active), np.int64)
        for k, table in enumerate(self.blocks, start=1):
            b = cell >> k
            empty = ~table[lv, b[:, 0], b[:, 1], b[:, 2]]
            size = np.where(empty & (size == (1 << (k - 1))), 1 << k, size)
        low = origin_of[lv] + ((cell // size[:, None]) * size[:, None]) * (2.0 * half)[:, None]
        high = low + (size * 2.0 * half)[:, None]
        # where the ray leaves that block: every step before it stays inside
        inv = inverse[active]
        exit_t = np.min(np.where(d > 0, (high - o) * inv,
                                 np.where(d < 0, (low - o) * inv, np.inf)), axis=1)
        # the steps that stay inside are all empty: land on the first one past the block
        # (the tolerance keeps a point on the block's far face, which the next cell owns)
        steps = np.maximum(1.0, np.ceil((exit_t - ta) / half - 1e-9))
        t[active] = ta + steps * half
        keep = ~hit & inside & (t[active] < max_t[active])
        return active[keep]

    def _march(self, origins, dirs, max_t) -> np.ndarray:
        """``occluded`` one half-voxel step at a time (cascades that do not nest)."""
        n = len(origins)
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


def _nested(grids) -> bool:
    """Do the cascades nest as the update places them (module doc)?"""
    if not grids:
        return False
    res = grids[0][2]
    if res < 4 or res & (res - 1):
        return False
    for (o0, s0, r0, _), (o1, s1, r1, _) in zip(grids, grids[1:]):
        if r0 != res or r1 != res or abs(s1 - 2.0 * s0) > 1e-9 * s1:
            return False
        if np.abs((o0 - o1) - 0.5 * res * s0).max() > 1e-9 * s1:
            return False
    return True


def _skip_tables(grids) -> tuple[np.ndarray, list[np.ndarray]]:
    """(combined occupancy (G, R, R, R): a cascade's voxels or its coarser cascades' over it;
    per block size 2^k, k = 1 … log2(R/4), (G, R/2^k, …) whether a block holds an occupied
    cell or the finer cascade's region)."""
    count, res = len(grids), grids[0][2]
    quarter = res // 4
    combined = np.zeros((count, res, res, res), bool)
    for index in range(count - 1, -1, -1):
        combined[index] = grids[index][3]
        if index + 1 < count:  # the coarser cascade's middle half, each cell 2 × 2 × 2
            middle = combined[index + 1][quarter:3 * quarter, quarter:3 * quarter,
                                         quarter:3 * quarter]
            combined[index] |= middle.repeat(2, 0).repeat(2, 1).repeat(2, 2)
    blocks, level = [], combined
    while res >> (len(blocks) + 1) >= 4:  # blocks up to a quarter of the grid
        n = level.shape[1] // 2
        pairs = level.reshape(count, n, 2, n, 2, n, 2)
        level = pairs[:, :, 0] | pairs[:, :, 1]
        level = level[:, :, :, 0] | level[:, :, :, 1]
        level = level[..., 0] | level[..., 1]
        if not blocks:  # the finer cascade's region stops a skip (its cells are read there)
            level[1:, quarter // 2:3 * quarter // 2, quarter // 2:3 * quarter // 2,
                  quarter // 2:3 * quarter // 2] = True
        blocks.append(level)
    return combined, blocks
