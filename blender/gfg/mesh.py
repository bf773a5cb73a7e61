"""Meshes between Blender and GFG files (main thread).

Export reads an evaluated mesh with ``foreach_get`` (positions, loop triangles, corner
normals, active UV map, material slots, top-4 skin weights) and lets the engine's
``build_mesh`` make it single-indexed. Import builds a Blender mesh with one vertex per GFG
vertex (like glTF's importer without "merge vertices"), its normals as free custom normals
(a float corner attribute, stored exactly), the UV map, material slots in range order and
vertex groups named after the skeleton's bones.
"""
from __future__ import annotations

import bpy
import numpy as np

from ...voxgi_addon.files.gfg import MeshArrays, VertexTypes, build_mesh, mesh_arrays
from ..snapshot.mesh import read_corner_uvs, read_triangles
from ..snapshot.skin import rest_corner_normals, rest_positions

CUSTOM_NORMAL = "custom_normal"  # a FLOAT_VECTOR corner attribute of this name = free normals
UV_MAP = "UVMap"


def export_mesh(name: str, mesh, slot_materials, skin, skeleton: int, types: VertexTypes,
                interleaved: bool):
    """The GFG mesh of an evaluated ``bpy.types.Mesh``.

    slot_materials : callable(used slot indices) -> (S,) material index per slot (-1 = none).
    skin : ``SkinData`` (weights (V, 4), bone_indices (V, 4)) or None. A skinned mesh read
    inside ``snapshot.skin.temporary_weight_attributes`` is exported in its rest shape.
    """
    triangles, corners, slots = read_triangles(mesh)
    count = max(len(mesh.materials), 1)
    used = np.unique(np.clip(slots, 0, count - 1)) if len(slots) else np.zeros(0, np.int64)
    return build_mesh(
        name, rest_positions(mesh), triangles,
        corner_normals=rest_corner_normals(mesh, corners),
        corner_uvs=read_corner_uvs(mesh, corners),
        triangle_slots=slots, slot_materials=slot_materials(count, used),
        weights=None if skin is None else skin.weights,
        bone_indices=None if skin is None else skin.bone_indices,
        skeleton=skeleton, types=types, interleaved=interleaved,
    )


def import_mesh(gfg_mesh, materials: list) -> tuple[bpy.types.Mesh, MeshArrays]:
    """A new ``bpy.types.Mesh`` from a TRIANGLES GFG mesh (ValueError for other topologies).

    materials : the imported ``bpy.types.Material`` list the ranges refer to.
    """
    a = mesh_arrays(gfg_mesh)
    mesh = bpy.data.meshes.new(gfg_mesh.name)
    v, t = len(a.positions), len(a.triangles)
    mesh.vertices.add(v)
    mesh.loops.add(3 * t)
    mesh.polygons.add(t)
    mesh.vertices.foreach_set("co", a.positions.reshape(-1))
    mesh.loops.foreach_set("vertex_index", a.triangles.astype(np.int32).reshape(-1))
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * t, 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    for material in a.slot_materials:
        mesh.materials.append(materials[material] if material >= 0 else None)
    if t:
        mesh.polygons.foreach_set("material_index", a.triangle_slots)
    if a.uvs is not None:
        uv = mesh.uv_layers.new(name=UV_MAP)
        uv.data.foreach_set("uv", a.uvs[a.triangles].reshape(-1))
    mesh.shade_smooth()
    if a.normals is not None:
        attribute = mesh.attributes.new(CUSTOM_NORMAL, "FLOAT_VECTOR", "CORNER")
        attribute.data.foreach_set("vector", a.normals[a.triangles].reshape(-1))
    mesh.update()
    return mesh, a


def assign_weights(obj, arrays: MeshArrays, bone_names) -> None:
    """Vertex groups named after ``bone_names`` holding the GFG skin weights of ``obj``'s mesh.

    One ``VertexGroup.add`` call per (bone, distinct weight): quantised weights have few
    distinct values, so this stays fast without per-vertex Python loops.
    """
    if arrays.weights is None or arrays.bone_indices is None:
        return
    weights, bones = arrays.weights, arrays.bone_indices
    for b in np.unique(bones[weights > 0]):
        group = obj.vertex_groups.get(bone_names[b]) or obj.vertex_groups.new(name=bone_names[b])
        rows, cols = np.nonzero((bones == b) & (weights > 0))
        values = weights[rows, cols]
        for value in np.unique(values):
            group.add(rows[values == value].tolist(), float(value), "REPLACE")
