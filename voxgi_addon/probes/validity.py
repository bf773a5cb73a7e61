"""Probe validity and relocation (docs/probes.md "Validity"), as EEVEE's and Unity's adaptive
probe volumes do it: a probe whose rays mostly hit **back faces** sits inside geometry (or
behind a one-sided wall) and would light the room with what it sees from in there.

``trace_probe_rays`` casts every probe's bake rays (exact, ``scene.raycast``); the back-face
share is the probe's *validity* value. ``relocate_probes`` moves a probe whose share exceeds the
threshold through its nearest back face (along that ray, a small offset beyond the hit), up to
``rounds`` times and never further than ``max_offset`` from its grid corner; a probe still
invalid after that is disabled (left out of every query).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import raycast
from ..scene.short_axis import norm3
from .grid import DISABLED, RELOCATED

__all__ = ["ProbeRays", "trace_probe_rays", "relocate_probes"]


@dataclass(frozen=True, eq=False)
class ProbeRays:
    """Closest hits of each probe's rays (P probes × N directions; -1/inf for a miss)."""

    t: np.ndarray
    triangle: np.ndarray
    u: np.ndarray
    v: np.ndarray
    back: np.ndarray  # (P, N) bool: the hit triangle faces away from the probe

    @property
    def back_share(self) -> np.ndarray:
        return self.back.mean(axis=1) if self.back.size else np.zeros(len(self.back))


def trace_probe_rays(tris, positions, directions) -> ProbeRays:
    """Closest hits of rays from every position (P, 3) along every direction (N, 3)."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    n = len(d)
    origins = np.repeat(p, n, axis=0)
    dirs = np.tile(d, (len(p), 1))
    t, tri, u, v = raycast.closest_hits(tris, origins, dirs)
    shape = (len(p), n)
    normals = np.asarray(tris.normals, np.float64)
    hit = tri >= 0
    facing = np.zeros(len(tri))
    if len(normals):
        facing[hit] = np.einsum("ij,ij->i", normals[tri[hit]], dirs[hit])
    back = hit & (facing > 0)
    return ProbeRays(t.reshape(shape), tri.reshape(shape), u.reshape(shape), v.reshape(shape),
                     back.reshape(shape))


def _merge(rays: ProbeRays, rows: np.ndarray, new: ProbeRays) -> ProbeRays:
    out = [np.array(a) for a in (rays.t, rays.triangle, rays.u, rays.v, rays.back)]
    for arr, part in zip(out, (new.t, new.triangle, new.u, new.v, new.back)):
        arr[rows] = part
    return ProbeRays(*out)


def relocate_probes(tris, positions, directions, threshold: float, max_offset: float,
                    step: float, rounds: int = 3, relocate: bool = True):
    """Validity, relocation and disabling of probes.

    positions : (P, 3) grid positions; directions : (N, 3) the bake's ray directions.
    threshold : back-face share above which a probe is invalid. max_offset : how far (m) a probe
    may move from its grid position; step : how far beyond the back face it goes.
    Returns (positions (P, 3), validity (P,) float32, flags (P,) uint32, ProbeRays at the final
    positions — the bake reuses them).
    """
    start = np.asarray(positions, np.float64).reshape(-1, 3)
    pos = start.copy()
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    flags = np.zeros(len(pos), np.uint32)
    rays = trace_probe_rays(tris, pos, d)
    for _ in range(rounds if relocate else 0):
        invalid = np.flatnonzero(rays.back_share > threshold)
        if len(invalid) == 0:
            break
        t_back = np.where(rays.back[invalid], rays.t[invalid], np.inf)
        j = np.argmin(t_back, axis=1)
        t_near = t_back[np.arange(len(invalid)), j]
        target = pos[invalid] + d[j] * (t_near + step)[:, None]
        ok = np.isfinite(t_near) & (norm3(target - start[invalid]) <= max_offset)
        moved = invalid[ok]
        if len(moved) == 0:
            break
        pos[moved] = target[ok]
        flags[moved] |= RELOCATED
        rays = _merge(rays, moved, trace_probe_rays(tris, pos[moved], d))
    validity = rays.back_share.astype(np.float32)
    flags[validity > threshold] |= DISABLED
    return pos, validity, flags, rays
