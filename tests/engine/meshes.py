"""Small deterministic meshes for engine tests (numpy only)."""
import numpy as np


def uv_sphere(rings=12, segments=24, radius=1.0, centre=(0.0, 0.0, 0.0)):
    """(V, 3) float64 positions and (T, 3) int64 triangles of a closed UV sphere."""
    th = np.linspace(0.0, np.pi, rings + 1)
    ph = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pos = radius * np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    idx = np.arange((rings + 1) * segments).reshape(rings + 1, segments)
    a, b = idx[:-1], np.roll(idx[:-1], -1, 1)
    c, d = idx[1:], np.roll(idx[1:], -1, 1)
    tris = np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3),  # counter-clockwise
                           np.stack([b, c, d], -1).reshape(-1, 3)])  # seen from outside
    return pos.reshape(-1, 3) + np.asarray(centre), tris


def tube(rings=9, segments=12, length=3.0, radius=0.3):
    """An open cylinder along +Z from z=0 to z=length: positions (V, 3), triangles (T, 3)."""
    z = np.linspace(0.0, length, rings)
    ph = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    zz, pp = np.meshgrid(z, ph, indexing="ij")
    pos = np.stack([radius * np.cos(pp), radius * np.sin(pp), zz], -1).reshape(-1, 3)
    idx = np.arange(rings * segments).reshape(rings, segments)
    a, b = idx[:-1], np.roll(idx[:-1], -1, 1)
    c, d = idx[1:], np.roll(idx[1:], -1, 1)
    tris = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                           np.stack([b, d, c], -1).reshape(-1, 3)])
    return pos, tris


def box(size=(1.0, 1.0, 1.0), centre=(0.0, 0.0, 0.0)):
    """A closed axis-aligned box: 8 vertices, 12 triangles."""
    s = np.asarray(size) / 2
    pos = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * s
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads]
    return pos + np.asarray(centre), np.array(tris)
