"""What F12 traces for a Render Region (Output › Format › Render Region, Ctrl B in the camera
view): the region grown by the reach of the preview's filters, aligned to the gather's lattice
(docs/gi_pipeline.md "A Render Region traced alone").

Cycles renders a region's pixels alone, so a small region renders in a fraction of the whole
frame's time. The preview's passes are not each pixel's alone: the gathers run on a lattice of
cells (one per ``stride`` × ``stride`` pixels, the sparse gather traces every other one and
fills the rest) and their filters read cells several taps away. So the traced rectangle is the
region plus ``MARGIN_CELLS`` cells each way, clipped to the frame (where the frame ends the
whole frame's filters see its edge as well), with its top-left corner on the whole frame's
lattice of ``ALIGN_CELLS`` cells: the region's cells are the cells the whole frame would trace,
and the filters see the neighbours they would see there, to the margin's depth.

Numpy only.
"""
from __future__ import annotations

__all__ = ["ALIGN_CELLS", "MARGIN_CELLS", "traced_rect"]

# Cells beyond the region on each side. The à-trous filter's passes reach 2 + 4 + 8 + … cells
# (docs/gi_pipeline.md "A Render Region traced alone": measured against the whole frame's
# pixels, this margin leaves the region at the whole frame's noise level)
MARGIN_CELLS = 8
# The traced rectangle's top-left corner lies on the whole frame's lattice of this many cells
# (the sparse gather's first list takes every other cell, counted from the top left)
ALIGN_CELLS = 8


def traced_rect(region, width: int, height: int, stride: int,
                margin_cells: int | None = None) -> tuple[int, int, int, int]:
    """(x0, y0, w, h), pixels from the bottom left like ``region``, of the part of a
    ``width`` × ``height`` frame to trace for the Render Region ``region`` (x0, y0, w, h):
    the region grown by ``margin_cells`` (None: ``MARGIN_CELLS``) gather cells of ``stride``
    pixels each way, its left column and top row moved out to a multiple of ``ALIGN_CELLS``
    cells from the frame's top left corner, clipped to the frame."""
    x0, y0, w, h = (int(v) for v in region)
    if w < 1 or h < 1 or x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise ValueError(f"region {region} is not inside a {width} × {height} frame")
    cells = MARGIN_CELLS if margin_cells is None else margin_cells
    margin, align = cells * stride, ALIGN_CELLS * stride
    left = max(0, x0 - margin) // align * align
    top = max(0, height - (y0 + h) - margin) // align * align  # rows counted from the top
    right = min(width, x0 + w + margin)
    bottom = max(0, y0 - margin)  # the lowest row, from the bottom
    return left, bottom, right - left, height - top - bottom
