"""STRG, NODE and MATL sections: strings, the scene hierarchy (with armature poses), materials."""
from __future__ import annotations

import numpy as np

from . import data_types as dtypes
from .container import SectionBuilder, SectionView
from .model import Material, Node, Pose
from .spec import (
    MATERIAL_RECORD,
    MATERIALS_INFO,
    NODE_RECORD,
    NODES_INFO,
    NONE,
    STRINGS_INFO,
    TEXTURE_RECORD,
    UNIFORM_RECORD,
    Kind,
    MaterialLogic,
    NodeKind,
    Role,
    StringType,
)

U32, U64, U8 = dtypes.code_of("UINT32_1"), dtypes.code_of("UINT64_1"), dtypes.code_of("UINT8_1")
FLOAT3, QUAT = dtypes.code_of("FLOAT_3"), dtypes.code_of("QUATERNION")
FLOAT_N = tuple(dtypes.code_of(f"FLOAT_{n}") for n in (1, 2, 3, 4))


# ------------------------------------------------------------------ strings

class StringTable:
    """Writer side: interns strings, ``table(s)`` → index."""

    def __init__(self):
        self._index: dict[str, int] = {}
        self.items: list[bytes] = []

    def __call__(self, text: str) -> int:
        index = self._index.get(text)
        if index is None:
            index = self._index[text] = len(self.items)
            self.items.append(text.encode("utf-8"))
        return index

    def section(self) -> SectionBuilder:
        offsets = np.zeros(len(self.items) + 1, "<u8")
        np.cumsum([len(b) for b in self.items], out=offsets[1:])
        info = np.array([(len(self.items), 0)], STRINGS_INFO)
        s = SectionBuilder(Kind.STRINGS, info)
        s.add(Role.STRING_OFFSETS, U64, offsets)
        s.add(Role.STRING_BYTES, U8, np.frombuffer(b"".join(self.items), np.uint8))
        return s


class StringView:
    """Reader side: strings decoded on first use, each lookup checked."""

    def __init__(self, view: SectionView | None):
        self._cache: dict[int, str] = {}
        if view is None:
            self.count, self._offsets, self._bytes = 0, None, None
            return
        count = int(view.info(STRINGS_INFO)["count"])
        self._offsets = view.array(Role.STRING_OFFSETS, "STRING_OFFSETS", (U64,), count + 1)
        self._bytes = view.array(Role.STRING_BYTES, "STRING_BYTES", (U8,), None)
        if int(self._offsets[0]) != 0 or int(self._offsets[-1]) != len(self._bytes):
            view.fail("array STRING_OFFSETS", f"must run from 0 to {len(self._bytes)}")
        if count and not bool(np.all(self._offsets[1:] >= self._offsets[:-1])):
            view.fail("array STRING_OFFSETS", "offsets decrease")
        self.count = count

    def get(self, index, view: SectionView, field: str) -> str:
        index = int(index)
        if not 0 <= index < self.count:
            view.fail(field, f"string {index} does not exist (the file has {self.count})")
        text = self._cache.get(index)
        if text is None:
            start, end = int(self._offsets[index]), int(self._offsets[index + 1])
            try:
                text = self._cache[index] = self._bytes[start:end].tobytes().decode("utf-8")
            except UnicodeDecodeError as error:
                view.fail(field, f"string {index} is not UTF-8 ({error.reason})")
        return text


def check_index(view: SectionView, field: str, value, count: int, allow_none: bool = False) -> int:
    value = int(value)
    if allow_none and value in (-1, NONE):
        return -1
    if not 0 <= value < count:
        view.fail(field, f"{value} is not in [0, {count})")
    return value


# ------------------------------------------------------------------ nodes

def encode_nodes(nodes: list[Node], strings: StringTable) -> SectionBuilder:
    records = np.zeros(len(nodes), NODE_RECORD)
    posed = [i for i, n in enumerate(nodes) if n.pose is not None]
    for i, n in enumerate(nodes):
        records[i] = (n.parent, n.kind, n.mesh, n.skeleton, n.armature_node, strings(n.name),
                      n.translation, n.rotation, n.scale, n.parent_inverse, n.world, 0)
    s = SectionBuilder(Kind.NODES, np.array([(len(nodes), len(posed))], NODES_INFO))
    s.add(Role.NODES, dtypes.RECORD, records, element_size=NODE_RECORD.itemsize)
    if posed:
        poses = [nodes[i].pose for i in posed]
        s.add(Role.POSE_NODES, U32, np.array(posed, "<u4"))
        s.add(Role.POSE_ROTATIONS, QUAT, np.concatenate([p.rotations for p in poses]).astype("<f4"))
        s.add(Role.POSE_LOCATIONS, FLOAT3, np.concatenate([p.locations for p in poses]).astype("<f4"))
        s.add(Role.POSE_SCALES, FLOAT3, np.concatenate([p.scales for p in poses]).astype("<f4"))
    return s


def decode_nodes(view: SectionView, strings: StringView, mesh_count: int,
                 bone_counts: list[int]) -> list[Node]:
    info = view.info(NODES_INFO)
    count, pose_count = int(info["node_count"]), int(info["pose_count"])
    records = view.array(Role.NODES, "NODES", (dtypes.RECORD,), count, record=NODE_RECORD)
    nodes = []
    for i, r in enumerate(records):
        field = f"node {i}"
        parent = int(r["parent"])
        if not -1 <= parent < i:
            view.fail(field + " parent", f"{parent} is not an earlier node (parents come first)")
        kind = int(r["kind"])
        if kind not in (NodeKind.EMPTY, NodeKind.MESH, NodeKind.ARMATURE):
            view.fail(field + " kind", f"{kind} is not EMPTY, MESH or ARMATURE")
        mesh = check_index(view, field + " mesh", r["mesh"], mesh_count, allow_none=kind != NodeKind.MESH)
        skeleton = check_index(view, field + " skeleton", r["skeleton"], len(bone_counts),
                               allow_none=kind != NodeKind.ARMATURE)
        armature = int(r["armature_node"])
        if armature != -1 and not 0 <= armature < count:
            view.fail(field + " armature_node", f"{armature} is not a node")
        nodes.append(Node(strings.get(r["name"], view, field + " name"), parent, kind, mesh, skeleton,
                          armature, r["translation"], r["rotation"], r["scale"], r["parent_inverse"],
                          r["world"]))
    for i, node in enumerate(nodes):
        if node.armature_node != -1 and nodes[node.armature_node].kind != NodeKind.ARMATURE:
            view.fail(f"node {i} armature_node", f"node {node.armature_node} is not an ARMATURE node")
    if pose_count:
        _decode_poses(view, nodes, pose_count, bone_counts)
    return nodes


def _decode_poses(view, nodes, pose_count, bone_counts):
    posed = view.array(Role.POSE_NODES, "POSE_NODES", (U32,), pose_count)
    total = 0
    for j, index in enumerate(posed):
        index = check_index(view, f"pose {j} node", index, len(nodes))
        if nodes[index].kind != NodeKind.ARMATURE or nodes[index].pose is not None:
            view.fail(f"pose {j} node", f"node {index} is not an unposed ARMATURE node")
        nodes[index].pose = Pose(None, None, None)  # marks it; filled below
        total += bone_counts[nodes[index].skeleton]
    rot = view.array(Role.POSE_ROTATIONS, "POSE_ROTATIONS", (QUAT,), total)
    loc = view.array(Role.POSE_LOCATIONS, "POSE_LOCATIONS", (FLOAT3,), total)
    scale = view.array(Role.POSE_SCALES, "POSE_SCALES", (FLOAT3,), total)
    start = 0
    for index in posed:
        node = nodes[int(index)]
        end = start + bone_counts[node.skeleton]
        node.pose = Pose(rot[start:end], loc[start:end], scale[start:end])
        start = end


# ------------------------------------------------------------------ materials

def encode_materials(materials: list[Material], strings: StringTable) -> SectionBuilder:
    records = np.zeros(len(materials), MATERIAL_RECORD)
    uniforms, textures = [], []
    for i, m in enumerate(materials):
        records[i] = (strings(m.name), m.logic, len(uniforms), len(m.uniforms), len(textures),
                      len(m.textures))
        for slot, value in m.uniforms.items():
            v = np.zeros(4, np.float32)
            value = np.asarray(value, np.float32).reshape(-1)
            v[:len(value)] = value
            uniforms.append((slot, FLOAT_N[len(value) - 1], v))
        for slot, path in m.textures.items():
            textures.append((slot, StringType.UTF8, strings(path), 0))
    info = np.array([(len(materials), len(uniforms), len(textures), 0)], MATERIALS_INFO)
    s = SectionBuilder(Kind.MATERIALS, info)
    s.add(Role.MATERIALS, dtypes.RECORD, records, element_size=MATERIAL_RECORD.itemsize)
    s.add(Role.UNIFORMS, dtypes.RECORD, np.array(uniforms, UNIFORM_RECORD).reshape(-1),
          element_size=UNIFORM_RECORD.itemsize)
    s.add(Role.TEXTURES, dtypes.RECORD, np.array(textures, TEXTURE_RECORD).reshape(-1),
          element_size=TEXTURE_RECORD.itemsize)
    return s


def decode_materials(view: SectionView, strings: StringView) -> list[Material]:
    info = view.info(MATERIALS_INFO)
    records = view.array(Role.MATERIALS, "MATERIALS", (dtypes.RECORD,), int(info["material_count"]),
                         record=MATERIAL_RECORD)
    uniforms = view.array(Role.UNIFORMS, "UNIFORMS", (dtypes.RECORD,), int(info["uniform_count"]),
                          record=UNIFORM_RECORD)
    textures = view.array(Role.TEXTURES, "TEXTURES", (dtypes.RECORD,), int(info["texture_count"]),
                          record=TEXTURE_RECORD)
    materials, next_uniform, next_texture = [], 0, 0
    for i, r in enumerate(records):
        field = f"material {i}"
        logic = int(r["logic"])
        if logic >= len(MaterialLogic.NAMES):
            view.fail(field + " logic", f"{logic} is not a known material logic")
        material = Material(strings.get(r["name"], view, field + " name"), logic)
        for j in _range(view, field + " uniforms", r["uniform_start"], r["uniform_count"], next_uniform,
                        len(uniforms)):
            u = uniforms[j]
            if int(u["data_type"]) not in FLOAT_N:
                view.fail(f"uniform {j} data_type", f"{dtypes.name_of(u['data_type'])} is not FLOAT_1..4")
            material.uniforms[int(u["slot"])] = u["value"][:FLOAT_N.index(int(u["data_type"])) + 1]
        for j in _range(view, field + " textures", r["texture_start"], r["texture_count"], next_texture,
                        len(textures)):
            t = textures[j]
            if int(t["string_type"]) not in (StringType.ASCII, StringType.UTF8):
                view.fail(f"texture {j} string_type", f"{int(t['string_type'])} is not ASCII or UTF8")
            material.textures[int(t["slot"])] = strings.get(t["path"], view, f"texture {j} path")
        materials.append(material)
        next_uniform += int(r["uniform_count"])
        next_texture += int(r["texture_count"])
    return materials


def _range(view, field, start, count, expected_start, total) -> range:
    """Materials own consecutive entries in order (so reading them is linear in the file)."""
    start, count = int(start), int(count)
    if start != expected_start or start + count > total:
        view.fail(field, f"[{start}, {start + count}) does not continue at entry {expected_start} "
                  f"within the {total} entries")
    return range(start, start + count)
