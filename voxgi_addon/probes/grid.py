"""The baked light-probe grid (Bowald 2016, ch. 3; docs/probes.md "Data").

One ``ProbeGrid`` per probe box: the box [origin, origin + dims · volume_size] is split into
dims[0] × dims[1] × dims[2] volumes; volumes that contain geometry are *active* and carry
probes at their 8 corners, shared with their neighbours. Everything the runtime query needs
sits in flat arrays (Bowald eq. 3.2–3.5):

origin : (3,) float64 min corner (metres); volume_size : (3,) float64 edge of one volume per
    axis; dims : (3,) int64 volumes per axis.
positions : (P, 3) float32 probe positions (after relocation, see ``validity``).
sh : (P, 9, 3) float32 SH L2 RGB coefficients of each probe's incoming radiance.
volume_cells : (V,) uint32 linear volume ``x + X·(y + Y·z)`` of each active volume, ascending.
volume_probes : (V, 8) uint32 probe of corner ``c = x | y<<1 | z<<2`` of each active volume.
volume_masks : (V, 8) uint64 per corner probe, bit ``sx + 4·(sy + 4·sz)`` set where the probe
    may light sub-volume (sx, sy, sz) of the 4×4×4 split (``masks``).
sh_index : ((X+1)(Y+1)(Z+1),) uint32 probe at grid corner ``x + (X+1)·(y + (Y+1)·z)``,
    ``NO_INDEX`` where there is none (Bowald's SH index, eq. 3.2).
mask_index : (X·Y·Z,) uint32 row of ``volume_masks`` of each volume, ``NO_INDEX`` for an
    inactive one (Bowald's occlusion index, eq. 3.4).
validity : (P,) float32 share of the probe's rays that hit a back face (at its final place).
flags : (P,) uint32 ``RELOCATED`` | ``DISABLED``.
mask_threshold : the front-facing share the masks were built with (0 = masks off: all set).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ProbeGrid", "NO_INDEX", "RELOCATED", "DISABLED", "CORNER_OFFSETS", "memory_report",
           "index_arrays"]

NO_INDEX = 0xFFFFFFFF
RELOCATED = 1
DISABLED = 2
# Corner c = x | y<<1 | z<<2 → its (x, y, z) offset.
CORNER_OFFSETS = np.array([[c & 1, (c >> 1) & 1, (c >> 2) & 1] for c in range(8)], np.int64)


@dataclass
class ProbeGrid:
    """See the module docstring."""

    origin: np.ndarray
    volume_size: np.ndarray
    dims: np.ndarray
    positions: np.ndarray
    sh: np.ndarray
    volume_cells: np.ndarray
    volume_probes: np.ndarray
    volume_masks: np.ndarray
    sh_index: np.ndarray | None = None
    mask_index: np.ndarray | None = None
    validity: np.ndarray | None = None
    flags: np.ndarray | None = None
    mask_threshold: float = 0.5
    name: str = field(default="")

    def __post_init__(self):
        self.origin = np.asarray(self.origin, np.float64).reshape(3)
        self.volume_size = np.broadcast_to(np.asarray(self.volume_size, np.float64), (3,)).copy()
        self.dims = np.asarray(self.dims, np.int64).reshape(3)
        p = len(self.positions)
        if self.sh_index is None or self.mask_index is None:
            self.sh_index, self.mask_index = index_arrays(self.dims, self.volume_cells,
                                                          self.volume_probes)
        if self.validity is None:
            self.validity = np.zeros(p, np.float32)
        if self.flags is None:
            self.flags = np.zeros(p, np.uint32)

    @property
    def cell_size(self) -> float:
        """The x edge of a volume (GFG 1.1's single cell size)."""
        return float(self.volume_size[0])

    @property
    def enabled(self) -> np.ndarray:
        """(P,) bool: probes that take part in queries."""
        return (np.asarray(self.flags) & DISABLED) == 0

    def corner_position(self, corners) -> np.ndarray:
        """(N, 3) float64 world position of linear grid corners (before relocation)."""
        c = np.asarray(corners, np.int64)
        x1, y1 = self.dims[0] + 1, self.dims[1] + 1
        xyz = np.stack([c % x1, (c // x1) % y1, c // (x1 * y1)], axis=1)
        return self.origin + xyz * self.volume_size


def index_arrays(dims, volume_cells, volume_probes) -> tuple[np.ndarray, np.ndarray]:
    """Bowald's two index arrays from the sparse volume list: the SH index ((X+1)(Y+1)(Z+1),)
    and the occlusion index (X·Y·Z,), both uint32 with ``NO_INDEX`` for none."""
    dims = np.asarray(dims, np.int64)
    cells = np.asarray(volume_cells, np.int64)
    mask_index = np.full(int(dims.prod()), NO_INDEX, np.uint32)
    mask_index[cells] = np.arange(len(cells), dtype=np.uint32)
    sh_index = np.full(int((dims + 1).prod()), NO_INDEX, np.uint32)
    if len(cells):
        x = cells % dims[0]
        y = (cells // dims[0]) % dims[1]
        z = cells // (dims[0] * dims[1])
        xyz = np.stack([x, y, z], axis=1)[:, None, :] + CORNER_OFFSETS[None]
        corner = xyz[..., 0] + (dims[0] + 1) * (xyz[..., 1] + (dims[1] + 1) * xyz[..., 2])
        sh_index[corner.ravel()] = np.asarray(volume_probes, np.uint32).ravel()
    return sh_index, mask_index


def memory_report(grid: ProbeGrid) -> dict[str, int]:
    """Bytes of the runtime arrays (Bowald eq. 3.2–3.5, with 64-bit masks: 8 per volume corner)."""
    report = {
        "sh_index": grid.sh_index.size * 4,
        "sh_coefficients": len(grid.positions) * 27 * 4,
        "occlusion_index": grid.mask_index.size * 4,
        "occlusion_masks": len(grid.volume_cells) * 8 * 8,
    }
    report["total"] = sum(report.values())
    return report
