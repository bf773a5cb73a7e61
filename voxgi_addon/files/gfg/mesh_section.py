"""MESH sections: vertex blocks with a per-component layout, an index buffer, material ranges."""
from __future__ import annotations

import numpy as np

from . import data_types as dtypes
from .container import SectionBuilder, SectionView, align
from .errors import GFGError
from .model import MaterialRange, Mesh, VertexComponent
from .scene_sections import StringTable, StringView, check_index
from .spec import COMPONENT_RECORD, MESH_INFO, NONE, RANGE_RECORD, Kind, Logic, Role, Topology

INDEX_TYPES = {1: dtypes.code_of("UINT8_1"), 2: dtypes.code_of("UINT16_1"),
               4: dtypes.code_of("UINT32_1")}
NOT_STORABLE = (dtypes.RECORD, dtypes.BYTES)


def index_dtype(vertex_count: int) -> np.dtype:
    """The smallest GPU index type for ``vertex_count`` vertices (uint16 or uint32)."""
    return np.dtype("<u2") if vertex_count <= 0xFFFF else np.dtype("<u4")


def compute_aabb(positions) -> np.ndarray:
    """(2, 3) float32 min/max of (V, 3) positions; zeros for an empty mesh."""
    p = np.asarray(positions, np.float32)
    if len(p) == 0:
        return np.zeros((2, 3), np.float32)
    return np.stack([p.min(axis=0), p.max(axis=0)]).astype(np.float32)


def _component_bytes(mesh: Mesh, i: int, c: VertexComponent) -> tuple[np.ndarray, int]:
    """(V, size) uint8 bytes of a component and its size, after checking its storage."""
    dt = dtypes.data_type(c.data_type)
    where = f"mesh '{mesh.name}'"
    if dt is None or c.data_type in NOT_STORABLE:
        raise GFGError(where, f"component {i} data_type", f"{c.data_type} is not a vertex data type")
    v = np.asarray(c.values)
    if v.ndim == 1:
        v = v[:, None]
    if v.dtype.newbyteorder("<") != dt.base.newbyteorder("<") or v.shape[1:] != (dt.components,):
        raise GFGError(where, f"component {i} values", f"{v.dtype}{v.shape} is not {dt.name} storage "
                       f"({dt.base.str} × {dt.components}); use data_types.encode")
    if len(v) != mesh.vertex_count:
        raise GFGError(where, f"component {i} values", f"{len(v)} vertices, expected {mesh.vertex_count}")
    v = np.ascontiguousarray(v, dtype=dt.base)
    return v.view(np.uint8).reshape(len(v), dt.size), dt.size


def _blocks(mesh: Mesh):
    """[(block bytes (V, stride) uint8, stride)], [(block, offset)] per component."""
    parts = [_component_bytes(mesh, i, c) for i, c in enumerate(mesh.components)]
    groups = [list(range(len(parts)))] if mesh.interleaved else [[i] for i in range(len(parts))]
    blocks, placement = [], [None] * len(parts)
    for b, members in enumerate(g for g in groups if g):
        offsets, offset = [], 0
        for i in members:
            offsets.append(offset)
            offset = align(offset + parts[i][1], 4)
        stride = offset
        if len(members) == 1 and parts[members[0]][1] == stride:
            block = parts[members[0]][0]  # written without a copy
        else:
            block = np.zeros((mesh.vertex_count, stride), np.uint8)
            for i, o in zip(members, offsets):
                block[:, o:o + parts[i][1]] = parts[i][0]
        blocks.append((block, stride))
        for i, o in zip(members, offsets):
            placement[i] = (b, o)
    return blocks, placement


def encode_mesh(mesh: Mesh, strings: StringTable) -> SectionBuilder:
    blocks, placement = _blocks(mesh)
    comps = np.array([(c.logic, c.data_type, *placement[i]) for i, c in enumerate(mesh.components)],
                     COMPONENT_RECORD).reshape(-1)
    ranges = np.array([(NONE if r.material < 0 else r.material, 0, r.index_offset, r.index_count)
                       for r in mesh.ranges], RANGE_RECORD).reshape(-1)
    indices = None if mesh.indices is None else np.asarray(mesh.indices)
    index_size = 0 if indices is None else indices.dtype.itemsize
    if indices is not None and (indices.dtype.kind != "u" or index_size not in INDEX_TYPES):
        raise GFGError(f"mesh '{mesh.name}'", "indices", f"{indices.dtype} is not uint8/16/32")
    aabb = np.asarray(mesh.aabb, np.float32).reshape(2, 3)
    info = np.array([(strings(mesh.name), mesh.topology, mesh.vertex_count,
                      0 if indices is None else len(indices), index_size, mesh.skeleton,
                      aabb[0], aabb[1], len(mesh.components), len(mesh.ranges))], MESH_INFO)
    s = SectionBuilder(Kind.MESH, info)
    for block, stride in blocks:
        s.add(Role.VERTEX_BLOCK, dtypes.BYTES, block, count=mesh.vertex_count, element_size=stride)
    s.add(Role.COMPONENTS, dtypes.RECORD, comps, element_size=COMPONENT_RECORD.itemsize)
    if indices is not None:
        s.add(Role.INDICES, INDEX_TYPES[index_size], indices.astype(indices.dtype.newbyteorder("<")))
    s.add(Role.RANGES, dtypes.RECORD, ranges, element_size=RANGE_RECORD.itemsize)
    return s


def decode_mesh(view: SectionView, strings: StringView, material_count: int,
                bone_counts: list[int]) -> Mesh:
    info = view.info(MESH_INFO)
    name = strings.get(info["name"], view, "info.name")
    view.name_as(name)
    vertex_count, index_count = int(info["vertex_count"]), int(info["index_count"])
    topology, index_size = int(info["topology"]), int(info["index_size"])
    if topology > Topology.POINTS:
        view.fail("info.topology", f"{topology} is not TRIANGLES, STRIP, LINES or POINTS")
    skeleton = check_index(view, "info.skeleton", info["skeleton"], len(bone_counts), allow_none=True)
    blocks = view.descs(Role.VERTEX_BLOCK)
    for k, d in enumerate(blocks):
        if d.data_type != dtypes.BYTES or d.count != vertex_count:
            view.fail(f"array VERTEX_BLOCK {k}", f"must be BYTES with {vertex_count} vertices")
    comps = view.array(Role.COMPONENTS, "COMPONENTS", (dtypes.RECORD,), int(info["component_count"]),
                       record=COMPONENT_RECORD)
    components = [_component(view, j, c, blocks, vertex_count) for j, c in enumerate(comps)]
    if view.zero_padding:
        _check_vertex_padding(view, comps, blocks, vertex_count)
    indices = _indices(view, index_size, index_count, vertex_count)
    ranges = _ranges(view, info, material_count, index_count if indices is not None else vertex_count)
    elements = index_count if indices is not None else vertex_count
    if topology == Topology.TRIANGLES and elements % 3:
        view.fail("info.index_count", f"{elements} is not a whole number of triangles")
    mesh = Mesh(name, components, indices, np.stack([info["aabb_min"], info["aabb_max"]]),
                topology, ranges, skeleton, interleaved=len(blocks) <= 1)
    for j, c in enumerate(components):
        if c.logic == Logic.WEIGHT_INDEX and vertex_count:
            if skeleton < 0:
                view.fail(f"component {j}", "WEIGHT_INDEX needs info.skeleton")
            if int(c.values.max()) >= bone_counts[skeleton] or int(c.values.min()) < 0:
                view.fail(f"component {j} values", f"bone index outside the skeleton's "
                          f"{bone_counts[skeleton]} bones")
    return mesh


def _component(view, j, c, blocks, vertex_count) -> VertexComponent:
    field = f"component {j}"
    code = int(c["data_type"])
    dt = dtypes.data_type(code)
    if dt is None or code in NOT_STORABLE:
        view.fail(field + " data_type", f"{dtypes.name_of(code)} is not a supported vertex type")
    block = int(c["block"])
    if block >= len(blocks):
        view.fail(field + " block", f"{block} is not one of the {len(blocks)} vertex blocks")
    d, offset = blocks[block], int(c["offset"])
    if offset + dt.size > d.element_size:
        view.fail(field + " offset", f"{dt.name} at byte {offset} does not fit the {d.element_size}-byte "
                  "vertex")
    if vertex_count == 0:
        values = np.zeros((0, dt.components), dt.base)
    else:
        values = np.ndarray((vertex_count, dt.components), dt.base, view.buf, d.offset + offset,
                            (d.element_size, dt.base.itemsize))
    return VertexComponent(int(c["logic"]), code, values)


def _check_vertex_padding(view, comps, blocks, vertex_count) -> None:
    """The bytes of a vertex that no component covers (alignment to 4, stride padding) are 0."""
    for k, d in enumerate(blocks):
        covered = np.zeros(d.element_size, bool)
        for c in comps:
            if int(c["block"]) == k:
                offset = int(c["offset"])
                covered[offset:offset + dtypes.data_type(int(c["data_type"])).size] = True
        if covered.all() or vertex_count == 0:
            continue
        vertices = np.ndarray((vertex_count, d.element_size), np.uint8, view.buf, d.offset)
        padding = vertices[:, ~covered]
        if padding.any():
            v, b = divmod(int(np.argmax(padding != 0)), padding.shape[1])
            at = int(np.flatnonzero(~covered)[b])
            view.fail(f"array VERTEX_BLOCK {k}", f"vertex {v} byte {at} (file offset "
                      f"{view.entry.offset + d.offset + v * d.element_size + at}) is padding but "
                      f"0x{int(padding[v, b]):02X}, not 0")


def _indices(view, index_size, index_count, vertex_count):
    if index_size == 0:
        if index_count or view.descs(Role.INDICES):
            view.fail("info.index_size", "0 (non-indexed) but the mesh has indices")
        return None
    if index_size not in INDEX_TYPES:
        view.fail("info.index_size", f"{index_size} is not 0, 1, 2 or 4")
    indices = view.array(Role.INDICES, "INDICES", (INDEX_TYPES[index_size],), index_count)
    if index_count and int(indices.max()) >= vertex_count:
        view.fail("array INDICES", f"index {int(indices.max())} ≥ vertex count {vertex_count}")
    return indices


def _ranges(view, info, material_count, elements) -> list[MaterialRange]:
    records = view.array(Role.RANGES, "RANGES", (dtypes.RECORD,), int(info["range_count"]),
                         record=RANGE_RECORD)
    ranges = []
    for k, r in enumerate(records):
        material = check_index(view, f"range {k} material", r["material"], material_count,
                               allow_none=True)
        start, count = int(r["index_offset"]), int(r["index_count"])
        if start + count > elements:
            view.fail(f"range {k}", f"[{start}, {start + count}) is outside the {elements} indices")
        ranges.append(MaterialRange(material, start, count))
    return ranges
