"""From per-corner mesh data (as Blender stores it) to a single-indexed GFG ``Mesh`` and back.

GPUs index one vertex per (position, normal, UV) combination, Blender stores normals and UVs
per face corner. ``build_mesh`` merges the corners of each source vertex that agree exactly
and numbers the resulting vertices in order of first use, triangles sorted (stably) by
material slot so that each slot is one contiguous index range. ``mesh_arrays`` decodes a
``Mesh`` back to float arrays. Building a mesh from what ``mesh_arrays`` returned gives the
same vertices, indices and ranges again, which is what makes export → import → export exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...voxelize.packing import quantize_weights
from . import data_types as dtypes
from .mesh_section import compute_aabb, index_dtype
from .model import MaterialRange, Mesh, VertexComponent
from .spec import Logic, Topology

WEIGHT_LEVELS = {"UNORM8_4": 255, "UNORM16_4": 65535, "FLOAT_4": 65535}
POSITION_TYPES = ("FLOAT_3", "HALF_3")
NORMAL_TYPES = ("FLOAT_3", "NORM16_4", "NORM_2_10_10_10", "CUSTOM_1_15N_16N")
UV_TYPES = ("FLOAT_2", "HALF_2", "UNORM16_2")
WEIGHT_TYPES = tuple(WEIGHT_LEVELS)
WEIGHT_INDEX_TYPES = ("UINT8_4", "UINT16_4")


@dataclass(frozen=True)
class VertexTypes:
    """Storage of each vertex component, by data type name (see the *_TYPES tuples)."""

    position: str = "FLOAT_3"
    normal: str = "FLOAT_3"
    uv: str = "FLOAT_2"
    weight: str = "UNORM8_4"
    weight_index: str = "UINT8_4"


@dataclass
class MeshArrays:
    """Decoded, single-indexed mesh data.

    positions, normals : (V, 3) float32; uvs : (V, 2) float32 or None; weights : (V, 4)
    float32 or None; bone_indices : (V, 4) int64 or None; triangles : (T, 3) int64;
    triangle_slots : (T,) int32 range (= material slot) of each triangle; slot_materials :
    (S,) int32 material index per slot, -1 for none.
    """

    positions: np.ndarray
    normals: np.ndarray | None
    uvs: np.ndarray | None
    weights: np.ndarray | None
    bone_indices: np.ndarray | None
    triangles: np.ndarray
    triangle_slots: np.ndarray
    slot_materials: np.ndarray


def canonical_skin(weights, bone_indices, weight_type: str = "UNORM8_4"):
    """Quantise top-4 weights and sort each row by weight (descending), then bone index.

    weights : (N, 4) float; bone_indices : (N, 4) int. Rows sum exactly to the type's levels
    (255 or 65535); zero weights get bone index 0 and go last. The same weights in any order
    give the same bytes, so re-exporting an imported skin reproduces it.
    Returns (weight storage (N, 4), indices (N, 4) int64).
    """
    levels = WEIGHT_LEVELS[weight_type]
    q = quantize_weights(weights, levels).astype(np.int64)
    idx = np.where(q > 0, np.asarray(bone_indices, np.int64), 0)
    order = np.argsort((levels - q) * (1 << 20) + idx, axis=1, kind="stable")
    q, idx = np.take_along_axis(q, order, axis=1), np.take_along_axis(idx, order, axis=1)
    if weight_type == "UNORM8_4":
        stored = q.astype(np.uint8)
    elif weight_type == "UNORM16_4":
        stored = q.astype("<u2")
    else:
        stored = (q / levels).astype("<f4")
    return stored, idx


def _storage(values, type_name: str) -> tuple[int, np.ndarray]:
    code = dtypes.code_of(type_name)
    dt = dtypes.data_type(code)
    v = np.asarray(values)
    if dt.kind != "packed" and v.shape[1] < dt.components:  # pad xyz → xyzw with zeros
        v = np.concatenate([v, np.zeros((len(v), dt.components - v.shape[1]), v.dtype)], axis=1)
    return code, dtypes.encode(v, code)


def _first_use_numbering(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Equal key rows share a vertex id, ids numbered by first appearance.

    Returns (vertex id per row, first row of each id).
    """
    rows = np.ascontiguousarray(keys).view(np.dtype((np.void, keys.dtype.itemsize * keys.shape[1])))
    _, first, inverse = np.unique(rows.reshape(-1), return_index=True, return_inverse=True)
    by_first = np.argsort(first, kind="stable")
    rank = np.empty(len(first), np.int64)
    rank[by_first] = np.arange(len(first))
    return rank[inverse.reshape(-1)], first[by_first]


def build_mesh(name: str, positions, triangles, *, corner_normals=None, corner_uvs=None,
               triangle_slots=None, slot_materials=(), weights=None, bone_indices=None,
               skeleton: int = -1, types: VertexTypes = VertexTypes(), interleaved: bool = True) -> Mesh:
    """A GFG mesh from Blender-style arrays.

    positions : (V0, 3) float32 object space; triangles : (T, 3) int source vertex indices.
    corner_normals : (T, 3, 3) float32; corner_uvs : (T, 3, 2) float32; triangle_slots : (T,)
    int material slot (out-of-range slots clamp, as in Blender); slot_materials : material
    index per slot (-1 = none). weights : (V0, 4) float; bone_indices : (V0, 4) int.
    """
    positions = np.asarray(positions, np.float32).reshape(-1, 3)
    tris = np.asarray(triangles, np.int64).reshape(-1, 3)
    slot_materials = np.asarray(slot_materials, np.int64).reshape(-1)
    slots = np.zeros(len(tris), np.int64) if triangle_slots is None else np.asarray(triangle_slots, np.int64)
    slots = np.clip(slots, 0, max(len(slot_materials) - 1, 0))
    order = np.argsort(slots, kind="stable")
    tris, slots = tris[order], slots[order]
    corner_source = tris.reshape(-1)
    columns = [corner_source.astype(np.uint32)[:, None]]
    normals = uvs = None
    if corner_normals is not None:
        normals = np.asarray(corner_normals, np.float32).reshape(-1, 3, 3)[order].reshape(-1, 3)
        columns.append(normals.view(np.uint32))
    if corner_uvs is not None:
        uvs = np.asarray(corner_uvs, np.float32).reshape(-1, 3, 2)[order].reshape(-1, 2)
        columns.append(uvs.view(np.uint32))
    vertex_of_corner, first_corner = _first_use_numbering(np.concatenate(columns, axis=1))
    count = len(first_corner)
    source = corner_source[first_corner]

    components = [VertexComponent(Logic.POSITION, *_storage(positions[source], types.position))]
    if normals is not None:
        components.append(VertexComponent(Logic.NORMAL, *_storage(normals[first_corner], types.normal)))
    if uvs is not None:
        components.append(VertexComponent(Logic.UV, *_storage(uvs[first_corner], types.uv)))
    if weights is not None:
        stored, idx = canonical_skin(np.asarray(weights)[source], np.asarray(bone_indices)[source],
                                     types.weight)
        components.append(VertexComponent(Logic.WEIGHT, dtypes.code_of(types.weight), stored))
        components.append(VertexComponent(Logic.WEIGHT_INDEX, *_storage(idx, types.weight_index)))
    indices = vertex_of_corner.astype(index_dtype(count))
    ranges = []
    if len(tris):
        starts = np.flatnonzero(np.r_[True, slots[1:] != slots[:-1]])
        ends = np.r_[starts[1:], len(tris)]
        for a, b in zip(starts, ends):
            material = int(slot_materials[slots[a]]) if len(slot_materials) else -1
            ranges.append(MaterialRange(material, 3 * int(a), 3 * int(b - a)))
    decoded_positions = dtypes.decode(components[0].values, components[0].data_type)
    return Mesh(name, components, indices, compute_aabb(decoded_positions), Topology.TRIANGLES,
                ranges, skeleton if weights is not None else -1, interleaved)


def mesh_arrays(mesh: Mesh) -> MeshArrays:
    """Decode a TRIANGLES mesh for an importer (raises ValueError for other topologies)."""
    if mesh.topology != Topology.TRIANGLES:
        raise ValueError(f"mesh '{mesh.name}' is not a triangle mesh")
    position = mesh.component(Logic.POSITION)
    if position is None:
        raise ValueError(f"mesh '{mesh.name}' has no POSITION component")

    def decoded(logic, width):
        c = mesh.component(logic)
        return None if c is None else np.ascontiguousarray(dtypes.decode(c.values, c.data_type)[:, :width])

    weights = decoded(Logic.WEIGHT, 4)
    index = mesh.component(Logic.WEIGHT_INDEX)
    tris = (np.arange(mesh.vertex_count) if mesh.indices is None else np.asarray(mesh.indices))
    tris = tris.astype(np.int64).reshape(-1, 3)
    slots = np.zeros(len(tris), np.int32)
    for k, r in enumerate(mesh.ranges):
        slots[r.index_offset // 3:(r.index_offset + r.index_count) // 3] = k
    return MeshArrays(
        positions=decoded(Logic.POSITION, 3).astype(np.float32),
        normals=decoded(Logic.NORMAL, 3),
        uvs=decoded(Logic.UV, 2),
        weights=None if weights is None else weights.astype(np.float32),
        bone_indices=None if index is None else np.asarray(index.values, np.int64)[:, :4],
        triangles=tris,
        triangle_slots=slots,
        slot_materials=np.array([r.material for r in mesh.ranges], np.int32),
    )
