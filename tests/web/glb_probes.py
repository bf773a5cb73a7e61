"""VOXGI_irradiance_volumes .glb files with numpy only (docs/gltf_probes.md), for the browser
tests: ``write_glb`` writes probe grids and a few flat-shaded meshes as the spec lays them out
(the same layout as Blender's exporter writes), ``read_glb`` / ``grids_from_glb`` read any such
file back into ``ProbeGrid``s for voxgi_addon/probes/query.py, and ``with_json`` / ``bad_*``
make the broken variants of the bad-input tests.
"""
from __future__ import annotations

import copy
import json
import math
import struct

import numpy as np

from voxgi.voxgi_addon.probes.grid import ProbeGrid

EXTENSION = "VOXGI_irradiance_volumes"
DISABLED_FLAG = 2  # flags bit 1 (voxgi_addon/probes/grid.py DISABLED)
FLOAT, UNSIGNED_INT, UNSIGNED_SHORT = 5126, 5125, 5123  # glTF component types
# the volume node's rotation: Blender's Z-up world to glTF's Y-up (docs/gltf_probes.md)
Z_UP_TO_Y_UP = np.array([-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)])  # x, y, z, w


def y_up(points) -> np.ndarray:
    """Blender (Z-up) coordinates → glTF (Y-up): (x, y, z) → (x, z, −y)."""
    p = np.asarray(points, np.float64)
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


def quaternion_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def node_local_matrix(node) -> np.ndarray:
    if "matrix" in node:
        return np.asarray(node["matrix"], np.float64).reshape(4, 4).T  # column-major
    m = np.eye(4)
    rs = quaternion_matrix(node.get("rotation", [0, 0, 0, 1])) * np.asarray(node.get("scale", [1, 1, 1]))
    m[:3, :3] = rs
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def node_world_matrix(gltf, index) -> np.ndarray:
    """The node's world matrix (its parents' composed), float64."""
    parent = {c: i for i, n in enumerate(gltf.get("nodes", [])) for c in n.get("children", [])}
    m = node_local_matrix(gltf["nodes"][index])
    while index in parent:
        index = parent[index]
        m = node_local_matrix(gltf["nodes"][index]) @ m
    return m


class _Builder:
    """Accessors, buffer views and one binary buffer."""

    def __init__(self):
        self.gltf = {"asset": {"version": "2.0", "generator": "tests/web/glb_probes.py"},
                     "buffers": [], "bufferViews": [], "accessors": []}
        self.blob = bytearray()

    def view(self, array) -> int:
        """A bufferView of the array's bytes (little-endian), 4-byte aligned."""
        data = np.ascontiguousarray(array)
        data = data.astype(data.dtype.newbyteorder("<"), copy=False)
        while len(self.blob) % 4:
            self.blob.append(0)
        self.gltf["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob),
                                         "byteLength": data.nbytes})
        self.blob += data.tobytes()
        return len(self.gltf["bufferViews"]) - 1

    def words(self, array) -> int | None:
        """docs/gltf_probes.md's integer arrays: a bufferView of packed uint32 words (None when
        empty: the field is then absent)."""
        data = np.asarray(array, np.uint32).ravel()
        return self.view(data) if data.size else None

    def accessor(self, array, component, type_, minmax=False) -> int:
        data = np.ascontiguousarray(array)
        view = self.view(data)
        size = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[type_]
        acc = {"bufferView": view, "componentType": component, "count": int(data.size // size),
               "type": type_}
        if minmax:
            flat = data.reshape(-1, size)
            acc["min"] = flat.min(axis=0).tolist()
            acc["max"] = flat.max(axis=0).tolist()
        self.gltf["accessors"].append(acc)
        return len(self.gltf["accessors"]) - 1


def write_glb(path, grids, meshes=(), camera=None, lights=(), volume_nodes=None,
              root_translation=None, root_scale=None):
    """Write a .glb.

    grids : ProbeGrids (grid frame = Blender world), one volume each, each with a node rotated
        by ``Z_UP_TO_Y_UP`` (``volume_nodes`` overrides: one dict of node fields per grid).
    meshes : (name, triangles (T, 3, 3) Blender world, base colour RGB) flat-shaded, double-sided.
    camera : (position, look_at, yfov radians, aspect) in Blender world, or None.
    lights : (position, colour, intensity in candela) KHR_lights_punctual point lights.
    root_translation, root_scale : put every node under one root node moved and scaled by these
        (glTF frame).
    """
    b = _Builder()
    g = b.gltf
    g["nodes"], g["meshes"], g["materials"] = [], [], []
    scene_nodes = []
    for name, tris, colour in meshes:
        tris = np.asarray(tris, np.float64)
        n = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        pos = y_up(tris.reshape(-1, 3)).astype(np.float32)
        nrm = y_up(np.repeat(n, 3, axis=0)).astype(np.float32)
        a_pos = b.accessor(pos, FLOAT, "VEC3", minmax=True)
        a_nrm = b.accessor(nrm, FLOAT, "VEC3")
        a_idx = b.accessor(np.arange(len(pos), dtype=np.uint32), UNSIGNED_INT, "SCALAR")
        g["materials"].append({"name": name, "doubleSided": True, "pbrMetallicRoughness": {
            "baseColorFactor": [*map(float, colour), 1.0], "metallicFactor": 0.0,
            "roughnessFactor": 1.0}})
        g["meshes"].append({"name": name, "primitives": [{
            "attributes": {"POSITION": a_pos, "NORMAL": a_nrm}, "indices": a_idx,
            "material": len(g["materials"]) - 1}]})
        g["nodes"].append({"name": name, "mesh": len(g["meshes"]) - 1})
        scene_nodes.append(len(g["nodes"]) - 1)
    if camera is not None:
        position, target, yfov, aspect = camera
        eye, at = y_up(position), y_up(target)
        forward = (at - eye) / np.linalg.norm(at - eye)
        right = np.cross(forward, [0.0, 1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, up, -forward, eye
        g["cameras"] = [{"type": "perspective", "perspective": {
            "yfov": float(yfov), "aspectRatio": float(aspect), "znear": 0.01, "zfar": 100.0}}]
        g["nodes"].append({"name": "Camera", "camera": 0, "matrix": m.T.ravel().tolist()})
        scene_nodes.append(len(g["nodes"]) - 1)
    if lights:
        g.setdefault("extensions", {})["KHR_lights_punctual"] = {"lights": [
            {"type": "point", "color": list(map(float, c)), "intensity": float(i)}
            for _, c, i in lights]}
        for k, (p, _, _) in enumerate(lights):
            g["nodes"].append({"name": f"Light{k}", "translation": y_up(p).tolist(),
                               "extensions": {"KHR_lights_punctual": {"light": k}}})
            scene_nodes.append(len(g["nodes"]) - 1)
    volumes = []
    for i, grid in enumerate(grids):
        node = {"name": f"Probes{i}", "rotation": Z_UP_TO_Y_UP.tolist(),
                "extensions": {EXTENSION: {"volume": i}}}
        if volume_nodes is not None:
            node.update(volume_nodes[i])
        g["nodes"].append(node)
        scene_nodes.append(len(g["nodes"]) - 1)
        masks = np.asarray(grid.volume_masks, np.uint64).reshape(-1)
        pairs = np.stack([masks & np.uint64(0xFFFFFFFF), masks >> np.uint64(32)], axis=1).astype(np.uint32)
        volume = {
            "name": grid.name or f"grid{i}", "node": len(g["nodes"]) - 1,
            "dims": [int(x) for x in grid.dims], "origin": [float(x) for x in grid.origin],
            "volumeSize": [float(x) for x in grid.volume_size], "subdivisions": 4,
            "maskThreshold": float(grid.mask_threshold),
            "probeCount": len(grid.positions), "activeVolumeCount": len(grid.volume_cells)}
        if len(grid.positions):
            volume.update(
                positions=b.accessor(np.asarray(grid.positions, np.float32), FLOAT, "VEC3"),
                sh=b.accessor(np.asarray(grid.sh, np.float32).reshape(-1, 3), FLOAT, "VEC3"),
                validity=b.accessor(np.asarray(grid.validity, np.float32), FLOAT, "SCALAR"),
                flags=b.words(grid.flags))
        if len(grid.volume_cells):
            volume.update(volumeCells=b.words(grid.volume_cells), volumeProbes=b.words(grid.volume_probes),
                          volumeMasks=b.words(pairs))
        volumes.append(volume)
    if volumes:
        g.setdefault("extensions", {})[EXTENSION] = {"volumes": volumes}
    g["extensionsUsed"] = sorted(g.get("extensions", {}))
    if root_translation is not None or root_scale is not None:
        root = {"name": "Root", "children": scene_nodes}
        if root_translation is not None:
            root["translation"] = [float(x) for x in root_translation]
        if root_scale is not None:
            root["scale"] = [float(x) for x in root_scale]
        g["nodes"].append(root)
        scene_nodes = [len(g["nodes"]) - 1]
    g["scenes"] = [{"nodes": scene_nodes}]
    g["scene"] = 0
    g["buffers"] = [{"byteLength": len(b.blob)}]
    save_glb(path, g, bytes(b.blob))
    return g


def save_glb(path, gltf, blob: bytes):
    text = json.dumps(gltf, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    blob = blob + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    with open(path, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, total))
        f.write(struct.pack("<I4s", len(text), b"JSON") + text)
        f.write(struct.pack("<I4s", len(blob), b"BIN\0") + blob)


def read_glb(path) -> tuple[dict, bytes]:
    data = open(path, "rb").read()
    magic, version, _ = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2, f"{path}: not a glTF 2.0 binary"
    at, gltf, blob = 12, None, b""
    while at < len(data):
        length, kind = struct.unpack_from("<I4s", data, at)
        chunk = data[at + 8: at + 8 + length]
        if kind == b"JSON":
            gltf = json.loads(chunk)
        elif kind == b"BIN\0":
            blob = chunk
        at += 8 + length
    return gltf, blob


def accessor_array(gltf, blob, index) -> np.ndarray:
    acc = gltf["accessors"][index]
    view = gltf["bufferViews"][acc["bufferView"]]
    dtype = {FLOAT: np.float32, UNSIGNED_INT: np.uint32, UNSIGNED_SHORT: np.uint16}[acc["componentType"]]
    size = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[acc["type"]]
    item = size * np.dtype(dtype).itemsize
    stride = view.get("byteStride", item)
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    raw = np.frombuffer(blob, np.uint8, count=stride * (acc["count"] - 1) + item if acc["count"] else 0,
                        offset=start)
    if stride == item:
        return raw.view(dtype).reshape(acc["count"], size)
    rows = np.lib.stride_tricks.as_strided(raw, (acc["count"], item), (stride, 1))
    return np.ascontiguousarray(rows).view(dtype).reshape(acc["count"], size)


def view_words(gltf, blob, index) -> np.ndarray:
    """A bufferView's little-endian uint32 words (an absent field: none)."""
    if index is None:
        return np.zeros(0, np.uint32)
    view = gltf["bufferViews"][index]
    start = view.get("byteOffset", 0)
    return np.frombuffer(blob, "<u4", count=view["byteLength"] // 4, offset=start).astype(np.uint32)


def grids_from_glb(path) -> tuple[list[ProbeGrid], list[np.ndarray]]:
    """The file's volumes as ProbeGrids (grid frame) and each volume node's world matrix (4, 4)."""
    gltf, blob = read_glb(path)
    grids, matrices = [], []
    for v in gltf["extensions"][EXTENSION]["volumes"]:
        p = v["probeCount"]
        masks = view_words(gltf, blob, v.get("volumeMasks")).astype(np.uint64).reshape(-1, 2)

        def floats(field, shape):
            return (accessor_array(gltf, blob, v[field]).reshape(shape).copy() if field in v
                    else np.zeros(shape, np.float32))

        grids.append(ProbeGrid(
            origin=v["origin"], volume_size=v["volumeSize"], dims=v["dims"],
            positions=floats("positions", (p, 3)), sh=floats("sh", (p, 9, 3)),
            volume_cells=view_words(gltf, blob, v.get("volumeCells")),
            volume_probes=view_words(gltf, blob, v.get("volumeProbes")).reshape(-1, 8),
            volume_masks=(masks[:, 0] | (masks[:, 1] << np.uint64(32))).reshape(-1, 8),
            flags=view_words(gltf, blob, v.get("flags")) if "flags" in v else None,
            mask_threshold=v.get("maskThreshold", 0.5), name=v.get("name", "")))
        matrices.append(node_world_matrix(gltf, v["node"]))
    return grids, matrices


def with_json(src, dst, change):
    """Copy a .glb with ``change(gltf)`` applied to a deep copy of its JSON (binary unchanged)."""
    gltf, blob = read_glb(src)
    gltf = copy.deepcopy(gltf)
    change(gltf)
    save_glb(dst, gltf, blob)
