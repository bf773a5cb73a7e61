"""OpenEXR files of render passes, in plain Python (struct + zlib + numpy).

Writing: ``write_exr`` makes one single-part scanline file, uncompressed, with channels
``<Pass>.R/.G/.B`` — the layout Blender and other tools read as a multilayer image whose
layers are named like Cycles' passes.

Reading: ``read_exr`` reads scanline files, single-part or multi-part, with HALF, FLOAT or
UINT channels and NONE, RLE, ZIPS or ZIP compression. That covers what Blender 5.0 writes for
``OPEN_EXR_MULTILAYER`` with those codecs: by default one *part per pass* (multi-part,
part names ``ViewLayer.<Pass>``, channels ``ViewLayer.<Pass>.R`` …), or a single part holding
every channel when ``use_exr_interleave`` is on. Tiled files and the lossy/wavelet codecs
(PIZ, PXR24, B44, DWA) are refused with a clear error.

Images are (H, W) arrays with row 0 at the **top** (EXR's increasing-y scanline order).
"""
from __future__ import annotations

import os
import struct
import zlib

import numpy as np

__all__ = ["write_exr", "read_exr", "read_exr_passes", "group_passes", "exr_parts"]

_MAGIC = 20000630
_VERSION = 2
_FLAG_TILED = 0x200
_FLAG_LONG_NAMES = 0x400
_FLAG_DEEP = 0x800
_FLAG_MULTIPART = 0x1000

_UINT, _HALF, _FLOAT = 0, 1, 2
_PIXEL_DTYPES = {_UINT: np.dtype("<u4"), _HALF: np.dtype("<f2"), _FLOAT: np.dtype("<f4")}

_CODECS = {0: "NONE", 1: "RLE", 2: "ZIPS", 3: "ZIP", 4: "PIZ", 5: "PXR24", 6: "B44", 7: "B44A",
           8: "DWAA", 9: "DWAB"}
_LINES_PER_CHUNK = {"NONE": 1, "RLE": 1, "ZIPS": 1, "ZIP": 16}


# --------------------------------------------------------------------------- writing

def _attribute(name: str, type_name: str, payload: bytes) -> bytes:
    return name.encode() + b"\0" + type_name.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def _channel_list(names: list[str], pixel_type: int) -> bytes:
    body = b"".join(
        n.encode() + b"\0" + struct.pack("<iB3xii", pixel_type, 0, 1, 1) for n in names
    )
    return body + b"\0"


def write_exr(path, layers: dict[str, np.ndarray], half: bool = False) -> None:
    """Write passes as one single-part, uncompressed, scanline OpenEXR file.

    Parameters
    ----------
    path : file path (str or PathLike); overwritten.
    layers : pass name → (H, W, 3) image (row 0 = top), all the same H, W. Channels are written
        as ``<pass>.R``, ``<pass>.G``, ``<pass>.B`` (``.A`` too for (H, W, 4); a (H, W) or
        (H, W, 1) image becomes one channel ``<pass>.V``).
    half : store 16-bit floats instead of 32-bit.
    """
    if not layers:
        raise ValueError("write_exr needs at least one layer")
    channels: dict[str, np.ndarray] = {}
    shape = None
    for name, image in layers.items():
        image = np.asarray(image)
        if image.ndim == 2:
            image = image[:, :, None]
        if image.ndim != 3 or image.shape[2] not in (1, 3, 4):
            raise ValueError(f"layer {name!r}: expected (H, W, 3), got {image.shape}")
        if shape is None:
            shape = image.shape[:2]
        elif image.shape[:2] != shape:
            raise ValueError(f"layer {name!r} is {image.shape[:2]}, others are {shape}")
        suffixes = {1: "V", 3: "RGB", 4: "RGBA"}[image.shape[2]]
        for c, suffix in enumerate(suffixes):
            channels[f"{name}.{suffix}"] = image[:, :, c]
    height, width = shape
    if height < 1 or width < 1:
        raise ValueError("write_exr needs a non-empty image")
    names = sorted(channels, key=lambda n: n.encode())  # OpenEXR: sorted by byte value
    pixel_type = _HALF if half else _FLOAT
    dtype = _PIXEL_DTYPES[pixel_type]

    box = struct.pack("<iiii", 0, 0, width - 1, height - 1)
    header = b"".join([
        _attribute("channels", "chlist", _channel_list(names, pixel_type)),
        _attribute("compression", "compression", b"\x00"),
        _attribute("dataWindow", "box2i", box),
        _attribute("displayWindow", "box2i", box),
        _attribute("lineOrder", "lineOrder", b"\x00"),
        _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        _attribute("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
        _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]) + b"\0"
    flags = _FLAG_LONG_NAMES if max(len(n.encode()) for n in names) > 31 else 0
    prefix = struct.pack("<ii", _MAGIC, _VERSION | flags) + header

    # Scanline blocks of one line: y, byte count, then each channel's W values in name order.
    planes = np.stack([np.asarray(channels[n], dtype=np.float32) for n in names], axis=1)  # (H, C, W)
    pixels = planes.astype(dtype)
    line_bytes = pixels[0].nbytes
    chunk_size = 8 + line_bytes
    table_end = len(prefix) + 8 * height
    offsets = table_end + chunk_size * np.arange(height, dtype=np.int64)
    block = np.empty((height, chunk_size), dtype=np.uint8)
    block[:, 0:4] = np.arange(height, dtype="<i4").view(np.uint8).reshape(height, 4)
    block[:, 4:8] = np.frombuffer(struct.pack("<i", line_bytes), dtype=np.uint8)
    block[:, 8:] = pixels.reshape(height, -1).view(np.uint8).reshape(height, line_bytes)
    tmp = f"{os.fspath(path)}.tmp{os.getpid()}"
    with open(tmp, "wb") as f:
        f.write(prefix)
        f.write(offsets.astype("<u8").tobytes())
        f.write(block.tobytes())
    os.replace(tmp, path)


# --------------------------------------------------------------------------- reading

class _Reader:
    def __init__(self, data: bytes, pos: int = 0):
        self.data, self.pos = data, pos

    def cstring(self) -> str:
        end = self.data.index(b"\0", self.pos)
        text = self.data[self.pos:end].decode("utf-8", "replace")
        self.pos = end + 1
        return text

    def take(self, n: int) -> bytes:
        out = self.data[self.pos:self.pos + n]
        if len(out) != n:
            raise ValueError("truncated OpenEXR file")
        self.pos += n
        return out

    def unpack(self, fmt: str):
        return struct.unpack(fmt, self.take(struct.calcsize(fmt)))


def _parse_channels(payload: bytes) -> list[tuple[str, int, int, int]]:
    """(name, pixel type, x sampling, y sampling) per channel, in file order."""
    r, out = _Reader(payload), []
    while r.data[r.pos] != 0:
        name = r.cstring()
        pixel_type, _linear, xs, ys = r.unpack("<iB3xii")
        out.append((name, pixel_type, xs, ys))
    return out


def _parse_header(r: _Reader) -> dict:
    header = {}
    while True:
        name = r.cstring()
        if not name:
            return header
        type_name = r.cstring()
        (size,) = r.unpack("<i")
        payload = r.take(size)
        if type_name == "chlist":
            header[name] = _parse_channels(payload)
        elif type_name == "box2i":
            header[name] = struct.unpack("<iiii", payload)
        elif type_name in ("compression", "lineOrder"):
            header[name] = payload[0]
        elif type_name == "string":
            header[name] = payload.decode("utf-8", "replace")
        elif type_name == "int":
            header[name] = struct.unpack("<i", payload)[0]
        else:
            header[name] = payload


def _undo_predictor_and_interleave(raw: bytes) -> bytes:
    """ZIP/RLE post-processing: un-delta the bytes, then re-interleave the two halves."""
    t = np.frombuffer(raw, dtype=np.uint8)
    # t[0] = d[0], t[i] = t[i-1] + d[i] - 128 (mod 256)
    t = ((np.cumsum(t.astype(np.int64) - 128) + 128) % 256).astype(np.uint8)
    out = np.empty_like(t)
    half = (len(t) + 1) // 2
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def _rle_decode(data: bytes, expected: int) -> bytes:
    out, i = bytearray(), 0
    while i < len(data):
        count = struct.unpack("b", data[i:i + 1])[0]
        i += 1
        if count < 0:
            out += data[i:i - count]
            i -= count
        else:
            out += data[i:i + 1] * (count + 1)
            i += 1
    if len(out) != expected:
        raise ValueError("corrupt RLE block in OpenEXR file")
    return bytes(out)


def _decompress(codec: str, data: bytes, expected: int) -> bytes:
    if len(data) == expected:  # a block that would not shrink is stored raw
        return data
    if codec in ("ZIP", "ZIPS"):
        return _undo_predictor_and_interleave(zlib.decompress(data))
    if codec == "RLE":
        return _undo_predictor_and_interleave(_rle_decode(data, expected))
    raise ValueError(f"OpenEXR compression {codec} is not supported")


def _read_part(data: bytes, header: dict, offsets: np.ndarray, multipart: bool, part: int):
    x0, y0, x1, y1 = header["dataWindow"]
    width, height = x1 - x0 + 1, y1 - y0 + 1
    codec = _CODECS.get(header.get("compression", 0), "unknown")
    if codec not in _LINES_PER_CHUNK:
        raise ValueError(f"OpenEXR compression {codec} is not supported (use NONE, RLE, ZIPS or ZIP)")
    channels = header["channels"]
    if any(xs != 1 or ys != 1 for _, _, xs, ys in channels):
        raise ValueError("sub-sampled OpenEXR channels are not supported")
    dtypes = [_PIXEL_DTYPES[t] for _, t, _, _ in channels]
    out = {name: np.zeros((height, width), np.float32) for name, _, _, _ in channels}
    lines = _LINES_PER_CHUNK[codec]
    for offset in offsets:
        r = _Reader(data, int(offset))
        if multipart:
            (chunk_part,) = r.unpack("<i")
            if chunk_part != part:
                raise ValueError("OpenEXR chunk belongs to another part")
        y, size = r.unpack("<ii")
        row = y - y0
        count = min(lines, height - row)
        expected = count * width * sum(d.itemsize for d in dtypes)
        block = _decompress(codec, r.take(size), expected)
        pos = 0
        for line in range(count):
            for (name, _, _, _), dtype in zip(channels, dtypes):
                n = width * dtype.itemsize
                out[name][row + line] = np.frombuffer(block, dtype, width, pos)
                pos += n
    return out


def exr_parts(path) -> list[dict]:
    """Headers of every part of an OpenEXR file (attribute name → parsed value)."""
    with open(path, "rb") as f:
        data = f.read()
    return _parse(data)[0]


def _parse(data: bytes):
    r = _Reader(data)
    magic, version = r.unpack("<ii")
    if magic != _MAGIC:
        raise ValueError("not an OpenEXR file")
    if version & (_FLAG_TILED | _FLAG_DEEP):
        raise ValueError("tiled or deep OpenEXR files are not supported")
    multipart = bool(version & _FLAG_MULTIPART)
    headers = [_parse_header(r)]
    if multipart:
        while data[r.pos] != 0:
            headers.append(_parse_header(r))
        r.pos += 1
    return headers, r, multipart


def read_exr(path) -> dict[str, np.ndarray]:
    """Every channel of a scanline OpenEXR file: full channel name → (H, W) float32, row 0 on top.

    Multi-part files (Blender's multilayer default) are merged: channel names are unique across
    Blender's parts (``ViewLayer.Diffuse Direct.R`` …). See the module docstring for formats.
    """
    with open(path, "rb") as f:
        data = f.read()
    headers, r, multipart = _parse(data)
    tables = []
    for header in headers:
        if header.get("type", "scanlineimage") != "scanlineimage":
            raise ValueError(f"OpenEXR part type {header['type']!r} is not supported")
        _, y0, _, y1 = header["dataWindow"]
        codec = _CODECS.get(header.get("compression", 0), "unknown")
        count = header.get("chunkCount") or -(-(y1 - y0 + 1) // _LINES_PER_CHUNK.get(codec, 1))
        tables.append(np.frombuffer(r.take(8 * count), dtype="<u8"))
    result: dict[str, np.ndarray] = {}
    for part, (header, offsets) in enumerate(zip(headers, tables)):
        result.update(_read_part(data, header, offsets, multipart, part))
    return result


def read_exr_passes(path) -> dict[str, np.ndarray]:
    """Passes of a multilayer EXR: pass name → (H, W, 3) float32 (R, G, B), row 0 on top.

    See ``group_passes``.
    """
    return group_passes(read_exr(path))


def group_passes(channels: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Group ``read_exr`` channels into passes: pass name → (H, W, 3) float32 (R, G, B).

    A view-layer prefix is dropped (``ViewLayer.Diffuse Direct.R`` → ``Diffuse Direct``); an A
    channel is left out; X/Y/Z passes (``Position``, ``Normal``) come as (H, W, 3) too; passes
    without such channels (single-value passes such as ``Depth``) are returned as (H, W, 1) from
    their first channel.
    """
    grouped: dict[str, dict[str, np.ndarray]] = {}
    for name, plane in channels.items():
        base, _, suffix = name.rpartition(".")
        pass_name = base.rpartition(".")[2] if base else ""
        grouped.setdefault(pass_name, {})[suffix] = plane
    passes = {}
    for name, planes in grouped.items():
        if all(c in planes for c in "RGB"):
            passes[name] = np.stack([planes["R"], planes["G"], planes["B"]], axis=-1)
        elif all(c in planes for c in "XYZ"):
            passes[name] = np.stack([planes["X"], planes["Y"], planes["Z"]], axis=-1)
        else:
            passes[name] = planes[sorted(planes)[0]][:, :, None]
    return passes
