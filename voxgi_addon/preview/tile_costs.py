"""Where on the image a view's slices cost their time: a map of each stage's seconds per pixel
over the image, and tiles split where that map says one stage would run past the draw's budget.

A stage's cost per pixel differs across the view: the emitters' light field and glossy light
cost two to ten times as much a pixel by the emissive room's panel as elsewhere
(docs/gi_pipeline.md "Tiles split where they cost"). The viewport's tiles of one sample all
have one size, fitted to the stages' recent runs, so a tile that lands on the costly part ran
one stage past the 30 ms a draw may take. The map (``CostMap``) holds, per stage and per cell
of ``COST_CELL`` pixels, the seconds per pixel of the last tile that ran that stage over the
cell. A tile about to be traced whose longest stage the map predicts past its budget is cut
in two (``split_tile``) — sides of every tile's kind, so no kernel is built anew — until it
fits or cannot be cut. (The map is not the draws' prediction of their next stage: the same
tile's stage scatters about the map's value from run to run, 1.6 × it at the 90th percentile
on the emissive room, and a draw that trusted it ran two stages to 30–40 ms.)
"""
from __future__ import annotations

import math

import numpy as np

from .progressive import allowed_side

COST_CELL = 8  # pixels: a side of the cost map's cells (a work group of the image's kernels)


class CostMap:
    """Seconds per pixel of each stage (any hashable key: the slice's kind and the stage's
    index), per cell of ``cell`` pixels of a ``width`` × ``height`` image (rows from the top,
    as tiles count them): the last tile's that ran the stage over the cell (float32: a
    1920 × 1080 view's 33 stages take 4 MB)."""

    def __init__(self, width: int, height: int, cell: int = COST_CELL):
        if cell <= 0:
            raise ValueError(f"a cost map in cells of {cell} pixels")
        self.cell = int(cell)
        self.restart(width, height)

    def restart(self, width: int, height: int) -> None:
        """A new image (another view, scene or setting): no stage has run over it yet."""
        if width <= 0 or height <= 0:
            raise ValueError(f"a cost map of a {width}×{height} image")
        self.width, self.height = int(width), int(height)
        self.shape = (math.ceil(self.height / self.cell), math.ceil(self.width / self.cell))
        self.maps: dict = {}

    def _cells(self, rect) -> tuple[slice, slice] | None:
        """The cells a tile (x0, y0 from the top, w, h) covers inside the image; None when it
        lies past it."""
        x0, y0, w, h = (int(v) for v in rect)
        lo_x, hi_x = max(x0, 0), min(x0 + w, self.width)
        lo_y, hi_y = max(y0, 0), min(y0 + h, self.height)
        if lo_x >= hi_x or lo_y >= hi_y:
            return None
        c = self.cell
        return slice(lo_y // c, (hi_y - 1) // c + 1), slice(lo_x // c, (hi_x - 1) // c + 1)

    def inside(self, rect) -> bool:
        """Whether the tile ``rect`` has a pixel inside the image."""
        return self._cells(rect) is not None

    def measured(self, key, rect, seconds: float) -> None:
        """Stage ``key`` took ``seconds`` over the tile ``rect`` (every traced pixel, those past
        the image's border too): its cells now cost that much a pixel."""
        cells = self._cells(rect)
        w, h = int(rect[2]), int(rect[3])
        if cells is None or w * h <= 0 or not math.isfinite(seconds) or seconds < 0.0:
            return
        if key not in self.maps:
            self.maps[key] = np.full(self.shape, np.nan, np.float32)
        self.maps[key][cells] = seconds / (w * h)

    def predicted(self, key, rect) -> float | None:
        """Seconds stage ``key`` would take over the tile ``rect``: its cells' mean cost a pixel
        × its traced pixels; None where the stage never ran over one of its cells."""
        cells = self._cells(rect)
        costs = self.maps.get(key)
        if cells is None or costs is None:
            return None
        part = costs[cells]
        if np.isnan(part).any():
            return None
        return float(part.mean()) * int(rect[2]) * int(rect[3])

    def longest(self, kind, rect) -> float | None:
        """The longest of the stages of ``kind`` (keys (kind, index)) predicted over ``rect``;
        None when none can be."""
        times = [self.predicted(key, rect) for key in self.maps if key[0] == kind]
        times = [t for t in times if t is not None]
        return max(times) if times else None


def _halves(side: int, multiple: int, stride: int) -> tuple[int, int] | None:
    """Two allowed sides, multiples of ``multiple``, adding up to ``side``, as near halves as
    there are; None when there are none."""
    if side % multiple:
        return None
    k = side // multiple
    parts = [(a, k - a) for a in range(1, k) if allowed_side(a * multiple, stride)
             and allowed_side((k - a) * multiple, stride)]
    if not parts:
        return None
    a, b = min(parts, key=lambda p: (abs(p[0] - p[1]), -p[0]))
    return a * multiple, b * multiple


def split_tile(rect, multiple: int, stride: int):
    """The tile ``rect`` (x0, y0, w, h) cut in two across its longer side that can be cut into
    two sides of every tile's kind (multiples of ``multiple``: whole work groups of the gather
    grid; ``progressive.allowed_side``); None when neither side can."""
    x0, y0, w, h = (int(v) for v in rect)
    for axis in sorted((0, 1), key=lambda a: -(w, h)[a]):
        halves = _halves((w, h)[axis], multiple, stride)
        if halves is None:
            continue
        a, b = halves
        if axis == 0:
            return (x0, y0, a, h), (x0 + a, y0, b, h)
        return (x0, y0, w, a), (x0, y0 + a, w, b)
    return None


def split_to_fit(rect, longest, budget: float, multiple: int, stride: int, inside) -> list:
    """The tile ``rect`` as tiles whose predicted longest stage (``longest(rect)`` → seconds or
    None: unknown) is within ``budget``, cut in two (``split_tile``) as often as that takes and
    the sides allow; parts with no pixel inside the image (``inside(rect)`` False) are dropped.
    The first part first (the left or top one)."""
    done, todo = [], [rect]
    while todo:
        part = todo.pop(0)
        seconds = longest(part)
        halves = split_tile(part, multiple, stride) if seconds is not None and seconds > budget \
            else None
        if halves is None:
            done.append(part)
        else:
            todo[:0] = [half for half in halves if inside(half)]
    return done
