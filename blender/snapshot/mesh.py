"""Read an evaluated Blender mesh into flat numpy arrays (main thread).

Everything goes through ``foreach_get`` into preallocated flat arrays; no
per-vertex Python loops.
"""
from __future__ import annotations

import numpy as np


def read_positions(mesh) -> np.ndarray:
    """Vertex positions of ``mesh`` (a ``bpy.types.Mesh``).

    Returns (V, 3) float32, object space. Non-finite values are passed through.
    """
    positions = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    attribute = _attribute(mesh, "position", "POINT", "FLOAT_VECTOR")
    if attribute is not None:  # the attribute's array: 50× quicker than MeshVertex.co
        attribute.data.foreach_get("vector", positions)
    else:
        mesh.vertices.foreach_get("co", positions)
    return positions.reshape(-1, 3)


def _attribute(mesh, name: str, domain: str, data_type: str):
    """``mesh``'s attribute ``name`` when it is of that domain and type, else None.
    ``foreach_get`` on an attribute's ``data`` copies its array at once; the same values
    through ``MeshVertex``, ``MeshLoopTriangle`` or ``MeshUVLoop`` go item by item through
    RNA (on a 142k-triangle scene the snapshot's reads took 117 of its 150 ms that way)."""
    attribute = mesh.attributes.get(name)
    if attribute is None or attribute.domain != domain or attribute.data_type != data_type:
        return None
    return attribute


def _int_attribute(mesh, name: str, domain: str, size: int) -> np.ndarray | None:
    attribute = _attribute(mesh, name, domain, "INT")
    if attribute is None:
        return None
    values = np.empty(size, dtype=np.int32)
    attribute.data.foreach_get("value", values)
    return values


def read_triangles(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Blender's loop triangulation of ``mesh``.

    Returns
    -------
    triangles : (T, 3) int32 vertex indices.
    corners : (T, 3) int32 loop (face corner) indices, to look up per-corner data.
    slot_indices : (T,) int32 material slot index of each triangle.
    """
    mesh.calc_loop_triangles()
    tris = mesh.loop_triangles
    count = len(tris)
    # Read through the mesh's attribute arrays where it can (``_attribute``): each triangle's
    # face (``loop_triangle_polygons``), the faces' material slots, the corners' vertices.
    # Only the triangles' corners have no array of their own; where every face is a
    # triangle, Blender's loop triangles are the faces' corners in order.
    faces = np.empty(count, dtype=np.int32)
    mesh.loop_triangle_polygons.foreach_get("value", faces)
    loop_count = len(mesh.loops)
    if loop_count == 3 * count and len(mesh.polygons) == count and \
            np.array_equal(faces, np.arange(count, dtype=np.int32)):
        corners = np.arange(3 * count, dtype=np.int32)
    else:
        corners = np.empty(count * 3, dtype=np.int32)
        tris.foreach_get("loops", corners)
    corner_vertices = _int_attribute(mesh, ".corner_vert", "CORNER", loop_count)
    if corner_vertices is not None:
        triangles = corner_vertices[corners]
    else:
        triangles = np.empty(count * 3, dtype=np.int32)
        tris.foreach_get("vertices", triangles)
    face_slots = _int_attribute(mesh, "material_index", "FACE", len(mesh.polygons))
    slot_indices = np.zeros(count, dtype=np.int32) if face_slots is None else face_slots[faces]
    return triangles.reshape(-1, 3), corners.reshape(-1, 3), slot_indices


def at_corners(values: np.ndarray, corners: np.ndarray, width: int) -> np.ndarray:
    """``values`` (one row of ``width`` per corner, flat) at ``corners`` (T, 3): (T, 3, width).
    Where the triangles are every corner in order (a mesh of triangles: ``read_triangles``)
    the array itself, not a gather of it (the same values; 2–3 ms less on 142k triangles)."""
    rows = values.reshape(-1, width)
    if corners.size == len(rows) and np.array_equal(corners.ravel(),
                                                     np.arange(corners.size, dtype=corners.dtype)):
        return rows.reshape(-1, 3, width)
    return rows[corners]


def read_corner_uvs(mesh, corners: np.ndarray, name: str = "") -> np.ndarray | None:
    """UVs of a UV map at the given corners: the one called ``name``, else the active render
    one (what Cycles' textures read by default), else the active one.

    corners : (T, 3) int32 loop indices (from ``read_triangles``).
    Returns (T, 3, 2) float32, or None when the mesh has no UV map.
    """
    layers = mesh.uv_layers
    layer = layers.get(name) if name else None
    if layer is None:
        layer = next((candidate for candidate in layers if candidate.active_render), None) \
            or layers.active
    if layer is None:
        return None
    uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    attribute = _attribute(mesh, layer.name, "CORNER", "FLOAT2")
    if attribute is not None:  # the UV map's attribute array (``_attribute``)
        attribute.data.foreach_get("vector", uv)
    else:
        layer.data.foreach_get("uv", uv)
    return at_corners(uv, corners, 2)


def named_uvs(mesh, corners: np.ndarray, materials: np.ndarray, table, uvs):
    """``uvs`` (T, 3, 2) with the triangles whose material's texture names another UV map
    (``table.uv_map(index)``) reading that one; unchanged when none does."""
    if uvs is None:
        return None
    for index in np.unique(materials[materials >= 0]):
        name = table.uv_map(int(index))
        if name and mesh.uv_layers.get(name) is not None:
            at = materials == index
            uvs = np.array(uvs, copy=True)
            uvs[at] = read_corner_uvs(mesh, corners[at], name)
    return uvs


def read_corner_normals(mesh, corners: np.ndarray) -> np.ndarray:
    """(T, 3, 3) float32 object-space shading normals at each loop triangle corner.

    corners : (T, 3) loop indices of the loop triangles (``read_triangles``).
    """
    normals = np.empty(len(mesh.loops) * 3, dtype=np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    return at_corners(normals, corners, 3)


def read_point_float(mesh, name: str) -> np.ndarray:
    """A float POINT attribute of ``mesh`` as (V,) float32."""
    values = np.empty(len(mesh.vertices), dtype=np.float32)
    mesh.attributes[name].data.foreach_get("value", values)
    return values


def material_lookup(slot_materials: list, material_index_of) -> np.ndarray:
    """Map material slot indices to indices into the snapshot's material list.

    slot_materials : the object's slot materials (``bpy.types.Material`` or None).
    material_index_of : callable(Material) -> int, the global index (adds it if new).
    Returns (S,) int32, -1 for an empty slot.
    """
    return np.array(
        [-1 if mat is None else material_index_of(mat) for mat in slot_materials],
        dtype=np.int32,
    )


def triangle_materials(slot_indices: np.ndarray, lookup: np.ndarray) -> np.ndarray:
    """Global material index per triangle.

    slot_indices : (T,) int32 slot index per triangle; lookup : (S,) int32 from
    ``material_lookup``. Out-of-range slot indices use the last slot, as Blender does.
    Returns (T,) int32, -1 where there is no material.
    """
    if lookup.size == 0:
        return np.full(slot_indices.shape, -1, dtype=np.int32)
    return lookup[np.clip(slot_indices, 0, lookup.size - 1)]
