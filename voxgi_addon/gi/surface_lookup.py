"""The triangle under a shading point: the G-buffer holds a point, its shading normal and the
camera ray that saw it, not its triangle; the shadow terminator's lift (``terminator``) and
the gather's rays below the triangle's plane (``exact_indirect.indirect_and_ao(geometric=…)``)
need that triangle. A ray along the camera ray from ``REACH`` in front of the point to as far
behind it finds it. For the gather the face found is trusted only within 60° of the shading
normal (``TRUST``): a point on a crease finds the other face, perpendicular and a hair in
front, as often as its own (36 gather points of the Cornell box at 160 × 120 on the GPU,
whose G-buffer points lie a hair off their triangles), and half its rays dropped with it.
The terminator's lift trusts any face found: a flat face lifts nothing whichever it is, and a
noisy rock's own faces turn further than 60° from its smooth normals (trusting by the angle
there took the diorama's Combined 0.086 → 0.099). GLSL twins:
``bvh_direct.glsl`` ``terminator_set``, ``bvh_gather.glsl`` ``geometric_normal``. Numpy only.
"""
from __future__ import annotations

import numpy as np

from ..scene.short_axis import norm3
from ..scene.snapshot import RAY_CAMERA

__all__ = ["REACH", "TRUST", "find_triangles", "geometric_normals"]

REACH = 1e-3  # metres in front of the point and behind it
TRUST = 0.5   # cos 60°: a face further from the shading normal is another surface's ...


def find_triangles(tris, points, views, normals, ray: int = RAY_CAMERA, trust: bool = False):
    """((N,) triangle or −1, (N,) u, (N,) v, (N, 3) face normals on the shading normal's side)
    under shading points (N, 3) seen along unit ``views`` (N, 3) with shading normals (N, 3);
    ``ray``: the kind of ray that looks (``snapshot.RAY_*``: the kernel's closest hits);
    ``trust``: only faces within 60° of the shading normal (``TRUST``), others as not found."""
    from ..scene.bvh import closest_hits

    p = np.asarray(points, np.float64).reshape(-1, 3)
    d = np.asarray(views, np.float64).reshape(-1, 3)
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    tri = np.full(len(p), -1, np.int64)
    u, v, face = np.zeros(len(p)), np.zeros(len(p)), np.zeros_like(p)
    if len(p) == 0:
        return tri, u, v, face
    _, found, fu, fv = closest_hits(tris, p - REACH * d, d, 0.0, 2.0 * REACH, ray=ray)
    hit = np.flatnonzero(found >= 0)
    corners = np.asarray(tris.positions, np.float64).reshape(-1, 3, 3)[found[hit]]
    f = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    f /= np.maximum(norm3(f), 1e-30)[:, None]
    f = np.where((np.einsum("ij,ij->i", f, n[hit]) < 0.0)[:, None], -f, f)
    trusted = np.einsum("ij,ij->i", f, n[hit]) > TRUST if trust else np.ones(len(hit), bool)
    at = hit[trusted]
    tri[at], u[at], v[at], face[at] = found[at], fu[at], fv[at], f[trusted]
    return tri, u, v, face


def geometric_normals(tris, points, views, normals, ray: int = RAY_CAMERA) -> np.ndarray:
    """(N, 3) the face normals of the triangles under the points (``find_triangles``, trusted
    within ``TRUST``), the shading normal where none is found or trusted."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    tri, _, _, face = find_triangles(tris, points, views, n, ray, trust=True)
    return np.where((tri >= 0)[:, None], face, n)
