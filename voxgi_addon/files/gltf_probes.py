"""VOXGI_irradiance_volumes: baked probe grids in glTF 2.0 (docs/gltf_probes.md).

Plain numpy, no Blender: ``encode_grid`` turns a ``ProbeGrid`` into the extension's JSON
properties and its binary arrays (float accessors, uint32 bufferViews: docs/gltf_probes.md
"Properties"); ``add_volumes`` writes grids into a glTF document held as a dict and one binary
buffer (what the tests and the benchmark use; Blender's exporter places the same arrays in its
own buffer, blender/gltf_probes.py); ``read_gltf`` loads a .glb or .gltf with its
buffers (GLB chunk, data URI or file); ``decode_volumes`` reads the grids back, checking every
count, index, offset and size against the document and the buffers, and raises
``GltfProbesError`` naming the volume and the field that is wrong.

A grid's numbers are written as they are (float32 arrays byte for byte, float64 box values as
JSON numbers, which Python prints exactly), so ``decode_volumes(encode …)`` gives back equal
arrays of the same dtypes. Grids live in their volume node's local frame; ``node_world_matrix``
gives that frame in glTF's world.
"""
from __future__ import annotations

import base64
import json
import math
import os
import struct
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..errors import VoxGIError
from ..probes.grid import CORNER_OFFSETS, DISABLED, RELOCATED, ProbeGrid

__all__ = ["EXTENSION", "SUBDIVISIONS", "GltfProbesError", "EncodedVolume", "DecodedVolume",
           "GltfFile", "encode_grid", "add_volumes", "new_document", "glb_bytes", "write_gltf",
           "read_gltf", "decode_volumes", "read_volumes", "node_world_matrix", "scene_nodes",
           "node_name", "Y_UP_ROTATION", "MAX_GRID_CORNERS"]

EXTENSION = "VOXGI_irradiance_volumes"
SUBDIVISIONS = 4
FLOAT = 5126
KNOWN_FLAGS = RELOCATED | DISABLED
# Blender's Z-up world → glTF's Y-up world: -90° about X (x, y, z) → (x, z, -y), as (x, y, z, w).
Y_UP_ROTATION = [-math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)]
# The decoder refuses grids whose corner index would pass 2^26 entries (256 MiB of uint32; a
# 405³ grid): a damaged `dims` must not make it allocate without bound (docs/gltf_probes.md
# "Blender").
MAX_GRID_CORNERS = 1 << 26

# name → (accessor type, components, what one element is per probe)
ACCESSORS = {"positions": ("VEC3", 3), "sh": ("VEC3", 3), "validity": ("SCALAR", 1)}
WORD_VIEWS = ("flags", "volumeCells", "volumeProbes", "volumeMasks")
_GLB_MAGIC, _GLB_JSON, _GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942


class GltfProbesError(VoxGIError):
    """A VOXGI_irradiance_volumes extension (or a grid to write) that breaks the format.

    ``where`` names the volume ("volume 2 'Probe Box'") or the part of the file, ``field`` the
    property; both are in the message."""

    def __init__(self, where: str, field: str, problem: str):
        super().__init__(f"{where}: {field}: {problem}")
        self.where = where
        self.field = field
        self.problem = problem


@dataclass
class EncodedVolume:
    """One grid as the extension stores it: ``properties`` (JSON, without ``node`` and without
    the array references), ``accessors`` (name → (type, count, little-endian float32 bytes)) and
    ``word_views`` (name → little-endian uint32 bytes), both empty for a count of 0."""

    properties: dict
    accessors: dict[str, tuple[str, int, bytes]] = field(default_factory=dict)
    word_views: dict[str, bytes] = field(default_factory=dict)


@dataclass
class DecodedVolume:
    """A grid read back, in its node's local frame; ``node`` is the node's index."""

    grid: ProbeGrid
    node: int
    index: int


@dataclass
class GltfFile:
    """A glTF document (the parsed JSON) and a way to its buffers' bytes."""

    document: dict
    buffer: Callable[[int], bytes | None]


# --------------------------------------------------------------------------------------------
# Writing


def _where(index, name) -> str:
    return f"volume {index} '{name}'" if name else f"volume {index}"


def encode_grid(grid: ProbeGrid, index: int = 0) -> EncodedVolume:
    """The extension's data for ``grid``; raises ``GltfProbesError`` for a grid the format cannot
    hold (arrays of inconsistent sizes, dims < 1, sizes ≤ 0, non-finite numbers)."""
    where = _where(index, grid.name)
    dims = np.asarray(grid.dims, np.int64)
    origin = np.asarray(grid.origin, np.float64)
    size = np.asarray(grid.volume_size, np.float64)
    if dims.shape != (3,) or (dims < 1).any():
        raise GltfProbesError(where, "dims", f"must be 3 integers ≥ 1, got {dims.tolist()}")
    if int((dims + 1).prod()) > MAX_GRID_CORNERS:
        raise GltfProbesError(where, "dims", f"{dims.tolist()} has more grid corners than readers take "
                              f"({MAX_GRID_CORNERS})")
    if not np.isfinite(origin).all():
        raise GltfProbesError(where, "origin", f"must be finite, got {origin.tolist()}")
    if not (np.isfinite(size).all() and (size > 0).all()):
        raise GltfProbesError(where, "volumeSize", f"must be finite and > 0, got {size.tolist()}")
    positions = np.asarray(grid.positions)
    p = len(positions)
    arrays = {
        "positions": (positions, (p, 3), np.float32),
        "sh": (np.asarray(grid.sh), (p, 9, 3), np.float32),
        "validity": (np.asarray(grid.validity), (p,), np.float32),
        "flags": (np.asarray(grid.flags), (p,), np.uint32),
    }
    v = len(grid.volume_cells)
    arrays.update({
        "volumeCells": (np.asarray(grid.volume_cells), (v,), np.uint32),
        "volumeProbes": (np.asarray(grid.volume_probes), (v, 8), np.uint32),
        "volumeMasks": (np.asarray(grid.volume_masks), (v, 8), np.uint64),
    })
    for name, (array, shape, dtype) in arrays.items():
        if array.shape != shape:
            raise GltfProbesError(where, name, f"shape {array.shape}, expected {shape}")
        if array.dtype != dtype:
            raise GltfProbesError(where, name, f"dtype {array.dtype}, expected {np.dtype(dtype)}")
    for name in ACCESSORS:
        if not np.isfinite(arrays[name][0]).all():
            raise GltfProbesError(where, name, "holds NaN or infinite values")
    mask_threshold = float(grid.mask_threshold)
    if not math.isfinite(mask_threshold):
        raise GltfProbesError(where, "maskThreshold", "must be finite")
    properties = {
        "name": str(grid.name),
        "dims": [int(d) for d in dims],
        "origin": [float(x) for x in origin],
        "volumeSize": [float(x) for x in size],
        "subdivisions": SUBDIVISIONS,
        "maskThreshold": mask_threshold,
        "probeCount": p,
        "activeVolumeCount": v,
    }
    out = EncodedVolume(properties)
    if p:
        out.accessors = {
            "positions": ("VEC3", p, arrays["positions"][0].astype("<f4").tobytes()),
            "sh": ("VEC3", 9 * p, arrays["sh"][0].astype("<f4").tobytes()),
            "validity": ("SCALAR", p, arrays["validity"][0].astype("<f4").tobytes()),
        }
        out.word_views["flags"] = arrays["flags"][0].astype("<u4").tobytes()
    if v:
        out.word_views["volumeCells"] = arrays["volumeCells"][0].astype("<u4").tobytes()
        out.word_views["volumeProbes"] = arrays["volumeProbes"][0].astype("<u4").tobytes()
        # (low, high) uint32 words of each mask: exactly the little-endian bytes of the uint64
        out.word_views["volumeMasks"] = arrays["volumeMasks"][0].astype("<u8").tobytes()
    return out


def node_name(name: str, index: int) -> str:
    """The name VoxGI gives a volume's node (informative only: the volume keeps its own)."""
    return f"VoxGI Volume {name}" if name else f"VoxGI Volume {index}"


def new_document(generator: str = "VoxGI") -> dict:
    """An empty glTF 2.0 document with one scene (the default one)."""
    return {"asset": {"version": "2.0", "generator": generator}, "scene": 0,
            "scenes": [{"nodes": []}], "nodes": [], "accessors": [], "bufferViews": [],
            "buffers": []}


def _append_view(document: dict, binary: bytearray, data: bytes, buffer_index: int) -> int:
    while len(binary) % 4:
        binary.append(0)
    document.setdefault("bufferViews", []).append(
        {"buffer": buffer_index, "byteOffset": len(binary), "byteLength": len(data)})
    binary.extend(data)
    return len(document["bufferViews"]) - 1


def add_volumes(document: dict, binary: bytearray, grids, *, y_up: bool = True, scene: int | None = None,
                buffer_index: int = 0) -> list[int]:
    """Write ``grids`` into ``document`` (a glTF JSON dict) and ``binary`` (the bytes of buffer
    ``buffer_index``, appended to, 4-byte aligned): one node per grid in scene ``scene`` (the
    default scene), rotated Blender → glTF when ``y_up``, and the root extension. Declares the
    extension in ``extensionsUsed`` and sets the buffer's ``byteLength`` (creating the buffer
    entry if missing; a caller writing .gltf + .bin sets its ``uri``). Returns the nodes' indices."""
    encoded = [encode_grid(g, i) for i, g in enumerate(grids)]
    if scene is None:
        scene = document.get("scene", 0)
    scenes = document.setdefault("scenes", [{"nodes": []}])
    nodes = document.setdefault("nodes", [])
    root = document.setdefault("extensions", {}).setdefault(EXTENSION, {"volumes": []})
    added = []
    for enc in encoded:
        volume = dict(enc.properties)
        volume["node"] = len(nodes)
        for name, (kind, count, data) in enc.accessors.items():
            view = _append_view(document, binary, data, buffer_index)
            document.setdefault("accessors", []).append(
                {"bufferView": view, "componentType": FLOAT, "count": count, "type": kind})
            volume[name] = len(document["accessors"]) - 1
        for name, data in enc.word_views.items():
            volume[name] = _append_view(document, binary, data, buffer_index)
        node = {"name": node_name(volume["name"], len(root["volumes"])),
                "extensions": {EXTENSION: {"volume": len(root["volumes"])}}}
        if y_up:
            node["rotation"] = list(Y_UP_ROTATION)
        nodes.append(node)
        scenes[scene].setdefault("nodes", []).append(volume["node"])
        root["volumes"].append(volume)
        added.append(volume["node"])
    used = document.setdefault("extensionsUsed", [])
    if EXTENSION not in used:
        used.append(EXTENSION)
    while len(binary) % 4:
        binary.append(0)
    buffers = document.setdefault("buffers", [])
    while len(buffers) <= buffer_index:
        buffers.append({"byteLength": 0})
    buffers[buffer_index]["byteLength"] = len(binary)
    for key in ("accessors", "bufferViews", "buffers"):
        if not document.get(key):
            document.pop(key, None)
    return added


def glb_bytes(document: dict, binary: bytes) -> bytes:
    """A GLB file: the JSON chunk (space-padded) and, when ``binary`` is not empty, the BIN
    chunk (zero-padded) holding buffer 0."""
    text = json.dumps(document, separators=(",", ":"), allow_nan=False).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), _GLB_JSON) + text
    if binary:
        data = bytes(binary) + b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(data), _GLB_BIN) + data
    return struct.pack("<III", _GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def write_gltf(path, document: dict, binary: bytes, *, embed: bool = False) -> None:
    """Write ``document`` with buffer 0 = ``binary``: a .glb when ``path`` ends in .glb, else
    .gltf JSON with the buffer as a data URI (``embed``) or a .bin file beside it."""
    path = os.fspath(path)
    if path.lower().endswith(".glb"):
        with open(path, "wb") as f:
            f.write(glb_bytes(document, binary))
        return
    document = json.loads(json.dumps(document))
    if binary:
        if embed:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(binary)).decode("ascii")
        else:
            bin_path = os.path.splitext(path)[0] + ".bin"
            with open(bin_path, "wb") as f:
                f.write(bytes(binary))
            uri = urllib.parse.quote(os.path.basename(bin_path))
        document["buffers"][0]["uri"] = uri
    with open(path, "w", encoding="utf-8") as f:
        json.dump(document, f, indent=1, allow_nan=False)


# --------------------------------------------------------------------------------------------
# Reading


def read_gltf(path) -> GltfFile:
    """Parse a .glb or .gltf file; buffers are resolved on demand (the GLB BIN chunk for a
    buffer without ``uri``, a base64 data URI, or a file relative to ``path``). Raises
    ``GltfProbesError`` for a file that is not glTF."""
    path = os.fspath(path)
    with open(path, "rb") as f:
        content = f.read()
    glb_bin = None
    if content[:4] == b"glTF":
        if len(content) < 20:
            raise GltfProbesError("file", "GLB header", "truncated")
        _, version, length = struct.unpack_from("<III", content, 0)
        if version != 2 or length != len(content):
            raise GltfProbesError("file", "GLB header", f"version {version}, length {length} for a "
                                  f"{len(content)}-byte file")
        chunk_len, chunk_type = struct.unpack_from("<II", content, 12)
        if chunk_type != _GLB_JSON or 20 + chunk_len > len(content):
            raise GltfProbesError("file", "GLB JSON chunk", "missing or truncated")
        text = content[20:20 + chunk_len]
        offset = 20 + chunk_len
        if offset + 8 <= len(content):
            chunk_len, chunk_type = struct.unpack_from("<II", content, offset)
            if chunk_type == _GLB_BIN:
                if offset + 8 + chunk_len > len(content):
                    raise GltfProbesError("file", "GLB BIN chunk", "truncated")
                glb_bin = content[offset + 8:offset + 8 + chunk_len]
    else:
        text = content
    try:
        document = json.loads(text.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as error:
        raise GltfProbesError("file", "JSON", str(error)) from None
    if not isinstance(document, dict):
        raise GltfProbesError("file", "JSON", "the document is not an object")
    base = os.path.dirname(path)
    cache: dict[int, bytes | None] = {}

    def buffer(index: int) -> bytes | None:
        if index in cache:
            return cache[index]
        entry = document.get("buffers", [])[index]
        uri = entry.get("uri") if isinstance(entry, dict) else None
        data = None
        if uri is None:
            data = glb_bin if index == 0 else None
        elif isinstance(uri, str) and uri.startswith("data:"):
            head, _, body = uri.partition(",")
            if head.endswith(";base64"):
                try:
                    data = base64.b64decode(body, validate=True)
                except ValueError:
                    data = None
        elif isinstance(uri, str):
            try:
                with open(os.path.join(base, urllib.parse.unquote(uri)), "rb") as f:
                    data = f.read()
            except OSError:
                data = None
        cache[index] = data
        return data

    return GltfFile(document, buffer)


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


class _Reader:
    """Bytes of a document's bufferViews and accessors, every step checked."""

    def __init__(self, gltf: GltfFile):
        self.document = gltf.document
        self.buffer = gltf.buffer

    def _entry(self, where, field, kind, index):
        items = self.document.get(kind)
        if not _is_int(index):
            raise GltfProbesError(where, field, f"must be an index into {kind}, got {index!r}")
        if not isinstance(items, list) or not 0 <= index < len(items):
            count = len(items) if isinstance(items, list) else 0
            raise GltfProbesError(where, field, f"{kind} index {index} out of range ({count} {kind})")
        entry = items[index]
        if not isinstance(entry, dict):
            raise GltfProbesError(where, field, f"{kind}[{index}] is not an object")
        return entry

    def view_bytes(self, where, field, index) -> tuple[bytes, dict]:
        view = self._entry(where, field, "bufferViews", index)
        label = f"bufferViews[{index}]"
        buffer_index = view.get("buffer")
        offset = view.get("byteOffset", 0)
        length = view.get("byteLength")
        if not _is_int(offset) or offset < 0:
            raise GltfProbesError(where, field, f"{label}.byteOffset must be an integer ≥ 0, got {offset!r}")
        if not _is_int(length) or length < 1:
            raise GltfProbesError(where, field, f"{label}.byteLength must be an integer ≥ 1, got {length!r}")
        buffer_entry = self._entry(where, f"{field} ({label}.buffer)", "buffers", buffer_index)
        declared = buffer_entry.get("byteLength")
        if not _is_int(declared) or declared < 1:
            raise GltfProbesError(where, field, f"buffers[{buffer_index}].byteLength must be an integer ≥ 1")
        if offset + length > declared:
            raise GltfProbesError(where, field, f"{label} (bytes {offset}..{offset + length}) runs past "
                                  f"buffers[{buffer_index}] ({declared} bytes)")
        data = self.buffer(buffer_index)
        if data is None:
            raise GltfProbesError(where, field, f"the data of buffers[{buffer_index}] cannot be read")
        if len(data) < declared:
            raise GltfProbesError(where, field, f"buffers[{buffer_index}] holds {len(data)} bytes, "
                                  f"its byteLength says {declared}")
        return bytes(memoryview(data)[offset:offset + length]), view

    def words(self, where, field, index, count, counted) -> np.ndarray:
        """``count`` little-endian uint32 words from bufferView ``index`` (``counted`` says where
        the count comes from)."""
        data, view = self.view_bytes(where, field, index)
        if view.get("byteOffset", 0) % 4:
            raise GltfProbesError(where, field, f"bufferViews[{index}].byteOffset must be a multiple of 4")
        if "byteStride" in view:
            raise GltfProbesError(where, field, f"bufferViews[{index}] must not have a byteStride")
        if len(data) != 4 * count:
            raise GltfProbesError(where, field, f"bufferViews[{index}].byteLength is {len(data)}, expected "
                                  f"{4 * count} ({count} uint32 words: {counted})")
        return np.frombuffer(data, "<u4").astype(np.uint32)

    def floats(self, where, field, index, kind, components, count, counted) -> np.ndarray:
        """(count, components) float32 from accessor ``index`` (FLOAT, ``kind``, ``count``;
        ``counted`` says where the count comes from)."""
        accessor = self._entry(where, field, "accessors", index)
        label = f"accessors[{index}]"
        expect = {"componentType": FLOAT, "type": kind, "count": count}
        for key, value in expect.items():
            if accessor.get(key) != value:
                why = f" ({counted})" if key == "count" else ""
                raise GltfProbesError(where, field, f"{label}.{key} is {accessor.get(key)!r}, expected "
                                      f"{value!r}{why}")
        if accessor.get("normalized", False) is not False:
            raise GltfProbesError(where, field, f"{label}.normalized must be false")
        if "sparse" in accessor:
            raise GltfProbesError(where, field, f"{label} must not be sparse")
        if "bufferView" not in accessor:
            raise GltfProbesError(where, field, f"{label} has no bufferView")
        offset = accessor.get("byteOffset", 0)
        if not _is_int(offset) or offset < 0 or offset % 4:
            raise GltfProbesError(where, field, f"{label}.byteOffset must be a multiple of 4 ≥ 0, got {offset!r}")
        data, view = self.view_bytes(where, f"{field} ({label})", accessor["bufferView"])
        element = 4 * components
        stride = view.get("byteStride", element)
        if stride != element:
            raise GltfProbesError(where, field, f"bufferViews[{accessor['bufferView']}].byteStride is "
                                  f"{stride!r}, expected {element} (tightly packed)")
        if offset + count * element > len(data):
            raise GltfProbesError(where, field, f"{label} needs {offset + count * element} bytes of its "
                                  f"bufferView, which has {len(data)}")
        values = np.frombuffer(data, "<f4", count * components, offset).astype(np.float32)
        if not np.isfinite(values).all():
            raise GltfProbesError(where, field, "holds NaN or infinite values")
        return values.reshape(count, components)


def _number_list(where, volume, name, *, positive=False) -> np.ndarray:
    value = volume.get(name)
    if not (isinstance(value, list) and len(value) == 3 and all(_is_number(x) for x in value)):
        raise GltfProbesError(where, name, f"must be 3 finite numbers, got {value!r}")
    if positive and not all(x > 0 for x in value):
        raise GltfProbesError(where, name, f"must be > 0 on every axis, got {value!r}")
    return np.array([float(x) for x in value], np.float64)


def _count(where, volume, name) -> int:
    value = volume.get(name)
    if not _is_int(value) or value < 0:
        raise GltfProbesError(where, name, f"must be an integer ≥ 0, got {value!r}")
    return value


def _check_corners(where, dims, volume_cells, volume_probes) -> None:
    """A corner shared by several volumes names one probe, and a probe sits at one corner."""
    cells = volume_cells.astype(np.int64)
    x, y, z = cells % dims[0], (cells // dims[0]) % dims[1], cells // (dims[0] * dims[1])
    xyz = np.stack([x, y, z], axis=1)[:, None, :] + CORNER_OFFSETS[None]
    corner = (xyz[..., 0] + (dims[0] + 1) * (xyz[..., 1] + (dims[1] + 1) * xyz[..., 2])).ravel()
    pairs = np.unique(np.stack([corner, volume_probes.astype(np.int64).ravel()], axis=1), axis=0)
    if len(np.unique(pairs[:, 0])) != len(pairs):
        raise GltfProbesError(where, "volumeProbes", "volumes sharing a grid corner name different probes there")
    if len(np.unique(pairs[:, 1])) != len(pairs):
        raise GltfProbesError(where, "volumeProbes", "a probe sits at two different grid corners")


def _decode_volume(reader: _Reader, index: int, volume) -> DecodedVolume:
    where = f"volume {index}"
    if not isinstance(volume, dict):
        raise GltfProbesError(where, "volume", "is not an object")
    name = volume.get("name", "")
    if not isinstance(name, str):
        raise GltfProbesError(where, "name", f"must be a string, got {name!r}")
    where = _where(index, name)
    node = volume.get("node")
    node_entry = reader._entry(where, "node", "nodes", node)
    node_extensions = node_entry.get("extensions")
    back = node_extensions.get(EXTENSION) if isinstance(node_extensions, dict) else None
    if not (isinstance(back, dict) and back.get("volume") == index):
        pointed = None if not isinstance(back, dict) else back.get("volume")
        raise GltfProbesError(where, "node", f"nodes[{node}] does not point back to this volume "
                              f"(its extensions.{EXTENSION}.volume is {pointed!r})")
    dims = volume.get("dims")
    if not (isinstance(dims, list) and len(dims) == 3 and all(_is_int(d) for d in dims)):
        raise GltfProbesError(where, "dims", f"must be 3 integers, got {dims!r}")
    if min(dims) < 1:
        raise GltfProbesError(where, "dims", f"every axis must be ≥ 1, got {dims}")
    corners = (dims[0] + 1) * (dims[1] + 1) * (dims[2] + 1)
    if corners > MAX_GRID_CORNERS:
        raise GltfProbesError(where, "dims", f"{dims} has {corners} grid corners, more than VoxGI reads "
                              f"({MAX_GRID_CORNERS})")
    cells = dims[0] * dims[1] * dims[2]
    origin = _number_list(where, volume, "origin")
    size = _number_list(where, volume, "volumeSize", positive=True)
    if volume.get("subdivisions") != SUBDIVISIONS:
        raise GltfProbesError(where, "subdivisions", f"must be {SUBDIVISIONS}, got {volume.get('subdivisions')!r}")
    threshold = volume.get("maskThreshold")
    if not _is_number(threshold) or not 0 <= threshold <= 1:
        raise GltfProbesError(where, "maskThreshold", f"must be a number in [0, 1], got {threshold!r}")
    p = _count(where, volume, "probeCount")
    v = _count(where, volume, "activeVolumeCount")
    if v > cells:
        raise GltfProbesError(where, "activeVolumeCount", f"{v} is more than the grid's {cells} volumes")
    if v and not p:
        raise GltfProbesError(where, "probeCount", f"0 with {v} active volumes")
    for names, count in ((("positions", "sh", "validity", "flags"), p),
                         (("volumeCells", "volumeProbes", "volumeMasks"), v)):
        for key in names:
            if count and key not in volume:
                raise GltfProbesError(where, key, "missing")
            if not count and key in volume:
                raise GltfProbesError(where, key, "present although its count is 0")
    if p:
        positions = reader.floats(where, "positions", volume["positions"], "VEC3", 3, p, "probeCount")
        sh = reader.floats(where, "sh", volume["sh"], "VEC3", 3, 9 * p, "9 × probeCount").reshape(p, 9, 3)
        validity = reader.floats(where, "validity", volume["validity"], "SCALAR", 1, p, "probeCount").reshape(p)
        if ((validity < 0) | (validity > 1)).any():
            raise GltfProbesError(where, "validity", "values must lie in [0, 1]")
        flags = reader.words(where, "flags", volume["flags"], p, "probeCount")
        if (flags & ~np.uint32(KNOWN_FLAGS)).any():
            bad = int(np.flatnonzero(flags & ~np.uint32(KNOWN_FLAGS))[0])
            raise GltfProbesError(where, "flags", f"probe {bad} has unknown bits set ({int(flags[bad]):#x})")
    else:
        positions, sh = np.zeros((0, 3), np.float32), np.zeros((0, 9, 3), np.float32)
        validity, flags = np.zeros(0, np.float32), np.zeros(0, np.uint32)
    if v:
        volume_cells = reader.words(where, "volumeCells", volume["volumeCells"], v, "activeVolumeCount")
        if int(volume_cells.max()) >= cells:
            raise GltfProbesError(where, "volumeCells", f"volume {int(volume_cells.max())} is outside the "
                                  f"{dims} grid ({cells} volumes)")
        if v > 1 and not (np.diff(volume_cells.astype(np.int64)) > 0).all():
            raise GltfProbesError(where, "volumeCells", "must be strictly ascending")
        volume_probes = reader.words(where, "volumeProbes", volume["volumeProbes"], 8 * v,
                                     "8 × activeVolumeCount").reshape(v, 8)
        if int(volume_probes.max()) >= p:
            raise GltfProbesError(where, "volumeProbes", f"probe index {int(volume_probes.max())} out of range "
                                  f"({p} probes)")
        _check_corners(where, dims, volume_cells, volume_probes)
        masks = reader.words(where, "volumeMasks", volume["volumeMasks"], 16 * v, "16 × activeVolumeCount")
        volume_masks = masks.astype("<u4").view("<u8").astype(np.uint64).reshape(v, 8)
    else:
        volume_cells = np.zeros(0, np.uint32)
        volume_probes = np.zeros((0, 8), np.uint32)
        volume_masks = np.zeros((0, 8), np.uint64)
    grid = ProbeGrid(origin=origin, volume_size=size, dims=np.array(dims, np.int64), positions=positions,
                     sh=sh, volume_cells=volume_cells, volume_probes=volume_probes,
                     volume_masks=volume_masks, validity=validity, flags=flags,
                     mask_threshold=float(threshold), name=name)
    return DecodedVolume(grid, node, index)


def decode_volumes(gltf: GltfFile) -> list[DecodedVolume]:
    """Every volume of the document's root ``VOXGI_irradiance_volumes`` extension ([] when the
    document has none). Raises ``GltfProbesError`` at the first thing that is wrong."""
    document = gltf.document
    extensions = document.get("extensions")
    if not isinstance(extensions, dict) or EXTENSION not in extensions:
        return []
    root = extensions[EXTENSION]
    if not isinstance(root, dict) or not isinstance(root.get("volumes"), list):
        raise GltfProbesError(EXTENSION, "volumes", "the root extension must be an object with a "
                              "'volumes' array")
    reader = _Reader(gltf)
    out = [_decode_volume(reader, i, volume) for i, volume in enumerate(root["volumes"])]
    nodes = [d.node for d in out]
    if len(set(nodes)) != len(nodes):
        raise GltfProbesError(EXTENSION, "node", f"two volumes share a node ({nodes})")
    return out


def read_volumes(path) -> list[DecodedVolume]:
    """``decode_volumes(read_gltf(path))``."""
    return decode_volumes(read_gltf(path))


def _local_matrix(where, node: dict) -> np.ndarray:
    if "matrix" in node:
        m = node["matrix"]
        if not (isinstance(m, list) and len(m) == 16 and all(_is_number(x) for x in m)):
            raise GltfProbesError(where, "matrix", "must be 16 finite numbers")
        return np.array(m, np.float64).reshape(4, 4).T  # column-major
    t = node.get("translation", [0.0, 0.0, 0.0])
    r = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    s = node.get("scale", [1.0, 1.0, 1.0])
    for key, value, n in (("translation", t, 3), ("rotation", r, 4), ("scale", s, 3)):
        if not (isinstance(value, list) and len(value) == n and all(_is_number(x) for x in value)):
            raise GltfProbesError(where, key, f"must be {n} finite numbers")
    x, y, z, w = r
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                    [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                    [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = rot * np.asarray(s, np.float64)[None, :]
    m[:3, 3] = t
    return m


def node_world_matrix(document: dict, node: int) -> np.ndarray:
    """(4, 4) float64: node ``node``'s local frame → the glTF world (its parents' transforms
    times its own)."""
    nodes = document.get("nodes", [])
    parent = {}
    for i, entry in enumerate(nodes):
        for child in (entry.get("children") or []) if isinstance(entry, dict) else []:
            if _is_int(child):
                parent.setdefault(child, i)
    m = np.eye(4)
    seen = set()
    while node is not None:
        if node in seen:
            raise GltfProbesError(f"nodes[{node}]", "children", "the node hierarchy has a cycle")
        seen.add(node)
        m = _local_matrix(f"nodes[{node}]", nodes[node]) @ m
        node = parent.get(node)
    return m


def scene_nodes(document: dict, scene) -> set[int]:
    """Indices of every node in scene ``scene`` (its roots and their descendants); every node
    when the document names no usable scene."""
    scenes = document.get("scenes")
    nodes = document.get("nodes") or []
    if not (_is_int(scene) and isinstance(scenes, list) and 0 <= scene < len(scenes)
            and isinstance(scenes[scene], dict)):
        return set(range(len(nodes)))
    out, todo = set(), list(scenes[scene].get("nodes") or [])
    while todo:
        n = todo.pop()
        if not _is_int(n) or n in out or not 0 <= n < len(nodes) or not isinstance(nodes[n], dict):
            continue
        out.add(n)
        todo.extend(nodes[n].get("children") or [])
    return out
