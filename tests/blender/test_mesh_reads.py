"""The snapshot's mesh reads through attribute arrays (``blender/snapshot/mesh.py``) equal
Blender's item-by-item RNA values: loop triangles' vertices, corners and material slots,
positions and UVs, for triangle, quad and n-gon meshes with several material slots."""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from voxgi.blender.snapshot.mesh import read_corner_uvs, read_positions, read_triangles


def _reference(mesh):
    mesh.calc_loop_triangles()
    tris = mesh.loop_triangles
    count = len(tris)
    vertices = np.empty(3 * count, np.int32)
    corners = np.empty(3 * count, np.int32)
    slots = np.empty(count, np.int32)
    tris.foreach_get("vertices", vertices)
    tris.foreach_get("loops", corners)
    tris.foreach_get("material_index", slots)
    positions = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", positions)
    uv = np.empty(2 * len(mesh.loops), np.float32)
    mesh.uv_layers.active.data.foreach_get("uv", uv)
    return (vertices.reshape(-1, 3), corners.reshape(-1, 3), slots, positions.reshape(-1, 3),
            uv.reshape(-1, 2)[corners.reshape(-1, 3)])


@pytest.mark.parametrize("shape", ["triangles", "quads", "ngons", "one slot"])
def test_attribute_reads_equal_rna(shape):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if shape == "ngons":
        bpy.ops.mesh.primitive_cylinder_add(vertices=7)
    else:
        bpy.ops.mesh.primitive_uv_sphere_add(segments=9, ring_count=6)
    obj = bpy.context.object
    mesh = obj.data
    if shape == "triangles":
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_all(action="SELECT")
        bpy.ops.mesh.quads_convert_to_tris(quad_method="SHORTEST_DIAGONAL")
        bpy.ops.object.mode_set(mode="OBJECT")
    if shape != "one slot":
        for name in ("a", "b", "c"):
            obj.data.materials.append(bpy.data.materials.new(name))
        indices = np.arange(len(mesh.polygons), dtype=np.int32) % 3
        mesh.polygons.foreach_set("material_index", indices)
    mesh.vertices[0].co.x += 0.3  # a concave-ish face somewhere
    mesh.update()
    uv = np.random.default_rng(1).random(2 * len(mesh.loops)).astype(np.float32)
    mesh.uv_layers.active.data.foreach_set("uv", uv)
    vertices, corners, slots, positions, uvs = _reference(mesh)
    got_vertices, got_corners, got_slots = read_triangles(mesh)
    np.testing.assert_array_equal(got_vertices, vertices)
    np.testing.assert_array_equal(got_corners, corners)
    np.testing.assert_array_equal(got_slots, slots)
    np.testing.assert_array_equal(read_positions(mesh), positions)
    np.testing.assert_array_equal(read_corner_uvs(mesh, got_corners), uvs)
