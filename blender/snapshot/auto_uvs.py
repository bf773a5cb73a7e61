"""UVs of a bake over a mesh that has no UV map.

Artists shade many meshes they never unwrap: procedural textures on Generated or Object
coordinates, vertex colours painted on a low-poly model, a Geometry Nodes or CAD mesh. Cycles
evaluates those nodes per shading point; the preview bakes a node-built socket over the mesh's
UV map (``materials.bake_socket``), and with none it drew the socket's plain value. Here each
polygon gets its own square of the UV square, its side ∝ √(its area) (the texels spread evenly
over the surface), the squares packed in rows, largest first, ``PAD`` apart. A polygon is
drawn into its square as it lies in its own plane (flat, aspect kept), so any triangulation of
it reads the same UVs at its corners. The layout is per loop, in the mesh's loop order: the
bake's copy of the mesh takes it as a UV map, the snapshot reads it at its triangles' corners.
"""
from __future__ import annotations

import numpy as np

PAD = 1.5 / 512  # around each polygon's square: 1.5 texels of a 512² bake


def polygon_uvs(mesh) -> np.ndarray:
    """(L, 2) float32 UVs of ``mesh``'s loops (a ``bpy.types.Mesh`` with polygons): each
    polygon flat in its own square (module doc)."""
    polygons, loops = len(mesh.polygons), len(mesh.loops)
    starts = np.empty(polygons, np.int64)
    totals = np.empty(polygons, np.int64)
    mesh.polygons.foreach_get("loop_start", starts)
    mesh.polygons.foreach_get("loop_total", totals)
    normals = np.empty(polygons * 3, np.float32)
    mesh.polygons.foreach_get("normal", normals)
    vertices = np.empty(loops, np.int64)
    mesh.loops.foreach_get("vertex_index", vertices)
    positions = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", positions)
    return layout(positions.reshape(-1, 3).astype(np.float64)[vertices], starts, totals,
                  normals.reshape(-1, 3).astype(np.float64))


def layout(points: np.ndarray, starts: np.ndarray, totals: np.ndarray,
           normals: np.ndarray) -> np.ndarray:
    """(L, 2) float32 UVs of loops at ``points`` (L, 3), polygons of ``totals`` loops from
    ``starts`` (loop order) with unit ``normals`` (P, 3): ``polygon_uvs``' layout."""
    points = np.nan_to_num(points, nan=0.0, posinf=0.0, neginf=0.0)  # (a broken vertex's
    normals = np.nan_to_num(normals, nan=0.0, posinf=0.0, neginf=0.0)  # triangles are not drawn)
    owner = np.repeat(np.arange(len(starts)), totals)
    tangent, bitangent = _basis(normals)
    flat = np.stack([(points * tangent[owner]).sum(-1), (points * bitangent[owner]).sum(-1)], -1)
    low = np.stack([np.minimum.reduceat(flat[:, k], starts) for k in (0, 1)], -1)
    high = np.stack([np.maximum.reduceat(flat[:, k], starts) for k in (0, 1)], -1)
    extent = np.maximum((high - low).max(-1), 1e-12)  # the polygon's larger side
    area = np.maximum(_areas(points, starts, totals), 1e-12 * extent ** 2)
    sides = np.sqrt(area)
    corners, scale = _pack(sides)
    size = sides * scale  # each square's side in the UV square
    uv = corners[owner] + (flat - low[owner]) * (size / extent)[owner, None]
    return uv.astype(np.float32)


def _basis(normals: np.ndarray):
    """Two unit tangents per normal, perpendicular to it and to each other."""
    n = normals / np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-30)
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    tangent = np.cross(n, helper)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=-1, keepdims=True), 1e-30)
    return tangent, np.cross(n, tangent)


def _areas(points: np.ndarray, starts: np.ndarray, totals: np.ndarray) -> np.ndarray:
    """(P,) the polygons' areas (their fans from the first corner)."""
    owner = np.repeat(np.arange(len(starts)), totals)
    first = points[starts][owner]
    following = np.roll(points, -1, axis=0)
    last = starts + totals - 1  # the closing edge of each fan adds nothing
    following[last] = first[last]
    cross = np.cross(points - first, following - first)
    return 0.5 * np.linalg.norm(np.add.reduceat(cross, starts, axis=0), axis=-1)


def _pack(sides: np.ndarray):
    """((P, 2) lower-left corners of the polygons' squares in the UV square, the scale of
    ``sides`` into it): squares in rows, largest first, each in a cell PAD wider on every side
    (the bake's margin fills it from the polygon's edge, so that a texture lookup by a
    polygon's edge reads its own colour, not its neighbour's). One step per row (a row ends
    where the cells' running sum passes the row's width), not per polygon."""
    order = np.argsort(-sides, kind="stable")
    scale, pad, used = 1.0, 0.0, 0.0
    corners = np.zeros((len(sides), 2))
    for _ in range(2):  # the padding is in UV units: the scale it gives, then the rows again
        used = pad
        cells = sides[order] + 2.0 * used
        width = np.sqrt((cells ** 2).sum()) * 1.1 + cells[0]
        ends = np.cumsum(cells)
        x = np.zeros(len(cells))
        y = np.zeros(len(cells))
        start, top = 0, 0.0
        while start < len(cells):
            before = ends[start - 1] if start else 0.0
            stop = max(start + 1, int(np.searchsorted(ends, before + width, side="right")))
            x[start:stop] = ends[start:stop] - cells[start:stop] - before
            y[start:stop] = top
            top += cells[start]  # the row's tallest: its first (sorted largest first)
            start = stop
        corners[order] = np.stack([x, y], axis=-1)
        scale = 1.0 / max((x + cells).max(), top)
        pad = PAD / scale
    return (corners + used) * scale, scale
