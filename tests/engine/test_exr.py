"""OpenEXR writing and reading (plain Python): round trips, header layout, every supported codec.

Blender-written files (multi-part ZIP, interleaved single part) are read in the Blender lane
(tests/blender/test_exr_files.py); here a small reference encoder builds compressed and
multi-part files the way the OpenEXR format describes them.
"""
import struct
import zlib

import numpy as np
import pytest

from voxgi.voxgi_addon.files.exr import exr_parts, read_exr, read_exr_passes, write_exr

CODEC_ID = {"NONE": 0, "RLE": 1, "ZIPS": 2, "ZIP": 3}
LINES = {"NONE": 1, "RLE": 1, "ZIPS": 1, "ZIP": 16}


def sample_layers(h=7, w=5, seed=0):
    rng = np.random.default_rng(seed)
    return {name: rng.normal(size=(h, w, 3)).astype(np.float32) * 10
            for name in ("Diffuse Direct", "Combined", "Ambient Occlusion", "Diffuse Indirect")}


def test_round_trip_is_exact_and_names_are_sorted(tmp_path):
    layers = sample_layers()
    path = tmp_path / "passes.exr"
    write_exr(path, layers)
    channels = read_exr(path)
    expected = sorted(f"{n}.{c}" for n in layers for c in "RGB")
    assert list(channels) == expected  # file order = OpenEXR's sorted order
    for name, image in layers.items():
        for c, suffix in enumerate("RGB"):
            np.testing.assert_array_equal(channels[f"{name}.{suffix}"], image[:, :, c])
    passes = read_exr_passes(path)
    assert set(passes) == set(layers)
    for name in layers:
        np.testing.assert_array_equal(passes[name], layers[name])


def test_header_layout_is_a_plain_uncompressed_scanline_file(tmp_path):
    path = tmp_path / "a.exr"
    write_exr(path, {"Combined": np.zeros((3, 4, 3), np.float32)})
    data = path.read_bytes()
    magic, version = struct.unpack("<ii", data[:8])
    assert magic == 20000630 and version == 2  # single part, scanline, short names
    (header,) = exr_parts(path)
    assert {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "pixelAspectRatio",
            "screenWindowCenter", "screenWindowWidth"} <= set(header)
    assert header["compression"] == 0 and header["lineOrder"] == 0
    assert header["dataWindow"] == header["displayWindow"] == (0, 0, 3, 2)
    assert [(n, t) for n, t, _, _ in header["channels"]] == [("Combined.B", 2), ("Combined.G", 2), ("Combined.R", 2)]
    # header, 3 offsets, then 3 lines of (y, byte count, 3 channels × 4 pixels × 4 bytes)
    table = len(data) - 3 * (8 + 48) - 3 * 8
    assert data[table - 1] == 0  # the header's terminating null
    offsets = struct.unpack("<3Q", data[table:table + 24])
    assert offsets == tuple(table + 24 + 56 * y for y in range(3))
    assert [struct.unpack("<ii", data[o:o + 8]) for o in offsets] == [(y, 48) for y in range(3)]


def test_half_floats_and_long_names(tmp_path):
    image = np.linspace(-4, 4, 2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    long_name = "A Very Long Pass Name For Long Names"
    write_exr(tmp_path / "h.exr", {long_name: image}, half=True)
    version = struct.unpack("<i", (tmp_path / "h.exr").read_bytes()[4:8])[0]
    assert version & 0x400  # long-name flag for channel names over 31 bytes
    back = read_exr_passes(tmp_path / "h.exr")[long_name]
    np.testing.assert_array_equal(back, image.astype(np.float16).astype(np.float32))
    assert exr_parts(tmp_path / "h.exr")[0]["channels"][0][1] == 1  # HALF


def test_bad_input_is_refused(tmp_path):
    with pytest.raises(ValueError):
        write_exr(tmp_path / "x.exr", {})
    with pytest.raises(ValueError):
        write_exr(tmp_path / "x.exr", {"A": np.zeros((2, 2, 3)), "B": np.zeros((3, 2, 3))})
    (tmp_path / "junk.exr").write_bytes(b"not an exr file")
    with pytest.raises(ValueError):
        read_exr(tmp_path / "junk.exr")


# --------------------------------------------------------------------------- reference encoder

def _predict_and_split(raw: bytes) -> bytes:
    """OpenEXR's ZIP/RLE preprocessing: even bytes then odd bytes, then byte deltas + 128."""
    b = np.frombuffer(raw, np.uint8)
    t = np.concatenate([b[0::2], b[1::2]]).astype(np.int64)
    d = t.copy()
    d[1:] = (t[1:] - t[:-1] + 128) % 256
    return d.astype(np.uint8).tobytes()


def _rle(data: bytes) -> bytes:
    out, i = bytearray(), 0
    while i < len(data):
        run = 1
        while i + run < len(data) and data[i + run] == data[i] and run < 128:
            run += 1
        if run >= 3:
            out += struct.pack("b", run - 1) + data[i:i + 1]
            i += run
        else:
            j = i
            while j < len(data) and j - i < 127 and not (j + 2 < len(data) and data[j] == data[j + 1] == data[j + 2]):
                j += 1
            out += struct.pack("b", -(j - i)) + data[i:j]
            i = j
    return bytes(out)


def _compress(codec, raw):
    if codec == "NONE":
        return raw
    packed = _predict_and_split(raw)
    data = zlib.compress(packed) if codec in ("ZIP", "ZIPS") else _rle(packed)
    return data if len(data) < len(raw) else raw


def _attr(name, kind, payload):
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(payload)) + payload


def encode_exr(parts, half=False):
    """Bytes of an EXR file: ``parts`` = [(part name or None, {channel: (H, W)}, codec)]; more
    than one part makes a multi-part file (chunks tagged with their part number)."""
    multipart = len(parts) > 1
    pixel = 1 if half else 2
    dtype = np.float16 if half else np.float32
    headers, chunk_lists = [], []
    for name, channels, codec in parts:
        names = sorted(channels)
        h, w = next(iter(channels.values())).shape
        count = -(-h // LINES[codec])
        chlist = b"".join(n.encode() + b"\0" + struct.pack("<iB3xii", pixel, 0, 1, 1) for n in names) + b"\0"
        box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
        header = [_attr("channels", "chlist", chlist),
                  _attr("compression", "compression", bytes([CODEC_ID[codec]])),
                  _attr("dataWindow", "box2i", box), _attr("displayWindow", "box2i", box),
                  _attr("lineOrder", "lineOrder", b"\0"),
                  _attr("pixelAspectRatio", "float", struct.pack("<f", 1)),
                  _attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0)),
                  _attr("screenWindowWidth", "float", struct.pack("<f", 1))]
        if multipart:
            header += [_attr("name", "string", name.encode()), _attr("type", "string", b"scanlineimage"),
                       _attr("chunkCount", "int", struct.pack("<i", count))]
        headers.append(b"".join(header) + b"\0")
        chunks = []
        for y in range(0, h, LINES[codec]):
            rows = range(y, min(h, y + LINES[codec]))
            raw = b"".join(channels[n][r].astype(dtype).tobytes() for r in rows for n in names)
            data = _compress(codec, raw)
            chunks.append(struct.pack("<ii", y, len(data)) + data)
        chunk_lists.append(chunks)
    flags = 0x1000 if multipart else 0
    prefix = struct.pack("<ii", 20000630, 2 | flags) + b"".join(headers) + (b"\0" if multipart else b"")
    table_size = 8 * sum(len(c) for c in chunk_lists)
    offset, tables, body = len(prefix) + table_size, [], []
    for part, chunks in enumerate(chunk_lists):
        for chunk in chunks:
            chunk = (struct.pack("<i", part) if multipart else b"") + chunk
            tables.append(struct.pack("<Q", offset))
            body.append(chunk)
            offset += len(chunk)
    return prefix + b"".join(tables) + b"".join(body)


@pytest.mark.parametrize("codec", ["NONE", "RLE", "ZIPS", "ZIP"])
@pytest.mark.parametrize("half", [False, True])
def test_every_supported_codec_reads_back(tmp_path, codec, half):
    rng = np.random.default_rng(1)
    h, w = 37, 11  # ZIP: two full 16-line chunks and a partial one
    smooth = np.add.outer(np.arange(h), np.arange(w)).astype(np.float32) / 7  # compresses well
    channels = {"ViewLayer.Combined.R": smooth, "ViewLayer.Combined.G": np.zeros((h, w), np.float32),
                "ViewLayer.Diffuse Direct.R": rng.normal(size=(h, w)).astype(np.float32)}
    path = tmp_path / f"{codec}.exr"
    path.write_bytes(encode_exr([(None, channels, codec)], half=half))
    got = read_exr(path)
    dtype = np.float16 if half else np.float32
    for name, image in channels.items():
        np.testing.assert_array_equal(got[name], image.astype(dtype).astype(np.float32))


def test_multi_part_files_merge_their_channels(tmp_path):
    h, w = 20, 6
    parts = []
    expected = {}
    for i, (pass_name, codec) in enumerate([("Combined", "ZIP"), ("Diffuse Direct", "ZIPS"), ("AO", "NONE")]):
        channels = {f"ViewLayer.{pass_name}.{c}": np.full((h, w), i * 3 + k, np.float32) + np.arange(w)
                    for k, c in enumerate("RGB")}
        expected.update(channels)
        parts.append((f"ViewLayer.{pass_name}", channels, codec))
    path = tmp_path / "multi.exr"
    path.write_bytes(encode_exr(parts))
    got = read_exr(path)
    assert set(got) == set(expected)
    for name, image in expected.items():
        np.testing.assert_array_equal(got[name], image)
    passes = read_exr_passes(path)
    assert set(passes) == {"Combined", "Diffuse Direct", "AO"} and passes["AO"].shape == (h, w, 3)
    assert [p["name"] for p in exr_parts(path)] == ["ViewLayer.Combined", "ViewLayer.Diffuse Direct", "ViewLayer.AO"]


def test_unsupported_codecs_are_named(tmp_path):
    data = bytearray(encode_exr([(None, {"R": np.zeros((2, 2), np.float32)}, "NONE")]))
    at = data.index(b"compression\0compression\0") + len(b"compression\0compression\0") + 4
    data[at] = 4  # PIZ
    (tmp_path / "piz.exr").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="PIZ"):
        read_exr(tmp_path / "piz.exr")
