"""A tiny dense, mipmapped stand-in for the octree, for testing the cone tracer on its own.

It follows the octree's sampling contract (docs/gi_pipeline.md): node-centred values,
premultiplied trilinear samples, parents average radiance over present children and hold
occlusion = present children / 8.
"""
import numpy as np


class DenseMipVolume:
    def __init__(self, occupied, radiance, origin, size):
        """occupied (R, R, R) bool, radiance (R, R, R, 3) at the finest level; a cube at origin."""
        r = occupied.shape[0]
        self.depth = int(np.log2(r))
        self.origin = np.asarray(origin, float)
        self.size = float(size)
        occ = occupied.astype(np.float64)
        rad = radiance * occ[..., None]
        self.levels = {self.depth: (rad, occ)}
        present = occupied
        for level in range(self.depth - 1, -1, -1):
            s = 2**level
            child_rad, _ = self.levels[level + 1]
            p = present.reshape(s, 2, s, 2, s, 2).sum(axis=(1, 3, 5))
            total = child_rad.reshape(s, 2, s, 2, s, 2, 3).sum(axis=(1, 3, 5))
            mean = np.divide(total, p[..., None], out=np.zeros_like(total), where=p[..., None] > 0)
            self.levels[level] = (mean, p / 8.0)
            present = p > 0

    def node_size(self, level):
        return self.size / 2**level

    def finest_level_at(self, points):
        return np.full(len(points), self.depth)

    def _sample_level(self, points, level):
        rad, occ = self.levels[level]
        s = 2**level
        u = (points - self.origin) / self.node_size(level) - 0.5
        base = np.floor(u).astype(int)
        f = u - base
        c_out, a_out = np.zeros((len(points), 3)), np.zeros(len(points))
        for corner in range(8):
            o = np.array([(corner >> 0) & 1, (corner >> 1) & 1, (corner >> 2) & 1])
            idx = base + o
            w = np.prod(np.where(o == 1, f, 1 - f), axis=1)
            inside = ((idx >= 0) & (idx < s)).all(axis=1)
            i = np.clip(idx, 0, s - 1)
            a = np.where(inside, occ[i[:, 0], i[:, 1], i[:, 2]], 0.0)
            c = np.where(inside[:, None], rad[i[:, 0], i[:, 1], i[:, 2]], 0.0)
            c_out += w[:, None] * c * a[:, None]
            a_out += w * a
        return c_out, a_out

    def sample(self, points, level):
        lo = np.floor(level).astype(int)
        hi = np.minimum(lo + 1, self.depth)
        t = level - lo
        c, a = np.zeros((len(points), 3)), np.zeros(len(points))
        for lv in np.unique(np.concatenate([lo, hi])):
            w = np.where(lo == lv, 1 - t, 0.0) + np.where(hi == lv, t, 0.0)
            w = np.where((lo == lv) & (hi == lv), 1.0, w)
            sel = w > 0
            if sel.any():
                cs, as_ = self._sample_level(points[sel], lv)
                c[sel] += w[sel, None] * cs
                a[sel] += w[sel] * as_
        return c, a
