"""Input hygiene for meshes: drop triangles the voxelizer cannot use, and say how many."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import VoxGIError
from ..scene.short_axis import all_along, norm3


@dataclass(frozen=True)
class TriangleFilter:
    """Which triangles of a mesh are usable.

    keep : (T,) bool. non_finite / degenerate : how many were dropped for NaN/inf vertices and
    for zero area (collinear or repeated vertices).
    """

    keep: np.ndarray
    non_finite: int
    degenerate: int

    @property
    def dropped(self) -> int:
        return self.non_finite + self.degenerate


def filter_triangles(name: str, positions: np.ndarray, triangles: np.ndarray) -> TriangleFilter:
    """Flag NaN/inf and zero-area triangles of a mesh.

    positions : (V, 3); triangles : (T, 3) int. A triangle is degenerate when its area is
    below 1e-12 of its longest edge squared (float noise on collinear points included).
    Raises VoxGIError if an index is out of range.
    """
    tris = np.asarray(triangles).reshape(-1, 3)
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    if tris.size and (tris.min() < 0 or tris.max() >= len(pos)):
        raise VoxGIError(f"mesh '{name}': triangle vertex index out of range (0..{len(pos) - 1})")
    p = pos[tris]
    finite = all_along(np.isfinite(p).reshape(-1, 9))
    with np.errstate(invalid="ignore", over="ignore"):
        e0, e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 1], p[:, 0] - p[:, 2]
        twice_area = norm3(np.cross(e0, -e2))
        longest_sq = np.maximum(np.maximum((e0**2).sum(1), (e1**2).sum(1)), (e2**2).sum(1))
        solid = 0.5 * twice_area > 1e-12 * longest_sq
    solid &= finite
    return TriangleFilter(keep=solid, non_finite=int((~finite).sum()),
                          degenerate=int((finite & ~solid).sum()))
